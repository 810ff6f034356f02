"""Which conduction law the DEM's fluctuation-energy flux follows (docs/decisions/
granular-temperature-closures.md, "Conductivity against the DEM"; docs/validation.md).

    python benchmarks/heat_flux_laws.py RUN_DIR [--width-factor 2] [--batches N --thermal-only]

RUN_DIR: a finished DEM run (dem.h5 with snapshots and ball contacts) and its calibration.toml
([kinetic] phi_rcp, g0_form, restitution), e.g. a `vibroflow run` of tub47-quick.  It
coarse-grains the run's averaging window twice, the flux of the fluctuation about each phase's
mean over the cycles (run_fields.coarse_grain_run, as `vibroflow calibrate` does) and about
each snapshot's own coarse-grained velocity (thermal_flux.py, Gaussian of `--width-factor`
diameters), and prints for each:

* the bed's collective motion: the scatter from cycle to cycle of the mean vertical velocity
  of the whole bed and of its lowest fifth at each phase, beside sqrt(T) of the cells;
* by phase, the cells' median sqrt(T) and mean vertical flux (solid fraction > 0.3);
* Fourier's law with Gidaspow's conductivity (conductivity.py) and Garzo & Dufty's two-term law
  (heat_flux_law.py), weighted (1 / batch-means error^2) and with equal weights: the
  multipliers with their batch-means errors, R^2, the share of cells whose flux the law points
  the right way, by solid-fraction band, and the cycle-mean fits;
* for the thermal flux, the shape of its conductivity in phi: C(phi) = C_0 (phi / 0.4)^beta
  fitted to the bands' equal-weight multipliers, weighted by their batch-means errors (log C
  against log phi), with beta's standard error (beta = 0: Gidaspow's own phi dependence).

--batches N: the thermal flux's batches of whole cycles (default the scenario's run.batches):
more batches, steadier weights; --thermal-only: only the thermal flux.
"""
from __future__ import annotations

import argparse
import tomllib
from pathlib import Path

import numpy as np

from vibroflow.calibration.conductivity import fit_conductivity
from vibroflow.calibration.dem_result import DEMResult
from vibroflow.calibration.heat_flux_law import fit_cycle_mean, fit_heat_flux_law
from vibroflow.calibration.run_fields import coarse_grain_run
from vibroflow.calibration.thermal_flux import thermal_energy_flux
from vibroflow.measure.stats import phase_bins


def collective_scatter(res: DEMResult, n_phases: int):
    """By phase: (std over cycles of the bed's mean v_z, of its lowest fifth's) (m/s)."""
    batch = res.batches()
    used = np.nonzero(batch >= 0)[0]
    ph = phase_bins(res.times, float(res.scenario.motion.frequency), n_phases)
    rows = []
    for s, snap in res.iter_snapshots(used):
        z = snap["positions_tub"][:, 2]
        vz = snap["velocities_rel_tub"][:, 2]
        rows.append((ph[s], vz.mean(), vz[z < np.percentile(z, 20)].mean()))
    a = np.array(rows)
    return [(a[a[:, 0] == k, 1].std(), a[a[:, 0] == k, 2].std()) for k in range(n_phases)]


