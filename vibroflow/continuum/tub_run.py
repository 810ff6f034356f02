"""A continuum run of a tub scenario, by any formulation (continuum.formulation).

Timeline (tub47.md "Procedure", the DEM's clock: t = 0 when the vibration starts):

1. The settled bed: the DEM's solid volume (fill.count balls of fill.diameter, over the slice
   L_y) at the critical solid fraction fills the U to the height h that holds it, at rest under
   the lithostatic stress, so its weight is carried from the start (bed.py; each formulation
   places it on its points or cells, Formulation.initial_state).  It then settles for
   `settle_time` in the still tub, where the walls take up the load.
2. Vibrate for run.duration in the tub frame (grid_update.TubFrame: the tub's motion from
   vibroflow.tub.motion enters as the frame's inertial force), sampling `run.phases_per_cycle`
   instants a cycle over the whole cycles of the last run.average_last seconds, at exactly the
   DEM's sample phases (m / (P f), sampling.sample_times); the time step divides the sampling
   interval (timeline.py).
3. Results, through vibroflow.measure (the DEM's own code): each sampled point or cell is a
   "ball" (Formulation.sampler) with its lab position and velocity at the sample;
   bulk_velocity.csv (CellTable / write_csv on the scenario's cells) with its batches of whole
   cycles beside it (bulk_velocity_stderr.csv, bulk_velocity_batches.csv:
   measure.bulk_batches; from the samples, which the checkpoint carries, so a resumed run
   writes the same files) and summary.json with the
   DEM's keys (probes, circulation, wall_contacts from the points or cells touching the U,
   impacts: none, window, cells), the floor's force over the cycle and the bed's take-off
   (floor.csv and the summary's "floor": measure.floor_force, as the DEM's); with the
   temperature, the U wall's feed of fluctuation energy by region and phase (wall_feed.csv,
   the summary's "wall_feed": wall_feed.py), plus a
   "continuum" block: the method, numerics, material,
   and the shear rate with the impact speed and granular temperature it implies through the
   calibrated relations (calibration.toml [impacts]), when a calibration is given
   (shear_outputs.py); with the granular temperature (ContinuumOptions.temperature), its map
   temperature.csv and the summary's "granular_temperature" block (temperature_outputs.py),
   and, where the calibration prefers the temperature, the impact speeds it implies
   (temperature_impacts.py).  With parts (part_obstacle.py), parts.nc: the impact speed each
   part's surface patches receive as the calibrated relation infers it and the force on each
   part by phase (part_outputs.py, io/parts_file.py's schema).

Parameters come from calibration.toml (vibroflow.io.calibration_file.read_calibration) or the
tub47 defaults (ContinuumMaterial, material.py): the wall friction [wall] friction (default:
the scenario's ball-wall contact friction), the partitions' [partitions] friction (default: the
scenario's ball-partition friction), the diameter and solid density (default: the scenario's
fill).

Checkpoints (checkpoint.py) every run.checkpoint_every wall seconds of the vibration; a resumed
run gives the numbers of an uninterrupted one bit for bit; results are written atomically and
summary.json last.  A blow-up (ContinuumBlowUp: a point or cell non-finite, off the grid or
through the wall) ends the run with the ids and the likely cause, and removes the checkpoint.
"""
from __future__ import annotations

import dataclasses
import json
import math
import shutil
from pathlib import Path

import numpy as np

from vibroflow.errors import InputError
from vibroflow.scenario.checks import require_tub_mode
from vibroflow.io.atomic import write_json_atomic
from vibroflow.io.calibration_file import Calibration
from vibroflow.io.folder_lock import folder_lock
from vibroflow.io.parts_file import PARTS_NC_NAME, write_parts
from vibroflow.io.run_folder import claim_for_fresh_run
from vibroflow.io.vtk_frame import extra_frame_steps, vtk_options, write_vtk_record
from vibroflow.measure.bulk_batches import BATCHES_CSV_NAME, STDERR_CSV_NAME
from vibroflow.measure.floor_force import (FLOOR_CSV_NAME, WALL_FEED_CSV_NAME, floor_cycle,
                                           region_lengths, wall_feed_cycle, weight_of,
                                           write_floor_csv, write_wall_feed_csv)
