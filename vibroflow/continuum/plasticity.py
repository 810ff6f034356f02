"""The points' volume, density and stress update (the constitutive step of the MPM).

Per point, after g2p: the deformation over the step F_inc = I + dt L (plane strain: no change
along y) updates the volume V_p <- det(F_inc) V_p (m^2 per metre of thickness), the density
rho_p = m_p / V_p (kg/m^3), and the stress through the shared constitutive law
(vibroflow.continuum.constitutive: elastic predictor, then the mu(I) or Drucker-Prager return
map and the disconnected state below rho_c; Dunatunga & Kamrin 2015).
"""
from __future__ import annotations

import numba as nb

from .constitutive import P_RHO_C
from .stress_update import update_stress_points_rated


#: the lowest density of a point, as a fraction of the critical density rho_c (see update_volume)
DILUTE_DENSITY_FLOOR = 0.25


@nb.njit(cache=True)
def update_volume(L, mass, volume, density, dt, rho_min):
    """V_p *= det(I + dt L_p) and rho_p = m_p / V_p for every point (in place), with V_p at most
    m_p / rho_min.  L (N, 4) [xx, xz, zx, zz] 1/s, or (N, 5) with the hoop rate v_r / r last
    (axisymmetric: volumes and masses per radian, m^3 and kg); mass kg/m; volume m^2; density
    kg/m^3; rho_min (kg/m^3; 0: no bound).

    Why the bound: a point flying alone keeps the affine velocity field APIC gives it (C is
    carried unchanged by a point with no neighbours), so its volume grows exponentially,
    det F = exp(t tr C), instead of linearly as a cloud in free flight would.  A tub47 point at
    amplitude factor 1.5 reached 5 000 times its volume (0.9 kg/m^3) and a side of 0.27 m,
    with which the penalty wall, whose reach is half the point's side (boundary.py), caught
    it from 0.1 m away and threw it out of the grid.  The bound, rho_min = DILUTE_DENSITY_FLOOR
    rho_c (solid fraction about 0.15, a granular gas) is far below any density of the flowing
    bed (tub47-quick: every point above 0.5 rho_c at all times), so the bed's numbers do not
    change; the point stays stress-free, since it is far below rho_c."""
    hoop = L.shape[1] > 4
    for p in range(volume.shape[0]):
        fxx = 1.0 + dt * L[p, 0]
        fxz = dt * L[p, 1]
        fzx = dt * L[p, 2]
        fzz = 1.0 + dt * L[p, 3]
        volume[p] *= fxx * fzz - fxz * fzx
        if hoop:
            # axisymmetric: the hoop stretch 1 + dt v_r / r (F_yy of the section)
            volume[p] *= 1.0 + dt * L[p, 4]
        if rho_min > 0.0 and mass[p] < rho_min * volume[p]:
            volume[p] = mass[p] / rho_min
        density[p] = mass[p] / volume[p]


@nb.njit(cache=True)
def plasticity_step(L, mass, volume, density, stress, dt, params, gamma_dot, phase,
                    rate_ratio):
    """Volume, density and stress of every point after a step dt (s); see the module docstring.
    params = ContinuumMaterial.as_array(); gamma_dot (1/s) and phase (0 disconnected, 1 elastic,
    2 flowing) are written per point; rate_ratio (N,) the return map's ratio of the inertial
    number read from the granular temperature (kinetic_stress.py), (0,) without it."""
    update_volume(L, mass, volume, density, dt, DILUTE_DENSITY_FLOOR * params[P_RHO_C])
    update_stress_points_rated(stress, L, density, dt, params, gamma_dot, phase, rate_ratio)
