"""Both continuum formulations (Lagrangian material point method, Eulerian fixed mesh) against
vibroflow's DEM on the tub case.

    python benchmarks/continuum_vs_dem.py [--case tub47-quick|tub47] [--factors 0.5 1.0 1.5]
        [--methods lagrangian eulerian] [--calibration FILE] [--dem-dir DIR ...] [--run-dem]
        [--seeds 1 2 ...] [--e-seed E] [--dx M] [--rheology mu_i|drucker_prager]
        [--warm-up] [--out DIR]

For each amplitude factor s (tub47.md "Amplitude sweep": the three amplitudes times s) the
script needs the DEM of the case at s for each seed of --seeds, and runs every continuum method
of --methods (the study's registry, vibroflow.study.methods: default all of them) on the same
scenario, so for the same simulated time and on the same cells and probes, with the parameters
of --calibration (a calibration.toml from `vibroflow calibrate`; without it tub47's defaults).

The DEM runs come from --dem-dir (existing `vibroflow dem` folders, each matched to its case,
amplitude factor and seed through the scenario stored in its dem.h5; a folder whose scenario
differs from the case's in anything else is refused), else from --out/dem_s<factor>_seed<seed>
when a finished run is there, else, with --run-dem, they are run there now (tub47-quick: minutes
each; tub47: about half an hour each).  A factor with no DEM run is reported without it.

Printed for each factor: the probe velocities (vx, vz +- batch-means standard errors) of the DEM
and of each continuum method, one column each; the circulation strengths with their standard
errors and senses; the field
difference E(continuum, DEM) of tub47.md (vibroflow.analysis.compare, the DEM of the first seed
the reference) beside the DEM's seed-to-seed E.  With two or more seeds, that floor is the mean
of E over every ordered pair of them (compare.seed_scatter; with three or more, its jackknife
standard error), and the continuum is compared with every seed in turn (compare.
difference_to_seeds: each E, their mean and its standard error), so the comparison and its floor
are measured on the same ensemble; with one seed the floor is the value of --e-seed, marked
"given".  The tub47.md verdicts: strengths agree within max(10 %, 2 combined standard errors)
and the same sense (against the first seed); fields agree when E(continuum, DEM) <= 1.5 E_seed
(the mean over the seeds when there are several).  With several seeds, also E against the
seeds' mean field (compare.ensemble_mean: their noise averaged down, so nearer the systematic
part of the difference) beside each seed's E against the mean of the others; where E comes
from (each continuum's share of E^2 in the tub's width and the
DEM bed's depth in thirds, vibroflow.analysis.compare.difference_by_region); and the wall times
of both and their ratio (the mission's target: the continuum at
least 100 times cheaper at equal accuracy).  Wall times are those the runs recorded in their
summary.json ("wall_time_s": the DEM's from its start, fill from the cache or not, the
continuum's with its settling); the DEM's were taken whenever and with whatever load its run
had, so the ratio is indicative unless both ran on a quiet machine.  Every method's
wall_time_s leaves numba's compilation out (vibroflow.run_clock: it is compile_time_s, printed
beside it), so a cold kernel cache does not put the ratio at 12 - 16 instead of 100 - 250
(docs/validation.md, cost); `--warm-up` still runs each method once
unrecorded first (warm_up), for timings that also hold no first load of the cached kernels.

Everything also goes to --out/report.json (default runs/continuum_vs_dem/<case>/, git-ignored),
with the continuum runs' folders (<method>_s<factor>) beside it.
"""
from __future__ import annotations

import argparse
import json
import math
import shutil
import sys
import time
import tomllib
from pathlib import Path

import bench

PROBES = ("P1", "P2", "P3", "P4", "P5")


def scenario_at(case: str, factor: float, seed: int, overrides: list[str]):
    return bench.scenario(case, [*overrides, f"motion.amplitude_factor={factor!r}",
                                 f"run.seed={seed}"])


def _comparable(s) -> dict:
    """A scenario's fields that must agree between a reused DEM run and the case (all but
    the amplitude factor, the seed and the run's bookkeeping)."""
    d = s.model_dump(mode="json")
    d["motion"].pop("amplitude_factor", None)
    for key in ("seed", "checkpoint_every", "series_every", "record_impacts"):
        d["run"].pop(key, None)
    return d


