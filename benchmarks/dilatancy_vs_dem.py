"""The continuum with and without the dilatancy option against the DEM (benchmarks/README.md,
"Dilatancy"): one continuum run of a finished DEM's scenario with a given calibration, K_dil set
in its [dilatancy] table, printed as one JSON line: circulation strength against the DEM's, the
ratio and the field difference E (tub47.md; vibroflow.analysis.compare.field_difference).

    .venv/bin/python benchmarks/dilatancy_vs_dem.py --dem-dir runs/study-quick/dem \
        --calibration runs/study-quick/dem/calibration.toml --k-dil 6.71 --out runs/dil/L1
"""
from __future__ import annotations

import argparse
import copy
import json
import sys
import time
from pathlib import Path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--dem-dir", required=True, type=Path, help="a finished DEM folder")
    ap.add_argument("--calibration", required=True, type=Path, help="calibration.toml")
    ap.add_argument("--method", default="lagrangian", choices=("lagrangian", "eulerian"))
    ap.add_argument("--k-dil", type=float, default=0.0, help="K_dil (0: the option off)")
    ap.add_argument("--excess", type=float, default=0.0,
                    help="initial_excess_solid_fraction of the bed over phi_c")
    ap.add_argument("--cfl", type=float, default=0.3)
    ap.add_argument("--out", required=True, type=Path)
    args = ap.parse_args(argv)

    from vibroflow.analysis.bulk import read_csv
    from vibroflow.analysis.compare import field_difference
    from vibroflow.calibration.calibrate import read_calibration
    from vibroflow.calibration.dem_result import DEMResult
    from vibroflow.continuum.eulerian.run import EulerianOptions, run_eulerian
    from vibroflow.continuum.run import LagrangianOptions, run_lagrangian

    with DEMResult.open(args.dem_dir) as res:
        sc = res.scenario
    dem = json.loads((args.dem_dir / "summary.json").read_text())
    cal = copy.deepcopy(read_calibration(args.calibration))
    if args.k_dil > 0:
        cal["dilatancy"] = {**cal.get("dilatancy", {}), "K_dil": args.k_dil,
                            "initial_excess_solid_fraction": args.excess}
    opts = dict(dilatancy=args.k_dil > 0, cfl=args.cfl)
    t0 = time.perf_counter()
    if args.method == "lagrangian":
        s = run_lagrangian(sc, args.out, calibration=cal, options=LagrangianOptions(**opts))
    else:
        s = run_eulerian(sc, args.out, calibration=cal, options=EulerianOptions(**opts))
    h = sc.analysis.cell_size
    E = field_difference(read_csv(args.out / "bulk_velocity.csv", cell_size=h),
                         read_csv(args.dem_dir / "bulk_velocity.csv", cell_size=h),
                         sc.analysis.min_solid_fraction)
    c, dc = s["circulation"], dem["circulation"]
    print(json.dumps({"amplitude_factor": sc.motion.amplitude_factor, "method": args.method,
                      "K_dil": args.k_dil, "excess": args.excess, "cfl": args.cfl,
                      "strength": c["strength"], "strength_stderr": c["strength_stderr"],
                      "dem_strength": dc["strength"], "dem_strength_stderr": dc["strength_stderr"],
                      "ratio": c["strength"] / dc["strength"], "E": E,
                      "wall_time_s": time.perf_counter() - t0}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
