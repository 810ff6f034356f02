"""Kinetic theory's equation of state measured in the DEM's coarse-grained cells: the closure's
close packing phi_rcp fitted so that Lun et al.'s (1984, J. Fluid Mech. 140, 223) pressure

    p / (rho_s phi T) = 1 + 2 (1 + e) phi g0(phi; phi_rcp)

matches the cells' kinetic + contact pressure p, solid fraction phi and granular temperature T,
with g0 the continuum's own (vibroflow.continuum.kinetic_theory: Chialvo & Sundaresan 2013 by
default) and e the scenario's ball-ball restitution.

Which cells: the phase-resolved ones (each cell at each sampled phase), whose kinetic stress is
the fluctuation about that phase's mean velocity, the temperature kinetic theory means; the
time-averaged cells count the bed's oscillation over the cycle as temperature.  A cell enters
the fit when its p, phi and T are finite and positive, phi lies in [phi_lo, phi_hi] (default
0.1 - 0.6: below, a cell holds too few balls; kinetic theory has no enduring contacts, so the
packed core above is not its domain) and, where the fields carry batch-means errors, the
error of ln(p / (rho_s phi T)) is at most `max_log_error` (enough samples).

The fit: weighted least squares in ln(p / (rho_s phi T)), one parameter, weights
1 / sigma^2 with sigma^2 = (sigma_p/p)^2 + (sigma_T/T)^2 + (sigma_phi/phi)^2 from the batch-means
errors (equal weights without them).  The standard error of phi_rcp is sqrt(s^2 / sum w J^2),
J = d ln(model) / d phi_rcp and s^2 the weighted residual variance per degree of freedom, as in
impacts.weighted_linear_fit; the scatter is the weighted rms of the log residuals.

The joint fit (`fit_lun_frictional`): Lun's pressure plus Johnson & Jackson's (1987, J. Fluid
Mech. 176, 67) frictional pressure of enduring contacts, the continuum's own
(kinetic_theory.frictional_pressure_Pa),

    p = rho_s phi T (1 + 2 (1 + e) phi g0(phi; phi_rcp)) + Fr (phi - phi_min)^n / (phi_rcp - phi)^p,

n = 2 and p = 5 (Johnson & Jackson's exponents), phi_rcp, ln Fr and phi_min fitted together
by weighted least squares in ln(p / (rho_s phi T)) over the same cells (scipy's
trust-region least_squares, from several starting phi_min, the best kept); standard errors
from the weighted Jacobian, s^2 (J^T W J)^-1.  The frictional part does not scale with T, which
is what lets it describe cold dense cells that Lun's pressure alone puts far below their p.

Those least-squares errors count every cell as an independent point; the cells of one chaotic
bed are not (neighbours share balls and the bed's collective motion), so with the coarse-grained
batches (`fit_cells(..., batches=...)`, as `vibroflow calibrate` calls it) each constant's error
is the delete-one-batch jackknife's instead (`jackknife_errors`; docs/decisions/
batch-jackknife-errors.md).
"""
from __future__ import annotations

import math

import numba as nb
import numpy as np
from scipy.optimize import least_squares, minimize_scalar

from vibroflow.continuum.kinetic_theory import (G0_FORMS, KineticParameters,
                                                frictional_pressure_Pa, radial_distribution)
from vibroflow.errors import InputError
from vibroflow.measure.stats import jackknife_of_batches

PHI_RANGE = (0.1, 0.6)
MAX_LOG_ERROR = 0.5
#: a scatter of the cells about the closure above this (a factor 1.65) is said in the status
MAX_RMS_LOG_RESIDUAL = 0.5
#: the largest phi_rcp the fit may return: the packing fraction of face-centred cubic spheres
PHI_RCP_MAX = math.pi / (3.0 * math.sqrt(2.0))


@nb.njit(cache=True)
def _g0_of(phi, prm):
    out = np.empty(phi.size)
    for k in range(phi.size):
        out[k] = radial_distribution(phi[k], prm)
    return out


@nb.njit(cache=True)
def _pf_of(phi, prm):
    out = np.empty(phi.size)
    for k in range(phi.size):
        out[k] = frictional_pressure_Pa(phi[k], prm)
    return out


def frictional_pressure(phi, phi_rcp: float, frictional_Pa: float, phi_min: float,
                        n: float = 2.0, p: float = 5.0) -> np.ndarray:
    """Johnson & Jackson's p_f (Pa) = Fr (phi - phi_min)^n / (phi_rcp - phi)^p above phi_min
    (kinetic_theory.frictional_pressure_Pa) at solid fractions phi."""
    phi = np.ascontiguousarray(phi, dtype=float).ravel()
    prm = KineticParameters(phi_rcp=float(phi_rcp), frictional_Pa=float(frictional_Pa),
                            frictional_phi_min=float(phi_min), frictional_n=float(n),
                            frictional_p=float(p))
    return _pf_of(phi, prm)


