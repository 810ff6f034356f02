"""Orchestration of an Eulerian continuum run of a tub scenario (the Lagrangian run's timeline
and outputs, vibroflow.continuum.run, on the fixed mesh of solver.py).

1. The settled bed: the DEM's solid mass, the Lagrangian bed's (continuum.run.bed_area at the
   critical density), fills the mesh's cells inside the U up to the height that holds exactly
   that mass (the top row partly filled) at the density rho_c exp(p / K) of its pressure, at
   rest, with the lithostatic stress sigma_zz = -rho_c g (h - z),
   sigma_xx = sigma_yy = K0 sigma_zz, K0 = 1 - sin(atan mu_s) (Jaky), as the Lagrangian bed;
   it settles for `settle_time` in the still tub.
2. Vibrate for run.duration in the tub frame (grid_update.TubFrame: the tub's motion from
   vibroflow.tub.motion enters as the frame's inertial forces), sampling at the DEM's sample
   instants (continuum.run.sample_times); the time step divides the sampling interval.
3. Results through the DEM's analysis (analysis.summary.tub_summary), as the Lagrangian run:
   the cells are sampled as pseudo-balls, each of the solid volume
   m_unit L_y / rho_s of a unit mass m_unit = 1.1 rho_c h^2 (a little above a full cell's), and
   a cell is in a sample when its accumulated mass in units, sum m / m_unit, has reached the
   next half unit (error diffusion in time): over the samples a cell then counts its mass to
   within one unit, so the cell table's solid fraction and its ball-averaged velocity are the
   mass-weighted ones to within 1 / samples, with the shared code unchanged.  A pseudo-ball
   sits at its cell's centre shifted by the same offset for every cell of a sample, the
   sample's point of a two-dimensional low-discrepancy sequence over the cell (`cell_offset`):
   over the samples each cell's mass is spread evenly over its square, so the analysis cells
   (15 mm, not a multiple of the mesh's cells) each receive the material of the area they
   cover, where pseudo-balls at the fixed centres gave some analysis cells two rows of
   centres and some one (a striped solid-fraction map).  The offset depends on the sample's
   index only, so a resumed run places the balls as the uninterrupted one.  Wall contacts:
   the wall-layer cells holding at least half a cell of material pressing on the U (wall.py),
   their force over the slice (N).  The summary's "continuum" block holds the method,
   numerics, material, shear rates (as the Lagrangian's, from the cells holding at least half
   a cell of material) and the mass error (M_end - M_0) / M_0 with its largest magnitude over
   the run.

Checkpoints (continuum.checkpoint) every run.checkpoint_every wall seconds of the vibration,
--resume gives the uninterrupted numbers bit for bit, results are written atomically and
summary.json last, a blow-up (mpm.ContinuumBlowUp) names the cells and the likely cause and
removes the checkpoint: all as the Lagrangian run.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vibroflow.measure.stats import batches_of_whole_cycles
from vibroflow.measure.summary import json_safe, tub_summary
from vibroflow.tub.geometry import geometry_of
from vibroflow.errors import InputError
from vibroflow.io.calibration_file import Calibration
from vibroflow.io.folder_lock import folder_lock
from vibroflow.progress import RunProgress
from vibroflow.run_clock import RunClock
from vibroflow.tub.motion import TubMotion

from ..boundary import PartitionFriction, damping_ratio_of_restitution
from ..checkpoint import load_checkpoint, save_checkpoint
from ..constitutive import ContinuumMaterial
from ..fields import grid_fields, write_grid_vtr
from ..grid_update import LabFrame, TubFrame
from ..mpm import ContinuumBlowUp
from ..run import default_dx as lagrangian_default_dx
from ..run import (BULK_CSV_NAME, CHECKPOINT_NAME, REPORT_EVERY, SHEAR_RATE_CSV_NAME,
                   SUMMARY_NAME, VTK_DIR, LagrangianOptions, Samples, VibrationInterrupted,
                   bed_area, cell_grid_of, interrupted, interrupted_while_settling,
                   interrupted_while_writing, material_for, phase_shear_of_samples,
                   run_fingerprint, sample_times, samples_source, shear_rate,
                   shear_rate_outputs, to_lab, vibration_timeline, write_json_atomic,
                   write_shear_rate_csv)
from ..timestep import stable_dt
from .mesh import EulerianMesh
from .solver import EulerianState, EulerianSystem, advance, init_state, state_from_checkpoint
from .wall import MeshWall

#: the pseudo-ball's mass in full cells at the critical density (module docstring, 3)
UNIT = 1.1

#: the Courant number of the APIC transfers (LagrangianOptions.transfer_cfl, continuum.run
#: DEFAULT_TRANSFER_CFL): round(0.3 / 0.0375) = 8 transfers a step at the default cfl 0.3.
#: The Eulerian formulation's own, fewer than the Lagrangian's because its remap damps the
#: grid-scale motion too.  Chosen on tub47 at amplitude factor 1.0 (E against the DEM,
#: strength over the DEM's): E 0.433, strength 0.99; at factors 0.5 and 1.5 E 0.363 and 0.562,
#: on tub47-quick 0.666; with 6 transfers a step (cfl 0.05) about 0.419, 0.418, 0.582 and
#: 0.632, no clear gain, with 4 (0.075) about 0.474 at factor 1.0 and 0.610 on tub47-quick
#: (docs/decisions/transfer-rate.md).
DEFAULT_TRANSFER_CFL = 0.0375


@dataclass(frozen=True)
class EulerianOptions(LagrangianOptions):
    """Numerical options (SI), the Lagrangian's fields and checks: node spacing dx (m; the
    mesh's cells are dx/2; default `default_dx`: about 3 ball diameters), Courant number,
    rheology model ("mu_i" or "drucker_prager"), settling time in the still tub (s), wall
    stiffness (Pa/m; default (K + 4G/3) / (dx/2), the Lagrangian default at the same dx),
    stiffness factor (-; LagrangianOptions).  No FLIP fraction: the mesh's cells are fresh
    copies of the fields at every step, with no velocity of their own to keep.  Its own
    default transfer Courant number, DEFAULT_TRANSFER_CFL (module docstring)."""

    transfer_cfl: float | None = DEFAULT_TRANSFER_CFL

    def default_grid(self, scenario) -> float:
        """The default node spacing (m): `default_dx` of the Lagrangian default (the mesh's
        cells must fill the tub's width)."""
        return default_dx(geometry_of(scenario).radius, lagrangian_default_dx(scenario))

    def __post_init__(self):
        super().__post_init__()
        if self.flip != 0.0:
            raise InputError(f"flip = {self.flip!r}: the Eulerian formulation has no FLIP "
                             "option (only 0)")


#: the additive recurrence of Roberts' R2 sequence (the plastic number's inverse powers), whose
#: points cover the unit square with the lowest discrepancy of its kind
R2 = (0.7548776662466927, 0.5698402909980532)


def cell_offset(j: int) -> tuple[float, float]:
    """The sample j's offset (-0.5 .. 0.5 of a cell side, x and z) of every pseudo-ball from its
    cell's centre (module docstring, 3): the j-th point of the R2 sequence."""
    return ((0.5 + j * R2[0]) % 1.0 - 0.5, (0.5 + j * R2[1]) % 1.0 - 0.5)


def default_dx(radius: float, target: float) -> float:
    """The default node spacing (m): the largest dx <= target (the Lagrangian default,
    continuum.run.default_dx: 3 ball diameters) whose cells of dx/2 fill the tub's width 2R
    exactly (the mesh's requirement; tub47: 18.75 mm for 19.05 mm)."""
    n = math.ceil(2.0 * radius / (0.5 * target) - 1e-9)
    return 2.0 * (2.0 * radius / n)


def make_system(scenario, material: ContinuumMaterial, calibration: Calibration | None,
                options: EulerianOptions, frame) -> EulerianSystem:
    """The Eulerian system of a tub scenario in `frame`: the U's mesh, the wall and partitions
    with the Lagrangian run's parameters (continuum.run.make_system), the time step."""
    from vibroflow.scenario.checks import find_contact

    geo = geometry_of(scenario)
    dx = options.grid(scenario)
    mesh = EulerianMesh.tub(geo, dx)
    wall_pair = find_contact(scenario, scenario.fill.material, scenario.tub.wall_material)
    mu_w = float(calibration.wall.friction if calibration is not None else wall_pair.friction)
    M = material.bulk_modulus + 4.0 * material.shear_modulus / 3.0
    k_wall = options.wall_stiffness if options.wall_stiffness is not None else M / mesh.h
    wall = MeshWall(stiffness=k_wall, friction=mu_w,
                    damping_ratio=damping_ratio_of_restitution(wall_pair.restitution))
    partitions = None
    if not geo.periodic:
        part_pair = find_contact(scenario, scenario.fill.material,
                                 scenario.tub.partition_material)
        mu_p = float(calibration.partitions.friction
                     if calibration is not None and calibration.partitions is not None
                     else part_pair.friction)
        partitions = PartitionFriction(friction=mu_p, length=geo.length)
    dt = stable_dt(material, dx, mesh.h, [wall], v_max=2.0, cfl=options.cfl)
    f, per = scenario.motion.frequency, scenario.run.phases_per_cycle
    interval = 1.0 / (f * per)
    dt = interval / math.ceil(interval / dt)
    return EulerianSystem(mesh, material, dt, frame=frame, wall=wall, partitions=partitions,
                          chunks=scenario.run.force_chunks,
                          transfers=options.transfers_on(scenario))


def bed_masses(system: EulerianSystem, area: float, gravity: float):
    """Cell masses (N,) kg/m, material densities (N,) kg/m^3 and lithostatic stresses (N, 4)
    Pa of the settled bed of cross-section `area` (m^2) at the critical density, and its
    height (m) on the mesh (module docstring, 1); gravity (m/s^2).  The densities are those
    the elastic law gives the lithostatic pressure, rho_c exp(p / K), as the Lagrangian bed's."""
    mesh = system.mesh
    mat = system.material
    rho_c = mat.initial_density  # rho_c unless the bed starts denser (dilatancy)
    c = system.x
    h = mesh.h
    inside = mesh.inside

    k0 = 1.0 - math.sin(math.atan(mat.mu_s))

    def bed(top):
        frac = np.where(inside, np.clip((top - (c[:, 1] - 0.5 * h)) / h, 0.0, 1.0), 0.0)
        stress = np.zeros((mesh.n, 4))
        szz = -rho_c * gravity * np.clip(top - c[:, 1], 0.0, None) * (frac > 0)
        stress[:, 1] = szz
        stress[:, 0] = stress[:, 3] = k0 * szz
        p = -(stress[:, 0] + stress[:, 1] + stress[:, 3]) / 3.0
        density = rho_c * np.exp(p / mat.bulk_modulus)
        return frac * density * h * h, density, stress

    target = rho_c * area  # the Lagrangian bed's mass (kg/m)
    if bed(mesh.zmin + mesh.ncz * h)[0].sum() <= target:
        raise InputError(f"bed area = {area:.4g} m^2: more than the mesh holds below its top")
    lo, hi = mesh.zmin, mesh.zmin + mesh.ncz * h
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        if bed(mid)[0].sum() < target:
            lo = mid
        else:
            hi = mid
    top = 0.5 * (lo + hi)
    mass, density, stress = bed(top)
    return mass, density, stress, top


def tub_system(scenario, calibration: dict | None, options: EulerianOptions
               ) -> tuple[EulerianSystem, ContinuumMaterial]:
    """What a run vibrates: the Eulerian system of the scenario in the vibrating tub's frame
    and its material (material_for)."""
    material = material_for(scenario, calibration, options)
    gravity = (float(scenario.gravity[0]), float(scenario.gravity[2]))
    system = make_system(scenario, material, calibration, options,
                         TubFrame(TubMotion.of_scenario(scenario), gravity))
    return system, material


def vibration_start(scenario, calibration: dict | None, options: EulerianOptions,
                    prog: RunProgress | None = None) -> tuple[EulerianSystem, EulerianState]:
    """The system in the vibrating tub's frame and the bed it starts vibrating from: settled
    for options.settle_time in the still tub, its clock set to t = 0, step 0 (run_eulerian's
    first two steps, for a diagnostic that drives the run itself: benchmarks/)."""
    system, material = tub_system(scenario, calibration, options)
    state, _ = settle(scenario, material, calibration, options, prog)
    state.t, state.step = 0.0, 0
    return system, state


def settle(scenario, material, calibration, options, prog: RunProgress | None = None):
    """The bed after options.settle_time in the still tub; returns (state, bed height m)."""
    gravity = (float(scenario.gravity[0]), float(scenario.gravity[2]))
    system = make_system(scenario, material, calibration, options, LabFrame(gravity))
    mass, density, stress, top = bed_masses(system, bed_area(scenario, material),
                                            math.hypot(*gravity))
    state = init_state(system, mass, density, stress=stress)
    steps = int(math.ceil(options.settle_time / system.dt))
    if prog is not None:
        prog.stage("continuum (eulerian): settle (still tub)", options.settle_time)
    for k in range(0, steps, REPORT_EVERY):
        advance(system, state, min(REPORT_EVERY, steps - k))
        if prog is not None:
            prog.update(state.t, state.step * state.n)
    return state, top


def run_eulerian(scenario, out_dir, calibration: dict | None = None,
                 options: EulerianOptions | None = None, progress: bool = False,
                 vtk: bool = False, resume: bool = False,
                 stop_after_steps: int | None = None,
                 keep_samples: list | None = None) -> dict | None:
    """Run the Eulerian continuum of a tub scenario into out_dir (module docstring); returns
    the summary (also out_dir/summary.json, with out_dir/bulk_velocity.csv), or None when
    stopped by stop_after_steps (a checkpoint is written; go on with resume=True).

    vtk: also the grid fields (continuum.fields: velocity relative to the tub, solid fraction,
    density, pressure, shear rate on the node grid) at the samples of the last cycle, as
    out_dir/vtk/grid_NNNNN.vtr + grid.pvd, and the tub's surface (tub.vtu).  Checkpoints,
    resume and the removal of stale results: as continuum.run.run_lagrangian, and so is
    keep_samples (its points are the cells' pseudo-balls)."""
    if scenario.tub is None or scenario.fill is None:
        raise InputError("scenario: the continuum needs a tub-mode scenario (with [tub] and "
                         "[fill]), not explicit particles")
    if sample_times(scenario)[0].size == 0:
        raise InputError(f"run.average_last = {scenario.run.average_last!r}: must hold at least "
                         "one whole vibration cycle to average over")
    if stop_after_steps is not None and not int(stop_after_steps) >= 0:
        raise InputError(f"stop_after_steps = {stop_after_steps!r}: must be >= 0")
    options = options or EulerianOptions()
    system, material = tub_system(scenario, calibration, options)
    geo = geometry_of(scenario)
    times, t0, t1 = sample_times(scenario)
    S = times.size
    probes = scenario.analysis.probes
    n_cells = int(system.mesh.inside.sum())
    out = Path(out_dir)
    ckpt = out / CHECKPOINT_NAME
    fingerprint = run_fingerprint(scenario, calibration, options, vtk)
    # the folder's lock first (as run_lagrangian): a --out that is a file or read-only is a
    # one-line error before anything is made
    with folder_lock(out, "vibroflow continuum"):
        clock = RunClock()   # the solver's time, numba's compilation apart
        with clock, RunProgress(progress) as prog:
            if resume and ckpt.exists():
                saved, arrays, meta = load_checkpoint(ckpt)
                if meta.get("fingerprint") != fingerprint or meta.get("method") != "eulerian":
                    raise InputError(f"--resume: {ckpt} is the checkpoint of another scenario, "
                                     "calibration, method or options; run without --resume to "
                                     "start afresh")
                state = state_from_checkpoint(system, saved, meta)
                samples = Samples.from_arrays(arrays, S, n_cells, len(probes),
                                              cell_grid_of(geo, scenario.analysis.cell_size))
                dither = arrays["dither"].copy()
                top = float(meta["bed_height_m"])
                clock.resume_from(float(meta["wall_time_s"]))
                prog.log(f"resuming from {ckpt} at t = {state.t:.4f} s")
            else:
                if resume:
                    prog.log(f"no checkpoint in {out}: starting afresh")
                for name in (SUMMARY_NAME, BULK_CSV_NAME, CHECKPOINT_NAME, SHEAR_RATE_CSV_NAME):
                    (out / name).unlink(missing_ok=True)
                with interrupted_while_settling():
                    state, top = settle(scenario, material, calibration, options, prog)
                state.t = 0.0
                state.step = 0
                samples = Samples(S, n_cells, len(probes),
                                  cell_grid_of(geo, scenario.analysis.cell_size))
                dither = np.zeros(n_cells)
            try:
                done = _vibrate(scenario, system, state, samples, dither, geo, material, times,
                                out, vtk, prog, ckpt, fingerprint, clock, top,
                                stop_after_steps)
            except ContinuumBlowUp:
                ckpt.unlink(missing_ok=True)
                raise
            except VibrationInterrupted as e:
                raise interrupted(out, e) from None
        if keep_samples is not None:
            keep_samples.append(samples)
        if not done:
            return None
        with interrupted_while_writing(out):
            summary = _eulerian_results(scenario, out, calibration, options, vtk, system,
                                        material, geo, top, times, state, samples, clock)
        ckpt.unlink(missing_ok=True)
        return summary


def _eulerian_results(scenario, out: Path, calibration, options, vtk, system, material, geo,
                      top, times, state, samples: Samples, clock: RunClock) -> dict:
    """Write a finished Eulerian run's results into out (summary.json last); the summary."""
    S = times.size
    probes = scenario.analysis.probes
    n_cells = int(system.mesh.inside.sum())
    wall_time = clock.solver_s()
    n_steps = state.step
    if vtk:
        from vibroflow.io.vtk import write_pvd

        write_pvd(out / VTK_DIR / "grid.pvd", samples.vtk["grid"])
    h = system.mesh.h
    unit_volume = UNIT * material.critical_density * h * h * geo.length / material.solid_density
    radius = np.full(n_cells, np.cbrt(3.0 * unit_volume / (4.0 * math.pi)))
    source = samples_source(scenario, samples, times, radius)
    summary = {"case": scenario.case, "source": "vibroflow continuum", "method": "eulerian",
               "n_particles": n_cells, "steps": n_steps, "dt": system.dt,
               "simulated_time_s": n_steps * system.dt, "wall_time_s": wall_time,
               "compile_time_s": clock.compile_s(),
               "particle_steps_per_s": n_cells * n_steps / wall_time if wall_time > 0 else None}
    summary.update(tub_summary(source, scenario, bulk_csv=out / BULK_CSV_NAME))
    batch = batches_of_whole_cycles(times, scenario.run.duration - scenario.run.average_last,
                                    scenario.run.duration, scenario.motion.frequency,
                                    scenario.run.batches) if S else np.zeros(0, np.int64)
    mesh = system.mesh
    summary["continuum"] = {
        "method": ("eulerian (fixed mesh in the tub frame, coupled Eulerian-Lagrangian split: "
                   "B-spline Lagrangian step + conservative MUSCL remap, 2D plane strain)"),
        "rheology": material.model,
        "material": material.to_dict(),
        "grid_spacing_m": mesh.grid.dx, "cell_size_m": h, "cells": n_cells,
        # the Lagrangian block's names: the cells are the fixed integration points
        "point_spacing_m": h, "points": n_cells,
        "bed_height_m": top, "dt_s": system.dt, "steps": n_steps,
        "transfers_per_step": system.transfers, "transfer_cfl": options.transfer_cfl,
        "wall_time_s": wall_time,
        "stiffness_factor": options.stiffness_factor,
        "wall_friction": system.wall.friction, "wall_stiffness_Pa_m": system.wall.stiffness,
        "partition_friction": (system.partitions.friction if system.partitions is not None
                               else None),
        "mass_kg_per_m": {"initial": state.mass0, "final": state.total_mass()},
        "mass_error": state.mass_error(), "mass_error_max_abs": state.mass_error_max,
        "max_solid_fraction": float(state.mass.max() / (h * h * material.solid_density)),
    }
    phase = phase_shear_of_samples(scenario, samples, times, radius)
    summary["continuum"].update(shear_rate_outputs(
        material, calibration, probes, batch, scenario.run.batches, samples, phase, geo.radius,
        summary["impacts"]))
    write_shear_rate_csv(out / SHEAR_RATE_CSV_NAME, samples, phase, calibration,
                         material.diameter)
    summary = json_safe(summary)
    write_json_atomic(out / SUMMARY_NAME, summary)
    return summary


def _vibrate(scenario, system: EulerianSystem, state: EulerianState, samples: Samples,
             dither: np.ndarray, geo, material, times, out: Path, vtk: bool,
             prog: RunProgress, ckpt: Path, fingerprint: str, clock: RunClock,
             top: float, stop_after_steps: int | None) -> bool:
    """Vibrate from state.step to the end of run.duration, sampling at `times` and writing a
    checkpoint every run.checkpoint_every wall seconds; False when stopped by
    stop_after_steps (after its checkpoint)."""
    run = scenario.run
    S = times.size
    mesh = system.mesh
    cells = np.nonzero(mesh.inside)[0]
    xc = np.ascontiguousarray(system.x[cells])
    n = cells.size
    motion = system.frame.motion
    pv = (motion.pivot_x, motion.pivot_z)
    cell = scenario.analysis.cell_size
    full = material.critical_density * mesh.h**2
    unit = UNIT * full
    probe_cells = [(math.floor(pr.x / cell + 0.5), math.floor(pr.z / cell + 0.5))
                   for pr in scenario.analysis.probes.values()]
    ci = np.floor(xc[:, 0] / cell + 0.5)
    ck = np.floor(xc[:, 1] / cell + 0.5)
    in_probe = [(ci == pi) & (ck == pk) for pi, pk in probe_cells]
    near_wall = mesh.wall[cells]
    wall_cells = cells[near_wall]
    sample_step = np.rint(times / system.dt).astype(np.int64)
    n_steps = int(round(run.duration / system.dt))
    buf_p, buf_v = np.zeros((n, 3)), np.zeros((n, 3))
    far = np.array([0.0, 0.5 * geo.length, 1.0e3])  # outside every analysis cell
    if vtk:
        from vibroflow.io.vtk import write_tub_surface

        (out / VTK_DIR).mkdir(exist_ok=True)
        write_tub_surface(out / VTK_DIR / "tub.vtu", geo)
    hist = state.wall

    def checkpoint():
        save_checkpoint(ckpt, state, {**samples.arrays(), "dither": dither}, {
            "fingerprint": fingerprint, "method": "eulerian", "mass0": state.mass0,
            "mass_error_max": state.mass_error_max, "bed_height_m": top,
            "wall_time_s": clock.solver_s()})

    prog.stage("continuum (eulerian)", run.duration)

    def record(j):
        """Sample j, at step sample_step[j]."""
        pose6 = np.array(system.frame.pose(state.t))
        v = np.ascontiguousarray(state.v[cells])
        ox, oz = cell_offset(j)
        x_ball = xc + np.array([ox * mesh.h, oz * mesh.h])
        to_lab(x_ball, v, pose6, pv[0], pv[1], buf_p, buf_v, 0.5 * geo.length)
        dither[:] += state.mass[cells] / unit  # in place: the checkpoint's array
        take = dither >= 0.5
        dither[take] -= 1.0
        buf_p[~take] = far
        samples.pos[j], samples.vel[j], samples.poses[j] = buf_p, buf_v, pose6
        # contacts as the Lagrangian run counts them: cells holding at least half a
        # cell of material (a material point's size), pressing on the U
        touching = np.nonzero((hist["state"][wall_cells] > 0)
                              & (state.mass[wall_cells] >= 0.5 * full))[0]
        tc = wall_cells[touching]
        samples.add_contacts(j, np.searchsorted(cells, tc), hist["fn"][tc], hist["ft"][tc],
                             hist["state"][tc], mesh.arc[tc], system.x[tc], geo.length)
        rate_all = shear_rate(state.L)
        if vtk and j >= S - run.phases_per_cycle:
            name = f"grid_{j:05d}.vtr"
            fields = grid_fields(mesh.grid, system.x, state.v, state.mass,
                                 state.pressure(), rate_all, material.solid_density)
            write_grid_vtr(out / VTK_DIR / name, mesh.grid, fields, 0.5 * geo.length)
            samples.vtk["grid"].append((state.t, name))
        rate = rate_all[cells]
        held = state.mass[cells] >= 0.5 * full
        if held.any():
            samples.rate_all[j] = rate[held].mean()
            samples.add_cell_rates(system.x[cells][held], rate[held])
        if (held & near_wall).any():
            samples.rate_wall[j] = rate[held & near_wall].mean()
        for q, inside in enumerate(in_probe):
            if (inside & held).any():
                samples.rate_probe[j, q] = rate[inside & held].mean()

    return vibration_timeline(state, n_steps, sample_step, samples, record,
                              lambda m: advance(system, state, m), checkpoint, prog, n,
                              run.checkpoint_every, stop_after_steps)
