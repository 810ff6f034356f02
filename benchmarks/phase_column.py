"""The bed's column by phase of the cycle, DEM against a continuum (docs/validation.md).

    python benchmarks/phase_column.py --dem-dir runs/s18/dem-tub47-seed1
        [--calibration tests/data/tub47-dem/calibration.toml] [--method lagrangian|eulerian]
        [--x 0.0] [--heights 0.05,0.12,0.17,0.19] [--band 0.025] [--no-fields]

Prints, for a vertical column of the tub's cross-section at x = `--x` (m, tub frame):

1. the DEM's coarse-grained column (vibroflow.calibration.run_fields.coarse_grain_run on a 5 mm
   grid): solid fraction, time-averaged velocity, the cycle means of the phase-resolved granular
   temperature and inertial number, pressure and stress ratio tau / p, by height (skipped with
   `--no-fields`);
2. the mean velocity relative to the tub (tub axes) of the bodies in the column (|x - x0| <
   band / 2) in bands of height `band` around each of `--heights`, at each sampled phase of the
   cycle and over the cycle: the DEM's balls (DIR/dem.h5 snapshots) and the continuum's points
   (a run of the same scenario with the calibration, its sampled points through
   run_*(keep_samples=...)), binned the same way;
3. the packing of both beds from their bulk_velocity.csv (the DEM's DIR/bulk_velocity.csv and
   the continuum run's): the mean solid fraction of the dense cells (>= 0.55), the
   solid-fraction-weighted mean solid fraction and the centre of mass's height, and the roll's
   centre (summary.json circulation x, z).

Why: the roll is the cycle-mean drift of a motion relative to the tub that is ten times faster
(+-0.5 m/s up and down at 13 g); this shows whether a continuum gets the motion and misses the
drift, or misses both, at the place where E's largest share lies (the centre column).
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np


def column_by_phase(positions, velocities, poses, phases, per_cycle, x0, band, heights, pivot):
    """{height: (mean vx per phase (per_cycle,), mean vz per phase, bodies per phase)} of the
    bodies with |x - x0| < band / 2 and |z - height| < band / 2 (m, tub frame); velocities
    relative to the tub in tub axes (m/s).  positions, velocities (S, N, 3) lab frame; poses
    (S, 6) X, Z, theta, Xdot, Zdot, thetadot; phases (S,) each sample's phase as a fraction of
    the cycle.  A phase with no body in a band gives NaN."""
    from vibroflow.tub.motion import lab_to_tub_np, relative_velocity_tub_axes_np

    acc = {h: [[] for _ in range(per_cycle)] for h in heights}
    for s in range(len(poses)):
        X, Z, th, Xd, Zd, thd = poses[s]
        p = np.asarray(positions[s], dtype=float)
        v = np.asarray(velocities[s], dtype=float)
        pt = lab_to_tub_np(p, X, Z, th, pivot)
        vt = relative_velocity_tub_axes_np(p, v, X, Z, th, Xd, Zd, thd, pivot)
        k = int(round(phases[s] * per_cycle)) % per_cycle
        inside = np.abs(pt[:, 0] - x0) < 0.5 * band
        for h in heights:
            sel = inside & (np.abs(pt[:, 2] - h) < 0.5 * band)
            if sel.any():
                acc[h][k].append((vt[sel, 0].mean(), vt[sel, 2].mean(), sel.sum()))
    out = {}
    for h in heights:
        rows = [np.mean(r, axis=0) if r else np.full(3, np.nan) for r in acc[h]]
        a = np.array(rows)
        out[h] = (a[:, 0], a[:, 1], a[:, 2])
    return out


def packing(table) -> dict:
    """Packing figures of a bulk_velocity.csv table (vibroflow.measure.bulk.CellTable):
    dense-cell mean solid fraction (cells >= 0.55), solid-fraction-weighted mean solid fraction
    and the centre of mass's height (m, cell centres)."""
    phi = np.asarray(table.solid_fraction, float)
    dense = phi >= 0.55
    return {"dense_mean": float(phi[dense].mean()) if dense.any() else float("nan"),
            "weighted_mean": float(np.sum(phi * phi) / np.sum(phi)),
            "centre_of_mass_z": float(np.sum(phi * np.asarray(table.z)) / np.sum(phi))}


