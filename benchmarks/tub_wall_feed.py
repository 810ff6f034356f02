"""The tub's U wall feeding fluctuation energy into a continuum run with T, by arc and by phase,
against the DEM's measured wall flux, and the bed's take-off from the U floor's force
(docs/validation.md section 22, "The tub's wall feed and take-off").

    python benchmarks/tub_wall_feed.py --dem-dir RUN [--calibration TOML]
        [--methods lagrangian,eulerian] [--landing pairs|columns] [--initial-temperature 0.01]
        [--skip-cycles 23] [--cycles 47] [--batches 5]

The continuum: tub47-quick (the DEM run's scenario) from the bed run_continuum starts vibrating
(tub_run.vibration_start), its granular temperature on (`vibroflow continuum --temperature`,
--landing, --initial-temperature), the calibration `--calibration` (default
tests/data/tub47-quick-dem/calibration.toml), advanced as the run is (its compiled loops) one
sampling interval at a time.  At each sample after --skip-cycles, over the step that ends
there, the U wall's feed of each wall-touching point or cell, as the run's balance makes it
(temperature_field.py, wall_energy_flux.cell_wall_terms) from the U wall's contacts alone (the
partitions' and the parts' left out): slip production (capped by the wall friction's power),
plus the landing, less Johnson & Jackson's collision loss at the cell's phi and T, in W per
metre of thickness; the Lagrangian's cells' feed shared among their points by contact length.
Each feed is placed at its point's or cell's arc position on the U (tub.geometry.
point_to_arc) and summed by arc region (the floor within 30 degrees of the bottom, the arcs to
90 degrees, the side walls) and by eighth of the cycle (the tub's phase, t f mod 1), over the
region's arc length: W/m^2 of wall, the DEM's unit.

The DEM: the U wall's fluctuation flux F . (v - V) by arc bin and phase, the calibration's
[kinetic.wall_flux] in RUN/calibration.toml (vibroflow.calibration.wall_energy), summed into the
same regions (arc-length weighted; the bins' batch errors combined in quadrature); and the
bed's floor force: the sampled ball-wall contacts in RUN/dem.h5 within 30 degrees of the
bottom, their force's z component in the tub's axes, by phase over the bed's weight
(vibroflow.measure.floor_force.dem_floor_cycle: every run's floor.csv).  The
continuum's floor force: the U wall's force on the points or wall-layer cells there, the same
component.  The take-off phase: where that force first falls to a twentieth of the weight after
its maximum (measure.floor_force.sampled_take_off, section 23's definition), resolved to the
eighths the samples give.  Every mean carries its batch-means standard error over --batches
batches of whole cycles (the DEM's floor force over its run's run.batches, as its floor.csv).
"""
from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from vibroflow.continuum.boundary import UWall
from vibroflow.continuum.kinetic_stress import KINETIC_COLUMNS
from vibroflow.continuum.temperature_balance import kinetic_stress_of, temperature_step
from vibroflow.continuum.temperature_field import point_cells
from vibroflow.continuum.wall_energy_flux import (cell_wall_terms, contact_terms,
                                                  normal_of_force)
from vibroflow.io.calibration_file import read_calibration
from vibroflow.measure.floor_force import (REGIONS, dem_floor_cycle, region_lengths, region_of,
                                           sampled_take_off, weight_of)
from vibroflow.measure.stats import stderr_of_batches
from vibroflow.tub.geometry import geometry_of, point_to_arc

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_CALIBRATION = ROOT / "tests/data/tub47-quick-dem/calibration.toml"
#: a force sampled at the phases k / P (not at the bins' centres (k + 1/2) / P)
take_off = sampled_take_off


def cell_feed_W_m(phi, T, sums, h, model):
    """The U wall's net feed (W/m) of cells of side h (m) with solid fraction phi, T (m^2/s^2)
    (both (nx, nz)) and wall sums (nx, nz, 4): wall_energy_flux.cell_wall_terms' heating less
    the loss (3/2) rho_s phi a_w T^(3/2), times the cell's area."""
    w = model.walls
    heat, cool = cell_wall_terms(phi, T, sums, float(h), float(w.restitution),
                                 float(w.specularity), bool(w.landing),
                                 model.grid.void_solid_fraction, model.params)
    loss = 1.5 * model.params.density_kg_m3 * phi * cool * np.clip(T, 0, None) ** 1.5
    return (heat - loss) * h * h