def dem_run_scenario(folder: Path):
    """The scenario a `vibroflow dem` folder was run with (from dem.h5)."""
    import h5py

    from vibroflow.scenario.io import parse_scenario

    with h5py.File(folder / "dem.h5", "r") as f:
        text = f.attrs["scenario_toml"]
    return parse_scenario(tomllib.loads(text if isinstance(text, str) else text.decode()))


def collect_dem_dirs(dirs: list[Path], case: str, overrides: list[str]) -> dict:
    """{(factor, seed): folder} of the given DEM folders, checked against the case."""
    found = {}
    for d in dirs:
        if not (d / "summary.json").is_file() or not (d / "dem.h5").is_file():
            sys.exit(f"error: --dem-dir = {str(d)!r}: no finished DEM run (summary.json, "
                     "dem.h5) there")
        s = dem_run_scenario(d)
        ref = scenario_at(case, s.motion.amplitude_factor, s.run.seed, overrides)
        if _comparable(s) != _comparable(ref):
            sys.exit(f"error: --dem-dir = {str(d)!r}: its scenario ({s.case}) is not {case} "
                     "(with these --set) but for the amplitude factor and seed")
        found[(round(float(s.motion.amplitude_factor), 6), int(s.run.seed))] = d
    return found


def run_dem_here(scenario, folder: Path) -> None:
    from vibroflow.dem.run import run_dem

    print(f"  DEM {scenario.case} x{scenario.motion.amplitude_factor:g} seed "
          f"{scenario.run.seed} -> {folder}", flush=True)
    run_dem(scenario, folder, resume=True, progress=True)


def load_result(folder: Path, cell_size: float) -> dict:
    """A run's summary.json with its bulk_velocity.csv (cells of cell_size m) as "_table"."""
    from vibroflow.measure.bulk import read_csv

    summary = json.loads((folder / "summary.json").read_text())
    summary["_table"] = read_csv(folder / "bulk_velocity.csv", cell_size=cell_size)
    summary["_folder"] = str(folder)
    return summary


def _run_result(r: dict):
    """A loaded run (load_result) as vibroflow.analysis.judge reads one."""
    from vibroflow.analysis.judge import result_from_summary

    return result_from_summary(r, r["_folder"], r["_table"])


def _f(x, fmt="{:+.4f}") -> str:
    return "n/a" if x is None or (isinstance(x, float) and not math.isfinite(x)) else fmt.format(x)


def _pm(v, se, fmt="{:+.4f}") -> str:
    return f"{_f(v, fmt)} +- {_f(se, fmt.replace('+', ''))}"