def _dem_fields_column(dem_dir: Path, x0: float) -> None:
    from vibroflow.calibration.run_fields import coarse_grain_run

    ta, _, _ = coarse_grain_run(dem_dir, cell_size=0.005)
    x = ta["x"].values
    i = int(np.argmin(np.abs(x - x0)))
    print(f"DEM coarse-grained column at x = {x[i]:.3f} m (5 mm grid, kernel d/2; T and I are "
          "the cycle means of the phase-resolved fields)")
    print("   z (m)   phi   vx mm/s  vz mm/s  T (1e-3 m2/s2)   p (Pa)  tau/p     I")
    for k, z in enumerate(ta["z"].values):
        phi = float(ta["solid_fraction"].isel(x=i, z=k))
        if not np.isfinite(phi) or phi < 0.05:
            continue
        v = ta["velocity"].isel(x=i, z=k).values
        T = float(ta["temperature_cycle_mean"].isel(x=i, z=k))
        p = float(ta["pressure"].isel(x=i, z=k))
        mu = float(ta["friction_coefficient"].isel(x=i, z=k))
        inert = float(ta["inertial_number_cycle_mean"].isel(x=i, z=k))
        print(f"  {z:.3f}  {phi:.3f}  {1e3 * v[0]:7.1f}  {1e3 * v[-1]:7.1f}  {1e3 * T:13.1f}"
              f"  {p:8.0f}  {mu:5.2f}  {inert:6.3f}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--dem-dir", required=True, type=Path)
    ap.add_argument("--calibration", type=Path,
                    help="calibration.toml (default DIR/calibration.toml)")
    ap.add_argument("--method", choices=("lagrangian", "eulerian"), default="lagrangian")
    ap.add_argument("--x", type=float, default=0.0, help="the column's x (m, tub frame)")
    ap.add_argument("--heights", default="0.05,0.12,0.17,0.19",
                    help="band centres (m, tub frame), comma-separated")
    ap.add_argument("--band", type=float, default=0.025, help="band width and height (m)")
    ap.add_argument("--no-fields", action="store_true",
                    help="skip the DEM's coarse-grained column")
    a = ap.parse_args(argv)
    try:
        heights = [float(h) for h in a.heights.split(",")]
    except ValueError:
        print(f"--heights = {a.heights!r}: must be numbers (m) separated by commas",
              file=sys.stderr)
        return 2
    if not a.band > 0:
        print(f"--band = {a.band!r}: must be > 0 m", file=sys.stderr)
        return 2
    if not (a.dem_dir / "dem.h5").exists():
        print(f"--dem-dir = {str(a.dem_dir)!r}: no dem.h5 there (a finished vibroflow DEM run "
              "folder)", file=sys.stderr)
        return 2

    import h5py

    from vibroflow.continuum.sampling import sample_times
    from vibroflow.continuum.tub_run import run_continuum
    from vibroflow.measure.bulk import read_csv
    from vibroflow.io.calibration_file import read_calibration
    from vibroflow.calibration.dem_result import DEMResult

    with DEMResult.open(a.dem_dir) as res:
        sc = res.scenario
    per = sc.run.phases_per_cycle
    f = sc.motion.frequency
    pivot = tuple(sc.motion.pivot)
    if not a.no_fields:
        _dem_fields_column(a.dem_dir, a.x)
    with h5py.File(a.dem_dir / "dem.h5", "r") as h:
        dem = column_by_phase(h["snapshots/position"][:], h["snapshots/velocity"][:],
                              h["snapshots/tub_pose"][:], h["snapshots/phase"][:], per, a.x,
                              a.band, heights, pivot)

    cal = read_calibration(a.calibration or a.dem_dir / "calibration.toml")
    samplers = []
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / a.method
        summ = run_continuum(sc, out, a.method, calibration=cal, keep_samples=samplers)
        cont_table = read_csv(out / "bulk_velocity.csv")
    smp = samplers[-1]
    times, _, _ = sample_times(sc)
    n = smp.j
    cont = column_by_phase(smp.pos[:n], smp.vel[:n], smp.poses[:n], (np.asarray(times[:n]) * f)
                           % 1.0, per, a.x, a.band, heights, pivot)

    print(f"\n{sc.case}: bodies with |x - {a.x:g}| < {a.band / 2:g} m in bands of "
          f"{a.band * 1e3:g} mm; mean velocity relative to the tub (mm/s) at the {per} phases "
          "of the cycle, and over the cycle")
    for h in heights:
        for comp, j in (("vx", 0), ("vz", 1)):
            for name, r in (("DEM", dem), (a.method, cont)):
                v = r[h][j]
                print(f"  z {h:.3f} {comp} {name:<10} " + " ".join(f"{1e3 * q:6.0f}" for q in v)
                      + f"   mean {1e3 * np.nanmean(v):6.1f}")

    dem_table = read_csv(a.dem_dir / "bulk_velocity.csv")
    with open(a.dem_dir / "summary.json") as fh:
        dem_circ = json.load(fh)["circulation"]
    print("\npacking (bulk_velocity.csv cells) and the roll's centre (summary.json)")
    for name, t, circ in (("DEM", dem_table, dem_circ), (a.method, cont_table,
                                                          summ["circulation"])):
        pk = packing(t)
        print(f"  {name:<10} dense cells {pk['dense_mean']:.3f}  phi-weighted "
              f"{pk['weighted_mean']:.3f}  centre of mass z {pk['centre_of_mass_z']:.4f} m  "
              f"roll centre ({circ['x']:.3f}, {circ['z']:.3f}) m")
    return 0


if __name__ == "__main__":
    sys.exit(main())