def eulerian_sampler(system, state):
    """advance(n) and sample() of an Eulerian run: the wall-layer cells' arc positions (m),
    their U-wall feed (W/m), their floor force's z component (N/m, tub axes)."""
    from vibroflow.continuum.eulerian import solver as eulerian
    from vibroflow.continuum.eulerian import temperature_loop

    model = system.temperature
    mesh = system.mesh
    ts = temperature_step(model, system.material.critical_density
                          / system.material.solid_density, system.dt,
                          system.material.p_wave_speed())
    p_kin = np.zeros((state.n, KINETIC_COLUMNS))
    cells = system.wall_cells
    n = mesh.normal
    rho_s = model.params.density_kg_m3
    h = mesh.h

    def step_and_sample():
        kinetic_stress_of(state.density, state.temperature, state.L, state.stress,
                          state.gamma_dot, state.phase, ts, p_kin)
        start = (state.mass.copy(), state.v.copy(), state.density.copy(),
                 state.stress + p_kin[:, :4])
        eulerian.advance(system, state, 1)
        sums = np.zeros((state.n, 4))
        # the U wall's contacts alone: the partitions off (fused.MeshBoundaries)
        bnd = eulerian._boundaries(system, state)._replace(partitions_on=False)
        temperature_loop.cell_wall_sums(
            bnd, system.mesh_record, system.grid_spec, system.work, system.frame.as_array(),
            state.t - 0.5 * system.dt, state.mass, state.v, state.volume, state.stress,
            state.fext, float(system.material.critical_density), float(system.dt),
            *(np.ascontiguousarray(a, dtype=float) for a in start), True,
            bool(model.walls.columns), sums)
        only = np.zeros_like(sums)
        only[cells] = sums[cells]
        shape = (mesh.ncx, mesh.ncz)
        phi = (state.mass / (rho_s * h * h)).reshape(shape)
        feed = cell_feed_W_m(phi, state.temperature.reshape(shape),
                             only.reshape(shape + (4,)), h, model).ravel()
        fn, ft = state.wall["fn"], state.wall["ft"]
        fz = fn * n[cells, 1] - ft * n[cells, 0] if fn.size == cells.size else \
            (fn * n[:, 1] - ft * n[:, 0])[cells]
        x = system.x[cells]
        return x, feed[cells], fz

    return step_and_sample


def lagrangian_sampler(system, state):
    """As eulerian_sampler, of a Lagrangian run: the points' U-wall sums binned to the
    balance's cells, each cell's feed shared among its points by contact length."""
    from vibroflow.continuum.mpm import solver as mpm

    model = system.temperature
    g = system.grid
    h = model.spacing_m
    nx, nz = g.nx, g.nz   # the balance's cells: temperature_field.point_step's
    wall = next(b for b in system.boundaries if isinstance(b, UWall))
    rho_s = model.params.density_kg_m3

    def step_and_sample():
        mpm.advance(system, state, 1)
        hist = state.history[wall.slot]
        sums = np.zeros((state.n, 4))
        contact_terms(hist["fn"], hist["ft"], normal_of_force(hist["f"], hist["fn"], hist["ft"]),
                      state.v, state.mass, np.sqrt(state.volume), float(wall.stiffness),
                      float(wall.damping_ratio), system.dt, sums)
        idx = point_cells(state.x, g.x0, g.z0, h, (nx, nz))
        ncell = nx * nz
        M = np.bincount(idx, state.mass, ncell)
        E = np.bincount(idx, state.mass * state.temperature, ncell)
        T = np.divide(E, M, out=np.zeros(ncell), where=M > 0)
        phi = M / (rho_s * h * h)
        cs = np.stack([np.bincount(idx, sums[:, j], ncell) for j in range(4)], axis=1)
        feed = cell_feed_W_m(phi.reshape(nx, nz), T.reshape(nx, nz),
                             cs.reshape(nx, nz, 4), h, model).ravel()
        touch = hist["fn"] > 0
        share = np.divide(sums[:, 0], cs[idx, 0], out=np.zeros(state.n), where=cs[idx, 0] > 0)
        point_feed = feed[idx] * share
        return state.x[touch], point_feed[touch], hist["f"][touch, 1]

    return step_and_sample