def pressure_ratio(phi, phi_rcp: float, restitution: float,
                   g0_form: str = "chialvo_sundaresan") -> np.ndarray:
    """Lun et al.'s p / (rho_s phi T) = 1 + 2 (1 + e) phi g0(phi; phi_rcp) (-) at solid
    fractions phi, with the continuum's g0 (form `g0_form`)."""
    phi = np.ascontiguousarray(phi, dtype=float).ravel()
    prm = KineticParameters(restitution=float(restitution), phi_rcp=float(phi_rcp),
                            g0_form=G0_FORMS[g0_form])
    return 1.0 + 2.0 * (1.0 + restitution) * phi * _g0_of(phi, prm)


def _check(restitution, phi_range, g0_form, max_log_error):
    if not (0.0 < restitution <= 1.0):
        raise InputError(f"restitution = {restitution!r}: must be in (0, 1]")
    lo, hi = (float(v) for v in phi_range)
    if not (0.0 < lo < hi < PHI_RCP_MAX):
        raise InputError(f"phi_range = {tuple(phi_range)!r}: must be (lo, hi) with "
                         f"0 < lo < hi < {PHI_RCP_MAX:.4f}")
    if g0_form not in G0_FORMS:
        raise InputError(f"g0_form = {g0_form!r}: must be one of {', '.join(G0_FORMS)}")
    if not (max_log_error > 0):
        raise InputError(f"max_log_error = {max_log_error!r}: must be > 0")
    return lo, hi


def _cells_fitted(phi, T, p, rho_s, restitution, phi_stderr, T_stderr, p_stderr, phi_range,
                  g0_form, max_log_error, min_points, what):
    """The cells a fit uses (module docstring): (phi, T, y = ln(p / (rho_s phi T)), weights,
    count, weighted); InputError naming `what` when fewer than min_points qualify."""
    lo, hi = _check(restitution, phi_range, g0_form, max_log_error)
    if not (rho_s > 0):
        raise InputError(f"rho_s = {rho_s!r}: must be > 0 kg/m^3")
    phi = np.asarray(phi, float).ravel()
    T = np.asarray(T, float).ravel()
    p = np.asarray(p, float).ravel()
    if not (phi.size == T.size == p.size):
        raise InputError(f"phi, T, p have {phi.size}, {T.size}, {p.size} values: must have "
                         "one per cell each")
    with np.errstate(invalid="ignore", divide="ignore"):
        y = np.log(p / (rho_s * phi * T))
        ok = np.isfinite(y) & (phi >= lo) & (phi <= hi) & (T > 0) & (p > 0)
        errs = (phi_stderr, T_stderr, p_stderr)
        weighted = all(e is not None for e in errs)
        if weighted:
            var = sum((np.asarray(e, float).ravel() / v) ** 2 for e, v in zip(errs, (phi, T, p)))
            ok &= np.isfinite(var) & (var > 0) & (var <= max_log_error ** 2)
            w = np.where(ok, 1.0 / np.where(var > 0, var, 1.0), 0.0)
        else:
            w = np.ones_like(y)
    n = int(ok.sum())
    if n < min_points:
        raise InputError(f"cells = {n}: the {what} fit needs at least {min_points} cells with "
                         f"finite p, T > 0 and solid fraction in [{lo:g}, {hi:g}]"
                         + (f" and log error <= {max_log_error:g}" if weighted else ""))
    return phi[ok], T[ok], y[ok], w[ok], n, weighted


