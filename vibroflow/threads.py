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
import time
import warnings

from .errors import InputError

_requested: int | None = None

#: libgomp's spin before a waiting thread sleeps (iterations, GOMP_SPINCOUNT): long enough to
#: span a DEM step's barrier waits while every thread has a core to itself, short when other
#: processes need the cores, where a spinning thread starves the one still working
#: (docs/decisions/threads.md, "How long a waiting thread spins")
SPIN_FREE, SPIN_BUSY = 10_000, 1_000


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


def warn_if_tbb_launched(numba_module) -> bool:
    """Warn (RuntimeWarning, one line) when numba's parallel loops already run on TBB: numba was
    imported and its threads launched (numba.set_num_threads, a parallel function) before
    `import vibroflow` could put OpenMP first (vibroflow/__init__.py), and a launched layer is
    kept for the process, whose runs are then many times slower (tub47's Eulerian step 1.4 -
    5.9 ms against 0.2 ms, growing with every call).  numba_module: numba (or a stand-in with
    its `threading_layer`).  Returns whether it warned."""
    try:
        layer = numba_module.threading_layer()
    except ValueError:  # no parallel loop has run yet: the priority set at import applies
        return False
    if layer != "tbb":
        return False
    warnings.warn("numba's parallel loops already run on TBB (numba's threads were started "
                  "before `import vibroflow`): vibroflow's runs are many times slower on it; "
                  "import vibroflow first, or set NUMBA_THREADING_LAYER=omp",
                  RuntimeWarning, stacklevel=3)
    return True


def threads_fit(others_running: int, cores: int, threads: int) -> bool:
    """Whether `threads` threads and the `others_running` threads of other processes all fit
    on a machine of `cores` cores (the test of spin_count and cores_free)."""
    return others_running + threads <= cores


def spin_count(others_running: int, cores: int, threads: int) -> int:
    """GOMP_SPINCOUNT for `threads` threads on a machine of `cores` cores where
    `others_running` other threads are running: SPIN_FREE when they all fit on the cores
    (threads_fit), else SPIN_BUSY."""
    return SPIN_FREE if threads_fit(others_running, cores, threads) else SPIN_BUSY


def _own_running() -> int:
    """This process's threads that are running now (their state R in /proc/self/task; at
    least the one reading): a library's worker threads that spin after their start (a BLAS
    pool's, say) are this process's, not another's."""
    n = 0
    try:
        tasks = os.listdir("/proc/self/task")
    except OSError:
        return 1
    for task in tasks:
        try:
            with open(f"/proc/self/task/{task}/stat", "rb") as f:
                stat = f.read()
        except OSError:
            continue
        end = stat.rfind(b")")
        n += stat[end + 2:end + 3] == b"R"
    return max(n, 1)


def others_running(reads: int = 3, pause_s: float = 1e-3) -> int | None:
    """Threads of other processes running or ready to run on the machine now: the least of
    `reads` reads of /proc/stat's procs_running less this process's running threads,
    `pause_s` apart, so that a process passing through does not count; None where /proc/stat
    does not say."""
    least = None
    for k in range(reads):
        try:
            with open("/proc/stat", "rb") as f:
                line = next(ln for ln in f if ln.startswith(b"procs_running"))
            n = int(line.split()[1]) - _own_running()
        except (OSError, StopIteration, ValueError, IndexError):
            return None
        least = n if least is None else min(least, n)
        if k + 1 < reads:
            time.sleep(pause_s)
    return max(least, 0) if least is not None else None


#: how long a reading of the machine's load (others_running) serves `cores_free` (s)
FREE_READ_S = 10.0
_free_read: tuple[float, int | None, int] | None = None


def cores_free(threads: int, max_age_s: float = FREE_READ_S) -> bool:
    """Whether `threads` threads fit on the cores that other processes leave free now
    (others_running, threads_fit); False where the load is unknown.  The reading is
    kept max_age_s seconds, so that a caller may ask before every batch of steps (a reading
    costs about 2 ms)."""
    global _free_read
    now = time.monotonic()
    if _free_read is None or now - _free_read[0] > max_age_s:
        # the machine's core count kept with the reading: os.cpu_count reads /sys (~20 us)
        _free_read = (now, others_running(), os.cpu_count() or 1)
    others = _free_read[1]
    return others is not None and threads_fit(others, _free_read[2], threads)


def default_spin_env() -> None:
    """GOMP_SPINCOUNT from spin_count() unless the environment sets it or OMP_WAIT_POLICY
    (called by `import vibroflow` after default_threads_env, so that the thread count is
    known; libgomp reads it when numba first starts its threads).  Where the machine's load
    is unknown, SPIN_BUSY."""
    if {"GOMP_SPINCOUNT", "OMP_WAIT_POLICY"} & set(os.environ):
        return
    try:
        threads = int(os.environ.get("NUMBA_NUM_THREADS", "")) or allowed_cores()
    except ValueError:
        threads = allowed_cores()
    others = others_running()
    os.environ["GOMP_SPINCOUNT"] = str(
        SPIN_BUSY if others is None else spin_count(others, os.cpu_count() or 1, threads))


#: the most threads a run takes per core it may use: beyond, threads only wait for each other
#: (a 2-core machine's tests run 1, 2 and 4)
THREADS_PER_CORE_MAX = 8


def check_threads_env() -> None:
    """InputError (one line) when NUMBA_NUM_THREADS is set to anything but a whole number >= 1
    (numba would stop with a traceback, or warn and use every core)."""
    raw = os.environ.get("NUMBA_NUM_THREADS")
    if raw is None:
        return
    try:
        n = int(raw)
    except ValueError:
        n = 0
    if n < 1:
        raise InputError(f"NUMBA_NUM_THREADS = {raw!r}: a whole number of threads, at least 1 "
                         "(or unset: every core the process may use)")


def use_threads(n: int | None) -> None:
    """Run numba's parallel loops on n threads from now on (None: leave the default).  Before
    numba is imported this sets NUMBA_NUM_THREADS; after, numba.set_num_threads, up to numba's
    NUMBA_NUM_THREADS.  InputError for n < 1 or beyond that limit."""
    global _requested
    if n is None:
        return
    if n < 1:
        raise InputError(f"--threads = {n}: a whole number of threads, at least 1")
    most = THREADS_PER_CORE_MAX * allowed_cores()
    if n > most:
        raise InputError(f"--threads = {n}: at most {most} here ({THREADS_PER_CORE_MAX} a core "
                         f"of the {allowed_cores()} this process may use)")
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