def compare_factor(factor: float, cont: dict, dems: list[dict],
                   e_seed_given: float | None, half_width: float) -> dict:
    """The numbers and verdicts of one amplitude factor (module docstring); half_width the
    tub's (m), for the regions of E."""
    from dataclasses import asdict

    from vibroflow.analysis.compare import (FIELD_FACTOR, bed_thirds, difference_by_region,
                                            field_difference, fields_agree, strengths_agree)
    from vibroflow.analysis.judge import judge

    out: dict = {"factor": factor, "continuum": _brief(cont),
                 "dem": [_brief(d) for d in dems]}
    if not dems:
        return out
    ref = dems[0]
    cc, dc = cont["circulation"], ref["circulation"]
    out["strengths_agree"] = strengths_agree(cc["strength"], cc["strength_stderr"],
                                             dc["strength"], dc["strength_stderr"],
                                             cc["sense"], dc["sense"])
    out["strength_ratio"] = cc["strength"] / dc["strength"] if dc["strength"] else None
    out["E_continuum_dem"] = field_difference(cont["_table"], ref["_table"])
    out["E_by_region"] = [asdict(r) for r in difference_by_region(
        cont["_table"], ref["_table"], *bed_thirds(ref["_table"], half_width))]
    if len(dems) > 1:
        # every ordered pair of the seeds, and the continuum against every seed and their mean
        # field: the floor and the comparison measured on the same ensemble, with their errors
        # (vibroflow.analysis.judge, what `vibroflow compare` prints)
        j = judge([_run_result(cont)], [_run_result(d) for d in dems])
        floor, res = j["floor"], j["results"][0]
        out["E_seed"] = floor["E_seed"]
        out["E_seed_stderr"] = floor["stderr"]
        out["E_seed_pairs"] = floor["pairs"]
        out["E_seed_source"] = (f"mean over the {len(floor['pairs'])} ordered pairs of "
                                f"{len(dems)} DEM seeds")
        out["E_seed_ensemble"] = floor["each_against_mean_of_others"]
        out["E_continuum_ensemble"] = res["E_mean_field"]
        out["E_continuum_seeds"] = res["E_each"]
        out["E_continuum_seeds_mean"] = res["E_mean"]
        out["E_continuum_seeds_stderr"] = res["E_stderr"]
    elif e_seed_given is not None:
        out["E_seed"] = e_seed_given
        out["E_seed_source"] = "given (--e-seed)"
    else:
        out["E_seed"] = None
        out["E_seed_source"] = "one DEM seed only"
    # judged on the ensemble when there is one (the mean over the seeds against the mean
    # seed-to-seed E), else the first seed's E against the given floor
    e_judged = out.get("E_continuum_seeds_mean", out["E_continuum_dem"])
    out["fields_agree"] = (fields_agree(e_judged, out["E_seed"])
                           if out["E_seed"] is not None else None)
    out["field_factor_limit"] = FIELD_FACTOR
    wd, wc = ref.get("wall_time_s"), cont.get("wall_time_s")
    out["wall_time_ratio_dem_over_continuum"] = wd / wc if wd and wc else None
    return out


def _brief(r: dict) -> dict:
    return {"folder": r["_folder"], "source": r.get("source"),
            "n_particles": r.get("n_particles"), "simulated_time_s": r.get("simulated_time_s"),
            "wall_time_s": r.get("wall_time_s"), "compile_time_s": r.get("compile_time_s"),
            "circulation": r.get("circulation"),
            "probes": r.get("probes")}


def print_factor(factor: float, results: dict[str, dict], conts: dict[str, dict],
                 dems: list[dict], seeds: list[int]) -> None:
    """One factor's table: a column of probe velocities per method and DEM seed, then each
    continuum method's strength ratio, E and wall-time ratio against the DEM."""
    print(f"\n=== amplitude factor {factor:g} ===")
    rows = list(conts.items()) + [(f"DEM seed {s}", d) for s, d in zip(seeds, dems)]
    print(f"{'probe':<6}" + "".join(f"{name + ' vx, vz (m/s)':>42}" for name, _ in rows))
    for p in PROBES:
        line = f"{p:<6}"
        for _, r in rows:
            q = r["probes"].get(p, {})
            pair = (f"{_pm(q.get('vx'), q.get('vx_stderr'))}, "
                    f"{_pm(q.get('vz'), q.get('vz_stderr'))}")
            line += pair.rjust(42)
        print(line)
    for name, r in rows:
        c = r["circulation"]
        print(f"{name:<12} circulation {c['sense']:<16} strength "
              f"{_pm(c['strength'], c['strength_stderr'], '{:.4e}')} m^2/s"
              f"   wall {r.get('wall_time_s', float('nan')):8.1f} s"
              f" (+{r.get('compile_time_s') or 0.0:.1f} s compiling)"
              f"   simulated {r.get('simulated_time_s', float('nan')):.3f} s"
              f"   {r.get('n_particles')} {'balls' if name.startswith('DEM') else 'points'}")
    if not dems:
        print("no DEM run for this factor: nothing to compare")
        return
    for name, res in results.items():
        ratio = res.get("strength_ratio")
        print(f"{name}: strength / DEM = {_f(ratio, '{:.3f}')}; strengths agree (tub47.md): "
              f"{'yes' if res['strengths_agree'] else 'no'}")
        es = res["E_seed"]
        verdict = {True: "yes", False: "no",
                   None: "cannot say (no seed-to-seed E)"}[res["fields_agree"]]
        if "E_continuum_seeds" in res:
            each = ", ".join(f"{e:.3f}" for e in res["E_continuum_seeds"])
            print(f"{name}: E(continuum, DEM seed k) = {each}: mean "
                  f"{_pm(res['E_continuum_seeds_mean'], res['E_continuum_seeds_stderr'], '{:.3f}')}"
                  f"; DEM seed-to-seed E = {_pm(es, res['E_seed_stderr'], '{:.3f}')} "
                  f"({res['E_seed_source']}, jackknife error); limit 1.5 E_seed = "
                  f"{1.5 * es:.3f}; fields agree: {verdict}")
            others = ", ".join(f"{e:.3f}" for e in res["E_seed_ensemble"])
            print(f"{name}: against the mean field of the {len(res['E_seed_ensemble'])} seeds: "
                  f"E = {res['E_continuum_ensemble']:.3f} (each seed against the mean of the "
                  f"others: {others})")
        else:
            print(f"{name}: E(continuum, DEM) = {res['E_continuum_dem']:.3f}; DEM seed-to-seed "
                  f"E = {_f(es, '{:.3f}')} ({res['E_seed_source']}); limit 1.5 E_seed = "
                  f"{_f(1.5 * es if es is not None else None, '{:.3f}')}; fields agree: "
                  f"{verdict}")
        r = res["wall_time_ratio_dem_over_continuum"]
        print(f"{name}: wall time DEM / continuum = {_f(r, '{:.1f}')} (target >= 100)")
    for name, res in results.items():
        print_regions(name, res["E_by_region"])