def fit_phi_rcp(phi, T, p, rho_s: float, restitution: float, phi_stderr=None, T_stderr=None,
                p_stderr=None, phi_range=PHI_RANGE, g0_form: str = "chialvo_sundaresan",
                max_log_error: float = MAX_LOG_ERROR, min_points: int = 3) -> dict:
    """phi_rcp fitted to cells (flat arrays of solid fraction phi, temperature T (m^2/s^2) and
    pressure p (Pa), optional batch-means errors of each); rho_s (kg/m^3).

    Returns {phi_rcp, phi_rcp_stderr, restitution, g0_form, points, solid_fraction_range
    (of the points used), rms_log_residual, chi2_per_dof (NaN unweighted), weighted,
    status ("measured", or "at the bound ..." when the best phi_rcp is within two standard
    errors of the densest cell's solid fraction or of PHI_RCP_MAX; the scatter said when
    the rms log residual exceeds MAX_RMS_LOG_RESIDUAL)}.  InputError when fewer
    than `min_points` cells qualify.
    """
    phi, T, y, w, n, weighted = _cells_fitted(phi, T, p, rho_s, restitution, phi_stderr,
                                              T_stderr, p_stderr, phi_range, g0_form,
                                              max_log_error, min_points, "phi_rcp")

    def sse(phi_rcp):
        r = y - np.log(pressure_ratio(phi, phi_rcp, restitution, g0_form))
        return float(np.sum(w * r * r))

    lo_b = float(phi.max()) + 1e-4
    best = minimize_scalar(sse, bounds=(lo_b, PHI_RCP_MAX), method="bounded",
                           options={"xatol": 1e-9})
    phi_rcp = float(best.x)
    h = 1e-6
    J = (np.log(pressure_ratio(phi, phi_rcp + h, restitution, g0_form))
         - np.log(pressure_ratio(phi, phi_rcp - h, restitution, g0_form))) / (2.0 * h)
    s2 = sse(phi_rcp) / max(n - 1, 1)
    se = math.sqrt(s2 / float(np.sum(w * J * J))) if n > 1 else float("nan")
    r = y - np.log(pressure_ratio(phi, phi_rcp, restitution, g0_form))
    # a bound within two standard errors: the cells do not fix phi_rcp on that side
    at_bound = min(phi_rcp - lo_b, PHI_RCP_MAX - phi_rcp) < max(2.0 * se, 1e-5)
    rms = float(math.sqrt(np.sum(w * r * r) / np.sum(w)))
    status = ("at the bound (within two standard errors of the densest cell's solid fraction "
              "or of close packing): the cells do not fix phi_rcp" if at_bound else "measured")
    if rms > MAX_RMS_LOG_RESIDUAL:
        status += (f"; the cells scatter about Lun's pressure by a factor {math.exp(rms):.3g} "
                   "(rms log residual): the closure does not describe them, and phi_rcp "
                   "depends on the solid fractions fitted")
    return {"phi_rcp": phi_rcp, "phi_rcp_stderr": se, "restitution": float(restitution),
            "g0_form": g0_form, "points": n,
            "solid_fraction_range": [float(phi.min()), float(phi.max())],
            "rms_log_residual": rms,
            "chi2_per_dof": s2 if weighted else float("nan"), "weighted": weighted,
            "status": status}


