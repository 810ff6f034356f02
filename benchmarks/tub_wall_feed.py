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

from vibroflow.continuum.wall_feed import LagrangianWallFeed
from vibroflow.io.calibration_file import read_calibration
from vibroflow.measure.floor_force import (REGIONS, dem_floor_cycle, dem_wall_feed,
                                           region_lengths, region_of, sampled_take_off,
                                           weight_of)
from vibroflow.measure.stats import stderr_of_batches
from vibroflow.tub.geometry import geometry_of, point_to_arc

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_CALIBRATION = ROOT / "tests/data/tub47-quick-dem/calibration.toml"
#: a force sampled at the phases k / P (not at the bins' centres (k + 1/2) / P)
take_off = sampled_take_off


def eulerian_sampler(system, state):
    """step_and_sample() of an Eulerian run: one step, then the wall-layer cells' positions
    (m), their U-wall feed (W/m, vibroflow.continuum.eulerian.wall_feed over that step), their
    floor force's z component (N/m, tub axes)."""
    from vibroflow.continuum.eulerian import solver as eulerian
    from vibroflow.continuum.eulerian.wall_feed import EulerianWallFeed

    feed = EulerianWallFeed(system, state)
    cells = system.wall_cells
    n = system.mesh.normal

    def step_and_sample():
        feed.before_last_step()
        eulerian.advance(system, state, 1)
        x, q = feed.feed()
        fn, ft = state.wall["fn"], state.wall["ft"]
        fz = fn * n[cells, 1] - ft * n[cells, 0] if fn.size == cells.size else \
            (fn * n[:, 1] - ft * n[:, 0])[cells]
        return x, q, fz

    return step_and_sample


def lagrangian_sampler(system, state):
    """As eulerian_sampler, of a Lagrangian run (vibroflow.continuum.wall_feed)."""
    from vibroflow.continuum.mpm import solver as mpm

    feed = LagrangianWallFeed(system, state)

    def step_and_sample():
        mpm.advance(system, state, 1)
        x, q = feed.feed()
        hist = state.history[feed.wall.slot]
        return x, q, hist["f"][hist["fn"] > 0, 1]

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
    """The DEM's U fluctuation flux (W/m^2) by region and by phase x region, with errors
    (vibroflow.measure.floor_force.dem_wall_feed)."""
    d = dem_wall_feed(table, radius)
    by_phase = [(d["by_phase_W_m2"][:, r], d["by_phase_W_m2_stderr"][:, r])
                for r in range(len(REGIONS))]
    return d["by_region_W_m2"], d["by_region_W_m2_stderr"], by_phase


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
