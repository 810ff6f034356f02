"""Fits of the mu(I) rheology to measured points, and the equivalent Drucker-Prager model with
viscosity (models.md, "Rheology of the continuum"); the laws are the continuum's
(vibroflow.continuum.rheology):

* mu(I) = mu_s + (mu_2 - mu_s) / (1 + I_0 / I)        (GDR MiDi 2004; Jop, Forterre &
  Pouliquen 2006, Nature 441:727)
* phi(I) = phi_max - (phi_max - phi_min) I             (GDR MiDi 2004; Forterre & Pouliquen
  2008, Annu. Rev. Fluid Mech. 40:1)

Both by weighted least squares (scipy.optimize.curve_fit): with standard errors of the points
the weights are 1/se^2 and the parameter errors come from the covariance as it stands
(absolute_sigma); without them the fit is unweighted and the covariance is scaled by the
residual variance (chi^2/dof then is the residual variance itself, not a goodness of fit).
"""
from __future__ import annotations

import math
import warnings

import numpy as np
from scipy.optimize import OptimizeWarning, curve_fit

from vibroflow.continuum.rheology import mu_of_I, phi_of_I
from vibroflow.errors import InputError

# Pailha & Pouliquen 2009 (JFM 633:115), the dilatancy law tan psi = K_1 (phi - phi_eq(I)) of an
# immersed granular layer of glass beads starting to flow
DILATANCY_K1 = 4.09


def _points(name: str, I, y, se, n_params: int):
    I = np.asarray(I, float).ravel()
    y = np.asarray(y, float).ravel()
    if I.shape != y.shape:
        raise InputError(f"{name}: {I.size} values of I and {y.size} values to fit: must be as "
                         f"many")
    if se is not None:
        se = np.asarray(se, float).ravel()
        if se.shape != y.shape:
            raise InputError(f"{name} standard errors: {se.size} values for {y.size} points: "
                             f"must be as many")
    ok = np.isfinite(I) & np.isfinite(y) & (I > 0)
    I, y = I[ok], y[ok]
    if se is not None:
        se = se[ok]
        # weights only when every point has a positive finite error; otherwise unweighted
        if not (np.all(np.isfinite(se)) and np.all(se > 0)):
            se = None
    if I.size < n_params:
        raise InputError(f"{name}: {I.size} usable points (finite, I > 0): the fit of "
                         f"{n_params} parameters needs at least {n_params}")
    return I, y, se


def _summary(f, p, cov, I, y, se, names) -> dict:
    resid = y - f(I, *p)
    dof = I.size - len(p)
    chi2 = float(np.sum((resid / se) ** 2)) if se is not None else float(np.sum(resid**2))
    out = {"points": int(I.size), "dof": int(dof), "weighted": se is not None,
           "chi2": chi2, "chi2_per_dof": chi2 / dof if dof > 0 else float("nan"),
           "residuals": resid, "covariance": cov}
    err = np.sqrt(np.clip(np.diag(cov), 0.0, None)) if np.all(np.isfinite(cov)) else \
        np.full(len(p), np.nan)
    for k, name in enumerate(names):
        out[name] = float(p[k])
        out[name + "_stderr"] = float(err[k])
    return out