def print_regions(name: str, regions: list[dict]) -> None:
    """Where E comes from (vibroflow.analysis.compare.difference_by_region on the tub's width
    and the DEM bed's depth in thirds): each region's share of E^2, the DEM's and the
    continuum's mean speed there and the continuum's mean velocity difference, mm/s."""
    print(f"{name}: where E comes from (share of E^2; |v| DEM / continuum; continuum - DEM "
          "vx, vz; mm/s)")
    names = ("left", "centre", "right")
    for k, z_name in enumerate(("bottom", "middle", "top")):
        row = regions[3 * k: 3 * k + 3]
        z0, z1 = row[0]["z_range"]
        cells = "  ".join(
            f"{names[i]:>6} {r['share']:4.2f} ({1e3 * r['speed_b']:3.0f} / "
            f"{1e3 * r['speed_a']:3.0f}; {1e3 * r['dvx']:+4.0f}, {1e3 * r['dvz']:+4.0f})"
            for i, r in enumerate(row))
        print(f"  {z_name:>6} z {z0:.3f}-{z1:.3f} m: {cells}")


def warm_up(methods, options, cal, scenario, out: Path) -> dict:
    """Run each method once, unrecorded (into out/warm_up_<method>, removed), so that the timed
    runs find numba's cache filled and loaded once.  A run's wall_time_s leaves its
    compilation out (vibroflow.run_clock), which is 40 - 55 s on tub47 against
    3 - 6 s of solving on a cold cache (after any edit of the package's sources,
    vibroflow/_kernel_cache.py clears it), so this is optional (`--warm-up`).  Returns
    {method: this run's wall time (s)}."""
    took = {}
    for name, m in methods.items():
        folder = out / f"warm_up_{name}"
        t0 = time.perf_counter()
        m.run(scenario, folder, cal, options[name], True, False)
        took[name] = time.perf_counter() - t0
        shutil.rmtree(folder, ignore_errors=True)
        print(f"  {name}: warm-up run {took[name]:.1f} s (numba's cache; not in the wall times)",
              flush=True)
    return took


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--case", default="tub47-quick", choices=["tub47-quick", "tub47"])
    ap.add_argument("--factors", type=float, nargs="+", default=[0.5, 1.0, 1.5])
    ap.add_argument("--methods", nargs="+", default=None,
                    help="continuum methods of the study's registry (default: all)")
    ap.add_argument("--calibration", type=Path, default=None,
                    help="calibration.toml (or a run folder holding one)")
    ap.add_argument("--dem-dir", type=Path, action="append", default=[],
                    help="an existing `vibroflow dem` folder of the case (repeatable)")
    ap.add_argument("--run-dem", action="store_true",
                    help="run the DEM runs that are missing into --out")
    ap.add_argument("--seeds", type=int, nargs="+", default=[1],
                    help="DEM fill seeds (the first is the reference)")
    ap.add_argument("--e-seed", type=float, default=None,
                    help="the DEM's seed-to-seed E to judge with when only one seed is there")
    ap.add_argument("--dx", type=float, default=None, help="continuum grid spacing (m)")
    ap.add_argument("--rheology", default="mu_i", choices=["mu_i", "drucker_prager"])
    ap.add_argument("--reuse-continuum", action="store_true",
                    help="reuse finished continuum runs in --out instead of running them")
    ap.add_argument("--set", dest="overrides", action="append", default=[],
                    metavar="KEY=VALUE", help="scenario override for both methods")
    ap.add_argument("--warm-up", dest="warm_up", action="store_true",
                    help="run each continuum method once unrecorded before the timed runs "
                         "(their wall_time_s leave numba's compilation out anyway)")
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args(argv)
    out = args.out or Path("runs") / "continuum_vs_dem" / args.case
    out.mkdir(parents=True, exist_ok=True)

    from vibroflow.errors import InputError
    from vibroflow.study.methods import METHODS, method

    try:
        cal = None
        if args.calibration is not None:
            from vibroflow.io.calibration_file import read_calibration

            cal = read_calibration(args.calibration)
        dem_dirs = collect_dem_dirs(args.dem_dir, args.case, args.overrides)
        methods = {name: method(name) for name in (args.methods or list(METHODS))}
        # each method's own options from the shared ones (its default dx when --dx is absent)
        options = {name: m.make_options({"model": args.rheology,
                                         **({"dx": args.dx} if args.dx else {})})
                   for name, m in methods.items()}
    except InputError as e:
        print(f"error: {e.message}", file=sys.stderr)
        return 2

    report = {"case": args.case, "calibration": str(args.calibration) if args.calibration
              else None, "options": {"dx": args.dx, "rheology": args.rheology},
              "seeds": args.seeds, "overrides": args.overrides,
              "machine": bench.machine(), "factors": []}
    print(f"{args.case}: continuum ({', '.join(methods)}; {args.rheology}) against the DEM; "
          "calibration "
          f"{args.calibration or 'none (tub47 defaults)'}; load {bench.load_1min():.2f}")
    base = scenario_at(args.case, 1.0, args.seeds[0], args.overrides)
    cell, radius = base.analysis.cell_size, base.tub.radius
    if args.warm_up and not args.reuse_continuum:
        report["warm_up_s"] = warm_up(methods, options, cal,
                                      scenario_at(args.case, args.factors[0], args.seeds[0],
                                                  args.overrides), out)
    for factor in args.factors:
        key_f = round(factor, 6)
        dems = []
        for seed in args.seeds:
            folder = dem_dirs.get((key_f, seed)) or out / f"dem_s{factor:g}_seed{seed}"
            if not (folder / "summary.json").is_file():
                if not args.run_dem:
                    print(f"  (no DEM run of x{factor:g} seed {seed}: give --dem-dir or "
                          "--run-dem)")
                    continue
                run_dem_here(scenario_at(args.case, factor, seed, args.overrides), folder)
            dems.append(load_result(folder, cell))
        seeds_found = [s for s in args.seeds
                       if (dem_dirs.get((key_f, s)) or out / f"dem_s{factor:g}_seed{s}"
                           ).joinpath("summary.json").is_file()]
        conts, results = {}, {}
        for name, m in methods.items():
            cfolder = out / f"{name}_s{factor:g}"
            if not (args.reuse_continuum and (cfolder / "summary.json").is_file()):
                s = scenario_at(args.case, factor, args.seeds[0], args.overrides)
                print(f"  {name} x{factor:g} -> {cfolder}", flush=True)
                m.run(s, cfolder, cal, options[name], True, False)
            conts[name] = load_result(cfolder, cell)
            results[name] = compare_factor(factor, conts[name], dems, args.e_seed, radius)
        print_factor(factor, results, conts, dems, seeds_found)
        report["factors"].append({"factor": factor, "methods": results})
        bench.write_json(out / "report.json", report)
    report["machine"]["load_1min_end"] = bench.load_1min()
    bench.write_json(out / "report.json", report)
    print(f"\nreport in {out / 'report.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
