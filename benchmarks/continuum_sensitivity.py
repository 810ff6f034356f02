"""Which continuum parameter moves the Lagrangian continuum towards the DEM on the tub case?

    python benchmarks/continuum_sensitivity.py --dem-dir DIR [--calibration FILE]
        [--cases base wall_friction=0.4 ...] [--out DIR]

Issue 4's continuum (vibroflow.continuum.run.run_lagrangian) circulates 1.3-1.7 times too fast
and its field differs from the DEM's by E ~ 1 (tub47.md), against the DEM's own seed-to-seed
E ~ 0.16.  This script runs the continuum of the DEM run's scenario once per case, each case
the calibration (default DIR/calibration.toml) or the numerical options with one thing changed,
and prints the circulation strength (m^2/s +- batch-means standard error) and E(continuum, DEM)
of each, so one sees which parameter, if any, the mismatch is sensitive to.

A case is `base` or `NAME=VALUE` with NAME one of
  wall_friction, partition_friction             (calibration [wall], [partitions] friction)
  mu_scale                                      (mu_s and mu_2 both multiplied)
  bulk_modulus_scale, shear_modulus_scale,
  moduli_scale                                  (K, G, or K and G, multiplied)
  critical_solid_fraction                       ([rheology])
  wall_stiffness (Pa/m), cfl, dx (m), model,
  transfer_cfl (0: one APIC transfer a step)    (LagrangianOptions)
The default list is the one whose figures benchmarks/README.md records.  Wall times are printed
but say little unless the machine is quiet.  Results also go to --out/sensitivity.json.
"""
from __future__ import annotations

import argparse
import copy
import json
import os
import sys
import time
from pathlib import Path

DEFAULT_CASES = ["base", "wall_friction=0.10", "wall_friction=0.40", "partition_friction=0",
                 "mu_scale=0.5", "bulk_modulus_scale=4", "moduli_scale=4",
                 "critical_solid_fraction=0.54", "critical_solid_fraction=0.60",
                 "wall_stiffness=5.9e7", "model=drucker_prager", "cfl=0.6", "dx=0.010",
                 "dx=0.015"]
OPTION_NAMES = ("wall_stiffness", "cfl", "dx", "model", "transfer_cfl")


def apply_case(case: str, calibration: dict) -> tuple[dict, dict]:
    """(calibration, LagrangianOptions keywords) of one case (module docstring)."""
    cal = copy.deepcopy(calibration)
    if case == "base":
        return cal, {}
    name, sep, text = case.partition("=")
    if not sep:
        raise SystemExit(f"--cases: {case!r}: must be base or NAME=VALUE")
    if name == "model":
        return cal, {"model": text}
    value = float(text)
    if name in OPTION_NAMES:
        return cal, {name: value}
    if name == "wall_friction":
        cal["wall"]["friction"] = value
    elif name == "partition_friction":
        cal["partitions"]["friction"] = value
    elif name == "mu_scale":
        cal["rheology"]["mu_s"] *= value
        cal["rheology"]["mu_2"] *= value
    elif name == "bulk_modulus_scale":
        cal["elastic"]["bulk_modulus_Pa"] *= value
    elif name == "shear_modulus_scale":
        cal["elastic"]["shear_modulus_Pa"] *= value
    elif name == "moduli_scale":
        cal["elastic"]["bulk_modulus_Pa"] *= value
        cal["elastic"]["shear_modulus_Pa"] *= value
    elif name == "critical_solid_fraction":
        cal["rheology"]["critical_solid_fraction"] = value
    else:
        raise SystemExit(f"--cases: unknown parameter {name!r} (module docstring lists them)")
    return cal, {}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--dem-dir", required=True, type=Path,
                    help="a finished `vibroflow dem` (or study dem/) folder")
    ap.add_argument("--calibration", type=Path, help="default DEM_DIR/calibration.toml")
    ap.add_argument("--cases", nargs="+", default=DEFAULT_CASES)
    ap.add_argument("--out", type=Path, default=Path("runs/continuum_sensitivity"))
    args = ap.parse_args(argv)

    from vibroflow.analysis.bulk import read_csv
    from vibroflow.analysis.compare import field_difference
    from vibroflow.calibration.calibrate import read_calibration
    from vibroflow.calibration.dem_result import DEMResult
    from vibroflow.continuum.run import LagrangianOptions, run_lagrangian

    with DEMResult.open(args.dem_dir) as res:
        scenario = res.scenario
    dem = json.loads((args.dem_dir / "summary.json").read_text())
    h = scenario.analysis.cell_size
    dem_table = read_csv(args.dem_dir / "bulk_velocity.csv", cell_size=h)
    base = read_calibration(args.calibration or args.dem_dir / "calibration.toml")
    dc = dem["circulation"]
    print(f"{scenario.case}: DEM strength {dc['strength']:.3e} +- {dc['strength_stderr']:.1e} "
          f"m^2/s ({dc['sense']})")
    print(f"{'case':<30} {'strength (m^2/s)':>22} {'/ DEM':>6} {'E(cont, DEM)':>13} {'wall':>7}")
    rows = []
    for case in args.cases:
        cal, opts = apply_case(case, base)
        out = args.out / case.replace("=", "_")
        t0 = time.perf_counter()
        s = run_lagrangian(scenario, out, calibration=cal, options=LagrangianOptions(**opts))
        wall = time.perf_counter() - t0
        c = s["circulation"]
        E = field_difference(read_csv(out / "bulk_velocity.csv", cell_size=h), dem_table,
                             scenario.analysis.min_solid_fraction)
        ratio = c["strength"] / dc["strength"]
        print(f"{case:<30} {c['strength']:>10.3e} +- {c['strength_stderr']:.1e} "
              f"{ratio:>6.2f} {E:>13.3f} {wall:>6.0f}s", flush=True)
        rows.append({"case": case, "strength": c["strength"],
                     "strength_stderr": c["strength_stderr"], "sense": c["sense"],
                     "ratio_to_dem": ratio, "E": E, "wall_time_s": wall})
    args.out.mkdir(parents=True, exist_ok=True)
    tmp = args.out / ".tmp-sensitivity.json"
    tmp.write_text(json.dumps({"case": scenario.case, "dem": dc, "rows": rows}, indent=2))
    os.replace(tmp, args.out / "sensitivity.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
