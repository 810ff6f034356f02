"""The points' volume, density and stress update (the constitutive step of the MPM).

Per point, after g2p: the deformation over the step F_inc = I + dt L (plane strain: no change
along y) updates the volume V_p <- det(F_inc) V_p (m^2 per metre of thickness), the density
rho_p = m_p / V_p (kg/m^3), and the stress through the shared constitutive law
(vibroflow.continuum.constitutive: elastic predictor, then the mu(I) or Drucker-Prager return
map and the disconnected state below rho_c; Dunatunga & Kamrin 2015).
"""
from __future__ import annotations

import numba as nb

from .constitutive import update_stress_points


@nb.njit(cache=True)
def update_volume(L, mass, volume, density, dt):
    """V_p *= det(I + dt L_p) and rho_p = m_p / V_p for every point (in place).  L (N, 4)
    [xx, xz, zx, zz] 1/s; mass kg/m; volume m^2; density kg/m^3."""
    for p in range(volume.shape[0]):
        fxx = 1.0 + dt * L[p, 0]
        fxz = dt * L[p, 1]
        fzx = dt * L[p, 2]
        fzz = 1.0 + dt * L[p, 3]
        volume[p] *= fxx * fzz - fxz * fzx
        density[p] = mass[p] / volume[p]


def plasticity_step(L, mass, volume, density, stress, dt, params, gamma_dot, phase):
    """Volume, density and stress of every point after a step dt (s); see the module docstring.
    params = ContinuumMaterial.as_array(); gamma_dot (1/s) and phase (0 disconnected, 1 elastic,
    2 flowing) are written per point."""
    update_volume(L, mass, volume, density, dt)
    update_stress_points(stress, L, density, dt, params, gamma_dot, phase)
