"""How many threads numba's parallel loops run on: by default every core the process may use
(its CPU affinity, `os.sched_getaffinity`), else NUMBA_NUM_THREADS, else `--threads N`.

The numbers of a run do not depend on the choice (the DEM: vibroflow.dem.step; the continuum:
run.force_chunks, DEVELOPERS.md "Threads"), only its speed does.  `import vibroflow` sets
NUMBA_NUM_THREADS to the affinity's core count when the environment does not name one (numba's
own default is every core of the machine, which a process pinned to a few cores oversubscribes).
"""
from __future__ import annotations

import os
import sys

from .errors import InputError

_requested: int | None = None


def allowed_cores() -> int:
    """The cores this process may run on (its affinity; every core where none is known)."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def default_threads_env() -> None:
    """NUMBA_NUM_THREADS set to allowed_cores() unless the environment names it (called by
    `import vibroflow`, before numba is imported)."""
    if "NUMBA_NUM_THREADS" not in os.environ and "numba" not in sys.modules:
        os.environ["NUMBA_NUM_THREADS"] = str(allowed_cores())


def use_threads(n: int | None) -> None:
    """Run numba's parallel loops on n threads from now on (None: leave the default).  Before
    numba is imported this sets NUMBA_NUM_THREADS; after, numba.set_num_threads, up to numba's
    NUMBA_NUM_THREADS.  InputError for n < 1 or beyond that limit."""
    global _requested
    if n is None:
        return
    if n < 1:
        raise InputError(f"--threads = {n}: a whole number of threads, at least 1")
    if "numba" not in sys.modules:
        os.environ["NUMBA_NUM_THREADS"] = str(n)
    else:
        import numba

        limit = numba.config.NUMBA_NUM_THREADS
        if n > limit:
            raise InputError(f"--threads = {n}: at most {limit} here (NUMBA_NUM_THREADS)")
        numba.set_num_threads(n)
    _requested = n


def requested_threads() -> int | None:
    """The thread count a caller chose with use_threads, or None (the default)."""
    return _requested
