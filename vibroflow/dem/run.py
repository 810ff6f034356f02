"""Orchestration of a DEM run: fill and settle (or the cached bed), vibrate, sample, checkpoint,
write results, summarise.  The numerics live in step.py / simulate.py; this file only decides
when things happen and where they are written, with its helpers: fill.settled_bed (the bed),
sampling.py (what is sampled when), checkpoint.py (checkpoints and what --resume finds),
fingerprint.py (the scenario's identity), interrupts.py (Ctrl-C, fault injection) and
summary.py (summary.json) and paraview.py (DIR/vtk/).

Timeline of a tub run (tub47.md, "Procedure"), t counted from the start of the vibration:
    [0, duration - average_last)      vibrate
    [duration - average_last, end]    vibrate and sample: `phases_per_cycle` snapshots a cycle
                                      over the whole cycles of the window (with the wall
                                      contacts at those instants), and every new contact's
                                      impact.

The folder (DIR) as a run leaves it at any instant, and what `--resume` does with it:
    checkpoint.h5 + dem.parts/            go on from the checkpoint (whether or not dem.h5 is
                                          there yet: it is assembled again)
    summary.json + dem.h5                 finished (a leftover checkpoint and dem.parts are
                                          removed); nothing to run
    neither                               start afresh
A run's end keeps this true at every instant: a checkpoint of the final state, dem.h5
assembled from the parts (kept), summary.json, the checkpoint removed, the parts removed last.
A fresh run removes the previous results first, so a summary.json is always its own run's.
The checkpoint records a fingerprint of the scenario and its start (fingerprint.run_record),
the sha256 of its own contents and of every result part it counts on: a resume of another
scenario or from a damaged file is refused in one line (InputError).  Ctrl-C (SIGINT) during
the vibration writes a checkpoint of the current state and raises errors.Interrupted; during
the fill it raises Interrupted with nothing written.
"""
from __future__ import annotations

import json
import os
import shutil
import signal
import time
from pathlib import Path

import numba
import numpy as np

from ..errors import Interrupted
from ..interrupts import deferred_sigint
from ..io.atomic import write_json_atomic
from ..io.folder_lock import folder_lock
from ..io.run_folder import claim_for_fresh_run
from ..io.vtk_frame import VtkOptions, vtk_options
from ..measure.bulk_batches import BATCHES_CSV_NAME, STDERR_CSV_NAME
from ..progress import RunProgress
from ..run_clock import RunClock
from ..threads import requested_threads
from .checkpoint import (CHECKPOINT_NAME, SUMMARY_NAME, finished_summary, resume_checkpoint,
                         write_checkpoint)
from .fill import settled_bed
from .fingerprint import record_fingerprint, run_record, scenario_toml
from .interrupts import fault_sigint_after_steps
from .output import ResultWriter, fault_kill_at
from .paraview import VTK_DIR, EarlyFrames, write_vtk
from .part_output import write_parts_nc
from .sampling import impact_rows, part_impact_rows, sample_steps, write_snapshot
from .impact_order import ImpactsLost
from .simulate import (BlowUp, DEMState, DEMSystem, forget_histories, init_state, make_system,
                       run_steps, store_by_id, take_max_overlaps)
from .summary import run_summary

SMALL_RUN = 1500  # below this many balls one thread is faster than two (thread wake-ups)

# what a fresh run removes before it writes: the previous run's results and checkpoint
_PREVIOUS = (CHECKPOINT_NAME, SUMMARY_NAME, "bulk_velocity.csv", STDERR_CSV_NAME,
             BATCHES_CSV_NAME, "dem.h5", "dem.h5.partial", "parts.nc", "floor.csv")


