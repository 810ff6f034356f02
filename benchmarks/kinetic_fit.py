"""The `[kinetic]` equation of state fitted to calibrated DEM runs, one line each, and the
scatter of each run's cells about its fit by solid-fraction band (docs/validation.md section
24; calibration/kinetic.py).

    python benchmarks/kinetic_fit.py RUN_DIR [RUN_DIR ...]

RUN_DIR: a folder `vibroflow calibrate` wrote into (fields.nc with its phase-resolved group, and
calibration.toml for the solid density and the ball-ball restitution).  For each run it prints
the joint fit of Lun's plus Johnson & Jackson's frictional pressure (kinetic.fit_lun_frictional,
what `vibroflow calibrate` stores), Lun's pressure alone (kinetic.fit_phi_rcp) and, over the
cells fitted, the mean and standard deviation of ln(p_DEM / p_fit) in solid-fraction bands
(equal weights).  With several runs (e.g. tub47-quick's fill seeds) it ends with the spread of
phi_rcp across them beside the fits' own standard errors.
"""
from __future__ import annotations

import argparse
import math
import tomllib
from pathlib import Path

import numpy as np

from vibroflow.calibration.kinetic import (MAX_LOG_ERROR, PHI_RANGE, _cells_fitted,
                                           fit_lun_frictional, fit_phi_rcp,
                                           frictional_pressure, pressure_ratio)
from vibroflow.calibration.run_fields import read_fields

BANDS = (0.1, 0.2, 0.3, 0.4, 0.5, 0.55, 0.6)


def one_run(run_dir: Path) -> dict:
    cal = tomllib.loads((run_dir / "calibration.toml").read_text())
    rho_s = float(cal["media"]["solid_density_kg_m3"])
    e = float(cal["kinetic"]["restitution"])
    ph = read_fields(run_dir / "fields.nc", phase_resolved=True)
    names = ("solid_fraction", "temperature", "pressure")
    args = [np.asarray(ph[k].values, float) for k in names]
    args += [np.asarray(ph[k + "_stderr"].values, float) for k in names]
    phi, T, p, *errs = args
    joint = fit_lun_frictional(phi, T, p, rho_s, e, *errs)
    lun = fit_phi_rcp(phi, T, p, rho_s, e, *errs)
    c_phi, c_T, y, _, _, _ = _cells_fitted(phi, T, p, rho_s, e, *errs, PHI_RANGE,
                                           joint["g0_form"], MAX_LOG_ERROR, 5, "joint")
    fr = joint["frictional_Pa"]
    pf = (frictional_pressure(c_phi, joint["phi_rcp"], fr, joint["frictional_phi_min"])
          if fr > 0 else 0.0)
    r = y - np.log(pressure_ratio(c_phi, joint["phi_rcp"], e, joint["g0_form"])
                   + pf / (rho_s * c_phi * c_T))
    bands = []
    for lo, hi in zip(BANDS[:-1], BANDS[1:]):
        m = (c_phi >= lo) & ((c_phi < hi) if hi < BANDS[-1] else (c_phi <= hi))
        bands.append((lo, hi, int(m.sum()), float(r[m].mean()) if m.any() else math.nan,
                      float(r[m].std(ddof=1)) if m.sum() > 1 else math.nan))
    return {"joint": joint, "lun": lun, "bands": bands,
            "T_percentiles": np.percentile(c_T, [5, 95])}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", type=Path)
    a = ap.parse_args(argv)
    rcp = []
    for run in a.runs:
        out = one_run(run)
        j, lun = out["joint"], out["lun"]
        lo, hi = j["solid_fraction_range"]
        t5, t95 = out["T_percentiles"]
        print(f"{run}: {j['points']} cells, phi {lo:.3f} - {hi:.3f}, T {t5:.4f} - {t95:.4f} "
              "m^2/s^2 (5 - 95 %)")
        print(f"  joint: phi_rcp {j['phi_rcp']:.4f} +- {j['phi_rcp_stderr']:.4f}, Fr "
              f"{j['frictional_Pa']:.3g} +- {j['frictional_Pa_stderr']:.2g} Pa, phi_min "
              f"{j['frictional_phi_min']:.4f} +- {j['frictional_phi_min_stderr']:.4f}, rms log "
              f"residual {j['rms_log_residual']:.3f} (a factor "
              f"{math.exp(j['rms_log_residual']):.2f}); {j['status']}")
        print(f"  Lun's alone: phi_rcp {lun['phi_rcp']:.4f} +- {lun['phi_rcp_stderr']:.4f}, rms "
              f"log residual {lun['rms_log_residual']:.3f} (a factor "
              f"{math.exp(lun['rms_log_residual']):.2f})")
        print("  ln(p_DEM / p_fit) by solid fraction: " + "; ".join(
            f"{b0:g} - {b1:g}: {n} cells, {m:+.2f} sd {s:.2f}" for b0, b1, n, m, s
            in out["bands"]))
        rcp.append((j["phi_rcp"], j["phi_rcp_stderr"], j["frictional_Pa"] > 0, lun["phi_rcp"]))
    if len(rcp) > 1:
        v = np.array([x[0] for x in rcp])
        print(f"phi_rcp over {len(v)} runs: {v.min():.4f} - {v.max():.4f}, mean {v.mean():.4f}, "
              f"sd {v.std(ddof=1):.4f} (the fits' own standard errors "
              f"{min(x[1] for x in rcp):.4f} - {max(x[1] for x in rcp):.4f}); a frictional "
              f"pressure resolved in {sum(x[2] for x in rcp)} of {len(v)}")
        u = np.array([x[3] for x in rcp])
        print(f"Lun's phi_rcp over {len(u)} runs: {u.min():.4f} - {u.max():.4f}, mean "
              f"{u.mean():.4f}, sd {u.std(ddof=1):.4f}")


if __name__ == "__main__":
    main()
