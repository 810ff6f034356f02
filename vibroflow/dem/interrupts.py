"""Ctrl-C during a DEM run, and the fault injection its tests use (environment variables that make
the run interrupt or kill itself at a known instant, deterministic where a signal from outside
would race the run).  The end-of-run kill points are vibroflow.dem.output.fault_kill_at.
"""
from __future__ import annotations

import contextlib
import os
import signal
import threading
from collections.abc import Iterator


@contextlib.contextmanager
def deferred_sigint() -> Iterator[dict]:
    """While the block runs, a first SIGINT only sets flag["raised"]; the caller stops at its
    next safe point (state and result rows consistent) with a checkpoint.  A KeyboardInterrupt
    raised anywhere else could land between the compiled step's return and the step count's
    update, and a checkpoint of that state would resume with other numbers.  A second SIGINT
    raises KeyboardInterrupt at once.  Only in the main thread with Python's own handler in
    place (a SIGINT ignored or handled by the caller is left so)."""
    flag = {"raised": False}
    install = (threading.current_thread() is threading.main_thread()
               and signal.getsignal(signal.SIGINT) is signal.default_int_handler)

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
            signal.signal(signal.SIGINT, signal.default_int_handler)


def fault_after_checkpoint() -> None:
    """Fault injection for the resume tests: with VIBROFLOW_FAULT_KILL_AFTER_CHECKPOINT=1 in
    the environment the process SIGKILLs itself as soon as its first checkpoint is on disk,
    the deterministic version of a power cut (a test that kills from outside races a fast
    machine, which may finish the run between the checkpoint and the signal)."""
    if os.environ.get("VIBROFLOW_FAULT_KILL_AFTER_CHECKPOINT") == "1":
        os.kill(os.getpid(), signal.SIGKILL)


def fault_sigint_after_steps() -> int | None:
    """Fault injection for the Ctrl-C tests: VIBROFLOW_FAULT_SIGINT_AFTER_STEPS=N makes the
    run send itself a SIGINT as soon as N vibration steps are done (at the return of the
    compiled call that passes N), deterministic where a signal from outside races the run."""
    value = os.environ.get("VIBROFLOW_FAULT_SIGINT_AFTER_STEPS")
    return int(value) if value else None


def fault_sigint_settling() -> None:
    """Fault injection: VIBROFLOW_FAULT_SIGINT_SETTLING=1 sends a SIGINT after each settling
    chunk (a Ctrl-C while the fill settles)."""
    if os.environ.get("VIBROFLOW_FAULT_SIGINT_SETTLING") == "1":
        os.kill(os.getpid(), signal.SIGINT)