def run_dem(scenario, out_dir: Path, vtk: VtkOptions | bool | None = None,
            resume: bool = False, progress: bool = True,
            forget_histories: bool = False, relax_s: float = 0.0) -> dict:
    """Run the scenario's DEM and write DIR/dem.h5, DIR/summary.json (and bulk_velocity.csv in
    tub mode).  Returns the summary.

    vtk: ParaView files in DIR/vtk/ (dem.paraview), in the frame it names
    (io.vtk_frame.VtkOptions; True: the tub frame, the window's snapshots; None: none).

    DIR is locked (io.folder_lock) while the run writes it: a second run on it is an
    InputError naming the holder.  resume=True goes on from DIR/checkpoint.h5 bit for bit, or
    returns the summary of a finished run (see the module's docstring); InputError when the
    checkpoint is another scenario's or a file it needs is damaged.  Ctrl-C raises
    errors.Interrupted (one line: where it stopped, how to go on); BlowUp names the cause.

    Fault injection for tests (environment): VIBROFLOW_FAULT_KILL_AFTER_CHECKPOINT=1
    (_fault_after_checkpoint), VIBROFLOW_FAULT_KILL_AT=<phase of the end> (output.fault_kill_at),
    VIBROFLOW_FAULT_SIGINT_AFTER_STEPS=N (a SIGINT to itself once N vibration steps are done),
    VIBROFLOW_FAULT_SIGINT_SETTLING=1 (a SIGINT after the first settling chunk).

    forget_histories: a tub run's settled bed starts the vibration with every tangential spring
    and rolling history at zero (simulate.forget_histories; summary.json's "settle" says
    "histories_forgotten"), as LIGGGHTS started from the bed's positions alone does
    (benchmarks/bar_maps.py --forget-histories, docs/validation.md section 27); with relax_s > 0
    the bed then rests relax_s seconds with the tub at rest before the vibration, as LIGGGHTS'
    --fill-from deck's settling does (its "settle" records "relaxed_s", the kinetic energy per
    ball and the fastest ball's speed then).  Both enter the checkpoint's fingerprint
    (fingerprint.run_record): a resume with the other start is refused."""
    out_dir = Path(out_dir)
    vtk = vtk_options(vtk)
    with folder_lock(out_dir, "vibroflow dem"):
        system = make_system(scenario)
        n_balls = len(scenario.particles) if scenario.explicit else scenario.fill.count
        threads_before = numba.get_num_threads()
        if n_balls < SMALL_RUN and requested_threads() is None:
            numba.set_num_threads(1)  # the same numbers on any thread count (dem.step)
        try:
            # the solver's time, numba's compilation apart (vibroflow.run_clock)
            with RunProgress(progress) as prog, RunClock() as clock:
                return _run(scenario, out_dir, system, vtk, resume, prog, clock,
                            forget_histories, relax_s)
        finally:
            numba.set_num_threads(threads_before)


def _run(scenario, out_dir: Path, system: DEMSystem, vtk: VtkOptions | None, resume: bool,
         prog: RunProgress, clock: RunClock, forget: bool = False,
         relax_s: float = 0.0) -> dict:
    dt = system.dt
    ckpt = out_dir / CHECKPOINT_NAME
    explicit = scenario.explicit
    record = run_record(scenario, forget, relax_s)
    fingerprint = record_fingerprint(record)
    if resume:
        summary = finished_summary(out_dir, fingerprint, record)
        if summary is not None:
            # a run killed after its summary: only the clean-up was left
            ckpt.unlink(missing_ok=True)
            shutil.rmtree(out_dir / "dem.parts", ignore_errors=True)
            prog.log(f"{out_dir}: the run is finished already; nothing to resume")
            return summary
    if resume and ckpt.exists():
        try:
            system, state, settle_info, writer = resume_checkpoint(scenario, out_dir, system,
                                                                   clock, fingerprint, record)
        except KeyboardInterrupt:
            # reading and checking only: the checkpoint and the parts it counts on are intact
            raise Interrupted(f"interrupted while reading {ckpt}; nothing changed, resume "
                              "again") from None
        prog.log(f"resuming from {ckpt} at t = {state.time(dt):.4f} s")
    else:
        # a folder of another command's results, or of the user's own files of those names, is
        # refused before the fill: the fresh run replaces only a DEM run's files
        claim_for_fresh_run(out_dir, "dem", (*_PREVIOUS, VTK_DIR))
        if resume:
            prog.log(f"no checkpoint in {out_dir}: starting afresh")
        try:
            settle_s0 = clock.solver_s()
            state, settle_info = _start(scenario, system, prog, forget, relax_s)
            if settle_info:  # the settling's own solver time: the summary reports both phases
                settle_info["wall_time_s"] = clock.solver_s() - settle_s0
        except KeyboardInterrupt:
            what = "setting up the run" if explicit else "settling the fill"
            raise Interrupted(f"interrupted while {what}; nothing to resume, run again") \
                from None
        # the previous run's results go before anything of this one is written, the
        # checkpoint first (with its parts it would be resumed), so no summary.json outlives
        # the run it belongs to
        for name in _PREVIOUS:
            (out_dir / name).unlink(missing_ok=True)
        shutil.rmtree(out_dir / VTK_DIR, ignore_errors=True)  # its frames were of that run
        attrs = {"case": scenario.case, "n_particles": state.n, "dt": dt,
                 "frequency": scenario.motion.frequency,
                 "scenario_toml": scenario_toml(scenario), "source": "vibroflow",
                 "fingerprint": fingerprint,
                 "scenario_json": json.dumps(record, sort_keys=True, default=str)}
        writer = ResultWriter(out_dir, state.n, attrs, state.radius, parts=bool(scenario.parts))
    try:
        summary = _vibrate(scenario, out_dir, system, state, writer, prog, settle_info,
                           clock, explicit, vtk, fingerprint, record)
    except (BlowUp, ImpactsLost):
        # nothing half-written stays behind: a blown-up run (or one short of impact rows) has
        # no result to resume
        writer.discard()
        ckpt.unlink(missing_ok=True)
        raise
    except Interrupted:
        writer.close()
        raise
    except KeyboardInterrupt:
        # a second Ctrl-C, or one outside the main thread's deferral: the state in memory may
        # be between two updates, so the last checkpoint on disk is where to go on from
        writer.close()
        if (out_dir / SUMMARY_NAME).exists():
            raise Interrupted(f"interrupted while tidying up after the run; its results are "
                              f"complete in {out_dir} (--resume removes what is left over)") \
                from None
        if ckpt.exists():
            raise Interrupted(f"interrupted at t = {state.time(dt):.4f} s; resume from the last "
                              f"checkpoint with: vibroflow dem <the same scenario and --set> "
                              f"--resume --out {out_dir}") from None
        writer.discard()
        raise Interrupted(f"interrupted at t = {state.time(dt):.4f} s before the first "
                          "checkpoint; nothing to resume, run again") from None
    except BaseException:
        writer.close()
        raise
    return summary