def report(name, ds, args):
    print(f"\n== {name}")
    T, phi, q = ds.temperature.values, ds.solid_fraction.values, ds.energy_flux.values
    for k in range(T.shape[0]):
        o = np.isfinite(T[k]) & (phi[k] > 0.3)
        print(f"  phase {k}/{T.shape[0]}: median sqrt(T) {np.sqrt(np.median(T[k][o])):.3f} m/s, "
              f"mean q_z {np.nanmean(q[k][o][:, 2]):7.0f} W/m^2")
    flat = ds.drop_vars("energy_flux_stderr")
    for label, data in (("weighted", ds), ("equal weights", flat)):
        c = fit_conductivity(data, *args)
        by = c["by_solid_fraction"]
        print(f"  Fourier (Gidaspow), {label}: C = {c['multiplier']:.3g} +- "
              f"{c['multiplier_stderr']:.2g}, R^2 {c['r2']:.3f}, down the gradient "
              f"{c['down_gradient_fraction']:.0%} ({c['cells']} cells)")
        print("    by band", by["edges"], "C", np.round(by["multiplier"], 3), "+-",
              np.round(by["multiplier_stderr"], 3), "R^2", np.round(by["r2"], 3))
        f = fit_heat_flux_law(ds, *args, weighted=(label == "weighted"))
        b = f["by_solid_fraction"]
        print(f"  Garzo & Dufty, {label}: A = {f['conductivity_multiplier']:.3g} +- "
              f"{f['conductivity_multiplier_stderr']:.2g}, B = {f['density_multiplier']:.3g} +- "
              f"{f['density_multiplier_stderr']:.2g}, R^2 {f['r2']:.3f}, direction right "
              f"{f['direction_fraction']:.0%}; as it is (A = B = 1) R^2 {f['r2_as_is']:.3f}, "
              f"direction right {f['direction_fraction_as_is']:.0%}")
        for key in ("conductivity_multiplier", "density_multiplier", "r2",
                    "direction_fraction"):
            print(f"    by band {key}", np.round(b[key], 3))
        cm = fit_cycle_mean(ds, *args, weighted=(label == "weighted"))
        print(f"  cycle means, {label}: A = {cm['conductivity_multiplier']:.3g} +- "
              f"{cm['conductivity_multiplier_stderr']:.2g}, B = {cm['density_multiplier']:.3g}"
              f" +- {cm['density_multiplier_stderr']:.2g}, R^2 {cm['r2']:.3f}, direction "
              f"right {cm['direction_fraction']:.0%} ({cm['cells']} cells)")


def phi_shape(ds, args) -> None:
    """C(phi) = C_0 (phi / 0.4)^beta over the equal-weight bands (module docstring)."""
    c = fit_conductivity(ds.drop_vars("energy_flux_stderr"), *args)["by_solid_fraction"]
    edges = np.asarray(c["edges"], float)
    mid = 0.5 * (edges[:-1] + edges[1:])
    C, se = np.asarray(c["multiplier"], float), np.asarray(c["multiplier_stderr"], float)
    ok = np.isfinite(C) & np.isfinite(se) & (C > 0) & (se > 0)
    x, y, w = np.log(mid[ok] / 0.4), np.log(C[ok]), (C[ok] / se[ok]) ** 2
    A = np.stack([np.ones_like(x), x], axis=1)
    cov = np.linalg.inv(A.T @ (A * w[:, None]))
    coef = cov @ (A.T @ (w * y))
    chi2 = float(np.sum(w * (y - A @ coef) ** 2)) / max(int(ok.sum()) - 2, 1)
    err = np.sqrt(np.diag(cov) * max(chi2, 1.0))
    print(f"  C(phi) = {np.exp(coef[0]):.3g} (phi / 0.4)^beta, beta = {coef[1]:.2f} +- "
          f"{err[1]:.2f} (bands {np.round(mid[ok], 3)}, C {np.round(C[ok], 2)} +- "
          f"{np.round(se[ok], 2)}; reduced chi^2 {chi2:.2f})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run_dir", type=Path)
    ap.add_argument("--width-factor", type=float, default=2.0)
    ap.add_argument("--batches", type=int, default=None)
    ap.add_argument("--thermal-only", action="store_true")
    a = ap.parse_args()
    cal = a.run_dir / "calibration" / "calibration.toml"
    if not cal.is_file():
        cal = a.run_dir / "calibration.toml"
    kin = tomllib.loads(cal.read_text())["kinetic"]
    dem = a.run_dir / "dem" if (a.run_dir / "dem" / "dem.h5").is_file() else a.run_dir
    with DEMResult.open(dem) as res:
        args = (res.solid_density, res.diameter, kin["restitution"], kin["phi_rcp"],
                kin["g0_form"])
        n = int(res.scenario.run.phases_per_cycle)
        if not a.thermal_only:
            print("bed's mean v_z, scatter from cycle to cycle (m/s), whole bed / lowest "
                  "fifth:")
            for k, (s_all, s_low) in enumerate(collective_scatter(res, n)):
                print(f"  phase {k}/{n}: {s_all:.3f} / {s_low:.3f}")
            _, _, info = coarse_grain_run(res, energy_flux=True)
            report("about each phase's mean over the cycles", info["energy_flux"], args)
        thermal = thermal_energy_flux(res, a.width_factor, n_batches=a.batches)
        report(f"about each snapshot's own velocity (width {a.width_factor:g} d, "
               f"{thermal.attrs['n_batches']} batches)", thermal, args)
        phi_shape(thermal, args)


if __name__ == "__main__":
    main()