def fit_lun_frictional(phi, T, p, rho_s: float, restitution: float, phi_stderr=None,
                       T_stderr=None, p_stderr=None, phi_range=PHI_RANGE,
                       g0_form: str = "chialvo_sundaresan", max_log_error: float = MAX_LOG_ERROR,
                       min_points: int = 5) -> dict:
    """Lun's plus Johnson & Jackson's frictional pressure fitted jointly to cells (module
    docstring; arguments as fit_phi_rcp's).

    Returns {phi_rcp, frictional_Pa (Fr), frictional_phi_min, frictional_n, frictional_p, their
    *_stderr (phi_rcp, Fr, phi_min), points, solid_fraction_range, rms_log_residual,
    lun_rms_log_residual (Lun's pressure alone, fit_phi_rcp), chi2_per_dof (NaN unweighted),
    weighted, status}; where the cells resolve no frictional pressure (Fr at its lower bound,
    1e-12 Pa, within two standard errors of 0, or a singular fit) Lun's fit alone with Fr = 0,
    phi_min NaN and the status saying so.  InputError when fewer than min_points cells qualify."""
    lun = fit_phi_rcp(phi, T, p, rho_s, restitution, phi_stderr, T_stderr, p_stderr,
                      phi_range, g0_form, max_log_error, min_points)
    phi, T, y, w, n, weighted = _cells_fitted(phi, T, p, rho_s, restitution, phi_stderr,
                                              T_stderr, p_stderr, phi_range, g0_form,
                                              max_log_error, min_points,
                                              "Lun + frictional pressure")
    sw = np.sqrt(w)
    scale = rho_s * phi * T
    lo_b = float(phi.max()) + 1e-4

    def resid(x):
        ratio = pressure_ratio(phi, x[0], restitution, g0_form)
        pf = frictional_pressure(phi, x[0], math.exp(x[1]), x[2])
        return sw * (y - np.log(ratio + pf / scale))

    lower = [lo_b, math.log(1e-12), 0.0]
    upper = [PHI_RCP_MAX, math.log(1e9), lo_b - 1e-3]
    best = None
    for phi_min in (0.3, 0.45, 0.55):
        x0 = [min(max(lun["phi_rcp"], lo_b + 1e-3), PHI_RCP_MAX - 1e-3), math.log(1e-2),
              min(phi_min, upper[2] - 1e-3)]
        res = least_squares(resid, x0, bounds=(lower, upper), x_scale=[0.01, 1.0, 0.05],
                            xtol=1e-12, ftol=1e-12, gtol=1e-12)
        if best is None or res.cost < best.cost:
            best = res
    x = best.x
    r = best.fun
    sse = float(np.sum(r * r))
    s2 = sse / max(n - 3, 1)
    J = best.jac
    try:
        cov = s2 * np.linalg.inv(J.T @ J)
        se = np.sqrt(np.diag(cov))
    except np.linalg.LinAlgError:
        se = np.full(3, np.nan)
    fr = math.exp(x[1])
    rms = float(math.sqrt(sse / np.sum(w)))
    common = {"frictional_n": 2.0, "frictional_p": 5.0, "restitution": float(restitution),
              "g0_form": g0_form, "points": n,
              "solid_fraction_range": [float(phi.min()), float(phi.max())],
              "lun_rms_log_residual": lun["rms_log_residual"], "weighted": weighted}
    if not (np.all(np.isfinite(se)) and x[1] > lower[1] + 1.0 and se[1] < 0.5):
        # Fr at its lower bound, within two standard errors of 0 (ln Fr's error above 1/2) or a
        # singular fit: the cells resolve no frictional pressure, and the fit is Lun's alone
        return {**common, "phi_rcp": lun["phi_rcp"], "phi_rcp_stderr": lun["phi_rcp_stderr"],
                "frictional_Pa": 0.0, "frictional_Pa_stderr": float("nan"),
                "frictional_phi_min": float("nan"), "frictional_phi_min_stderr": float("nan"),
                "rms_log_residual": lun["rms_log_residual"],
                "chi2_per_dof": lun["chi2_per_dof"],
                "status": lun["status"] + "; no frictional pressure resolved by the cells (Fr "
                                          "within two standard errors of 0): Lun's pressure "
                                          "alone"}
    status = "measured"
    if rms > MAX_RMS_LOG_RESIDUAL:
        status += (f"; the cells scatter about the joint pressure by a factor {math.exp(rms):.3g} "
                   "(rms log residual)")
    return {**common, "phi_rcp": float(x[0]), "phi_rcp_stderr": float(se[0]),
            "frictional_Pa": fr, "frictional_Pa_stderr": float(fr * se[1]),
            "frictional_phi_min": float(x[2]), "frictional_phi_min_stderr": float(se[2]),
            "rms_log_residual": rms, "chi2_per_dof": s2 if weighted else float("nan"),
            "status": status}


def fit_cells(fields, rho_s: float, restitution: float, joint: bool = False,
              batches: dict | None = None, **options) -> dict:
    """fit_phi_rcp (joint: fit_lun_frictional) on a coarse-grained Dataset
    (run_fields.coarse_grain_run's phase-resolved one, or any with solid_fraction, temperature,
    pressure and, optionally, their *_stderr).

    batches: each batch's phase-resolved solid_fraction, temperature and pressure (arrays
    (n_batches, ...) of the Dataset's shape: coarse_grain.CoarseGrainer.batch_phase_arrays).
    With two or more, the fitted constants' *_stderr are the delete-one-batch jackknife's
    (`jackknife_errors`) instead of the least-squares covariance over the cells, which counts
    the cells of one chaotic bed as independent; the values are the fit's on all batches."""
    for name in ("solid_fraction", "temperature", "pressure"):
        if name not in fields:
            raise InputError(f"fields: no {name!r}: not a coarse-grained field set")
    get = (lambda k: np.asarray(fields[k].values, float) if k in fields else None)
    fit = fit_lun_frictional if joint else fit_phi_rcp
    errs = (get("solid_fraction_stderr"), get("temperature_stderr"), get("pressure_stderr"))
    out = fit(get("solid_fraction"), get("temperature"), get("pressure"), rho_s,
              restitution, *errs, **options)
    if batches is None:
        return out
    shape = np.shape(fields["solid_fraction"].values)
    return jackknife_errors(out, fit, batches, shape, rho_s, restitution, errs, options)


#: the constants whose errors `jackknife_errors` gives (the frictional ones where resolved)
JACKKNIFED = ("phi_rcp", "frictional_Pa", "frictional_phi_min")


