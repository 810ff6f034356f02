"""The DEM's thermal balance on tub47-quick against kinetic theory's dissipation and the continua
(docs/validation.md section 29; calibration/thermal_balance.py, contact_power.py).

    python benchmarks/thermal_balance.py RUN CALIBRATION_TOML LAGRANGIAN_DIR EULERIAN_DIR
        [--save BALANCE_NC]

RUN: a DEM run directory with ball contacts and spins in dem.h5 (coarse-grained here:
thermal_balance.thermal_balance_run), or a NetCDF that --save wrote before.  CALIBRATION_TOML:
the run's calibration ([kinetic]: e, phi_rcp, g0's form).  The continua's run folders hold
temperature.csv (`vibroflow continuum tub47-quick --method M --calibration CAL --temperature`).

Printed:
- the springs' storage check: the contacts' mean power over the window, its phase-bin means,
  and the stored energy's change over the window per second (what does not average out);
- whole-bed totals over the slab (W): production, the walls' feed, dissipation by part
  (dashpot, sliding, rolling), kinetic theory's Gamma at the DEM's own phi and thermal T;
- by height on the analysis cells (cells with the DEM's phi >= 0.3, plain means of the per-volume
  fields, T mass-weighted): phi, thermal T, the DEM's production Pi and dissipation D (W/m^3,
  with the batch-means error), the sliding's and rolling's shares of D, the walls' feed W
  (in the cells at a wall), Gamma(phi, T_th),
  D / Gamma, the temperature T_eq = T_th (D / Gamma)^(2/3) at which the closure dissipates what
  the DEM does, and each continuum's T and its own Gamma(phi_c, T_c) (its dissipation, which its
  production feeds in its steady state).
"""
from __future__ import annotations

import argparse
import math
import tomllib
from pathlib import Path

import numpy as np
import xarray as xr

from vibroflow.calibration.shear_temperature import (dense_dissipation_coefficient,
                                                     kinetic_parameters)
from vibroflow.calibration.thermal_balance import PARTS, thermal_balance_run
from vibroflow.continuum.kinetic_theory import G0_FORMS, KineticParameters, dissipation_W_m3
from vibroflow.report.temperature_maps import PHI_KEY, T_KEY, read_temperature_csv
from vibroflow.scenario import load_scenario

H = 0.015          # tub47's analysis cells (m)
#: the DEM shear cell's steady points (docs/validation.md section 21: tub47's balls, seed 1):
#: I, phi, gamma_dot (1/s), T (m^2/s^2), mu = tau / p, p (Pa)
SHEAR_CELL = ((0.03, 0.598, 3.59, 4.28e-4, 0.350, 4334.0),
              (0.1, 0.591, 11.97, 3.08e-3, 0.383, 4525.0),
              (0.3, 0.564, 35.9, 1.71e-2, 0.470, 4561.0))


def gamma_closure(phi, T, prm) -> np.ndarray:
    """Lun's Gamma (W/m^3) elementwise (NaN or empty: 0)."""
    phi = np.nan_to_num(np.asarray(phi, float))
    T = np.nan_to_num(np.asarray(T, float))
    out = np.zeros(phi.shape)
    for idx in zip(*np.nonzero(phi > 0)):
        out[idx] = dissipation_W_m3(float(phi[idx]), float(T[idx]), 0.0, prm)
    return out


