"""Progress display of long runs: simulated time, particle-steps per second, time left.

While numba compiles the kernels (the first run after an install or an edit of the package,
which clears the cache: vibroflow._kernel_cache) the display says so, with the seconds spent,
from a small timer thread that watches numba's "numba:compile" events.  The time left is an
estimate from the rate measured since the last compilation ended: "estimating ..." until a
second of steps has run outside compilation, never negative.  On a terminal the display is a
rich progress bar; elsewhere (a log file, a pipe) it is plain lines, never wrapped.
"""
from __future__ import annotations

import sys
import threading
import time

from numba.core import event as numba_event
from rich.console import Console
from rich.progress import BarColumn, Progress, ProgressColumn, TaskProgressColumn, TextColumn
from rich.text import Text

COMPILING = "compiling the kernels (once per install) ..."
#: the line that ends it, before its seconds: "kernels compiled (N s)"
COMPILED = "kernels compiled"
#: seconds of steps outside compilation before a time left is shown
MEASURE_S = 1.0
#: seconds a compilation runs before it is announced (numba compiles small things in passing)
ANNOUNCE_S = 0.5
#: seconds between two plain progress lines
PLAIN_EVERY_S = 10.0


def format_duration(seconds: float) -> str:
    """A wall time for the progress lines: s, min or h."""
    seconds = max(0.0, seconds)
    if seconds < 60:
        return f"{seconds:.0f} s"
    if seconds < 3600:
        return f"{seconds / 60:.1f} min"
    return f"{seconds / 3600:.1f} h"


def left_text(left: float | None) -> str:
    """The time left of a progress line: 'estimating ...' without a measured rate."""
    if left is None:
        return "estimating ..."
    return f"{format_duration(left)} left"


class CompileWatch(numba_event.Listener):
    """numba's outermost "numba:compile" events: whether one is open, since when, and the
    seconds all of them took (nested events count once)."""

    def __init__(self):
        self._lock = threading.Lock()
        self._depth = 0
        self._since: float | None = None
        self._closed_s = 0.0

    def on_start(self, event) -> None:
        with self._lock:
            if self._depth == 0:
                self._since = time.perf_counter()
            self._depth += 1

    def on_end(self, event) -> None:
        with self._lock:
            self._depth = max(0, self._depth - 1)
            if self._depth == 0 and self._since is not None:
                self._closed_s += time.perf_counter() - self._since
                self._since = None

    def open_s(self) -> float | None:
        """Seconds of the compilation open now, None when none is."""
        since = self._since
        return None if since is None else time.perf_counter() - since

    def total_s(self) -> float:
        """Seconds of compilation so far, the open one included."""
        return self._closed_s + (self.open_s() or 0.0)


class _Rate(ProgressColumn):
    def render(self, task):
        rate = task.fields.get("rate")
        return Text(f"{rate / 1e6:6.2f} M particle-steps/s" if rate else "", style="cyan")


class _SimTime(ProgressColumn):
    def render(self, task):
        t = task.fields.get("sim_time")
        end = task.fields.get("sim_end")
        if t is None:
            return Text("")
        unit = task.fields.get("unit", "s")
        if unit != "s":
            return Text(f"{t:.0f} / {end:.0f} {unit}", style="green")
        return Text(f"t = {t:.4f} / {end:.4f} s", style="green")


class _Left(ProgressColumn):
    def render(self, task):
        if task.fields.get("compiling"):
            return Text("")
        return Text(left_text(task.fields.get("left")), style="cyan")


