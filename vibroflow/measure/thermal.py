"""The thermal agitation of grains: each grain's velocity about its own snapshot's local mean
velocity, not about a mean over cycles.

Why: a phase-resolved temperature (the departure from the phase's mean over the cycles) counts
the cycle-to-cycle scatter of the bed's collective motion as temperature; in a vibrated bed that
scatter is as large as the agitation itself (validation.md section 26).  A continuum's granular
temperature models the agitation about the local mean flow, so its like-for-like target is the
fluctuation c_i = v_i - V_s(r_i), V_s the snapshot's own velocity field smoothed over a few
grains.

Here V_s is the mass-weighted Gaussian mean in the x-z plane (the tub's plane of motion; the
grains' y is integrated over, as the coarse-graining does):

    V_s(r_i) = sum_j m_j v_j W(r_i - r_j) / sum_j m_j W(r_i - r_j),
    W(s) = exp(-|s|^2 / (2 w^2)) for |s| < 3 w, else 0,

w the kernel width (default two diameters: several grains, so V_s is a local mean, not the
grain itself; Goldhirsch 2010, Granular Matter 12, 239, on the scale separation).  A uniform
flow, a rigid translation and, away from the body's edges, a rigid rotation (a linear field,
which a symmetric kernel reproduces exactly) give c = 0; Maxwellian noise of temperature T
about them gives <|c|^2> / 3 = T (1 - 2 w_ii + sum_j w_ij^2), w_ij the normalised weights; for
n grains per x-z area, N_eff = (sum W)^2 / sum W^2 = 4 pi w^2 n, w_ii = 2 / N_eff and
sum w_ij^2 = 1 / N_eff, so T (1 - 3 / N_eff).

The tub's calibration takes the same local mean from its coarse-graining grid instead
(calibration.thermal_flux.thermal_velocities: the grid's field, bilinear at each ball), because
its fields are on that grid anyway; the vibrated layer's strip has no such grid, and this exact
sum at each grain is cheap for its balls, so both stay (the measure layer cannot use the
calibration's grid).
"""
from __future__ import annotations

import numpy as np

from vibroflow.errors import InputError

#: the Gaussian's cutoff in widths (its weight there is exp(-4.5) = 1.1 % of the centre's)
CUTOFF_WIDTHS = 3.0
#: grains per block of the pairwise sums (a block's work arrays stay under ~50 MB)
_BLOCK = 2048


def local_mean_velocity(positions, velocities, mass, width_m: float) -> np.ndarray:
    """V_s at each grain (N, 3) m/s: the Gaussian mean (module docstring) of the velocities
    (N, 3) m/s with masses (N,) kg over the x-z plane of positions (N, 3) m, width width_m."""
    if not (width_m > 0):
        raise InputError(f"width_m = {width_m!r}: must be > 0 (m)")
    pos = np.asarray(positions, float)
    vel = np.asarray(velocities, float)
    m = np.broadcast_to(np.asarray(mass, float), (pos.shape[0],))
    x, z = pos[:, 0], pos[:, 2]
    rc2 = (CUTOFF_WIDTHS * width_m) ** 2
    out = np.empty_like(vel)
    for a in range(0, x.size, _BLOCK):
        b = min(a + _BLOCK, x.size)
        r2 = (x[a:b, None] - x[None, :]) ** 2 + (z[a:b, None] - z[None, :]) ** 2
        w = np.where(r2 < rc2, np.exp(-0.5 * r2 / width_m**2), 0.0) * m[None, :]
        out[a:b] = (w @ vel) / w.sum(axis=1)[:, None]
    return out


def thermal_velocities(positions, velocities, mass, width_m: float) -> np.ndarray:
    """c_i = v_i - V_s(r_i) (N, 3) m/s (module docstring)."""
    return np.asarray(velocities, float) - local_mean_velocity(positions, velocities, mass,
                                                               width_m)
