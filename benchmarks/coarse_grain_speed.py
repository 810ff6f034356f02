"""Speed of the coarse-graining of a DEM run (the target: a tub47 run, 14 000 balls and 752
snapshots, in under a minute on the 2-core machine).

    python benchmarks/coarse_grain_speed.py RUN_DIR [--peer-snapshots 8]

Times `vibroflow.calibration.run_fields.coarse_grain_run` on the whole averaging window of
RUN_DIR (a `vibroflow dem` run folder: the snapshots, their ball-ball and wall contacts), and,
as the peer run in the same process, a direct NumPy implementation of the same sums (every ball
and every contact's quadrature point deposited on the grid points of its kernel support with
`np.add.at`, the way one would write it without a compiled kernel) on the first
--peer-snapshots snapshots.  Prints snapshots, balls, contacts per snapshot, wall seconds
(reading included), seconds per snapshot of both, and their ratio; checks that the two give the
same sums on the peer's snapshots.
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

import bench


def numpy_peer(cg, snaps) -> tuple[np.ndarray, np.ndarray]:
    """rho (nx, nz) and contact-stress sums (9, nx, nz) of the snapshots, in plain NumPy."""
    from vibroflow.calibration.coarse_grain_kernel import kernel_value

    x0, z0, h = cg.i_min * cg.h, cg.k_min * cg.h, cg.h
    rc = cg.cutoff_radius
    m = int(math.ceil(rc / h))
    da, db = np.meshgrid(np.arange(-m, m + 1), np.arange(-m, m + 1), indexing="ij")
    da, db = da.ravel(), db.ravel()
    rho = np.zeros((cg.nx, cg.nz))
    sig = np.zeros((9, cg.nx, cg.nz))
    nodes, weights = np.polynomial.legendre.leggauss(4)
    nodes, weights = 0.5 * (nodes + 1.0), 0.5 * weights

    def stencil(px, pz):
        a = np.rint((px - x0) / h).astype(np.int64)[:, None] + da[None, :]
        b = np.rint((pz - z0) / h).astype(np.int64)[:, None] + db[None, :]
        ok = (a >= 0) & (a < cg.nx) & (b >= 0) & (b < cg.nz)
        a, b = np.clip(a, 0, cg.nx - 1), np.clip(b, 0, cg.nz - 1)
        w = kernel_value(cg.kernel, cg.width, cg.cutoff if cg.kernel == "gaussian" else None,
                         x0 + a * h - px[:, None], z0 + b * h - pz[:, None]) * ok
        return a, b, w

    for s in snaps:
        p = s["positions_tub"]
        a, b, w = stencil(p[:, 0], p[:, 2])
        np.add.at(rho, (a, b), s["mass"][:, None] * w)
        start = p[s["contacts_i"]]
        br = s["contact_branch"]
        t = np.einsum("ci,cj->cij", s["contact_force"], br).reshape(-1, 9)
        for q in range(4):
            a, b, w = stencil(start[:, 0] - nodes[q] * br[:, 0], start[:, 2] - nodes[q] * br[:, 2])
            for k in range(9):
                np.add.at(sig[k], (a, b), weights[q] * w * t[:, k, None])
    return rho / cg.depth, sig / cg.depth


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("--peer-snapshots", type=int, default=8)
    ap.add_argument("--json", type=Path, default=None)
    a = ap.parse_args(argv)

    from vibroflow.tub.geometry import geometry_of
    from vibroflow.calibration.coarse_grain import CoarseGrainer
    from vibroflow.calibration.dem_result import DEMResult
    from vibroflow.calibration.run_fields import coarse_grain_run

    with DEMResult.open(a.run) as res:
        if not res.has_ball_contacts:
            print(f"{a.run}: no ball contacts stored (a run from before vibroflow 0.2 or an "
                  f"import): the timing covers balls and wall contacts only")
        n_used = int((res.batches() >= 0).sum())
        sc = res.scenario
        # load the numba kernels (compiled once, cached) before timing
        warm = CoarseGrainer(geometry_of(sc), cell_size=sc.analysis.cell_size / 3.0,
                             depth=sc.tub.length, diameter=res.diameter)
        for _, snap in res.iter_snapshots([0]):
            warm.add_snapshot(**{k: v for k, v in snap.items()
                                 if k not in ("time", "pose", "wall_kind")})
        t0 = time.perf_counter()
        avg, phases, info = coarse_grain_run(res)
        t_vf = time.perf_counter() - t0
        # peer: the same sums on the first snapshots, in NumPy
        used = np.nonzero(res.batches() >= 0)[0][: a.peer_snapshots]
        cg = CoarseGrainer(geometry_of(sc), cell_size=sc.analysis.cell_size / 3.0,
                           width=0.5 * res.diameter, depth=sc.tub.length,
                           rho_s=res.solid_density, diameter=res.diameter)
        t0 = time.perf_counter()
        snaps = [snap for _, snap in res.iter_snapshots(used)]
        t_read = time.perf_counter() - t0
        t0 = time.perf_counter()
        for snap in snaps:
            cg.add_snapshot(**{k: snap[k] for k in ("positions_tub", "velocities_rel_tub",
                                                     "radius", "mass", "contacts_i",
                                                     "contacts_j", "contact_force",
                                                     "contact_branch") if k in snap})
        t_vf_sub = time.perf_counter() - t0
        t0 = time.perf_counter()
        rho_np, sig_np = numpy_peer(cg, snaps) if res.has_ball_contacts else (None, None)
        t_np = time.perf_counter() - t0
        n_contacts = np.mean([s["contacts_i"].size for s in snaps]) if res.has_ball_contacts \
            else 0.0
        if rho_np is not None:
            rho_vf = cg._ball[0, 0, 0] / cg.depth
            sig_vf = cg._cont[0, 0] / cg.depth
            err_rho = np.abs(rho_vf - rho_np).max() / np.abs(rho_np).max()
            err_sig = np.abs(sig_vf - sig_np).max() / np.abs(sig_np).max()
        else:
            err_rho = err_sig = float("nan")
        out = {
            "run": str(a.run), "balls": res.n_particles, "snapshots": n_used,
            "ball_contacts_per_snapshot": float(n_contacts),
            "vibroflow_wall_s": t_vf, "vibroflow_s_per_snapshot": t_vf / n_used,
            "vibroflow_deposit_s_per_snapshot": t_vf_sub / max(len(snaps), 1),
            "read_s_per_snapshot": t_read / max(len(snaps), 1),
            "numpy_peer_deposit_s_per_snapshot": t_np / max(len(snaps), 1),
            "ratio_numpy_over_vibroflow_deposit": (t_np / t_vf_sub) if t_vf_sub > 0 else None,
            "peer_relative_difference": {"rho": float(err_rho), "contact_stress": float(err_sig)},
            "machine": bench.machine(),
        }
    print(f"run {a.run}: {out['balls']} balls, {n_used} snapshots, "
          f"{n_contacts:.0f} ball contacts a snapshot")
    print(f"vibroflow coarse_grain_run (read + deposit + fields): {t_vf:.1f} s "
          f"({1e3 * t_vf / n_used:.1f} ms a snapshot)")
    dep_vf = 1e3 * out['vibroflow_deposit_s_per_snapshot']
    print(f"deposit only, {len(snaps)} snapshots: vibroflow {dep_vf:.1f}"
          f" ms, NumPy peer {1e3 * out['numpy_peer_deposit_s_per_snapshot']:.1f} ms a snapshot; "
          f"ratio {out['ratio_numpy_over_vibroflow_deposit']:.1f}x; reading "
          f"{1e3 * out['read_s_per_snapshot']:.1f} ms a snapshot")
    print(f"same sums: max relative difference rho {err_rho:.1e}, contact stress {err_sig:.1e}")
    if a.json:
        bench.write_json(a.json, out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
