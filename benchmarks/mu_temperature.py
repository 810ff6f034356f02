"""Does the DEM's thermal temperature collapse the tub's mu(I) scatter?  (docs/validation.md
section 30; calibration/mu_temperature.py.)

    python benchmarks/mu_temperature.py FIELDS_NC BALANCE CALIBRATION_TOML

FIELDS_NC: the DEM run's fields.nc (`vibroflow calibrate`; its phase-resolved group);
BALANCE: the thermal balance on the same grid, a NetCDF that `benchmarks/thermal_balance.py
--save` wrote (or a DEM run directory with ball contacts, coarse-grained here); it gives the
thermal temperature and the measured dissipation per cell and phase.  CALIBRATION_TOML: the
run's calibration ([kinetic]: e, phi_rcp, g0's form; [rheology]: the calibrated mu(I)).

Printed: the dense cells' spread (percentiles of mu, I, T, Theta, r), each abscissa's best
curve and rms log residual (and the calibrated mu(I)'s at that abscissa), Pailha & Pouliquen's
dilatancy and Zhang & Kamrin's fluidity fitted to the same cells, the best mu(I)'s residual by
height, and the binned medians of mu with their batch-means errors and quartiles, and the
scatter within each phase bin of the cycle.
"""
from __future__ import annotations

import argparse
import sys
import tomllib
from pathlib import Path

import numpy as np
import xarray as xr

import bench

from vibroflow.calibration import mu_temperature as mt
from vibroflow.calibration.run_fields import read_fields
from vibroflow.calibration.thermal_balance import thermal_balance_run
from vibroflow.continuum.kinetic_theory import G0_FORMS, KineticParameters
from vibroflow.continuum.rheology import mu_of_I
from vibroflow.scenario import load_scenario