def _start(scenario, system: DEMSystem, prog: RunProgress,
           forget: bool = False, relax_s: float = 0.0) -> tuple[DEMState, dict]:
    """The state at the start of the vibration (explicit: the given balls; tub: the settled
    bed, its contact histories zeroed when forget, then relax_s at rest) and the settling's
    record."""
    if scenario.explicit:
        index = system.material_names
        ps = scenario.particles
        state = init_state(system, [p.position for p in ps], [p.velocity for p in ps],
                           [p.angular_velocity for p in ps], [0.5 * p.diameter for p in ps],
                           [scenario.materials[p.material].density for p in ps],
                           [index.index(p.material) for p in ps])
        settle_info = {}
    else:
        state, settle_info = settled_bed(system, scenario, prog)
        if forget:
            forget_histories(state)
            settle_info["histories_forgotten"] = True
            if relax_s > 0.0:
                state.vibrating = False
                run_steps(system, state, int(round(relax_s / system.dt)))
                settle_info.update(
                    relaxed_s=relax_s,
                    relaxed_kinetic_energy_per_ball_J=state.kinetic_energy() / state.n,
                    relaxed_fastest_ball_m_s=float(np.sqrt((state.vel ** 2).sum(1).max())))
        state.time_origin_step = state.step
        take_max_overlaps(system, state)  # the series starts with the vibration
    state.vibrating = True
    return state, settle_info


def _vibrate(scenario, out_dir, system, state, writer, prog, settle_info, clock: RunClock,
             explicit, vtk, fingerprint: str, record: dict):
    dt = system.dt
    run = scenario.run
    f = scenario.motion.frequency
    n = state.n
    total = int(round(run.duration / dt))
    if explicit:
        samples = np.arange(0, total + 1, run.series_every, dtype=np.int64)
        window = (0.0, run.duration)
    else:
        samples, t0, t1 = sample_steps(scenario, dt)
        window = (t0, t1)
    window_start = int(round(window[0] / dt))
    early = EarlyFrames(scenario, vtk, dt, window[0], out_dir)
    ckpt = out_dir / CHECKPOINT_NAME
    done_snapshots = writer.rows("snapshots/time")
    vstep = state.step - state.time_origin_step
    last_ckpt = time.perf_counter()
    stage_steps0 = vstep
    prog.stage("vibrate" if not explicit else "run", run.duration)

    def on_impacts(imp):
        writer.append("impacts", **impact_rows(system, imp))

    def on_part_impacts(imp):
        writer.append("part_impacts", **part_impact_rows(imp))

    def checkpoint():
        store_by_id(system, state)
        write_checkpoint(ckpt, state, writer, system, settle_info, clock.solver_s(), fingerprint,
                         record)

    sigint_after = fault_sigint_after_steps()
    with deferred_sigint() as sigint:
        try:
            _vibration_loop(state, system, writer, prog, run, samples, done_snapshots, total,
                            window_start, explicit, f, stage_steps0, n, last_ckpt,
                            (on_impacts, on_part_impacts), checkpoint, sigint, sigint_after,
                            out_dir, early)
        finally:
            store_by_id(system, state)
    if sigint["raised"] and ckpt.exists():
        # a SIGINT while the last rows were written: the final state's checkpoint is on disk
        raise Interrupted(f"interrupted at t = {state.time(dt):.4f} s; checkpoint written; "
                          f"resume with: vibroflow dem <the same scenario and --set> --resume "
                          f"--out {out_dir}")

    # the end, in an order that a kill at any instant leaves a folder --resume completes
    # (module docstring): dem.h5 from the parts (kept), summary.json, checkpoint, parts
    wall = clock.solver_s()
    path = writer.finish(keep_parts=True)
    fault_kill_at("assembled")
    summary = run_summary(scenario, system, state, path, out_dir, wall, settle_info, explicit)
    summary["compile_time_s"] = clock.compile_s()
    if scenario.parts:
        summary["parts"] = write_parts_nc(path, out_dir, scenario, system)
    if vtk:
        write_vtk(path, out_dir, scenario, vtk, early)
    write_json_atomic(out_dir / SUMMARY_NAME, summary)
    fault_kill_at("summary")
    ckpt.unlink(missing_ok=True)
    fault_kill_at("checkpoint-removed")
    writer.remove_parts()
    return summary


