"""The mu(I) relation read directly from the tub's coarse-grained fields: a scatter of the stress
ratio mu = tau_eq / p against the inertial number I = gamma_dot d / sqrt(p / rho_s) over the
cells of the cross-section, beside the shear-cell fit.

Points are the phase-resolved cell values (each cell at each sampled phase of the cycle), since
the bed's state changes over the cycle (it flies, lands and is sheared); the time-averaged cells
are given too.  A point is marked dilute when its solid fraction is below `dense_solid_fraction`
(default 0.5: below it the balls are no longer in enduring contact and mu(I), a dense-flow law,
is not expected to hold; GDR MiDi 2004).

Without shear cells the calibration fits mu(I) and phi(I) to the dense points of this scatter
(fit_tub_cells); a bed with too few of them is an input error saying what to change
(check_tub_cells, too_small).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from vibroflow.errors import InputError
from vibroflow.measure.stats import jackknife_of_batches

from .calibration_tables import mu_phi_keys
from .rheology_fit import fit_mu_i, fit_phi_i

DENSE_SOLID_FRACTION = 0.5
MIN_SOLID_FRACTION = 0.1


def tub_mu_i_scatter(time_averaged, phase_resolved=None,
                     dense_solid_fraction: float = DENSE_SOLID_FRACTION,
                     min_solid_fraction: float = MIN_SOLID_FRACTION) -> dict:
    """Scatter of (I, mu, phi, p) over the tub's cells.

    time_averaged, phase_resolved : the Datasets of run_fields.coarse_grain_run.
    Returns {"phase": {I, mu, phi, pressure, dense}, "time": {...}} (flat arrays over the
    cells with finite, positive I and p and solid fraction >= min_solid_fraction).
    """
    out = {}
    for name, ds in (("time", time_averaged), ("phase", phase_resolved)):
        if ds is None:
            continue
        out[name] = _scatter_of(*(ds[k].values for k in SCATTER_FIELDS),
                                dense_solid_fraction, min_solid_fraction)
    return out


#: the coarse-grained fields a scatter is made of
SCATTER_FIELDS = ("inertial_number", "friction_coefficient", "solid_fraction", "pressure")


def _scatter_of(I, mu, phi, p, dense_solid_fraction: float = DENSE_SOLID_FRACTION,
                min_solid_fraction: float = MIN_SOLID_FRACTION) -> dict:
    """tub_mu_i_scatter's points of one set of fields (arrays of any shape, flattened)."""
    I, mu, phi, p = (np.asarray(a, float).ravel() for a in (I, mu, phi, p))
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(I) & np.isfinite(mu) & (I > 0) & (p > 0) & (phi >= min_solid_fraction)
    return {"I": I[ok], "mu": mu[ok], "phi": phi[ok], "pressure": p[ok],
            "dense": phi[ok] >= dense_solid_fraction}


def bed_pressure(time_averaged, dense_solid_fraction: float = DENSE_SOLID_FRACTION) -> float:
    """Representative pressure of the bed (Pa): the median time-averaged pressure over the dense
    cells (the shear cell and the elastic tests are run at it)."""
    p = np.asarray(time_averaged["pressure"].values, float)
    phi = np.asarray(time_averaged["solid_fraction"].values, float)
    sel = np.isfinite(p) & (p > 0) & (phi >= dense_solid_fraction)
    if not sel.any():
        sel = np.isfinite(p) & (p > 0)
    return float(np.median(p[sel])) if sel.any() else float("nan")


def median_dense(ds, name: str) -> float:
    """The median of field `name` over the dense cells (solid fraction >= DENSE_SOLID_FRACTION)
    of a coarse-grained Dataset; NaN without one."""
    v = np.asarray(ds[name].values, float)
    phi = np.asarray(ds["solid_fraction"].values, float)
    sel = np.isfinite(v) & (phi >= DENSE_SOLID_FRACTION)
    return float(np.median(v[sel])) if sel.any() else float("nan")


#: the points the tub-cell fits need: mu(I) has three parameters (rheology_fit.fit_mu_i), phi(I)
#: two (fit_phi_i)
MU_I_POINTS = 3


def dense_points(scatter: dict) -> dict:
    """The phase-resolved (else time-averaged) scatter's dense points, which the fits use."""
    ph = scatter.get("phase") or scatter["time"]
    d = ph["dense"]
    return {k: ph[k][d] for k in ("I", "mu", "phi")}