def cells(x, z, nxh, nz, values, weight=None):
    """Fine grid (x, z) values onto the analysis cells (nz, 2 nxh + 1): their mean (weighted)."""
    X, Z = np.meshgrid(x, z, indexing="ij")
    i = np.floor(X / H + 0.5).astype(np.int64) + nxh
    k = np.floor(Z / H + 0.5).astype(np.int64)
    ok = (i >= 0) & (i <= 2 * nxh) & (k >= 0) & (k < nz)
    flat = (k * (2 * nxh + 1) + i)[ok]
    size = nz * (2 * nxh + 1)
    v = np.nan_to_num(np.asarray(values, float))[ok]
    w = np.ones_like(v) if weight is None else np.nan_to_num(np.asarray(weight, float))[ok]
    s, n = np.bincount(flat, w * v, size), np.bincount(flat, w, size)
    return np.divide(s, n, out=np.zeros(size), where=n > 0).reshape(nz, -1)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run")
    ap.add_argument("calibration")
    ap.add_argument("lagrangian")
    ap.add_argument("eulerian")
    ap.add_argument("--save", default=None)
    ap.add_argument("--case", default="tub47-quick")
    a = ap.parse_args()
    src = Path(a.run)
    ds = xr.open_dataset(src) if src.is_file() else thermal_balance_run(src)
    if a.save:
        ds.to_netcdf(a.save)
    sc = load_scenario(a.case)
    kin = tomllib.loads(Path(a.calibration).read_text())["kinetic"]
    prm = KineticParameters(diameter_m=float(sc.fill.diameter),
                            density_kg_m3=float(sc.materials[sc.fill.material].density),
                            restitution=float(kin["restitution"]), phi_rcp=float(kin["phi_rcp"]),
                            g0_form=G0_FORMS[kin["g0_form"]])
    # the sliding loss's k_f from the shear cell, never from the tub
    cell_prm = kinetic_parameters(float(sc.fill.diameter), prm.density_kg_m3, prm.restitution)
    ks = [dense_dissipation_coefficient(phi, gd, T, mu * p, p, cell_prm)
          for _I, phi, gd, T, mu, p in SHEAR_CELL]
    k_f = float(np.mean(ks))
    print("shear cell's k_f at I = " + ", ".join(f"{c[0]}: {k:.3f}" for c, k in zip(SHEAR_CELL, ks))
          + f"; mean {k_f:.3f}")
    x, z = ds.x.values, ds.z.values
    dA = float(ds.attrs["cell_size_m"]) ** 2 * float(ds.attrs["depth_m"])

    # -- the springs' storage averages out
    P = ds.contact_power.values
    t = ds.snapshot_time.values
    E = ds.elastic_energy.values
    print(f"contacts' power out of the balls: mean {P.mean():.3f} W over {t[-1] - t[0]:.3f} s "
          f"({P.size} snapshots), phase-bin means "
          + ", ".join(f"{float(ds.dissipation[p].sum()) * dA:.2f}" for p in range(ds.phase.size))
          + " W")
    rate = (E[-1] - E[0]) / (t[-1] - t[0])
    print(f"springs' stored energy {E[0]:.3e} J -> {E[-1]:.3e} J: {rate:.2e} W, "
          f"{abs(rate) / P.mean():.1e} of the mean power; its range over the snapshots "
          f"{E.min():.2e} - {E.max():.2e} J")

    # -- whole bed
    phi_ph = ds.solid_fraction.values
    T_ph = ds.thermal_temperature.values
    G_ph = gamma_closure(phi_ph, T_ph, prm)
    G_cm = G_ph.mean(axis=0)
    Gf_cm = (k_f * np.nan_to_num(ds.pressure.values).clip(min=0.0)
             * np.sqrt(np.nan_to_num(T_ph).clip(min=0.0)) / prm.diameter_m).mean(axis=0)
    tot = {"production": float(ds.production_cycle_mean.sum()) * dA,
           "production (contact stress)": float(ds.production_contact_cycle_mean.sum()) * dA}
    tot["walls' feed"] = float(ds.wall_feed_cycle_mean.sum()) * dA
    for p in PARTS:
        tot[f"dissipation, {p}"] = float(ds[f"dissipation_{p}_cycle_mean"].sum()) * dA
    tot["dissipation"] = float(ds.dissipation_cycle_mean.sum()) * dA
    tot["kinetic theory's Gamma at the DEM's phi, thermal T (phase by phase)"] = \
        float(G_cm.sum()) * dA
    tot["the sliding loss k_f p sqrt(T_th) / d at the DEM's p, thermal T"] = \
        float(Gf_cm.sum()) * dA
    for k, v in tot.items():
        print(f"  {k}: {v:.3f} W")

    # -- by height on the analysis cells
    nxh = int(math.floor(float(sc.tub.radius) / H + 0.5))
    nz = int(math.floor(float(sc.tub.rim_height) / H + 0.5)) + 1
    phi_cm = np.nan_to_num(phi_ph).mean(axis=0)
    phi_c = cells(x, z, nxh, nz, phi_cm)
    T_c = cells(x, z, nxh, nz, ds.thermal_temperature_cycle_mean.values, phi_cm)
    Pi = cells(x, z, nxh, nz, ds.production_cycle_mean.values)
    D = cells(x, z, nxh, nz, ds.dissipation_cycle_mean.values)
    Dse = cells(x, z, nxh, nz, ds.dissipation_cycle_mean_stderr.values)
    Pse = cells(x, z, nxh, nz, ds.production_cycle_mean_stderr.values)
    W = cells(x, z, nxh, nz, ds.wall_feed_cycle_mean.values)
    Ds = {p: cells(x, z, nxh, nz, ds[f"dissipation_{p}_cycle_mean"].values) for p in PARTS}
    G = cells(x, z, nxh, nz, G_cm)
    Gf = cells(x, z, nxh, nz, Gf_cm)
    G_mean_state = gamma_closure(phi_c, T_c, prm)
    cont = {}
    for name, d in (("lagrangian", a.lagrangian), ("eulerian", a.eulerian)):
        m = read_temperature_csv(Path(d) / "temperature.csv", H, nxh, nz)
        cont[name] = (m[T_KEY], m[PHI_KEY], gamma_closure(m[PHI_KEY], m[T_KEY], prm))
    print("\n| z (mm) | phi | T_th (m2/s2) | Pi (W/m3) | D (W/m3) | Pi/D | sliding, rolling / D "
          "| walls' feed W | (Pi + W)/D | Gamma(phi, T_th) | D/Gamma | T_eq/T_th "
          "| D/(Gamma + Gamma_f) | Lag T/T_th, Gamma_c | Eul T/T_th, Gamma_c |")
    print("|---" * 15 + "|")
    for k in range(nz):
        on = phi_c[k] >= 0.3
        if not on.any():
            continue

        def m(a, mask=on):
            return float(np.mean(a[k][mask]))
        Tth = float(np.sum(phi_c[k][on] * T_c[k][on]) / np.sum(phi_c[k][on]))
        ratio = m(D) / m(G)
        row = (f"| {z_mm(k)} | {m(phi_c):.3f} | {Tth:.2e} | {m(Pi):.0f} +- {m(Pse):.0f} | "
               f"{m(D):.0f} +- {m(Dse):.0f} | {m(Pi) / m(D):.2f} | "
               f"{m(Ds['tangential']) / m(D):.2f}, {m(Ds['rolling']) / m(D):.3f} | {m(W):.0f} | "
               f"{(m(Pi) + m(W)) / m(D):.2f} | {m(G):.0f} "
               f"(mean state {m(G_mean_state):.0f}) | {ratio:.1f} | {ratio ** (2 / 3):.1f} | "
               f"{m(D) / (m(G) + m(Gf)):.2f} |")
        for name, (Tc, phic, Gc) in cont.items():
            onc = on & (phic[k] >= 0.3)
            if not onc.any():
                row += " - |"
                continue
            Tm = float(np.sum(phic[k][onc] * Tc[k][onc]) / np.sum(phic[k][onc]))
            row += f" {Tm / Tth:.2f}, {m(Gc, onc):.0f} |"
        print(row)


def z_mm(k: int) -> int:
    return int(round(k * H * 1000))


if __name__ == "__main__":
    main()
