"""A run's wall clock, with numba's compilation counted apart.

Why.  Every solver of the package (the DEM, both continua) runs numba kernels with
`cache=True`.  On a warm cache a kernel loads in milliseconds; on a cold one (a fresh clone, a
new machine, or any edit of the package's sources, which clears the whole cache:
vibroflow._kernel_cache) the first call compiles it, and the fused continuum loops take
30 - 50 s to compile where the tub47 run itself takes 2 - 6 s.  A run's wall time that holds
that one-off cost says nothing of the method: on a cold cache a cost line would read about
x0.16 for a Lagrangian continuum about 200 times cheaper than its DEM (docs/validation.md).

How.  numba announces each compilation as a "numba:compile" event (numba.core.event; nested
compilations of the callees inside one outer event, and a cache load none at all).  A
TimingListener installed for the run sums the outermost events' durations; the clock's
`solver_s()` is the wall time since it started less that sum.  Each driver reports both in its
summary.json: `wall_time_s` (the solver's time, compilation excluded, the figure the cost
ratios use) and `compile_time_s` (what compilation took in this process).  Loading cached
kernels, importing and reading input stay in wall_time_s: every run pays them.

A resumed run carries the solver time of the runs before it (`before_s`), as the drivers'
checkpoints did with their wall time; its own compilation is excluded again.
"""
from __future__ import annotations

import time

from numba.core import event as numba_event


class RunClock:
    """Wall clock of one run, less numba's compilation (module docstring).  Use as a context
    manager around the run: the compilation listener is installed on entry and removed on
    exit; `solver_s()` and `compile_s()` may be read at any time inside and after."""

    def __init__(self, before_s: float = 0.0):
        self.before_s = float(before_s)
        self._listener = numba_event.TimingListener()
        self._t0: float | None = None
        self._t1: float | None = None

    def __enter__(self) -> RunClock:
        numba_event.register("numba:compile", self._listener)
        self._t0 = time.perf_counter()
        return self

    def __exit__(self, *exc) -> None:
        self._t1 = time.perf_counter()
        numba_event.unregister("numba:compile", self._listener)

    def compile_s(self) -> float:
        """Seconds this run spent compiling numba kernels (0 on a warm cache)."""
        return self._listener.duration if self._listener.done else 0.0

    def elapsed_s(self) -> float:
        """Wall seconds since the clock started (to its exit, once exited)."""
        if self._t0 is None:
            return 0.0
        end = self._t1 if self._t1 is not None else time.perf_counter()
        return end - self._t0

    def solver_s(self) -> float:
        """The run's solver time (s): the runs before a resume, plus this one's wall time
        less its compilation."""
        return self.before_s + max(self.elapsed_s() - self.compile_s(), 0.0)

    def resume_from(self, before_s: float) -> None:
        """Carry `before_s` (s) of solver time from a checkpoint."""
        self.before_s = float(before_s)