def jackknife_errors(out: dict, fit, batches: dict, shape, rho_s: float, restitution: float,
                     errs, options: dict) -> dict:
    """The fit `out` with its constants' *_stderr from the delete-one-batch jackknife
    (measure.stats.jackknife_of_batches): the fit repeated with each batch left out, on the cells'
    mean over the other batches (each batch's fields as coarse_grain gives them; NaN where a
    batch has no snapshot of a phase), with the same per-cell weights (the full fields'
    *_stderr) and options.  The least-squares errors are kept as *_stderr_least_squares.  A
    constant the full fit does not resolve (Fr = 0) keeps its NaN error; a left-out fit that
    fails gives NaN.  Fewer than two batches: `out` unchanged."""
    arrays = [np.asarray(batches[k], float) for k in ("solid_fraction", "temperature",
                                                       "pressure")]
    nb = arrays[0].shape[0]
    if nb < 2:
        return out
    for a in arrays:
        if a.shape[1:] != tuple(shape):
            raise ValueError(f"batches: fields of shape {a.shape[1:]}, not the cells' {shape}")
    keys = [k for k in JACKKNIFED if k in out and np.isfinite(out[k + "_stderr"])]

    def refit(*means):
        try:
            return fit(*means, rho_s, restitution, *errs, **options)
        except InputError:
            return {}

    se = jackknife_of_batches(refit, arrays, keys)
    res = dict(out)
    for k in keys:
        res[k + "_stderr_least_squares"] = out[k + "_stderr"]
        res[k + "_stderr"] = se[k]
    res["stderr_method"] = f"delete-one-batch jackknife over {nb} batches"
    return res


def _floats(a):
    """A (nested) list of plain floats for TOML (NaN stays NaN)."""
    return np.asarray(a, float).tolist()


def kinetic_table(fit: dict | None, flux: dict | None, restitution: float,
                  restitution_source: str, conductivity: dict | None = None) -> dict:
    """The [kinetic] table of calibration.toml (io.calibration_file.Kinetic) from a phi_rcp fit
    (fit_phi_rcp; None: not measured), the walls' fluxes (wall_energy.wall_flux; None: the
    run stores no wall forces) and the conductivity table (conductivity.conductivity_table)."""
    out = {"model": "p / (rho_s phi T) = 1 + 2 (1 + e) phi g0(phi; phi_rcp) (Lun et al. 1984)",
           "restitution": float(restitution), "restitution_source": restitution_source}
    if fit is not None:
        out.update(g0_form=fit["g0_form"], phi_rcp=fit["phi_rcp"],
                   phi_rcp_stderr=fit["phi_rcp_stderr"], status=fit["status"],
                   points=int(fit["points"]), solid_fraction_range=fit["solid_fraction_range"],
                   rms_log_residual=fit["rms_log_residual"], chi2_per_dof=fit["chi2_per_dof"])
        if "frictional_Pa" in fit:
            out["model"] = ("p = rho_s phi T (1 + 2 (1 + e) phi g0(phi; phi_rcp)) + Fr (phi - "
                            "phi_min)^n / (phi_rcp - phi)^p (Lun et al. 1984; Johnson & "
                            "Jackson 1987)")
            for key in ("frictional_Pa", "frictional_Pa_stderr", "frictional_phi_min",
                        "frictional_phi_min_stderr", "frictional_n", "frictional_p",
                        "lun_rms_log_residual"):
                out[key] = float(fit[key])
    if flux is not None:
        u, p = flux["u"], flux["partitions"]
        wf = {"arc_edges_m": _floats(flux["arc_edges_m"]),
              "phase_rad": _floats(flux["phase_rad"]), "length_m": float(flux["length_m"]),
              "partition_area_m2": float(flux["partition_area_m2"])}
        for name, tag in (("fluctuation_power", "fluctuation"), ("power", "power"),
                          ("drive_power", "drive")):
            for part, rec in (("u", u), ("partitions", p)):
                wf[f"{part}_{tag}_flux_W_m2"] = float(rec[name]["mean"])
                wf[f"{part}_{tag}_flux_stderr_W_m2"] = float(rec[name]["mean_stderr"])
        fl = u["fluctuation_power"]
        for key, k in (("by_arc", "arc"), ("by_phase", "phase"), ("by_phase_arc", "phase_arc")):
            wf[f"u_fluctuation_flux_{key}_W_m2"] = _floats(fl[k])
            wf[f"u_fluctuation_flux_{key}_stderr_W_m2"] = _floats(fl[k + "_stderr"])
        pf = p["fluctuation_power"]
        wf["partitions_fluctuation_flux_by_phase_W_m2"] = _floats(pf["phase"])
        wf["partitions_fluctuation_flux_by_phase_stderr_W_m2"] = _floats(pf["phase_stderr"])
        out["wall_flux"] = wf
    if conductivity is not None:
        out["conductivity"] = conductivity
    return out
