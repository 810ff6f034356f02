"""Does the granular temperature collapse the tub's mu(I) scatter?  The dense phase-resolved
cells' friction mu = tau / p against three abscissae (docs/validation.md section 30):

(a) the inertial number I = gamma_dot d / sqrt(p / rho_s) (GDR MiDi 2004; Jop et al. 2006);
(b) the continuum's r I, r = sqrt(T_bal / T) (continuum/kinetic_stress.py): T_bal the
    temperature at which the cell's own plastic work tau gamma_dot balances Lun's dissipation
    (kinetic_stress.balance_temperature, as the continuum computes it), T the DEM's thermal
    temperature; and r_D I with the DEM's measured dissipation D per cell (calibration/
    thermal_balance.py) in Lun's place: Gamma scales as T^(3/2), so T_bal / T =
    (tau gamma_dot / D)^(2/3) and r_D = (tau gamma_dot / D)^(1/3);
(c) Kim & Kamrin's (2020, Phys. Rev. Lett. 125, 088002) form mu = Theta^a F(I), Theta =
    rho_s T / p the dimensionless temperature, the exponent a fitted;
(d) Pailha & Pouliquen's (2009, J. Fluid Mech. 633, 115) dilatancy, mu = F(I) + tan psi, with
    the cell's own dilatancy angle tan psi = tr D / gamma_dot (tr D the coarse-grained
    velocity field's divergence, 1/s, dilation positive): the law with b = 1 in
    mu = F(I) + b tan psi, and b fitted;
(e) Zhang & Kamrin's (2017, Phys. Rev. Lett. 118, 058001) fluidity, g = gamma_dot / mu =
    (sqrt(T) / d) F(phi): mu = x^a / F(phi), x = gamma_dot d / sqrt(T) the fluidity number,
    ln F a quadratic in phi, a = 1 (their law) and a fitted.  Kinetic theory's ratio of shear
    viscosity to pressure has this form (both scale with sqrt(T) and T at one phi).

F is Jop's mu_s + (mu_2 - mu_s) / (1 + X_0 / X) throughout, fitted to log mu (the scatter is a
factor, 0.1 - 1), so each abscissa's rms log residual says how far the best curve of that family
leaves the cells; the scatter about the cells' median mu is the baseline it narrows, and the
cells' own batch-means error as an rms log, sqrt(mean((se_mu / mu)^2)), the noise floor no
abscissa can go below (the excess over it: sqrt(rms^2 - noise^2)).

A cell is used where its solid fraction is >= dense_solid_fraction (0.5: dense flow, the regime
mu(I) claims), its shear rate is resolved (above `resolved` times its batch-means standard error)
and mu, p and the thermal T are finite and positive.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.optimize import least_squares

from vibroflow.continuum.kinetic_stress import balance_temperature
from vibroflow.continuum.rheology import mu_of_I
from vibroflow.errors import InputError

DENSE_SOLID_FRACTION = 0.5
#: (d)'s predicted friction is counted at no less than this where F(I) + b tan psi falls below
#: it (a friction the law makes zero or negative is a miss of at least ln(mu / MU_FLOOR))
MU_FLOOR = 0.01
#: a shear rate is resolved when it exceeds this many batch-means standard errors
RESOLVED = 2.0
#: a median's standard error over that of a mean of normal values (Kenney & Keeping 1962)
MEDIAN_ERROR = math.sqrt(math.pi / 2.0)


def _flat(ds, name):
    return np.asarray(ds[name].values, float).ravel()


def cell_points(phase_fields, thermal_temperature, prm, dissipation=None,
                dense_solid_fraction: float = DENSE_SOLID_FRACTION,
                resolved: float = RESOLVED) -> dict:
    """The dense cells with a resolved shear rate, as flat arrays (SI).

    phase_fields: the phase-resolved Dataset of run_fields.coarse_grain_run (friction_coefficient,
    inertial_number, pressure, shear_rate, solid_fraction, each with _stderr where measured);
    thermal_temperature: array (m^2/s^2) on its grid (phase, x, z); prm:
    kinetic_theory.KineticParameters; dissipation: the DEM's dissipation (W/m^3) on the same
    grid, or None.  Returns {mu, mu_stderr, I, T, Theta, phi, pressure, shear_rate, phase (the
    cell's phase bin), rI, rI_median_T (the control: r at the cells' median T), rI_dem (NaN
    without dissipation), tan_psi (tr D / gamma_dot; NaN without a velocity_gradient),
    fluidity_number (gamma_dot d / sqrt(T)), x_m, z_m (the cell's centre; NaN without the
    grid's coordinates)}."""
    mu = _flat(phase_fields, "friction_coefficient")
    I = _flat(phase_fields, "inertial_number")
    p = _flat(phase_fields, "pressure")
    gd = _flat(phase_fields, "shear_rate")
    phi = _flat(phase_fields, "solid_fraction")
    T = np.asarray(thermal_temperature, float).ravel()
    if T.size != mu.size:
        raise InputError(f"thermal_temperature: {T.size} values, the fields' grid has {mu.size}")
    se = (_flat(phase_fields, "friction_coefficient_stderr")
          if "friction_coefficient_stderr" in phase_fields else np.full(mu.size, np.nan))
    gd_se = (_flat(phase_fields, "shear_rate_stderr")
             if "shear_rate_stderr" in phase_fields else np.zeros(mu.size))
    with np.errstate(invalid="ignore"):
        ok = (np.isfinite(mu) & (mu > 0) & np.isfinite(I) & (I > 0) & (p > 0) & (T > 0)
              & np.isfinite(T) & (phi >= dense_solid_fraction) & (phi < prm.phi_rcp)
              & (gd > resolved * np.nan_to_num(gd_se)))
    shape = phase_fields["friction_coefficient"].shape
    out = {"mu": mu[ok], "mu_stderr": se[ok], "I": I[ok], "T": T[ok], "phi": phi[ok],
           "pressure": p[ok], "shear_rate": gd[ok],
           "phase": np.indices(shape)[0].ravel()[ok]}
    if "velocity_gradient" in phase_fields:
        L = np.asarray(phase_fields["velocity_gradient"].values, float)
        div = np.trace(L, axis1=-2, axis2=-1).ravel()
        out["tan_psi"] = div[ok] / out["shear_rate"]
    else:
        out["tan_psi"] = np.full(out["mu"].size, np.nan)
    out["fluidity_number"] = out["shear_rate"] * prm.diameter_m / np.sqrt(out["T"])
    for axis, name in ((1, "x"), (2, "z")):
        if name in phase_fields.coords:
            c = np.broadcast_to(np.expand_dims(np.asarray(phase_fields[name].values, float),
                                               tuple(a for a in range(3) if a != axis)), shape)
            out[f"{name}_m"] = c.ravel()[ok]
        else:
            out[f"{name}_m"] = np.full(out["mu"].size, np.nan)
    out["Theta"] = prm.density_kg_m3 * out["T"] / out["pressure"]
    tau = out["mu"] * out["pressure"]
    t_bal = np.array([balance_temperature(float(f), float(t), float(g), prm, float(q))
                      for f, t, g, q in zip(out["phi"], tau, out["shear_rate"], out["pressure"])])
    out["rI"] = np.sqrt(t_bal / out["T"]) * out["I"]
    out["rI_median_T"] = np.sqrt(t_bal / np.median(out["T"])) * out["I"]
    if dissipation is None:
        out["rI_dem"] = np.full(out["I"].size, np.nan)
    else:
        D = np.asarray(dissipation, float).ravel()
        if D.size != mu.size:
            raise InputError(f"dissipation: {D.size} values, the fields' grid has {mu.size}")
        D = D[ok]
        with np.errstate(invalid="ignore", divide="ignore"):
            out["rI_dem"] = np.where(D > 0, np.cbrt(tau * out["shear_rate"] / D), np.nan) * out["I"]
    return out


def _log_fit(residual, starts, lo, hi):
    best = None
    for p0 in starts:
        r = least_squares(residual, p0, bounds=(lo, hi), method="trf", max_nfev=5000)
        if best is None or r.cost < best.cost:
            best = r
    return best


def fit_collapse(x, mu, theta=None) -> dict:
    """The best curve mu = F(x) (Jop's form, mu_s, mu_2 >= mu_s, x_0), or with theta
    mu = theta^a F(x) (Kim & Kamrin's), fitted to log mu.  Returns {mu_s, mu_2, x_0, a (0
    without theta), rms_log_residual, points}; InputError with fewer points than parameters."""
    x, mu = np.asarray(x, float), np.asarray(mu, float)
    ok = np.isfinite(x) & (x > 0) & np.isfinite(mu) & (mu > 0)
    if theta is not None:
        theta = np.asarray(theta, float)
        ok &= np.isfinite(theta) & (theta > 0)
    n_par = 3 if theta is None else 4
    if ok.sum() <= n_par:
        raise InputError(f"mu collapse fit: {int(ok.sum())} usable cells, needs more than {n_par}")
    x, y = x[ok], np.log(mu[ok])
    lt = np.log(theta[ok]) if theta is not None else np.zeros(x.size)

    def residual(q):
        mu_s, dmu, lx0 = q[:3]
        a = q[3] if theta is not None else 0.0
        return np.log(mu_of_I(x, mu_s, mu_s + dmu, math.exp(lx0))) + a * lt - y

    m = float(np.median(mu[ok]))
    starts = [[0.5 * m, m, lx] + ([0.0] if theta is not None else [])
              for lx in np.log(np.geomspace(x.min(), x.max(), 5))]
    lo = [1e-6, 0.0, math.log(x.min()) - 10.0] + ([-5.0] if theta is not None else [])
    hi = [10.0, 10.0, math.log(x.max()) + 10.0] + ([5.0] if theta is not None else [])
    r = _log_fit(residual, starts, lo, hi)
    q = r.x
    return {"mu_s": float(q[0]), "mu_2": float(q[0] + q[1]), "x_0": float(math.exp(q[2])),
            "a": float(q[3]) if theta is not None else 0.0,
            "rms_log_residual": float(np.sqrt(np.mean(r.fun ** 2))), "points": int(x.size)}


def fit_dilatancy(I, mu, tan_psi, b=None) -> dict:
    """(d): the best mu = F(I) + b tan psi (Jop's F, mu_s, mu_2 >= mu_s, I_0), b fixed (1:
    Pailha & Pouliquen) or fitted when None, fitted to log mu with the prediction counted at
    no less than MU_FLOOR.  Returns {mu_s, mu_2, x_0, b, rms_log_residual, points, floored: the
    share of cells where the prediction is at the floor}; InputError with too few cells."""
    I, mu, tp = (np.asarray(a, float) for a in (I, mu, tan_psi))
    ok = np.isfinite(I) & (I > 0) & np.isfinite(mu) & (mu > 0) & np.isfinite(tp)
    n_par = 3 if b is not None else 4
    if ok.sum() <= n_par:
        raise InputError(f"dilatancy fit: {int(ok.sum())} usable cells, needs more than {n_par}")
    I, y, tp = I[ok], np.log(mu[ok]), tp[ok]

    def predicted(q):
        bb = q[3] if b is None else b
        return np.maximum(mu_of_I(I, q[0], q[0] + q[1], math.exp(q[2])) + bb * tp, MU_FLOOR)

    def residual(q):
        return np.log(predicted(q)) - y

    m = float(np.median(mu[ok]))
    starts = [[0.5 * m, m, lx] + ([bs] if b is None else [])
              for lx in np.log(np.geomspace(I.min(), I.max(), 5))
              for bs in ((0.0, 1.0) if b is None else (None,))]
    lo = [1e-6, 0.0, math.log(I.min()) - 10.0] + ([-10.0] if b is None else [])
    hi = [10.0, 10.0, math.log(I.max()) + 10.0] + ([10.0] if b is None else [])
    r = _log_fit(residual, starts, lo, hi)
    q = r.x
    return {"mu_s": float(q[0]), "mu_2": float(q[0] + q[1]), "x_0": float(math.exp(q[2])),
            "b": float(q[3]) if b is None else float(b),
            "rms_log_residual": float(np.sqrt(np.mean(r.fun ** 2))), "points": int(I.size),
            "floored": float(np.mean(predicted(q) <= MU_FLOOR))}


def fit_fluidity(x, phi, mu, a=None) -> dict:
    """(e): the best ln mu = a ln x - ln F(phi), ln F = c0 + c1 phi + c2 phi^2, x the fluidity
    number gamma_dot d / sqrt(T): a fixed (1: Zhang & Kamrin) or fitted when None, by linear
    least squares in ln mu.  Returns {a, c (c0, c1, c2), rms_log_residual, points}."""
    x, phi, mu = (np.asarray(v, float) for v in (x, phi, mu))
    ok = np.isfinite(x) & (x > 0) & np.isfinite(phi) & np.isfinite(mu) & (mu > 0)
    n_par = 3 if a is not None else 4
    if ok.sum() <= n_par:
        raise InputError(f"fluidity fit: {int(ok.sum())} usable cells, needs more than {n_par}")
    lx, f, y = np.log(x[ok]), phi[ok], np.log(mu[ok])
    cols = [-np.ones_like(f), -f, -f * f]
    if a is None:
        A = np.column_stack([lx] + cols)
        q = np.linalg.lstsq(A, y, rcond=None)[0]
        aa, c = float(q[0]), q[1:]
        res = A @ q - y
    else:
        A = np.column_stack(cols)
        c = np.linalg.lstsq(A, y - a * lx, rcond=None)[0]
        aa = float(a)
        res = A @ c + a * lx - y
    return {"a": aa, "c": [float(v) for v in c],
            "rms_log_residual": float(np.sqrt(np.mean(res ** 2))), "points": int(f.size)}


def binned_medians(x, mu, mu_stderr, edges) -> list[dict]:
    """Per bin of x (edges): the cells' count, median x and mu, mu's quartiles, and the median's
    batch-means standard error: the cells' errors combined as independent, MEDIAN_ERROR times
    sqrt(sum se^2) / n (NaN where a cell has none)."""
    x, mu, se = (np.asarray(a, float) for a in (x, mu, mu_stderr))
    rows = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        s = np.isfinite(x) & (x >= lo) & (x < hi)
        n = int(s.sum())
        if n == 0:
            continue
        q1, med, q3 = np.percentile(mu[s], [25, 50, 75])
        rows.append({"lo": float(lo), "hi": float(hi), "n": n, "x": float(np.median(x[s])),
                     "mu": float(med), "mu_q1": float(q1), "mu_q3": float(q3),
                     "mu_stderr": float(MEDIAN_ERROR * np.sqrt(np.sum(se[s] ** 2)) / n)})
    return rows


def collapse_table(points: dict, calibrated=None) -> dict:
    """Each abscissa's collapse: {"baseline": rms log of mu about its median, "noise": the
    cells' batch-means error as an rms log (module docstring), name: fit_collapse
    (+ "calibrated_rms_log_residual" of the calibrated mu(x) {mu_s, mu_2, I_0} where given)}
    for name in I, rI, rI_median_T, rI_dem (where measured), Theta (Kim & Kamrin's
    mu = Theta^a F(I)), dilatancy and dilatancy_b (fit_dilatancy, b = 1 and fitted; where the
    velocity gradient is measured), fluidity and fluidity_a (fit_fluidity, a = 1 and fitted)."""
    mu = points["mu"]
    out = {"baseline": float(np.sqrt(np.mean(np.log(mu / np.median(mu)) ** 2))),
           "points": int(mu.size),
           "noise": float(np.sqrt(np.nanmean((points["mu_stderr"] / mu) ** 2)))}
    for name in ("I", "rI", "rI_median_T", "rI_dem"):
        x = points[name]
        if not np.isfinite(x).any():
            continue
        fit = fit_collapse(x, mu)
        if calibrated is not None:
            ok = np.isfinite(x) & (x > 0)
            c = mu_of_I(x[ok], calibrated["mu_s"], calibrated["mu_2"], calibrated["I_0"])
            fit["calibrated_rms_log_residual"] = float(np.sqrt(np.mean(np.log(mu[ok] / c) ** 2)))
        out[name] = fit
    out["Theta"] = fit_collapse(points["I"], mu, points["Theta"])
    if np.isfinite(points["tan_psi"]).any():
        out["dilatancy"] = fit_dilatancy(points["I"], mu, points["tan_psi"], b=1.0)
        out["dilatancy_b"] = fit_dilatancy(points["I"], mu, points["tan_psi"])
    out["fluidity"] = fit_fluidity(points["fluidity_number"], points["phi"], mu, a=1.0)
    out["fluidity_a"] = fit_fluidity(points["fluidity_number"], points["phi"], mu)
    return out