from vibroflow.measure.stats import batch_means, batches_of_whole_cycles
from vibroflow.measure.summary import json_safe, tub_summary
from vibroflow.progress import RunProgress
from vibroflow.run_clock import RunClock
from vibroflow.tub.geometry import geometry_of
from vibroflow.tub.motion import TubMotion
from vibroflow.tub.parts import pack

from .checkpoint import (check_resumable, load_checkpoint, run_fingerprint, run_record,
                         save_checkpoint)
from .files import BULK_CSV_NAME, CHECKPOINT_NAME, SHEAR_RATE_CSV_NAME, SUMMARY_NAME, VTK_DIR
from .formulation import Formulation, formulation
from .grid_update import LabFrame, TubFrame
from .material import material_for
from .mpm.solver import ContinuumBlowUp
from .part_obstacle import continuum_parts
from .part_outputs import part_dataset
from .sampling import Samples, cell_grid_of, phase_shear_of_samples, sample_times, samples_source
from .shear_outputs import shear_rate_outputs, write_shear_rate_csv
from .stress_outputs import (STRESS_BATCHES_CSV_NAME, STRESS_CSV_NAME, phase_stress,
                             write_stress_batches_csv, write_stress_csv)
from .temperature_impacts import impacts_from_temperature
from .temperature_outputs import TEMPERATURE_CSV_NAME, temperature_outputs, write_temperature_csv
from .timeline import (REPORT_EVERY, VibrationInterrupted, interrupted,
                       interrupted_while_settling, interrupted_while_writing, vibration_timeline)

#: an earlier continuum run's files in its folder, which a fresh run removes first
_PREVIOUS = (SUMMARY_NAME, BULK_CSV_NAME, BATCHES_CSV_NAME, STDERR_CSV_NAME, CHECKPOINT_NAME,
             SHEAR_RATE_CSV_NAME, TEMPERATURE_CSV_NAME, PARTS_NC_NAME, FLOOR_CSV_NAME,
             WALL_FEED_CSV_NAME, STRESS_CSV_NAME, STRESS_BATCHES_CSV_NAME)


def _gravity(scenario) -> tuple[float, float]:
    return float(scenario.gravity[0]), float(scenario.gravity[2])


def tub_system(form: Formulation, scenario, calibration: Calibration | None, options):
    """What a run vibrates: the formulation's system of the scenario in the vibrating tub's
    frame, and its material (material.material_for)."""
    material = material_for(scenario, calibration, options)
    system = form.make_system(scenario, material, calibration, options,
                              TubFrame(TubMotion.of_scenario(scenario), _gravity(scenario)))
    return system, material


def settle(form: Formulation, scenario, material, calibration: Calibration | None, options,
           prog: RunProgress | None = None):
    """(state, bed height m): the settled bed after options.settle_time in the still tub
    (module docstring, step 1)."""
    system = form.make_system(scenario, material, calibration, options,
                              LabFrame(_gravity(scenario)))
    state, h = form.initial_state(scenario, system)
    steps = int(math.ceil(options.settle_time / system.dt))
    if prog is not None:
        prog.stage(f"continuum ({form.name}): settle (still tub)", options.settle_time)
    for k in range(0, steps, REPORT_EVERY):
        form.advance(system, state, min(REPORT_EVERY, steps - k))
        if prog is not None:
            prog.update(state.t, state.step * state.n)
    return state, h


def vibration_start(scenario, calibration: Calibration | None, options,
                    method: str = "lagrangian", prog: RunProgress | None = None):
    """(system, state): the system in the vibrating tub's frame and the bed it starts
    vibrating from, settled for options.settle_time in the still tub, its clock set to t = 0,
    step 0 (run_continuum's first two steps, for a diagnostic that drives the run itself:
    benchmarks/)."""
    form = formulation(method)
    system, material = tub_system(form, scenario, calibration, options)
    state, _ = settle(form, scenario, material, calibration, options, prog)
    state.t, state.step = 0.0, 0
    return system, state


def _finished(out: Path, scenario, method: str) -> dict | None:
    """The summary of a finished run of this case and formulation in `out` (summary.json),
    None where there is none; InputError for another case's or formulation's run."""
    path = out / SUMMARY_NAME
    try:
        summary = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    there = (summary.get("case"), summary.get("method"))
    if there != (scenario.case, method):
        raise InputError(f"--resume: {out} holds the finished {there[1]} run of "
                         f"{there[0]!r}, not this {method} run of {scenario.case!r}; give "
                         "another --out, or leave --resume out to replace it")
    return summary