LABELS = {"I": "(a) I", "rI": "(b) r I, T_bal from Lun's Gamma",
          "rI_median_T": "control: r_0 I, r at the cells' median T",
          "rI_dem": "(b') r_D I, T_bal from the DEM's dissipation",
          "Theta": "(c) Theta^a F(I) (Kim & Kamrin)"}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("fields")
    ap.add_argument("balance")
    ap.add_argument("calibration")
    ap.add_argument("--case", default="tub47-quick")
    a = ap.parse_args(argv)
    ph = read_fields(a.fields, phase_resolved=True)
    src = Path(a.balance)
    bal = xr.load_dataset(src) if src.is_file() else thermal_balance_run(src)
    if not (np.allclose(ph.x, bal.x) and np.allclose(ph.z, bal.z)):
        print(f"BALANCE = {a.balance!r}: its grid is not the fields' grid", file=sys.stderr)
        return 2
    cal = tomllib.loads(Path(a.calibration).read_text())
    kin = cal["kinetic"]
    sc = load_scenario(a.case)
    prm = KineticParameters(diameter_m=float(sc.fill.diameter),
                            density_kg_m3=float(sc.materials[sc.fill.material].density),
                            restitution=float(kin["restitution"]), phi_rcp=float(kin["phi_rcp"]),
                            g0_form=G0_FORMS[kin["g0_form"]])
    pts = mt.cell_points(ph, bal.thermal_temperature.values, prm, bal.dissipation.values)
    print(f"{pts['mu'].size} dense cells x phases (phi >= {mt.DENSE_SOLID_FRACTION}, shear rate "
          f"above {mt.RESOLVED:g} batch-means errors)")
    r, rd = pts["rI"] / pts["I"], pts["rI_dem"] / pts["I"]
    for name, v in (("mu", pts["mu"]), ("I", pts["I"]), ("T (m2/s2)", pts["T"]),
                    ("Theta", pts["Theta"]), ("r (Lun)", r), ("r_D (DEM dissipation)", rd)):
        q = np.nanpercentile(v, [5, 25, 50, 75, 95])
        print(f"  {name}: 5/25/50/75/95 % " + " / ".join(f"{x:.3g}" for x in q))
    print(f"  share of cells hotter than their shear keeps (r < 1): Lun {np.mean(r < 1):.2f}, "
          f"DEM dissipation {np.nanmean(rd < 1):.2f}")
    tab = mt.collapse_table(pts, cal["rheology"])
    base, noise = tab["baseline"], tab["noise"]

    def excess(rms):
        return np.sqrt(max(rms ** 2 - noise ** 2, 0.0))
    print(f"\nrms log residual of mu about its median (no abscissa): {base:.3f}; the cells' "
          f"batch-means error as an rms log (noise floor): {noise:.3f}; the excess over it "
          f"{excess(base):.3f}")
    print("| abscissa | cells | best curve | rms log residual | narrowed by | excess over the "
          "noise (narrowed by) | calibrated mu(x) |")
    print("|---|---|---|---|---|---|---|")
    for key, label in LABELS.items():
        if key not in tab:
            continue
        f = tab[key]
        curve = (f"mu_s {f['mu_s']:.3f}, mu_2 {f['mu_2']:.3f}, x_0 {f['x_0']:.3g}"
                 + (f", a {f['a']:.3f}" if key == "Theta" else ""))
        cal_r = f.get("calibrated_rms_log_residual")
        print(f"| {label} | {f['points']} | {curve} | {f['rms_log_residual']:.3f} | "
              f"{1 - f['rms_log_residual'] / base:.1%} | {excess(f['rms_log_residual']):.3f} "
              f"({1 - excess(f['rms_log_residual']) / excess(base):.1%}) | "
              + (f"{cal_r:.3f}" if cal_r is not None else "-") + " |")
    for key, label in (("dilatancy", "(d) F(I) + tan psi (Pailha & Pouliquen)"),
                       ("dilatancy_b", "(d') F(I) + b tan psi, b fitted")):
        if key in tab:
            f = tab[key]
            print(f"| {label} | {f['points']} | mu_s {f['mu_s']:.3f}, mu_2 {f['mu_2']:.3f}, "
                  f"I_0 {f['x_0']:.3g}, b {f['b']:.3f} (at the floor {mt.MU_FLOOR:g}: "
                  f"{f['floored']:.1%}) | {f['rms_log_residual']:.3f} | "
                  f"{1 - f['rms_log_residual'] / base:.1%} | {excess(f['rms_log_residual']):.3f} "
                  f"({1 - excess(f['rms_log_residual']) / excess(base):.1%}) | - |")
    for key, label in (("fluidity", "(e) x / F(phi) (Zhang & Kamrin)"),
                       ("fluidity_a", "(e') x^a / F(phi), a fitted")):
        f = tab[key]
        print(f"| {label} | {f['points']} | a {f['a']:.3f}, ln F = "
              + " + ".join(f"{c:.3g} phi^{k}" for k, c in enumerate(f["c"]))
              + f" | {f['rms_log_residual']:.3f} | {1 - f['rms_log_residual'] / base:.1%} | "
              f"{excess(f['rms_log_residual']):.3f} "
              f"({1 - excess(f['rms_log_residual']) / excess(base):.1%}) | - |")
    q = np.percentile(pts["tan_psi"][np.isfinite(pts["tan_psi"])], [5, 25, 50, 75, 95]) \
        if np.isfinite(pts["tan_psi"]).any() else []
    print("  tan psi = tr D / gamma_dot: 5/25/50/75/95 % " + " / ".join(f"{v:.3g}" for v in q))
    print("  fluidity number gamma_dot d / sqrt(T): 5/25/50/75/95 % " + " / ".join(
        f"{v:.3g}" for v in np.percentile(pts["fluidity_number"], [5, 25, 50, 75, 95])))
    fi = tab["I"]
    res = np.log(pts["mu"] / mu_of_I(pts["I"], fi["mu_s"], fi["mu_2"], fi["x_0"]))
    if np.isfinite(pts["z_m"]).any():
        z = pts["z_m"]
        edges = np.arange(np.floor(z.min() / 0.04) * 0.04, z.max() + 0.04, 0.04)
        print("\nthe best mu(I)'s log residual by height band (z, m, tub axes): cells, median "
              "(+- its batch-means error as a log), quartiles")
        for lo, hi in zip(edges[:-1], edges[1:]):
            s = (z >= lo) & (z < hi)
            if s.sum():
                err = mt.MEDIAN_ERROR * np.sqrt(np.nansum((pts["mu_stderr"][s]
                                                           / pts["mu"][s]) ** 2)) / s.sum()
                q1, med, q3 = np.percentile(res[s], [25, 50, 75])
                print(f"  {lo:.2f} - {hi:.2f}: {int(s.sum())}, {med:+.3f} +- {err:.3f} "
                      f"[{q1:+.3f}, {q3:+.3f}]")
    print("\nby phase bin (each abscissa's curve fitted within the bin): cells, median mu, "
          "rms log about the median, about the best mu(I), about the best mu(r I); the best "
          "mu(I)'s (over all bins) median log residual in the lowest and the highest third of "
          "the cells' heights, and its correlation with height")
    z = pts["z_m"]
    has_z = bool(np.isfinite(z).all())
    z1, z2 = np.percentile(z, [100 / 3, 200 / 3]) if has_z else (np.nan, np.nan)
    pooled = np.zeros(3)
    for k in np.unique(pts["phase"]):
        s = pts["phase"] == k
        mu = pts["mu"][s]
        base = np.sqrt(np.mean(np.log(mu / np.median(mu)) ** 2))
        fi, fr = mt.fit_collapse(pts["I"][s], mu), mt.fit_collapse(pts["rI"][s], mu)
        pooled += s.sum() * np.array([base, fi["rms_log_residual"], fr["rms_log_residual"]]) ** 2
        by_z = (f"; {np.median(res[s & (z < z1)]):+.3f} / {np.median(res[s & (z >= z2)]):+.3f}, "
                f"{np.corrcoef(res[s], z[s])[0, 1]:+.2f}") if has_z else ""
        print(f"  phase {k}/{int(ph.phase.size)} of the cycle: {int(s.sum())}, "
              f"{np.median(mu):.3f}, "
              f"{base:.3f}, {fi['rms_log_residual']:.3f}, {fr['rms_log_residual']:.3f}" + by_z)
    b, i, r = np.sqrt(pooled / pts["mu"].size)
    print(f"  pooled over the bins: about the bins' medians {b:.3f}, about a mu(I) per bin "
          f"{i:.3f}, about a mu(r I) per bin {r:.3f}")
    for key in ("I", "rI", "rI_dem"):
        x = pts[key]
        edges = np.geomspace(np.nanpercentile(x, 1), np.nanpercentile(x, 99) * 1.0001, 9)
        print(f"\n{LABELS[key]}: binned medians of mu (+- batch-means error) [quartiles]")
        for b in mt.binned_medians(x, pts["mu"], pts["mu_stderr"], edges):
            print(f"  {b['lo']:.3g} - {b['hi']:.3g} (n {b['n']}, median {b['x']:.3g}): "
                  f"{b['mu']:.3f} +- {b['mu_stderr']:.3f} [{b['mu_q1']:.3f}, {b['mu_q3']:.3f}]")
    return 0


if __name__ == "__main__":
    bench.run(main)