def fit_mu_i(I, mu, mu_stderr=None) -> dict:
    """Fit mu(I) = mu_s + (mu_2 - mu_s) / (1 + I_0/I) to points (I, mu).

    Returns {mu_s, mu_2, I_0, *_stderr, chi2, dof, chi2_per_dof, residuals, covariance,
    points, weighted}.  Several starting values of I_0 (a log grid over the data's range) are
    tried and the lowest chi^2 kept, since the fit is non-linear in I_0.  Raises InputError
    with fewer than 3 usable points.  mu_2 >= mu_s is imposed (fitted as mu_s and
    mu_2 - mu_s >= 0, errors transformed back through the covariance).  With exactly 3 points
    and weights, the parameter errors are the propagated point errors (chi2/dof undefined:
    NaN)."""
    I, y, se = _points("mu(I) fit", I, mu, mu_stderr, 3)

    # fitted as (mu_s, mu_2 - mu_s, I_0) with mu_2 - mu_s >= 0: mu(I) never falls with I
    def model(x, mu_s, dmu, i0):
        return mu_of_I(x, mu_s, mu_s + dmu, i0)

    lo = [0.0, 0.0, 1e-8]
    hi = [10.0, 10.0, 1e3]
    best = None
    for i0 in np.geomspace(max(I.min(), 1e-6), max(I.max(), 1e-5), 7):
        p0 = [max(float(y.min()) - 0.01, 0.0), max(float(y.max() - y.min()), 0.0) + 0.05,
              float(i0)]
        try:
            with warnings.catch_warnings():
                # an exactly determined unweighted fit has no covariance: handled below
                warnings.simplefilter("ignore", OptimizeWarning)
                p, cov = curve_fit(model, I, y, p0=p0, sigma=se, absolute_sigma=se is not None,
                                   bounds=(lo, hi), method="trf", maxfev=20000)
        except (RuntimeError, ValueError):
            continue
        r = (y - model(I, *p)) / (se if se is not None else 1.0)
        c2 = float(np.sum(r * r))
        if best is None or c2 < best[0] - 1e-12 * max(c2, 1.0):
            best = (c2, p, cov)
    if best is None:
        raise InputError(f"mu(I) fit: no convergence on the {I.size} points (I from "
                         f"{I.min():.3g} to {I.max():.3g}): check the data")
    _, p, cov = best
    if I.size == 3 and se is None:
        cov = np.full((3, 3), np.nan)  # no residual left to scale an unweighted covariance
    # back to (mu_s, mu_2, I_0): mu_2 = mu_s + dmu, covariance J C J^T
    J = np.array([[1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    return _summary(mu_of_I, J @ p, J @ cov @ J.T, I, y, se, ("mu_s", "mu_2", "I_0"))


def fit_phi_i(I, phi, phi_stderr=None) -> dict:
    """Fit phi(I) = phi_max - (phi_max - phi_min) I to points (I, phi) (linear least squares).

    Returns {phi_max, phi_min, *_stderr, chi2, dof, chi2_per_dof, residuals, covariance,
    points, weighted}.  Raises InputError with fewer than 2 usable points."""
    I, y, se = _points("phi(I) fit", I, phi, phi_stderr, 2)
    p0 = [float(y.max()), float(y.min())]
    p, cov = curve_fit(phi_of_I, I, y, p0=p0, sigma=se, absolute_sigma=se is not None)
    if I.size == 2 and se is None:
        cov = np.full((2, 2), np.nan)
    return _summary(phi_of_I, p, cov, I, y, se, ("phi_max", "phi_min"))


def drucker_prager_equivalent(mu_s, mu_2, I_0, phi_max, phi_min, pressure, diameter, rho_s,
                              shear_rate) -> dict:
    """The Drucker-Prager model with viscosity equivalent to a mu(I), phi(I) rheology.

    Arguments: the rheology's parameters (-), the pressure p (Pa), the grain diameter d (m), the
    solid density rho_s (kg/m^3) and the shear rate gamma_dot (1/s) at which the rate-dependent
    part is matched.  Returns a dict (units in the key names):

    * friction_angle_deg: phi_f = atan(mu_s), the quasi-static (I -> 0) friction angle;
    * tan_beta, beta_deg: the Drucker-Prager cone q = tan(beta) p (q = sqrt(3 J_2)) matched to
      Mohr-Coulomb with phi_f in plane strain under associated flow,
      tan beta = 3 sqrt(3) tan phi_f / sqrt(9 + 12 tan^2 phi_f) (models.md; the classical
      plane-strain match alpha = tan phi / sqrt(9 + 12 tan^2 phi), tan beta = 3 sqrt(3) alpha);
    * dilation_angle_deg: psi from the phi(I) relation through the dilatancy law of Pailha &
      Pouliquen (2009), tan psi = K_1 (phi - phi_eq(I)) with K_1 = 4.09: a bed packed at phi_max
      (the quasi-static critical state) that is set flowing at the inertial number I of
      gamma_dot must loosen to phi(I), so it starts with tan psi = K_1 (phi_max - phi_min) I.
      This is the dilation at the onset of flow; in steady flow (the critical state) psi = 0;
    * viscosity_Pa_s: eta = (mu(I) - mu_s) p / gamma_dot, the viscosity that adds to the yield
      stress mu_s p to give the mu(I) shear stress at this shear rate;
    * inertial_number, mu_at_shear_rate, solid_fraction_at_shear_rate, and the inputs.

    A non-finite shear rate gives NaN for the rate-dependent entries; non-positive pressure,
    diameter, density or negative shear rate raise InputError.
    """
    for name, v in (("pressure", pressure), ("diameter", diameter), ("rho_s", rho_s)):
        if not (isinstance(v, (int, float, np.floating)) and math.isfinite(v) and v > 0):
            raise InputError(f"{name} = {v!r}: must be a positive finite number")
    if not math.isfinite(mu_s) or mu_s < 0:
        raise InputError(f"mu_s = {mu_s!r}: must be a finite number >= 0")
    if math.isfinite(shear_rate) and shear_rate < 0:
        raise InputError(f"shear_rate = {shear_rate!r} 1/s: must be >= 0")
    t = float(mu_s)
    tan_beta = 3.0 * math.sqrt(3.0) * t / math.sqrt(9.0 + 12.0 * t * t)
    I = float(shear_rate) * diameter / math.sqrt(pressure / rho_s)
    if math.isfinite(I) and I > 0:
        mu_i = float(mu_of_I(I, mu_s, mu_2, I_0))
        eta = (mu_i - mu_s) * pressure / shear_rate
        phi_i = float(phi_of_I(I, phi_max, phi_min))
        psi = math.degrees(math.atan(DILATANCY_K1 * (phi_max - phi_min) * I))
    elif I == 0.0:
        mu_i, phi_i, psi = float(mu_s), float(phi_max), 0.0
        # the limit gamma_dot -> 0 of (mu(I) - mu_s) p / gamma_dot: (mu_2 - mu_s) p d /
        # (I_0 sqrt(p / rho_s))
        eta = (mu_2 - mu_s) * pressure * diameter / (I_0 * math.sqrt(pressure / rho_s))
    else:
        mu_i = phi_i = psi = eta = float("nan")
    return {
        "model": "Drucker-Prager cone q = tan(beta) p matched to Mohr-Coulomb (phi_f = "
                 "atan mu_s) in plane strain, plus viscosity eta = (mu(I) - mu_s) p / gamma_dot",
        "friction_angle_deg": math.degrees(math.atan(t)),
        "tan_beta": tan_beta,
        "beta_deg": math.degrees(math.atan(tan_beta)),
        "dilation_angle_deg": psi,
        "dilatancy_K1": DILATANCY_K1,
        "viscosity_Pa_s": eta,
        "inertial_number": I,
        "mu_at_shear_rate": mu_i,
        "solid_fraction_at_shear_rate": phi_i,
        "pressure_Pa": float(pressure),
        "shear_rate_1_s": float(shear_rate),
        "diameter_m": float(diameter),
        "solid_density_kg_m3": float(rho_s),
    }
