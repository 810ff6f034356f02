"""Ctrl-C (SIGINT) during a run's loop, shared by the DEM and the continua: the first one only
asks the loop to stop at its next safe point, where it writes a checkpoint; a second one stops
it at once."""
from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator

#: the fault-injection hook of the Ctrl-C tests: VIBROFLOW_FAULT_SIGINT_AFTER_STEPS=N makes a
#: run send itself a SIGINT after N vibration steps (vibroflow.dem.interrupts,
#: vibroflow.continuum.timeline.FaultSigint)
FAULT_SIGINT_ENV = "VIBROFLOW_FAULT_SIGINT_AFTER_STEPS"


@contextlib.contextmanager
def deferred_sigint(over_any_handler: bool = False) -> Iterator[dict]:
    """While the block runs, a first SIGINT only sets flag["raised"]; the caller stops at its
    next safe point (state, samples and result rows consistent) with a checkpoint.  A
    KeyboardInterrupt raised at an arbitrary bytecode could land between a compiled step's
    return and the step count's update, or half-way through a sample, and a checkpoint of that
    state would resume with other numbers.  A second SIGINT raises KeyboardInterrupt at once.

    Installed only in the main thread (Python runs signal handlers there) and over Python's own
    handler; with over_any_handler, over any handler but an ignored one (SIG_IGN, or None: one
    not installed from Python).  Otherwise the caller's SIGINT handling is left so and the flag
    stays unset.  The previous handler is back when the block ends."""
    flag = {"raised": False}
    previous = signal.getsignal(signal.SIGINT)
    if over_any_handler:
        replaceable = previous not in (signal.SIG_IGN, None)
    else:
        replaceable = previous is signal.default_int_handler
    install = threading.current_thread() is threading.main_thread() and replaceable

    def handler(signum, frame):
        if flag["raised"]:
            raise KeyboardInterrupt
        flag["raised"] = True

    if install:
        signal.signal(signal.SIGINT, handler)
    try:
        yield flag
    finally:
        if install:
            signal.signal(signal.SIGINT, previous)
