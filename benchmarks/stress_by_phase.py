"""Where the bed's stress sits, by height and phase of the cycle: the DEM's coarse-grained cells
against the continua's (docs/validation.md section 30; vibroflow/analysis/stress_state.py).

    python benchmarks/stress_by_phase.py FIELDS_NC CALIBRATION_TOML RUN_DIR [RUN_DIR ...]

FIELDS_NC: the DEM run's fields.nc (`vibroflow calibrate`; its phase-resolved group);
CALIBRATION_TOML: its calibration ([rheology] mu_s: the yield friction); RUN_DIR: continuum run
folders, each with its stress.csv (`vibroflow continuum ... --out RUN_DIR`).

Printed for each source: its dense cells and phases, the median friction and pressure, the
share of cells at or above the calibrated mu_s, its own best mu(I), and by phase bin the median
mu and p in the lowest and the highest third of the cells' heights, the log residual about that
mu(I) there, and the residual's correlation with height.
"""
from __future__ import annotations

import argparse
import json
import tomllib
from pathlib import Path

import numpy as np

import bench

from vibroflow.analysis.stress_state import (continuum_points, dem_points, height_phase_table,
                                             share_at_yield)
from vibroflow.calibration.run_fields import read_fields


def _name(run: Path) -> str:
    s = run / "summary.json"
    if s.is_file():
        return str(json.loads(s.read_text()).get("method", run.name))
    return run.name


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("fields")
    ap.add_argument("calibration")
    ap.add_argument("runs", nargs="*", type=Path)
    a = ap.parse_args(argv)
    cal = tomllib.loads(Path(a.calibration).read_text())
    mu_s = float(cal["rheology"]["mu_s"])
    sources = [("DEM", dem_points(read_fields(a.fields, phase_resolved=True)))]
    sources += [(_name(r), continuum_points(r / "stress.csv")) for r in a.runs]
    for name, pts in sources:
        tab = height_phase_table(pts)
        f = tab["fit"]
        print(f"\n{name}: {pts['mu'].size} dense cells x phases; median mu "
              f"{np.median(pts['mu']):.3f}, median p {np.median(pts['pressure']):.0f} Pa; at or "
              f"above the calibrated mu_s {mu_s:.3f}: {share_at_yield(pts, mu_s):.1%}; its best "
              f"mu(I): mu_s {f['mu_s']:.3f}, mu_2 {f['mu_2']:.3f}, I_0 {f['x_0']:.3g}, rms log "
              f"residual {f['rms_log_residual']:.3f}")
        print("| phase | cells | mu, lowest / highest third | p (Pa) | log residual about its "
              "mu(I) | correlation with height |")
        print("|---|---|---|---|---|---|")
        for r in tab["rows"]:
            print(f"| {r['phase']} | {r['n']} | {r['mu_low']:.3f} / {r['mu_high']:.3f} | "
                  f"{r['p_low']:.0f} / {r['p_high']:.0f} | {r['res_low']:+.3f} / "
                  f"{r['res_high']:+.3f} | {r['corr']:+.2f} |")
    return 0


if __name__ == "__main__":
    bench.run(main)
