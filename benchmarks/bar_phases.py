"""The bar's impacts by phase of the cycle and by sector, in finished runs (benchmarks/bar_maps.py's
folders, the DEM's or LIGGGHTS' imported; docs/validation.md section 27): where in the cycle
the codes' underside impacts differ.

    python benchmarks/bar_phases.py RUN_DIR [RUN_DIR ...] [--sectors 24 29] [--phases 8]

Per run: the impacts in /part_impacts (dem.h5) on the bar's sectors SECTORS (inclusive, 10 deg
each from +x towards +z; 24 - 29 is 240 - 300 deg, the underside) binned by the tub's phase
t f mod 1 (t from the start of the vibration, f the scenario's frequency): count and mean
normal speed (m/s) per phase bin, then per sector the count and mean speed over the cycle.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from vibroflow.calibration.dem_result import DEMResult


def impacts(run_dir: Path):
    """(time s, sector, normal speed m/s) of the run's part impacts and its frequency (Hz)."""
    with DEMResult.open(run_dir) as res:
        g = res.file["part_impacts"]
        t, patch, vn = g["time"][:], g["patch"][:].astype(int), g["normal_speed"][:].astype(float)
        return t, patch, vn, float(res.scenario.motion.frequency)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("runs", type=Path, nargs="+")
    ap.add_argument("--sectors", type=int, nargs=2, default=[24, 29])
    ap.add_argument("--phases", type=int, default=8)
    args = ap.parse_args()
    lo, hi = args.sectors
    nb = args.phases
    for run in args.runs:
        t, patch, vn, freq = impacts(run)
        sel = (patch >= lo) & (patch <= hi)
        ph = np.floor((t * freq % 1.0) * nb).astype(int) % nb
        print(f"{run}: {t.size} impacts on the bar, {int(sel.sum())} on {10 * lo} - "
              f"{10 * hi + 10} deg, mean v_n {vn[sel].mean():.3f} m/s")
        print("  phase  " + " ".join(f"{k}/{nb:<9d}" for k in range(nb)))
        row = []
        for k in range(nb):
            m = sel & (ph == k)
            row.append(f"{int(m.sum()):3d} {vn[m].mean() if m.any() else float('nan'):.3f}  ")
        print("         " + " ".join(row))
        row = []
        for p in range(lo, hi + 1):
            m = patch == p
            row.append(f"{10 * p}: {int(m.sum())} @ {vn[m].mean() if m.any() else float('nan'):.3f}")
        print("  " + "; ".join(row))


if __name__ == "__main__":
    main()
