"""The vibration's timeline of a continuum tub run, the same for every formulation: samples at
their steps, checkpoints every few wall seconds, the steps between two events in one compiled
call, and Ctrl-C (SIGINT) stopping it between two steps with a checkpoint, turned into one-line
interruptions (`interrupted`, `interrupted_while_settling`, `interrupted_while_writing`)."""
from __future__ import annotations

import contextlib
import os
import signal
import time
from pathlib import Path

import numpy as np

from vibroflow.errors import Interrupted
from vibroflow.interrupts import FAULT_SIGINT_ENV, deferred_sigint
from vibroflow.progress import RunProgress

from .files import CHECKPOINT_NAME
from .sampling import Samples

#: steps between progress reports (and the checks for a checkpoint's wall time)
REPORT_EVERY = 200


def vibration_timeline(state, n_steps: int, sample_step: np.ndarray, samples: Samples,
                       record, advance_steps, checkpoint, prog: RunProgress, per_step: int,
                       checkpoint_every: float, stop_after_steps: int | None,
                       frame_step: np.ndarray | None = None, frame=None) -> bool:
    """The vibration's timeline, the same for both formulations: from state.step to n_steps,
    record(j) at each sample step sample_step[j] (samples.j counts them, so a resumed run goes
    on where it stopped), checkpoint() every checkpoint_every wall seconds, the steps between
    two events (next_event) in one advance_steps(m) call, progress reported as simulated time
    and per_step particle-steps a step.  False when stopped by stop_after_steps (after its
    checkpoint), True at the end.  frame(i) at each step frame_step[i] (increasing; the
    ParaView frames before the window, io.vtk_frame.extra_frame_steps), counted by
    samples.frames as the samples are, so that a resumed run writes each frame once; the
    frames add events, and the steps between events are the same steps, so no number changes.

    A Ctrl-C (SIGINT) stops the timeline at its next look, between two steps and two samples,
    where state and samples agree: checkpoint() and VibrationInterrupted(t, checkpointed=True),
    which the runners turn into Interrupted (`interrupted`).  A second Ctrl-C before that, or
    one outside the main thread's handler, stops it where it is: VibrationInterrupted(t,
    checkpointed=False), no checkpoint of a state that may be half-way through a sample (the
    last periodic one, if any, stays)."""
    S = sample_step.size
    frame_step = np.zeros(0, np.int64) if frame_step is None else frame_step
    F = frame_step.size
    k0 = k = state.step
    last_ckpt = time.perf_counter()
    fault = FaultSigint(k0)
    # over any SIGINT handler but an ignored one (vibroflow.interrupts)
    with deferred_sigint(over_any_handler=True) as stop:
        try:
            while True:
                while samples.j < S and sample_step[samples.j] == k:
                    record(samples.j)
                    samples.j += 1
                while samples.frames < F and frame_step[samples.frames] <= k:
                    frame(samples.frames)
                    samples.frames += 1
                if stop["raised"]:
                    break
                if k == n_steps:
                    break
                if stop_after_steps is not None and k - k0 >= stop_after_steps:
                    checkpoint()
                    prog.log(f"stopped at t = {state.t:.4f} s (step {k}); go on with --resume")
                    return False
                if time.perf_counter() - last_ckpt > checkpoint_every:
                    checkpoint()
                    last_ckpt = time.perf_counter()
                # the steps up to the next sample, stop or progress report, in one compiled
                # call
                nxt = next_event(k, n_steps, sample_step, samples.j, k0, stop_after_steps,
                                 frame_step[samples.frames:samples.frames + 1])
                advance_steps(nxt - k)
                k = nxt
                prog.update(state.t, (k - k0) * per_step)
                fault.check(k)
            if stop["raised"]:
                checkpoint()
                raise VibrationInterrupted(state.t, True)
        except KeyboardInterrupt:
            raise VibrationInterrupted(state.t, False) from None
    prog.update(state.t, (n_steps - k0) * per_step)
    return True


class VibrationInterrupted(Exception):
    """A Ctrl-C stopped the vibration at simulated time t (s); checkpointed: whether the state
    at t was written to the checkpoint (vibration_timeline)."""

    def __init__(self, t: float, checkpointed: bool):
        super().__init__(f"interrupted at t = {t:.4f} s")
        self.t, self.checkpointed = float(t), bool(checkpointed)


def resume_hint(out: Path) -> str:
    return f"resume with --resume (vibroflow continuum ... --out {out} --resume)"


def interrupted(out: Path, e: VibrationInterrupted) -> Interrupted:
    """The one-line Interrupted of a vibration stopped by Ctrl-C: the time and how to go on."""
    if e.checkpointed:
        return Interrupted(f"interrupted at t = {e.t:.4f} s; {resume_hint(out)}")
    if (Path(out) / CHECKPOINT_NAME).exists():
        return Interrupted(f"interrupted at t = {e.t:.4f} s, before its checkpoint was "
                           f"written; {resume_hint(out)} goes on from the last checkpoint")
    return Interrupted(f"interrupted at t = {e.t:.4f} s, before a first checkpoint; nothing "
                       "to resume, run again")


@contextlib.contextmanager
def interrupted_while_settling():
    """A Ctrl-C while the bed settles: Interrupted (one line); nothing is checkpointed before
    the vibration, so there is nothing to resume."""
    try:
        yield
    except KeyboardInterrupt:
        raise Interrupted("interrupted while settling; nothing to resume, run again") from None


@contextlib.contextmanager
def interrupted_while_writing(out: Path):
    """A Ctrl-C while a finished run writes its results: Interrupted (one line).  Every file is
    written atomically and summary.json last, so the folder holds no half file and no summary
    that looks complete; the checkpoint, when there is one, stays to resume from."""
    try:
        yield
    except KeyboardInterrupt:
        if (Path(out) / CHECKPOINT_NAME).exists():
            raise Interrupted(f"interrupted while writing the results; {resume_hint(out)} "
                              "goes on from the last checkpoint") from None
        raise Interrupted("interrupted while writing the results, before a checkpoint; "
                          "nothing to resume, run again") from None


class FaultSigint:
    """Fault injection for the Ctrl-C tests: with VIBROFLOW_FAULT_SIGINT_AFTER_STEPS=N in the
    environment the process sends itself SIGINT, once, at the vibration loop's first look after
    N steps of this call (from step k0): the deterministic version of a user's Ctrl-C (a test
    that signals from outside races the run).  The DEM has the same hook
    (vibroflow.dem.run)."""

    def __init__(self, k0: int):
        value = os.environ.get(FAULT_SIGINT_ENV)
        self.k0 = k0
        self.after = int(value) if value and value.strip().isdigit() else None

    def check(self, k: int) -> None:
        if self.after is not None and k - self.k0 >= self.after:
            self.after = None
            os.kill(os.getpid(), signal.SIGINT)


def next_event(k: int, n_steps: int, sample_step, j: int, k0: int,
               stop_after_steps: int | None, frame_next=()) -> int:
    """The step after k at which a vibration loop must look again: the next sample (sample
    steps sample_step[j:]), the next ParaView frame (frame_next: its step, or empty), the end
    n_steps, the stop after stop_after_steps steps from k0, or the next multiple of
    REPORT_EVERY."""
    nxt = min(n_steps, (k // REPORT_EVERY + 1) * REPORT_EVERY)
    if len(frame_next):
        nxt = min(nxt, int(frame_next[0]))
    if j < len(sample_step):
        nxt = min(nxt, int(sample_step[j]))
    if stop_after_steps is not None:
        nxt = min(nxt, k0 + int(stop_after_steps))
    return max(nxt, k + 1)


