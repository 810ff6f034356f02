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
from vibroflow.continuum.stress_outputs import STRESS_BATCH_COLUMNS, STRESS_BATCHES_CSV_NAME
from vibroflow.errors import InputError
from vibroflow.measure.stats import stderr_of_batches

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
    as calibration.mu_temperature.cell_points requires it (above RESOLVED batch-means errors);
    with fields.nc's batches (run_fields.BATCH_FIELDS), each batch's own mu and p in the same
    cells and phases, batch_mu and batch_pressure (n_batches, cells)."""
    def flat(name):
        return np.asarray(phase_fields[name].values, float)
    mu, I, p = flat("friction_coefficient"), flat("inertial_number"), flat("pressure")
    gd, phi = flat("shear_rate"), flat("solid_fraction")
    gd_se = flat("shear_rate_stderr") if "shear_rate_stderr" in phase_fields \
        else np.zeros(gd.shape)
    ok = _select(mu, I, p, phi, gd, gd > RESOLVED * np.nan_to_num(gd_se))
    z = np.broadcast_to(np.asarray(phase_fields["z"].values, float)[None, None, :], mu.shape)
    k = np.indices(mu.shape)[0]
    out = {"mu": mu[ok], "I": I[ok], "pressure": p[ok], "z": z[ok], "phase": k[ok]}
    if "friction_coefficient_batches" in phase_fields and "pressure_batches" in phase_fields:
        out["batch_mu"] = flat("friction_coefficient_batches")[:, ok]
        out["batch_pressure"] = flat("pressure_batches")[:, ok]
    return out


def continuum_points(stress_csv: Path) -> dict:
    """A continuum run's dense cells and phases from its stress.csv (the same keys as
    `dem_points`, the batches from the stress_batches.csv beside it where there is one);
    InputError when the file is missing or holds none, or the batches' file is damaged."""
    path = Path(stress_csv)
    if not path.is_file():
        raise InputError(f"{path}: no such file (a continuum run writes stress.csv)")
    r = np.genfromtxt(path, delimiter=",", names=True, ndmin=1)
    if r.size == 0 or "friction_coefficient" not in (r.dtype.names or ()):
        raise InputError(f"{path}: not a continuum's stress.csv (no friction_coefficient)")
    ok = _select(r["friction_coefficient"], r["inertial_number"], r["pressure"],
                 r["solid_fraction"], r["shear_rate"], np.ones(r.size, bool))
    out = {"mu": r["friction_coefficient"][ok], "I": r["inertial_number"][ok],
           "pressure": r["pressure"][ok], "z": r["z"][ok],
           "phase": r["phase"][ok].astype(np.int64)}
    batches = path.parent / STRESS_BATCHES_CSV_NAME
    if batches.is_file():
        out["batch_mu"], out["batch_pressure"] = _batch_columns(
            batches, r["x"][ok], r["z"][ok], r["phase"][ok])
    return out


def _batch_columns(path: Path, x, z, phase) -> tuple[np.ndarray, np.ndarray]:
    """(friction, pressure), each (n_batches, cells), of stress_batches.csv at the cells and
    phases (x, z, phase) of stress.csv; NaN where a batch held no material."""
    try:
        r = np.genfromtxt(path, delimiter=",", names=True, ndmin=1)
        names = r.dtype.names or ()
        if r.size == 0 or not set(STRESS_BATCH_COLUMNS) <= set(names):
            raise ValueError("not a continuum's stress_batches.csv")
        b = r["batch"].astype(np.int64)
        if (b < 0).any() or not np.array_equal(b, np.round(r["batch"])):
            raise ValueError("a batch is not a whole number from 0")
    except ValueError as exc:
        raise InputError(f"{path}: {exc}") from None
    n = int(b.max()) + 1
    col = {key: j for j, key in enumerate(zip(np.round(np.asarray(x) * 1e9).astype(np.int64),
                                              np.round(np.asarray(z) * 1e9).astype(np.int64),
                                              np.asarray(phase).astype(np.int64)))}
    mu = np.full((n, len(col)), np.nan)
    p = np.full((n, len(col)), np.nan)
    for row, (xi, zi, k) in enumerate(zip(np.round(r["x"] * 1e9).astype(np.int64),
                                          np.round(r["z"] * 1e9).astype(np.int64),
                                          r["phase"].astype(np.int64))):
        j = col.get((int(xi), int(zi), int(k)))
        if j is not None:
            mu[b[row], j] = r["friction_coefficient"][row]
            p[b[row], j] = r["pressure"][row]
    return mu, p


def batch_errors(points: dict, mu_yield: float) -> dict | None:
    """The batch-means standard errors (measure.stats.stderr_of_batches) of the stress table's
    statistics, each taken again on every batch's own mu and p in the same cells and phases
    (points["batch_mu"], points["batch_pressure"]; a batch's empty cells left out), in the
    cells the pooled field selects (one of _select's tests, the shear rate resolved above its
    batch-means error, exists for the pooled field only): the median mu, the median p (Pa),
    the share at or above mu_yield, and by phase the lowest and the highest third's median mu
    (height_phase_table's thirds): {"median_mu", "median_pressure", "share", "thirds":
    {phase: (low, high)}}.  None without two batches."""
    if "batch_mu" not in points or np.shape(points["batch_mu"])[0] < 2:
        return None
    bm, bp = np.asarray(points["batch_mu"], float), np.asarray(points["batch_pressure"], float)

    def median(a):
        a = a[np.isfinite(a)]
        return float(np.median(a)) if a.size else float("nan")

    def share(m):
        m = m[np.isfinite(m)]
        return float(np.mean(m >= mu_yield)) if m.size and np.isfinite(mu_yield) \
            else float("nan")

    z, phase = points["z"], points["phase"]
    z1, z2 = np.percentile(z, [100.0 / 3.0, 200.0 / 3.0])
    thirds = {}
    for k in np.unique(phase):
        s = phase == k
        lo, hi = s & (z < z1), s & (z >= z2)
        thirds[int(k)] = (stderr_of_batches([median(m[lo]) for m in bm]),
                          stderr_of_batches([median(m[hi]) for m in bm]))
    return {"median_mu": stderr_of_batches([median(m) for m in bm]),
            "median_pressure": stderr_of_batches([median(q) for q in bp]),
            "share": stderr_of_batches([share(m) for m in bm]), "thirds": thirds}


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