def too_small(run_dir: Path, scenario, avg, what: str, shear_cell: bool = True) -> InputError:
    """The one-line InputError of a DEM run too small for the tub-cell calibration: `what`
    failed, and what to change (the shear cells among it where they would serve)."""
    cell = ", or measure mu(I) in shear cells (--shear-cell)" if shear_cell else ""
    return InputError(
        f"RUN_DIR = {str(run_dir)!r}: the bed is too small to calibrate on: {what}; give the "
        f"DEM more balls (fill.count = {scenario.fill.count}) or a longer averaging window "
        f"(run.average_last = {scenario.run.average_last:g} s), or coarse-grain with a wider "
        f"kernel (--width, now {float(avg.attrs['width_m']) * 1e3:.3g} mm){cell}")


def check_dense_bed(scenario, avg, run_dir: Path) -> None:
    """InputError (too_small) when no cell of the time-averaged field is dense (solid fraction
    >= DENSE_SOLID_FRACTION): the bed's pressure, solid fraction and moduli are measured there,
    with or without the shear cells."""
    if not np.isfinite(median_dense(avg, "solid_fraction")):
        raise too_small(run_dir, scenario, avg, (
            f"no cell of the time-averaged field has solid fraction >= "
            f"{DENSE_SOLID_FRACTION:g}, where the bed's pressure, packing and moduli are "
            "measured"), shear_cell=False)


def check_tub_cells(scatter: dict, scenario, avg, run_dir: Path) -> None:
    """InputError (too_small) when the tub's coarse-grained cells hold fewer dense points
    (solid fraction >= DENSE_SOLID_FRACTION, finite mu, I > 0, over the cells and phases) than
    the mu(I) fit needs: a bed too thin or too agitated has none, and the calibration cannot
    be completed without --shear-cell."""
    n = int(dense_points(scatter)["I"].size)
    if n < MU_I_POINTS:
        raise too_small(run_dir, scenario, avg, (
            f"the mu(I) fit to the tub's cells has {n} dense cell value(s) (coarse-grained "
            f"cells x phases with solid fraction >= {DENSE_SOLID_FRACTION:g} and I > 0) and "
            f"needs at least {MU_I_POINTS}"))


def fit_tub_cells(scatter: dict, scenario=None, avg=None, run_dir: Path | None = None,
                  batches: dict | None = None) -> dict:
    """mu(I), phi(I) fitted to the tub's dense phase-resolved cells (no shear cell); a fit
    that fails (too few points, no convergence) is an InputError (too_small): the run is too
    small to calibrate on, and no number is invented for it.

    batches: each batch's phase-resolved SCATTER_FIELDS (arrays (n_batches, ...):
    coarse_grain.CoarseGrainer.batch_phase_arrays).  With two or more, each constant's
    *_stderr is the delete-one-batch jackknife's (`jackknife_rheology`) instead of the fit's
    covariance over the points, which counts the cells and phases of one bed as independent."""
    pts = dense_points(scatter)
    out = {"source": "tub cells (dense phase-resolved coarse-grained cells; run --shear-cell "
                     "for the Lees-Edwards simple-shear fit)", "points": int(pts["I"].size)}
    try:
        mu = fit_mu_i(pts["I"], pts["mu"])
        phi = fit_phi_i(pts["I"], pts["phi"])
    except InputError as e:
        if scenario is None:
            raise
        raise too_small(run_dir, scenario, avg, e.message.rstrip(".")) from None
    out.update(mu_phi_keys(mu, phi))
    if batches is not None:
        out.update(jackknife_rheology(out, batches))
    out["status"] = "measured"
    return out


#: the [rheology] constants whose errors jackknife_rheology gives
RHEOLOGY_CONSTANTS = ("mu_s", "mu_2", "I_0", "phi_max", "phi_min")


def jackknife_rheology(fit: dict, batches: dict) -> dict:
    """The tub-cell fit's constants' *_stderr from the delete-one-batch jackknife
    (measure.stats.jackknife_of_batches): mu(I) and phi(I) fitted again to the dense points
    of the cells' mean over the other batches, for each batch left out; the fit's own errors
    kept as *_stderr_least_squares (written to calibration.toml's [rheology] beside them).  A
    left-out fit that fails gives NaN.  Fewer than two batches: {}."""
    arrays = [np.asarray(batches[k], float) for k in SCATTER_FIELDS]
    nb = arrays[0].shape[0]
    if nb < 2:
        return {}

    def refit(*means):
        sc = _scatter_of(*means)
        d = sc["dense"]
        try:
            return {**fit_mu_i(sc["I"][d], sc["mu"][d]), **fit_phi_i(sc["I"][d], sc["phi"][d])}
        except InputError:
            return {}

    se = jackknife_of_batches(refit, arrays, RHEOLOGY_CONSTANTS)
    out = {}
    for k in RHEOLOGY_CONSTANTS:
        out[k + "_stderr_least_squares"] = fit[k + "_stderr"]
        out[k + "_stderr"] = se[k]
    out["stderr_method"] = f"delete-one-batch jackknife over {nb} batches"
    return out