def _vibration_loop(state, system, writer, prog, run, samples, done_snapshots, total,
                    window_start, explicit, f, stage_steps0, n, last_ckpt, on_impacts,
                    checkpoint, sigint, sigint_after, out_dir, early: EarlyFrames) -> None:
    """Step to the end, writing the rows of each sample and series step (and the ParaView
    frame of each of early.steps, outside dem.h5) before stepping on, and the impacts the
    callbacks on_impacts = (balls', parts') receive;
    a checkpoint every run.checkpoint_every wall seconds and one of the final state (before
    its rows, as every checkpoint), and one at a SIGINT, which then raises Interrupted."""
    dt = system.dt
    frames = early.steps
    # the next early frame: a resumed run starts at its checkpoint's step, whose frame (if any)
    # is written at the top of the loop as it was not yet (a checkpoint follows the stepping)
    k = int(np.searchsorted(frames, state.step - state.time_origin_step))
    while True:
        vstep = state.step - state.time_origin_step
        if k < frames.size and frames[k] == vstep:
            store_by_id(system, state)
            early.write(k, state.time(dt), state.pos, state.vel, state.omg, state.radius)
            k += 1
        if done_snapshots < len(samples) and samples[done_snapshots] == vstep:
            store_by_id(system, state)
            write_snapshot(writer, system, state, done_snapshots, f)
            done_snapshots += 1
        if vstep % run.series_every == 0:
            ob, ow = take_max_overlaps(system, state)
            writer.append("series", time=[state.time(dt)],
                          kinetic_energy=[state.kinetic_energy()], max_overlap_ball=[ob],
                          max_overlap_wall=[ow])
        if vstep >= total:
            break
        nxt = min(total, (vstep // run.series_every + 1) * run.series_every)
        if done_snapshots < len(samples):
            nxt = min(nxt, int(samples[done_snapshots]))
        if k < frames.size:
            nxt = min(nxt, int(frames[k]))
        # an explicit run records its ball-part impacts alone, over the whole run
        record = run.record_impacts and (system.n_parts > 0 if explicit
                                         else vstep >= window_start)
        if not explicit and vstep < window_start:
            nxt = min(nxt, window_start)
        # the balls may stay in space order until a row reads them (memory_order)
        run_steps(system, state, nxt - vstep, record_impacts=record, keep_order=True,
                  on_impacts=on_impacts[0] if record and not explicit else None,
                  on_part_impacts=on_impacts[1] if record else None)
        now = state.step - state.time_origin_step
        prog.update(state.time(dt), (now - stage_steps0) * n)
        if sigint_after is not None and now >= sigint_after:
            sigint_after = None
            os.kill(os.getpid(), signal.SIGINT)
        written = False
        if now >= total or time.perf_counter() - last_ckpt > run.checkpoint_every:
            checkpoint()
            written = True
            last_ckpt = time.perf_counter()
            if now >= total:
                fault_kill_at("final-checkpoint")
        if sigint["raised"]:
            if not written:
                checkpoint()
            raise Interrupted(f"interrupted at t = {state.time(dt):.4f} s; checkpoint written; "
                              f"resume with: vibroflow dem <the same scenario and --set> "
                              f"--resume --out {out_dir}")
