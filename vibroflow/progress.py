"""Progress display of long runs: simulated time, particle-steps per second, time left."""
from __future__ import annotations

import sys
import time

from rich.console import Console
from rich.progress import (BarColumn, Progress, ProgressColumn, TaskProgressColumn, TextColumn,
                           TimeRemainingColumn)
from rich.text import Text


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


class RunProgress:
    """A rich progress bar over one stage at a time; silent when `enabled` is False."""

    def __init__(self, enabled: bool = True, console: Console | None = None):
        self.enabled = enabled
        self.console = console or Console(file=sys.stderr)
        self._progress = None
        self._task = None
        self._t0 = None
        self._steps0 = 0
        self._plain_last = 0.0
        self._desc = ""
        self._end = 0.0
        self._unit = "s"

    def __enter__(self):
        if self.enabled and not self.console.is_terminal:
            return self  # a log file or a pipe: plain lines every few seconds instead
        if self.enabled:
            self._progress = Progress(
                TextColumn("[bold]{task.description}"), BarColumn(), TaskProgressColumn(),
                _SimTime(), _Rate(), TextColumn("left"), TimeRemainingColumn(),
                console=self.console, transient=False, refresh_per_second=4)
            self._progress.__enter__()
        return self

    def __exit__(self, *exc):
        if self._progress is not None:
            self._progress.__exit__(*exc)

    def stage(self, description: str, sim_end: float, unit: str = "s") -> None:
        """Start a stage that runs to `sim_end`: simulated seconds (unit "s"), or a count of
        other things ("snapshots", "points") whose updates carry no particle-steps."""
        self._t0 = time.perf_counter()
        self._steps0 = 0
        self._desc, self._end, self._unit = description, sim_end, unit
        self._plain_last = self._t0
        if self._progress is not None:
            self._task = self._progress.add_task(description, total=sim_end, sim_time=0.0,
                                                 sim_end=sim_end, rate=None, unit=unit)

    def update(self, sim_time: float, particle_steps: int | None = None) -> None:
        if not self.enabled or self._t0 is None:
            return
        now = time.perf_counter()
        elapsed = now - self._t0
        rate = particle_steps / elapsed if elapsed > 0 and particle_steps is not None else None
        if self._progress is not None and self._task is not None:
            self._progress.update(self._task, completed=sim_time, sim_time=sim_time, rate=rate)
            return
        if now - self._plain_last >= 10.0:
            self._plain_last = now
            left = elapsed * (self._end - sim_time) / sim_time if sim_time > 0 else float("nan")
            if self._unit != "s":
                self.console.print(f"{self._desc}: {sim_time:.0f} / {self._end:.0f} "
                                   f"{self._unit}, {left:.0f} s left", highlight=False)
                return
            self.console.print(f"{self._desc}: t = {sim_time:.4f} / {self._end:.4f} s, "
                               f"{(rate or 0) / 1e6:.2f} M particle-steps/s, "
                               f"{left:.0f} s left", highlight=False)

    def log(self, message: str) -> None:
        if self.enabled:
            self.console.print(message)
