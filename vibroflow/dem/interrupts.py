"""Ctrl-C during a DEM run, and the fault injection its tests use (environment variables that make
the run interrupt or kill itself at a known instant, deterministic where a signal from outside
would race the run).  The end-of-run kill points are vibroflow.dem.output.fault_kill_at.  The
deferred Ctrl-C of the vibration loop is vibroflow.interrupts' deferred_sigint, shared with the
continua.
"""
from __future__ import annotations

import os
import signal

from ..interrupts import FAULT_SIGINT_ENV


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
    value = os.environ.get(FAULT_SIGINT_ENV)
    return int(value) if value else None


def fault_sigint_settling() -> None:
    """Fault injection: VIBROFLOW_FAULT_SIGINT_SETTLING=1 sends a SIGINT after each settling
    chunk (a Ctrl-C while the fill settles)."""
    if os.environ.get("VIBROFLOW_FAULT_SIGINT_SETTLING") == "1":
        os.kill(os.getpid(), signal.SIGINT)
