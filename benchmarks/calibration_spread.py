"""How far a continuum's field depends on which DEM run it was calibrated on: the same continuum
run with each of several calibrations (`vibroflow calibrate` of the DEM's fill seeds), each
judged against the same reference seeds as `vibroflow compare` judges it (docs/validation.md
section 30).

    python benchmarks/calibration_spread.py --reference SEEDS_DIR [--case tub47-quick]
        [--methods lagrangian,eulerian] [--moduli calibrated|unloading]
        [--out DIR] CALIBRATION_TOML [CALIBRATION_TOML ...]

SEEDS_DIR: the reference runs (a folder of DEM run folders, as `vibroflow compare -r` takes it,
e.g. tests/data/tub47-quick-dem-seeds).  Printed for each method and calibration: E against the
references (their mean and its standard error), the strength over the references' and whether
the strengths agree; then for each method the mean E over the calibrations, their standard
deviation and range beside the fields-agree limit: the spread a single calibration's draw puts
on the verdict.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

import bench

from vibroflow.analysis.judge import judge, read_result, run_folders
from vibroflow.continuum.formulation import formulation
from vibroflow.continuum.tub_run import run_continuum
from vibroflow.io.calibration_file import read_calibration
from vibroflow.scenario import load_scenario


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("calibrations", nargs="+", type=Path)
    ap.add_argument("--reference", required=True, type=Path)
    ap.add_argument("--case", default="tub47-quick")
    ap.add_argument("--methods", default="lagrangian,eulerian")
    ap.add_argument("--moduli", default="calibrated")
    ap.add_argument("--out", type=Path, default=Path("runs/calibration_spread"))
    a = ap.parse_args(argv)
    refs = [read_result(f) for f in run_folders([a.reference])]
    sc = load_scenario(a.case)
    methods = [m.strip() for m in a.methods.split(",") if m.strip()]
    cals = [(p, read_calibration(p)) for p in a.calibrations]
    limit = None
    for method in methods:
        form = formulation(method)
        opts = form.options(moduli=a.moduli)
        es = []
        print(f"\n{method}, moduli {a.moduli}:")
        print("| calibration | E against the references | strength / theirs | strengths agree |")
        print("|---|---|---|---|")
        for k, (path, cal) in enumerate(cals):
            out = a.out / f"{method}_{k}"
            run_continuum(sc, out, method, calibration=cal, options=opts)
            j = judge([read_result(out)], refs)
            r = j["results"][0]
            limit = j["limit"]
            es.append(r["E_mean"])
            print(f"| {path} | {r['E_mean']:.3f} +- {r['E_stderr']:.3f} | "
                  f"{r['strength_ratio']:.3f} | {'yes' if r['strengths_agree'] else 'no'} |")
        e = np.array(es)
        sd = float(e.std(ddof=1)) if e.size > 1 else float("nan")
        print(f"  over {e.size} calibrations: mean E {e.mean():.3f}, standard deviation {sd:.3f}, "
              f"range {e.min():.3f} - {e.max():.3f}; the fields-agree limit "
              + (f"{limit:.3f}" if limit is not None else "n/a"))
    return 0


if __name__ == "__main__":
    bench.run(main)