def run_continuum(scenario, out_dir, method: str = "lagrangian",
                  calibration: Calibration | None = None, options=None, progress: bool = False,
                  vtk=None, resume: bool = False, stop_after_steps: int | None = None,
                  keep_samples: list | None = None) -> dict | None:
    """Run the continuum formulation `method` ("lagrangian", "eulerian":
    continuum.formulation.FORMULATIONS) of a tub scenario into out_dir (module docstring);
    returns the summary (also written to out_dir/summary.json with out_dir/bulk_velocity.csv
    and shear_rate.csv), or None when stopped by stop_after_steps.  options: the
    formulation's (Formulation.options; default its defaults).

    vtk (io.vtk_frame.VtkOptions; True: the tub frame; None: none): also write ParaView files
    in out_dir/vtk at the samples of the last vibration cycle, in the frame it names
    (continuum.paraview): the grid fields of fields.py (velocity relative to the tub and lab
    velocity, solid fraction, density, pressure, shear rate on the background grid; grid.pvd),
    the material points of the material point method (points.pvd) and the tub's surface; with
    vtk.every, also every `every` seconds from vtk.start up to the averaging window (the
    "early_" files), all listed in time order.  They change no number of the run.

    Checkpoints: every run.checkpoint_every wall seconds of the vibration the whole state and
    what has been sampled go to out_dir/checkpoint.npz (checkpoint.py, atomic); resume=True
    continues from it (a run killed while settling starts afresh) and gives the same numbers,
    bit for bit, as a run never interrupted; the checkpoint of another scenario, calibration,
    method or options is an input error.  stop_after_steps: write a checkpoint and return None
    after that many vibration steps of this call (to split a run; go on with resume=True).  A
    fresh run first removes the folder's summary.json and bulk_velocity.csv, so a run killed
    before its end never leaves results that look complete; summary.json is written last.

    keep_samples: a list that receives the run's `Samples` (every point or cell at every
    sample instant, the wall contacts) for an analysis beyond the summary's
    (benchmarks/wall_layer.py).
    """
    form = formulation(method)
    vtk = vtk_options(vtk)
    require_tub_mode(scenario, "the continuum")
    if sample_times(scenario)[0].size == 0:
        raise InputError(f"run.average_last = {scenario.run.average_last!r}: must hold at least "
                         "one whole vibration cycle to average over")
    if stop_after_steps is not None and not int(stop_after_steps) >= 0:
        raise InputError(f"stop_after_steps = {stop_after_steps!r}: must be >= 0")
    options = options or form.options()
    parts = continuum_parts(scenario)
    system, material = tub_system(form, scenario, calibration, options)
    geo = geometry_of(scenario)
    times, window_start, _ = sample_times(scenario)
    S = times.size
    n_probes = len(scenario.analysis.probes)
    cell_grid = cell_grid_of(geo, scenario.analysis.cell_size)
    out = Path(out_dir)
    ckpt = out / CHECKPOINT_NAME
    record = run_record(scenario, calibration, options, vtk)
    fingerprint = run_fingerprint(scenario, calibration, options, vtk)
    # the folder's lock first: nothing is written into a folder another run is writing, and a
    # --out that is a file or read-only is a one-line error before anything is made
    with folder_lock(out, "vibroflow continuum"):
        clock = RunClock()   # the solver's time, numba's compilation apart
        with clock, RunProgress(progress) as prog:
            if resume and ckpt.exists():
                saved, arrays, meta = load_checkpoint(ckpt)
                check_resumable(ckpt, meta, fingerprint, form.name, record)
                state = form.restore(system, saved, meta)
                h = float(meta["bed_height_m"])
                sampler = form.sampler(scenario, system, state, out, vtk)
                samples = Samples.from_arrays(arrays, S, sampler.n_points, n_probes, cell_grid,
                                              options.temperature, len(parts))
                sampler.restore(arrays)
                clock.resume_from(float(meta["wall_time_s"]))
                prog.log(f"resuming from {ckpt} at t = {state.t:.4f} s")
            else:
                # a folder of another command's results, or of the user's own files of those
                # names, is refused: the fresh run replaces only a continuum run's files
                claim_for_fresh_run(out, "continuum", (*_PREVIOUS, VTK_DIR))
                if resume:
                    done = _finished(out, scenario, form.name)
                    if done is not None:
                        prog.log(f"{out}: the run is finished already (summary.json, no "
                                 "checkpoint); nothing to resume: leave --resume out to run it "
                                 "again")
                        return done
                    prog.log(f"no checkpoint in {out}: starting afresh")
                for name in _PREVIOUS:
                    (out / name).unlink(missing_ok=True)
                shutil.rmtree(out / VTK_DIR, ignore_errors=True)  # another run's frames
                with interrupted_while_settling():
                    state, h = settle(form, scenario, material, calibration, options, prog)
                state.t = 0.0
                state.step = 0
                sampler = form.sampler(scenario, system, state, out, vtk)
                samples = Samples(S, sampler.n_points, n_probes, cell_grid, options.temperature,
                                  len(parts))

            def checkpoint():
                save_checkpoint(ckpt, state, {**samples.arrays(), **sampler.arrays()}, {
                    "fingerprint": fingerprint, "record": record, "method": form.name,
                    "bed_height_m": h,
                    **form.checkpoint_meta(state), "wall_time_s": clock.solver_s()})

            run = scenario.run
            sample_step = np.rint(times / system.dt).astype(np.int64)

            def advance(m: int) -> None:
                # a sampler that measures over a sample's step keeps its start (Sampler.
                # keeps_sample_step_start): the call's last step ends at the sample
                if (sampler.keeps_sample_step_start and samples.j < S
                        and state.step + m == sample_step[samples.j]):
                    form.advance(system, state, m, keep=sampler.sample_step_start())
                else:
                    form.advance(system, state, m)

            frame_step = extra_frame_steps(vtk, system.dt, window_start)
            n_steps = int(round(run.duration / system.dt))
            prog.stage(f"continuum ({form.name})", run.duration)
            try:
                done = vibration_timeline(
                    state, n_steps, sample_step, samples, lambda j: sampler.record(j, samples),
                    advance, checkpoint, prog,
                    sampler.n_points, run.checkpoint_every, stop_after_steps, frame_step,
                    lambda i: sampler.early_frame(i, samples))
            except ContinuumBlowUp:
                ckpt.unlink(missing_ok=True)  # a blown-up run has nothing to resume
                raise
            except VibrationInterrupted as e:
                raise interrupted(out, e) from None
        if keep_samples is not None:
            keep_samples.append(samples)
        if not done:
            return None
        with interrupted_while_writing(out):
            summary = _results(form, scenario, out, calibration, options, vtk, system,
                               material, h, times, state, samples, sampler, clock)
        ckpt.unlink(missing_ok=True)
        return summary


