"""Which continuum parameter moves the continuum towards the DEM on the tub case?

    python benchmarks/continuum_sensitivity.py --dem-dir DIR [--calibration FILE]
        [--cases base wall_friction=0.4 ...] [--settle-times 0.04,0.05,0.06,0.07]
        [--method lagrangian|eulerian] [--jobs 2] [--out DIR]
    python benchmarks/continuum_sensitivity.py --dem-dir tests/data/tub47-dem --case tub47 \
        --dem-strength 2.4418e-3 [--seeds tests/data/tub47-dem-seeds] ...

The second form compares with a reference folder that holds only the DEM's bulk_velocity.csv
and calibration.toml (tests/data/tub47-dem): the scenario is then --case (a preset or a TOML
file) and the DEM's circulation strength --dem-strength (m^2/s; its README gives it).  With
--seeds DIR (a folder of seed*/bulk_velocity.csv, tests/data/tub47-dem-seeds) a run's E is its
mean E against every seed, as `vibroflow compare RUN -r DIR/seed*` judges it
(analysis.compare.difference_to_seeds), instead of E against DEM_DIR/bulk_velocity.csv.

Ensembles.  A single run's E is not a measure: the settling time alone moves a run's E by up to
half its value (docs/validation.md).  Each case is therefore run once per settling
time of --settle-times (default four, 0.04 - 0.07 s)
and printed as mean +- standard error over them, with the members; --jobs runs them in
parallel, one numba thread each.

The continuum's field differs from the DEM's by more than the DEM's own seed-to-seed scatter
(docs/validation.md).  This script runs the continuum of the DEM run's scenario once per case,
each case the calibration (default DIR/calibration.toml) or the numerical options with one
thing changed, and prints the circulation strength (m^2/s +- batch-means standard error) and
E(continuum, DEM) of each, so one sees which parameter, if any, the mismatch is sensitive to.

A case is `base`, `NAME=VALUE`, or several NAME=VALUE joined by `;` (changed together), with
NAME one of
  wall_friction, partition_friction             (calibration [wall], [partitions] friction)
  mu_scale                                      (mu_s and mu_2 both multiplied)
  bulk_modulus_scale, shear_modulus_scale,
  moduli_scale                                  (K, G, or K and G, multiplied)
  critical_solid_fraction                       ([rheology])
  wall_stiffness (Pa/m), cfl, dx (m), model,
  transfer_cfl (0: one APIC transfer a step),
  bed_viscosity (Pa s), flip                    (ContinuumOptions)
  partition_law (contacts | along_flow),
  moduli (calibrated | unloading)               (ContinuumOptions partition_friction, moduli:
                                                 `vibroflow continuum --partition-friction`,
                                                 `--moduli`)
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

import bench

DEFAULT_CASES = ["base", "wall_friction=0.10", "wall_friction=0.40", "partition_friction=0",
                 "mu_scale=0.5", "bulk_modulus_scale=4", "moduli_scale=4",
                 "critical_solid_fraction=0.54", "critical_solid_fraction=0.60",
                 "wall_stiffness=5.9e7", "model=drucker_prager", "cfl=0.6", "dx=0.010",
                 "dx=0.015"]
OPTION_NAMES = ("wall_stiffness", "cfl", "dx", "model", "transfer_cfl", "bed_viscosity", "flip")
#: cases whose value is a word: the case's name -> ContinuumOptions' field
TEXT_OPTIONS = {"model": "model", "partition_law": "partition_friction", "moduli": "moduli"}
DEFAULT_SETTLE_TIMES = "0.04,0.05,0.06,0.07"


def apply_case(case: str, calibration: dict) -> tuple[dict, dict]:
    """(calibration tables, ContinuumOptions keywords) of one case (module docstring), from
    the tables of a calibration (`Calibration.to_toml_dict`)."""
    cal = copy.deepcopy(calibration)
    if ";" in case:
        # several changes at once, e.g. "dx=0.0095;transfer_cfl=0.0075"
        opts = {}
        for part in case.split(";"):
            cal, more = apply_case(part, cal)
            opts.update(more)
        return cal, opts
    if case == "base":
        return cal, {}
    name, sep, text = case.partition("=")
    if not sep:
        raise SystemExit(f"--cases: {case!r}: must be base or NAME=VALUE")
    if name in TEXT_OPTIONS:
        return cal, {TEXT_OPTIONS[name]: text}
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


def _worker_init() -> None:
    # one numba thread per run: the runs themselves are the parallel work
    os.environ["NUMBA_NUM_THREADS"] = "1"


def run_member(job: tuple) -> dict:
    """One run of the ensemble: job = (method, scenario, calibration, options keywords,
    settling time s, output folder, reference csvs, cell size m, min solid fraction).
    Returns {strength, E, wall_time_s}; E is the mean over the reference csvs (one: the DEM
    run's; several: the seeds', analysis.compare.difference_to_seeds)."""
    (method, scenario, cal, opts, settle, out, ref_csvs, h, phi_min) = job
    from vibroflow.measure.bulk import read_csv
    from vibroflow.analysis.compare import difference_to_seeds

    t0 = time.perf_counter()
    from vibroflow.continuum.formulation import formulation
    from vibroflow.continuum.tub_run import run_continuum

    s = run_continuum(scenario, out, method, calibration=cal,
                      options=formulation(method).options(settle_time=settle, **opts))
    wall = time.perf_counter() - t0
    E = difference_to_seeds(read_csv(Path(out) / "bulk_velocity.csv", cell_size=h),
                            [read_csv(c, cell_size=h) for c in ref_csvs], phi_min).mean
    return {"strength": s["circulation"]["strength"], "E": E, "wall_time_s": wall}


def _mean_se(values) -> tuple[float, float]:
    """Mean and standard error of an ensemble's members (measure.stats.stderr_of_batches)."""
    from vibroflow.measure.stats import stderr_of_batches

    return float(sum(values) / len(values)), stderr_of_batches(values)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--dem-dir", required=True, type=Path,
                    help="a finished `vibroflow dem` (or study dem/) folder, or a reference "
                         "folder with bulk_velocity.csv and calibration.toml (with --case)")
    ap.add_argument("--case", help="the scenario (preset or TOML) when --dem-dir holds no DEM "
                                   "run (tests/data/tub47-dem: tub47)")
    ap.add_argument("--dem-strength", type=float,
                    help="the DEM's circulation strength (m^2/s) when --dem-dir has no "
                         "summary.json")
    ap.add_argument("--calibration", type=Path, help="default DEM_DIR/calibration.toml")
    ap.add_argument("--seeds", type=Path,
                    help="a folder of seed*/bulk_velocity.csv: E is the mean against them")
    ap.add_argument("--cases", nargs="+", default=DEFAULT_CASES)
    ap.add_argument("--method", choices=("lagrangian", "eulerian"), default="lagrangian")
    ap.add_argument("--settle-times", default=DEFAULT_SETTLE_TIMES,
                    help="comma-separated settling times (s), one run each")
    ap.add_argument("--jobs", type=int, default=1, help="runs at a time (one thread each)")
    ap.add_argument("--out", type=Path, default=Path("runs/continuum_sensitivity"))
    args = ap.parse_args(argv)
    try:
        settle_times = [float(t) for t in args.settle_times.split(",")]
    except ValueError:
        raise SystemExit(f"--settle-times {args.settle_times!r}: must be comma-separated "
                         "numbers of seconds")
    if not settle_times or min(settle_times) < 0 or args.jobs < 1:
        raise SystemExit("--settle-times must be >= 0 s and --jobs >= 1")

    from concurrent.futures import ProcessPoolExecutor
    from multiprocessing import get_context

    from vibroflow.io.calibration_file import Calibration, read_calibration

    summary = args.dem_dir / "summary.json"
    if args.case is not None:
        scenario = bench.scenario(args.case)
    else:
        from vibroflow.calibration.dem_result import DEMResult

        with DEMResult.open(args.dem_dir) as res:
            scenario = res.scenario
    if summary.exists():
        dc = json.loads(summary.read_text())["circulation"]
    elif args.dem_strength is not None:
        dc = {"strength": args.dem_strength, "strength_stderr": float("nan"), "sense": "?"}
    else:
        raise SystemExit(f"{summary} is missing: give --dem-strength")
    h = scenario.analysis.cell_size
    if args.seeds is not None:
        ref_csvs = sorted(str(c) for c in args.seeds.glob("seed*/bulk_velocity.csv"))
        if not ref_csvs:
            raise SystemExit(f"--seeds {args.seeds}: holds no seed*/bulk_velocity.csv")
    else:
        ref_csvs = [str(args.dem_dir / "bulk_velocity.csv")]
    base = read_calibration(args.calibration or args.dem_dir / "calibration.toml").to_toml_dict()
    print(f"{scenario.case}, {args.method}: DEM strength {dc['strength']:.3e} m^2/s; "
          f"{len(settle_times)} settling times {args.settle_times} s each; E against "
          f"{len(ref_csvs)} DEM field(s)")
    print(f"{'case':<30} {'E(cont, DEM)':>16} {'strength / DEM':>16}  members (E / ratio)")
    jobs, keys = [], []
    for case in args.cases:
        tables, opts = apply_case(case, base)
        cal = Calibration.from_dict(tables, where=f"--cases {case}")
        for st in settle_times:
            out = args.out / f"{args.method}-{case.replace('=', '_')}-{st:g}"
            jobs.append((args.method, scenario, cal, opts, st, str(out), ref_csvs, h,
                         scenario.analysis.min_solid_fraction))
            keys.append(case)
    with ProcessPoolExecutor(args.jobs, mp_context=get_context("spawn"),
                             initializer=_worker_init) as ex:
        results = list(ex.map(run_member, jobs))
    rows = []
    for case in args.cases:
        members = [r for k, r in zip(keys, results) if k == case]
        E, E_se = _mean_se([m["E"] for m in members])
        ratios = [m["strength"] / dc["strength"] for m in members]
        R, R_se = _mean_se(ratios)
        detail = " ".join(f"{m['E']:.3f}/{r:.2f}" for m, r in zip(members, ratios))
        print(f"{case:<30} {E:>8.3f} +- {E_se:.3f} {R:>8.2f} +- {R_se:.2f}  {detail}",
              flush=True)
        rows.append({"case": case, "E": E, "E_stderr": E_se, "ratio_to_dem": R,
                     "ratio_stderr": R_se, "settle_times_s": settle_times,
                     "members": members})
    bench.write_json(args.out / "sensitivity.json", {"case": scenario.case, "method": args.method,
                                                      "dem": dc, "references": ref_csvs,
                                                      "rows": rows})
    return 0


if __name__ == "__main__":
    sys.exit(main())
