"""The tub's wall layer by phase of the cycle: how the side walls convey the bed, DEM against
the Lagrangian continuum (docs/validation.md).

    python benchmarks/wall_layer.py --dem-dir runs/study-quick/dem [--calibration FILE]
        [--settle-time 0.05] [--layer-diameters 2] [--above 0.15]

For the balls (DEM, the snapshots of DIR/dem.h5) and the material points (a Lagrangian run of
the same scenario, calibration DIR/calibration.toml by default, its sampled points) within
`--layer-diameters` ball diameters of either vertical side wall and above z = `--above` m (tub
frame), prints the mean vertical velocity relative to the tub (m/s, tub axes, as tub47.md's
bulk velocity) at each sampled phase of the cycle, and its mean over the phases: the net
transport up (+) or down (-) each wall.  The DEM's bed heaps towards the right wall because its
right wall carries the layer up more than down over a cycle (a vibratory conveyor's ratchet);
this script shows by how much, and how much of it the continuum has.

The continuum's sampled points are taken from the run's samples (vibroflow.continuum.sampling
.Samples, which keep every point at every sample instant; run_continuum's keep_samples); the
run itself is the ordinary material point method's run_continuum into a temporary folder.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np


def layer_by_phase(positions, velocities, poses, phases, per_cycle, half_width, depth, above,
                   pivot):
    """{side: (mean vz per phase (per_cycle,), count per phase)} of the bodies within `depth`
    (m) of the wall x = +-half_width above z = `above` (m): positions, velocities (S, N, 3) lab
    frame; poses (S, 6) X, Z, theta, Xdot, Zdot, thetadot; phases (S,) the phase of each
    sample as a fraction of the cycle."""
    from vibroflow.tub.motion import lab_to_tub_np, relative_velocity_tub_axes_np

    out = {s: [[] for _ in range(per_cycle)] for s in ("right", "left")}
    cnt = {s: [[] for _ in range(per_cycle)] for s in ("right", "left")}
    for s in range(len(poses)):
        X, Z, th, Xd, Zd, thd = poses[s]
        p = np.asarray(positions[s], dtype=float)
        v = np.asarray(velocities[s], dtype=float)
        pt = lab_to_tub_np(p, X, Z, th, pivot)
        vt = relative_velocity_tub_axes_np(p, v, X, Z, th, Xd, Zd, thd, pivot)
        k = int(round(phases[s] * per_cycle)) % per_cycle
        for side, sel in (("right", (pt[:, 0] > half_width - depth) & (pt[:, 2] > above)),
                          ("left", (pt[:, 0] < -half_width + depth) & (pt[:, 2] > above))):
            if sel.any():
                out[side][k].append(vt[sel, 2].mean())
                cnt[side][k].append(sel.sum())
    return {side: (np.array([np.mean(a) for a in out[side]]),
                   np.array([np.mean(c) for c in cnt[side]])) for side in out}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--dem-dir", required=True, type=Path)
    ap.add_argument("--calibration", type=Path)
    ap.add_argument("--settle-time", type=float, default=0.05)
    ap.add_argument("--cfl", type=float, default=None,
                    help="the continuum's Courant number (default: the material point method's)")
    ap.add_argument("--transfer-cfl", type=float, default=None,
                    help="its transfers' Courant number (default: the material point method's; "
                         "0: one transfer a step)")
    ap.add_argument("--layer-diameters", type=float, default=2.0)
    ap.add_argument("--above", type=float, default=0.15)
    a = ap.parse_args(argv)

    import h5py

    from vibroflow.continuum.formulation import formulation
    from vibroflow.continuum.sampling import sample_times
    from vibroflow.continuum.tub_run import run_continuum
    from vibroflow.io.calibration_file import read_calibration
    from vibroflow.calibration.dem_result import DEMResult

    with DEMResult.open(a.dem_dir) as res:
        sc = res.scenario
    per = sc.run.phases_per_cycle
    f = sc.motion.frequency
    depth = a.layer_diameters * sc.fill.diameter
    pivot = tuple(sc.motion.pivot)
    half = sc.tub.radius
    with h5py.File(a.dem_dir / "dem.h5", "r") as h:
        dem = layer_by_phase(h["snapshots/position"][:], h["snapshots/velocity"][:],
                             h["snapshots/tub_pose"][:], h["snapshots/phase"][:], per, half,
                             depth, a.above, pivot)
        dem_phase0 = float(h["snapshots/phase"][0])

    samplers = []
    cal = read_calibration(a.calibration or a.dem_dir / "calibration.toml")
    with tempfile.TemporaryDirectory() as tmp:
        run_continuum(sc, Path(tmp) / "lagrangian", "lagrangian", calibration=cal,
                      options=formulation("lagrangian").options(settle_time=a.settle_time, **{
                          k: v for k, v in (("cfl", a.cfl), ("transfer_cfl", a.transfer_cfl))
                          if v is not None}),
                      keep_samples=samplers)
    smp = samplers[-1]
    times, _, _ = sample_times(sc)
    n = smp.j
    phases = (np.asarray(times[:n]) * f) % 1.0
    cont = layer_by_phase(smp.pos[:n], smp.vel[:n], smp.poses[:n], phases, per, half, depth,
                          a.above, pivot)

    print(f"{sc.case}: bodies within {depth * 1e3:.1f} mm of a side wall above z = {a.above} m; "
          f"mean vertical velocity relative to the tub (m/s) by phase (DEM's first sample at "
          f"phase {dem_phase0:.3f})")
    for side in ("right", "left"):
        for name, r in (("DEM", dem), ("Lagrangian", cont)):
            vz, c = r[side]
            print(f"  {side:>5} {name:<10} " + " ".join(f"{x:+.3f}" for x in vz)
                  + f"   net {vz.mean():+.3f}   ({c.mean():.0f} bodies)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