def _calibration_block(calibration: Calibration | None) -> dict:
    """{"calibration": the DEM run it was measured on, its case and when} where the calibration
    names its source (calibration.toml's [source]): `vibroflow compare` sets each run beside the
    draw it was calibrated on.  Empty without a calibration or a source."""
    src = getattr(calibration, "source", None) if calibration is not None else None
    if src is None or src.run is None:
        return {}
    return {"calibration": {"source_run": str(src.run), "source_case": src.case,
                            "created": src.created}}


def _results(form: Formulation, scenario, out: Path, calibration, options, vtk, system,
             material, h, times, state, samples: Samples, sampler, clock: RunClock) -> dict:
    """Write a finished run's results into out (summary.json last); the summary."""
    geo = geometry_of(scenario)
    wall_time = clock.solver_s()
    n = sampler.n_points
    n_steps = state.step
    if vtk:
        from vibroflow.io.vtk import write_pvd  # noqa: PLC0415  (only with vtk: pyevtk)

        for kind in sampler.vtk_kinds:
            write_pvd(out / VTK_DIR / f"{kind}.pvd", sorted(samples.vtk[kind]))
        write_vtk_record(out / VTK_DIR, vtk)
    radius = sampler.radius()
    source = samples_source(scenario, samples, times, radius)
    # the DEM's top-level keys (vibroflow.dem.run), with the points or cells as its particles
    summary = {"case": scenario.case, "source": "vibroflow continuum", "method": form.name,
               "n_particles": n, "steps": n_steps, "dt": system.dt,
               "simulated_time_s": n_steps * system.dt, "wall_time_s": wall_time,
               "compile_time_s": clock.compile_s(),
               "particle_steps_per_s": n * n_steps / wall_time if wall_time > 0 else None}
    summary.update(tub_summary(source, scenario, bulk_csv=out / BULK_CSV_NAME, batch_csvs=True))
    run = scenario.run
    batch = batches_of_whole_cycles(times, run.duration - run.average_last, run.duration,
                                    scenario.motion.frequency, run.batches) \
        if times.size else np.zeros(0, np.int64)
    summary["continuum"] = {
        "rheology": material.model, "material": material.to_dict(), "bed_height_m": h,
        "dt_s": system.dt, "steps": n_steps, "transfers_per_step": system.transfers,
        "transfer_cfl": options.transfer_cfl, "wall_time_s": wall_time,
        "stiffness_factor": options.stiffness_factor,
        # the moduli's choice where it is not the default (the material holds the values)
        **({"moduli": options.moduli} if options.moduli != "calibrated" else {}),
        **_calibration_block(calibration),
        # every option as run, so that `vibroflow compare` pools only runs of the same options
        "options": dataclasses.asdict(options),
        **form.continuum_block(system, state, h)}
    phase = phase_shear_of_samples(scenario, samples, times, radius)
    summary["continuum"].update(shear_rate_outputs(
        material, calibration, scenario.analysis.probes, batch, run.batches, samples, phase,
        geo.radius, summary["impacts"]))
    write_shear_rate_csv(out / SHEAR_RATE_CSV_NAME, samples, phase, calibration,
                         material.diameter)
    stress = phase_stress(samples, times, scenario.motion.frequency, run.phases_per_cycle,
                          (run.duration - run.average_last, run.duration), run.batches, phase,
                          material.solid_density, material.diameter)
    write_stress_csv(out / STRESS_CSV_NAME, stress)
    write_stress_batches_csv(out / STRESS_BATCHES_CSV_NAME, stress)
    wrote = write_temperature_csv(out / TEMPERATURE_CSV_NAME, samples, phase)
    summary["continuum"].update(temperature_outputs(samples, batch, run.batches, wrote))
    if options.temperature:
        summary["continuum"]["granular_temperature"].update(
            initial_m2_s2=options.initial_temperature, landing=options.landing)
    summary["continuum"].update(impacts_from_temperature(
        calibration, samples, phase, geo.radius, batch, run.batches, summary["impacts"]))
    if times.size:
        floor = floor_cycle(samples.floor_force[:times.size], times,
                            run.duration - run.average_last, run.duration,
                            scenario.motion.frequency, run.phases_per_cycle, run.batches,
                            weight_of(scenario.gravity, state.mass.sum() * geo.length))
        write_floor_csv(out / FLOOR_CSV_NAME, floor)
        summary["floor"] = floor.as_dict()
    if samples.temperature and np.isfinite(samples.wall_feed[:times.size]).all(axis=1).any():
        feed = wall_feed_cycle(samples.wall_feed[:times.size], times,
                               run.duration - run.average_last, run.duration,
                               scenario.motion.frequency, run.phases_per_cycle, run.batches,
                               region_lengths(geo.radius, geo.rim_height))
        write_wall_feed_csv(out / WALL_FEED_CSV_NAME, feed)
        summary["wall_feed"] = feed.as_dict()
    parts = continuum_parts(scenario)
    if parts:
        window = sample_times(scenario)[1:]
        bed_T = None
        if samples.temperature and np.isfinite(samples.temperature_all).any():
            ok = np.isfinite(samples.temperature_all)
            bed_T = batch_means(samples.temperature_all[ok], batch[ok], run.batches)
        write_parts(out / PARTS_NC_NAME, part_dataset(
            form.name, scenario, parts, pack(parts), calibration, material.diameter, phase,
            samples, times, batch, window[1] - window[0], bed_T))
        summary["continuum"]["parts"] = {
            "file": PARTS_NC_NAME, "names": [p.name for p in parts],
            "obstacle": "each part a wall of the U wall's law in the slice's section"}
    summary = json_safe(summary)
    write_json_atomic(out / SUMMARY_NAME, summary)
    return summary
