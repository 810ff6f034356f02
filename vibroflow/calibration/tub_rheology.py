"""The mu(I) relation read directly from the tub's coarse-grained fields: a scatter of the stress
ratio mu = tau_eq / p against the inertial number I = gamma_dot d / sqrt(p / rho_s) over the
cells of the cross-section, beside the shear-cell fit.

Points are the phase-resolved cell values (each cell at each sampled phase of the cycle), since
the bed's state changes over the cycle (it flies, lands and is sheared); the time-averaged cells
are given too.  A point is marked dilute when its solid fraction is below `dense_solid_fraction`
(default 0.5: below it the balls are no longer in enduring contact and mu(I), a dense-flow law,
is not expected to hold; GDR MiDi 2004).
"""
from __future__ import annotations

import numpy as np

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
        I = np.asarray(ds["inertial_number"].values, float).ravel()
        mu = np.asarray(ds["friction_coefficient"].values, float).ravel()
        phi = np.asarray(ds["solid_fraction"].values, float).ravel()
        p = np.asarray(ds["pressure"].values, float).ravel()
        ok = np.isfinite(I) & np.isfinite(mu) & (I > 0) & (p > 0) & (phi >= min_solid_fraction)
        out[name] = {"I": I[ok], "mu": mu[ok], "phi": phi[ok], "pressure": p[ok],
                     "dense": phi[ok] >= dense_solid_fraction}
    return out


def bed_pressure(time_averaged, dense_solid_fraction: float = DENSE_SOLID_FRACTION) -> float:
    """Representative pressure of the bed (Pa): the median time-averaged pressure over the dense
    cells (the shear cell and the elastic tests are run at it)."""
    p = np.asarray(time_averaged["pressure"].values, float)
    phi = np.asarray(time_averaged["solid_fraction"].values, float)
    sel = np.isfinite(p) & (p > 0) & (phi >= dense_solid_fraction)
    if not sel.any():
        sel = np.isfinite(p) & (p > 0)
    return float(np.median(p[sel])) if sel.any() else float("nan")