class RunProgress:
    """A progress display over one stage at a time; silent when `enabled` is False."""

    def __init__(self, enabled: bool = True, console: Console | None = None):
        self.enabled = enabled
        self.console = console or Console(file=sys.stderr)
        self._progress = None
        self._task = None
        self._compile_task = None
        self._watch = CompileWatch()
        self._ticker: threading.Thread | None = None
        self._stop = threading.Event()
        self._compile_said = 0.0
        self._compile_from = 0.0
        self._t0 = None
        self._base: tuple[float, float, int, float] | None = None
        self._plain_last = 0.0
        self._desc = ""
        self._end = 0.0
        self._unit = "s"

    @property
    def plain(self) -> bool:
        """Plain lines (a log file, a pipe) rather than a live bar (a terminal)."""
        return not self.console.is_terminal

    def __enter__(self):
        if not self.enabled:
            return self
        if not self.plain:
            self._progress = Progress(
                TextColumn("[bold]{task.description}"), BarColumn(), TaskProgressColumn(),
                _SimTime(), _Rate(), _Left(),
                console=self.console, transient=False, refresh_per_second=4)
            self._progress.__enter__()
        numba_event.register("numba:compile", self._watch)
        self._stop.clear()
        self._ticker = threading.Thread(target=self._tick, name="vibroflow-progress",
                                        daemon=True)
        self._ticker.start()
        return self

    def __exit__(self, *exc):
        if self._ticker is not None:
            self._stop.set()
            self._ticker.join()
            self._ticker = None
            numba_event.unregister("numba:compile", self._watch)
            self._show_compiling()  # a compilation that ended since the last tick
        if self._progress is not None:
            self._progress.__exit__(*exc)

    # -- compilation ----------------------------------------------------------------------------

    def _tick(self) -> None:
        while not self._stop.wait(0.25):
            self._show_compiling()

    def _show_compiling(self) -> None:
        """Say "compiling the kernels" while a compilation of more than ANNOUNCE_S is open, with
        its seconds; once it ends, say so once, with the seconds since it was first said."""
        open_s = self._watch.open_s()
        if open_s is not None and open_s < ANNOUNCE_S and not self._compile_said \
                and self._compile_task is None:
            return
        if self._progress is not None:
            if open_s is not None:
                text = f"{COMPILING} {open_s:.0f} s"
                if self._compile_task is None:
                    self._compile_task = self._progress.add_task(text, total=None,
                                                                 compiling=True)
                else:
                    self._progress.update(self._compile_task, description=text)
            elif self._compile_task is not None:
                self._progress.remove_task(self._compile_task)
                self._compile_task = None
            return
        now = time.perf_counter()
        if open_s is not None:
            if not self._compile_said:
                self._compile_from = now - open_s
            if not self._compile_said or now - self._compile_said >= PLAIN_EVERY_S:
                self._line(f"{COMPILING} {now - self._compile_from:.0f} s")
                self._compile_said = now
        elif self._compile_said:
            self._line(f"{COMPILED} ({now - self._compile_from:.0f} s)")
            self._compile_said = 0.0

    # -- stages ---------------------------------------------------------------------------------

    def stage(self, description: str, sim_end: float, unit: str = "s") -> None:
        """Start a stage that runs to `sim_end`: simulated seconds (unit "s"), or a count of
        other things ("snapshots", "points") whose updates carry no particle-steps."""
        self._t0 = time.perf_counter()
        self._base = None
        self._desc, self._end, self._unit = description, sim_end, unit
        self._plain_last = self._t0
        if self._progress is not None:
            self._task = self._progress.add_task(description, total=sim_end, sim_time=0.0,
                                                 sim_end=sim_end, rate=None, unit=unit,
                                                 left=None)
        elif self.enabled:  # a log or a pipe: the stage's first line at once, then every 10 s
            self._plain_line(0.0, None, None)

    def _measure(self, now: float, sim_time: float, steps: int) -> tuple[float | None,
                                                                          float | None]:
        """(time left, particle-steps per second) from the updates since the last compilation
        ended; (None, None) until MEASURE_S seconds of them have run."""
        compiled = self._watch.total_s()
        if self._watch.open_s() is not None:
            self._base = None
            return None, None
        if self._base is None or self._base[3] != compiled:
            self._base = (now, sim_time, steps, compiled)
            return None, None
        t_b, sim_b, steps_b, _ = self._base
        dt, ds = now - t_b, sim_time - sim_b
        if dt < MEASURE_S or ds <= 0:
            return None, None
        left = max(0.0, dt * (self._end - sim_time) / ds)
        rate = (steps - steps_b) / dt if steps else None
        return left, rate

    def update(self, sim_time: float, particle_steps: int | None = None) -> None:
        if not self.enabled or self._t0 is None:
            return
        now = time.perf_counter()
        left, rate = self._measure(now, sim_time, particle_steps or 0)
        if self._progress is not None and self._task is not None:
            self._progress.update(self._task, completed=sim_time, sim_time=sim_time, rate=rate,
                                  left=left)
            return
        if now - self._plain_last >= PLAIN_EVERY_S:
            self._plain_last = now
            self._plain_line(sim_time, left, rate)

    def _plain_line(self, sim_time: float, left: float | None, rate: float | None) -> None:
        if self._unit != "s":
            self._line(f"{self._desc}: {sim_time:.0f} / {self._end:.0f} {self._unit}, "
                       f"{left_text(left)}")
            return
        speed = f"{rate / 1e6:.2f} M particle-steps/s, " if rate else ""
        self._line(f"{self._desc}: t = {sim_time:.4f} / {self._end:.4f} s, {speed}"
                   f"{left_text(left)}")

    def log(self, message: str) -> None:
        if not self.enabled:
            return
        if self._progress is None:
            self._line(message)
        else:
            self.console.print(message, markup=False, highlight=False, soft_wrap=True)

    def _line(self, text: str) -> None:
        """One plain line, whole (a log file or a pipe: no wrapping, no markup)."""
        print(text, file=self.console.file, flush=True)