def continuum(method, scenario, calibration, options, per, skip, cycles, batches):
    """By (batch, phase, region): the U wall's feed (W/m summed), the floor force (N/m), and the
    sample counts; the bed's weight (N/m)."""
    from vibroflow.continuum.eulerian.solver import advance as eul_advance
    from vibroflow.continuum.mpm.solver import advance as mpm_advance
    from vibroflow.continuum.tub_run import vibration_start

    system, state = vibration_start(scenario, calibration, options, method)
    geo = geometry_of(scenario)
    advance = eul_advance if method == "eulerian" else mpm_advance
    sample = (eulerian_sampler if method == "eulerian" else lagrangian_sampler)(system, state)
    f = scenario.motion.frequency
    steps = int(round(1.0 / (f * per) / system.dt))
    feed = np.zeros((batches, per, len(REGIONS)))
    floor = np.zeros((batches, per))
    count = np.zeros((batches, per))
    weight = float(np.hypot(scenario.gravity[0], scenario.gravity[2])) * state.mass.sum()
    for s in range((skip + cycles) * per):
        advance(system, state, steps - 1)
        x, q, fz = sample()
        if s < skip * per:
            continue
        b = min((s - skip * per) * batches // (cycles * per), batches - 1)
        k = int(round(state.t * f * per)) % per
        reg = region_of(point_to_arc(x[:, 0], x[:, 1], geo.radius), geo.radius)
        feed[b, k] += np.bincount(reg, q, len(REGIONS))
        floor[b, k] += fz[reg == 0].sum()
        count[b, k] += 1
    return feed, floor, count, weight


def dem_regions(table, radius):
    """The DEM's U fluctuation flux (W/m^2) by region and by phase x region, with errors."""
    edges = np.asarray(table.arc_edges_m, float)
    centre = 0.5 * (edges[1:] + edges[:-1])
    dl = np.diff(edges)
    reg = region_of(centre, radius)
    arc = np.asarray(table.u_fluctuation_flux_by_arc_W_m2, float)
    arc_se = np.asarray(table.u_fluctuation_flux_by_arc_stderr_W_m2, float)
    pa = np.asarray(table.u_fluctuation_flux_by_phase_arc_W_m2, float)
    pa_se = np.asarray(table.u_fluctuation_flux_by_phase_arc_stderr_W_m2, float)
    out, out_se, by_phase = [], [], []
    for r in range(len(REGIONS)):
        m = reg == r
        L = dl[m].sum()
        out.append((arc[m] * dl[m]).sum() / L)
        out_se.append(math.sqrt(((arc_se[m] * dl[m]) ** 2).sum()) / L)
        by_phase.append(((pa[:, m] * dl[m]).sum(1) / L,
                         np.sqrt(((pa_se[:, m] * dl[m]) ** 2).sum(1)) / L))
    return np.array(out), np.array(out_se), by_phase


def _mean_se(per_batch):
    """Mean and batch-means standard error over the first axis."""
    per_batch = np.asarray(per_batch, float)
    return per_batch.mean(0), stderr_of_batches(per_batch)


def report(name, feed, floor, count, weight, lengths, per):
    """Print a continuum's feed by region and phase, its floor force and take-off."""
    nb = feed.shape[0]
    flux_b = feed.sum(1) / count.sum(1)[:, None] / lengths        # (batch, region) W/m^2
    whole_b = feed.sum((1, 2)) / count.sum(1) / lengths.sum()
    m, se = _mean_se(flux_b)
    wm, wse = _mean_se(whole_b)
    print(f"{name}: U wall feed {wm:.4g} +- {wse:.2g} W/m^2; by region "
          + ", ".join(f"{r} {a:.4g} +- {b:.2g}" for r, a, b in zip(REGIONS, m, se)))
    ph_b = feed.sum(2) / np.maximum(count, 1) / lengths.sum()     # (batch, phase)
    pm, pse = _mean_se(ph_b)
    print(f"{name}: U wall feed by eighth W/m^2: "
          + ", ".join(f"{a:.3g} +- {b:.2g}" for a, b in zip(pm, pse)))
    fl_b = floor / np.maximum(count, 1) / weight
    fm, fse = _mean_se(fl_b)
    print(f"{name}: floor force / weight by eighth: "
          + ", ".join(f"{a:.3g} +- {b:.2g}" for a, b in zip(fm, fse)))
    tb = [take_off(fl_b[b], per) for b in range(nb)]
    print(f"{name}: take-off t f {take_off(fm, per):.3f} (batches {np.round(tb, 3).tolist()}, "
          f"resolution 1/{per})")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--dem-dir", required=True, type=Path)
    ap.add_argument("--calibration", type=Path, default=DEFAULT_CALIBRATION)
    ap.add_argument("--methods", default="lagrangian,eulerian")
    ap.add_argument("--landing", default="pairs", choices=("pairs", "columns"))
    ap.add_argument("--initial-temperature", type=float, default=0.01)
    ap.add_argument("--skip-cycles", type=int, default=23)
    ap.add_argument("--cycles", type=int, default=47)
    ap.add_argument("--batches", type=int, default=5)
    a = ap.parse_args(argv)

    from vibroflow.calibration.dem_result import DEMResult
    from vibroflow.continuum.formulation import formulation

    with DEMResult.open(a.dem_dir) as res:
        scenario = res.scenario
    geo = geometry_of(scenario)
    per = int(scenario.run.phases_per_cycle)
    lengths = region_lengths(geo.radius, geo.rim_height)
    table = read_calibration(a.dem_dir / "calibration.toml").kinetic.wall_flux
    dm, dse, dph = dem_regions(table, geo.radius)
    print(f"DEM: U wall F.(v - V) {table.u_fluctuation_flux_W_m2:.4g} +- "
          f"{table.u_fluctuation_flux_stderr_W_m2:.2g} W/m^2; by region "
          + ", ".join(f"{r} {x:.4g} +- {e:.2g}" for r, x, e in zip(REGIONS, dm, dse)))
    print("DEM: U wall F.(v - V) by eighth W/m^2: " + ", ".join(
        f"{x:.3g} +- {e:.2g}" for x, e in zip(table.u_fluctuation_flux_by_phase_W_m2,
                                                table.u_fluctuation_flux_by_phase_stderr_W_m2)))
    for r, (x, e) in zip(REGIONS, dph):
        print(f"DEM: {r} by eighth W/m^2: " + ", ".join(f"{u:.3g}" for u in x))
    import h5py

    fill = scenario.fill
    mass = fill.count * scenario.materials[fill.material].density * math.pi * fill.diameter ** 3 / 6
    with h5py.File(a.dem_dir / "dem.h5", "r") as hf:
        fl = dem_floor_cycle(hf, scenario, weight_of(scenario.gravity, mass))
    print("DEM: floor force / weight by eighth: "
          + ", ".join(f"{x:.3g} +- {e:.2g}" for x, e in zip(fl.force_over_weight, fl.stderr)))
    print(f"DEM: take-off t f {fl.take_off:.3f} (batches "
          f"{np.round(fl.take_off_batches, 3).tolist()}, resolution 1/{per})")
    cal = read_calibration(a.calibration)
    for method in a.methods.split(","):
        landing = a.landing if method == "eulerian" else "pairs"
        options = formulation(method).options(temperature=True, landing=landing,
                                              initial_temperature=a.initial_temperature)
        feed, floor, count, w = continuum(method, scenario, cal, options, per, a.skip_cycles,
                                          a.cycles, a.batches)
        report(f"{method} ({landing})", feed, floor, count, w, lengths, per)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
