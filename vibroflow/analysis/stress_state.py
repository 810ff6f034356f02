"""Where the bed's stress sits, by height and phase of the cycle: the DEM's coarse-grained cells
(fields.nc's phase-resolved group) and a continuum's analysis cells (its stress.csv,
continuum/stress_outputs.py) read the same way (docs/validation.md section 30).

For each source the dense cells (solid fraction >= DENSE_SOLID_FRACTION, a compressive
pressure, a shear rate, I <= MAX_INERTIAL_NUMBER: dense flow) at every phase give the friction
coefficient mu = tau_eq / p, the pressure p and the inertial number I.  `height_phase_table`
sets, phase by phase, the median mu and p of the lowest and the highest third of the cells'
heights beside the log residual about the source's own best mu(I) (Jop's form,
calibration.mu_temperature.fit_collapse) and its correlation with height; `share_at_yield` the
share of the cells whose mu reaches a yield friction (the calibrated mu_s): a cell below it is
loaded inside the yield cone, which an elasto-plastic bed can be and a bed flowing at mu(I)
cannot.  Units: m, Pa, 1/s and numbers."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from vibroflow.calibration.mu_temperature import DENSE_SOLID_FRACTION, RESOLVED, fit_collapse
from vibroflow.continuum.rheology import mu_of_I
from vibroflow.errors import InputError

#: a cell with a larger inertial number is not in dense flow (GDR MiDi 2004: I up to ~0.3)
MAX_INERTIAL_NUMBER = 1.0


def _select(mu, I, p, phi, gd, gd_resolved):
    with np.errstate(invalid="ignore"):
        return (np.isfinite(mu) & (mu >= 0) & np.isfinite(I) & (I > 0)
                & (I <= MAX_INERTIAL_NUMBER) & (p > 0) & (phi >= DENSE_SOLID_FRACTION)
                & gd_resolved & (gd > 0))


def dem_points(phase_fields) -> dict:
    """The DEM's dense cells and phases (calibration/run_fields.read_fields(...,
    phase_resolved=True)): {mu, I, pressure, z (m, tub axes), phase}, the shear rate resolved
    as calibration.mu_temperature.cell_points requires it (above RESOLVED batch-means errors)."""
    def flat(name):
        return np.asarray(phase_fields[name].values, float)
    mu, I, p = flat("friction_coefficient"), flat("inertial_number"), flat("pressure")
    gd, phi = flat("shear_rate"), flat("solid_fraction")
    gd_se = flat("shear_rate_stderr") if "shear_rate_stderr" in phase_fields \
        else np.zeros(gd.shape)
    ok = _select(mu, I, p, phi, gd, gd > RESOLVED * np.nan_to_num(gd_se))
    z = np.broadcast_to(np.asarray(phase_fields["z"].values, float)[None, None, :], mu.shape)
    k = np.indices(mu.shape)[0]
    return {"mu": mu[ok], "I": I[ok], "pressure": p[ok], "z": z[ok], "phase": k[ok]}


def continuum_points(stress_csv: Path) -> dict:
    """A continuum run's dense cells and phases from its stress.csv (the same keys as
    `dem_points`); InputError when the file is missing or holds none."""
    path = Path(stress_csv)
    if not path.is_file():
        raise InputError(f"{path}: no such file (a continuum run writes stress.csv)")
    r = np.genfromtxt(path, delimiter=",", names=True, ndmin=1)
    if r.size == 0 or "friction_coefficient" not in (r.dtype.names or ()):
        raise InputError(f"{path}: not a continuum's stress.csv (no friction_coefficient)")
    ok = _select(r["friction_coefficient"], r["inertial_number"], r["pressure"],
                 r["solid_fraction"], r["shear_rate"], np.ones(r.size, bool))
    return {"mu": r["friction_coefficient"][ok], "I": r["inertial_number"][ok],
            "pressure": r["pressure"][ok], "z": r["z"][ok],
            "phase": r["phase"][ok].astype(np.int64)}


def share_at_yield(points: dict, mu_yield: float) -> float:
    """The share of the cells whose friction reaches mu_yield."""
    return float(np.mean(points["mu"] >= mu_yield))


def height_phase_table(points: dict) -> dict:
    """The source's best mu(I) (fit_collapse of all its cells, mu > 0) and, by phase bin, the
    median mu, p and log residual about that curve in the lowest and the highest third of the
    cells' heights (the terciles over all phases), and the residual's correlation with height:
    {"fit": ..., "rows": [{phase, n, mu_low, mu_high, p_low, p_high, res_low, res_high,
    corr}]} (Pa for p)."""
    pos = points["mu"] > 0
    if pos.sum() <= 3:
        raise InputError(f"stress by height: {int(pos.sum())} dense cells with a shear stress")
    fit = fit_collapse(points["I"][pos], points["mu"][pos])
    with np.errstate(divide="ignore"):
        res = np.log(points["mu"] / mu_of_I(points["I"], fit["mu_s"], fit["mu_2"], fit["x_0"]))
    z = points["z"]
    z1, z2 = np.percentile(z, [100.0 / 3.0, 200.0 / 3.0])
    rows = []
    for k in np.unique(points["phase"]):
        s = points["phase"] == k
        lo, hi = s & (z < z1), s & (z >= z2)
        if not (lo.any() and hi.any()):
            continue
        sp = s & pos
        corr = float(np.corrcoef(res[sp], z[sp])[0, 1]) if sp.sum() > 2 else float("nan")
        rows.append({"phase": int(k), "n": int(s.sum()),
                     "mu_low": float(np.median(points["mu"][lo])),
                     "mu_high": float(np.median(points["mu"][hi])),
                     "p_low": float(np.median(points["pressure"][lo])),
                     "p_high": float(np.median(points["pressure"][hi])),
                     "res_low": float(np.median(res[lo & pos])) if (lo & pos).any()
                     else float("nan"),
                     "res_high": float(np.median(res[hi & pos])) if (hi & pos).any()
                     else float("nan"),
                     "corr": corr})
    return {"fit": fit, "rows": rows}
