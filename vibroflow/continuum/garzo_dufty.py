"""Garzo & Dufty's heat flux of a dense gas of smooth inelastic hard spheres, compiled.

For inelastic grains the Chapman-Enskog heat flux has, beside Fourier's term, one driven by the
density gradient (Brey, Dufty, Kim & Santos 1998, Phys. Rev. E 58, 4638, dilute; Garzo & Dufty
1999, "Dense fluid transport for inelastic hard spheres", Phys. Rev. E 59, 5895, dense):

    q = -kappa grad T - mu grad n = -kappa grad T - mu_phi grad phi,   mu_phi = mu n / phi,

with T (m^2/s^2) the granular temperature, n the number density and phi the solid fraction.
In the first Sonine approximation of Garzo & Dufty (1999), with chi = g0 of the
continuum's form and chi' = d g0 / d phi:

    c*    = 32 (1 - e)(1 - 2 e^2) / (81 - 17 e + 30 e^2 (1 - e))
    zeta* = (5/12) chi (1 - e^2)(1 + 3 c* / 32)                          cooling rate
    nu_k* = (chi / 3)(1 + e)(1 + (33/16)(1 - e) + (19 - 3 e) c* / 1024)
    p*    = 1 + 2 (1 + e) phi chi
    kappa_k* = (2/3)(1 + (1 + p*) c* / 2 + (3/5) phi chi (1 + e)^2 (2 e - 1
               + ((1 + e) / 2 - 5 / (3 (1 + e))) c*)) / (nu_k* - 2 zeta*)
    kappa* = kappa_k* (1 + (6/5) phi chi (1 + e)) + (256 / (25 pi)) phi^2 chi (1 + e)(1 + 7 c* / 32)
    mu_k* = 2 (zeta* kappa_k* (1 + phi chi' / chi) + (p* / 3)(1 + phi p*' / p*) c*
               - (4/5) phi chi (1 + phi chi' / (2 chi))(1 + e)(e (1 - e)
               + (4/3 + e (1 - e)) c* / 4)) / (2 nu_k* - 3 zeta*)
    mu*   = mu_k* (1 + (6/5) phi chi (1 + e))

    kappa = kappa_0 kappa*,   mu_phi = T kappa_0 mu* / phi,
    kappa_0 = (75 / 64) m sqrt(T / pi) / d^2 = 75 sqrt(pi) rho_s d sqrt(T) / 384,

kappa_0 the elastic dilute gas's (Chapman & Cowling), in the units of q = -kappa grad T with q
in W/m^2 and the fluctuation energy (3/2) rho_s phi T per volume.  At e = 1, mu* = 0 and
kappa* is Enskog's conductivity of elastic hard spheres; in the dilute limit they are Brey et
al.'s.  g0 is clamped below phi_rcp as in kinetic_theory.radial_distribution, and so is its
derivative, read at the clamped solid fraction.  MFiX's GD_99 kinetic theory evaluates the same
coefficients, except that it writes phi chi' where the density derivatives of the collision
frequency n chi give phi d ln(chi) / d phi (here).
"""
from __future__ import annotations

import math

import numba as nb

from .kinetic_theory import LUN_SAVAGE, PHI_GAP, radial_distribution


@nb.njit(cache=True)
def radial_distribution_slope(phi, prm):
    """d g0 / d phi (-) of the form prm.g0_form at phi clamped to [0, phi_rcp - PHI_GAP]."""
    phi_c = prm.phi_rcp
    f = min(max(phi, 0.0), phi_c - PHI_GAP)
    if prm.g0_form == LUN_SAVAGE:
        return 2.5 * (1.0 - f / phi_c) ** (-2.5 * phi_c - 1.0)
    # Carnahan-Starling (2 - phi) / (2 (1 - phi)^3) plus 1.1596 phi^2 / (phi_rcp - phi)^1.5
    return ((5.0 - 2.0 * f) / (2.0 * (1.0 - f) ** 4)
            + 1.1596 * (2.0 * f / (phi_c - f) ** 1.5 + 1.5 * f * f / (phi_c - f) ** 2.5))


@nb.njit(cache=True)
def _sonine(e):
    """c* (-), the fourth cumulant of the homogeneous cooling state's distribution."""
    return 32.0 * (1.0 - e) * (1.0 - 2.0 * e * e) / (81.0 - 17.0 * e + 30.0 * e * e * (1.0 - e))


@nb.njit(cache=True)
def heat_flux_factors(phi, prm):
    """(kappa*, mu*) (-) of Garzo & Dufty (1999) at solid fraction phi (module notes):
    kappa = kappa* kappa_0 and mu_phi = mu* kappa_0 T / phi."""
    e = prm.restitution
    f = max(phi, 0.0)
    chi = radial_distribution(f, prm)
    dchi = radial_distribution_slope(f, prm)
    c = _sonine(e)
    zeta = 5.0 / 12.0 * chi * (1.0 - e * e) * (1.0 + 3.0 / 32.0 * c)
    nu_k = chi / 3.0 * (1.0 + e) * (1.0 + 33.0 / 16.0 * (1.0 - e) + (19.0 - 3.0 * e) / 1024.0 * c)
    p = 1.0 + 2.0 * (1.0 + e) * f * chi
    kappa_k = (2.0 / 3.0 * (1.0 + 0.5 * (1.0 + p) * c + 0.6 * f * chi * (1.0 + e) ** 2
                            * (2.0 * e - 1.0 + (0.5 * (1.0 + e) - 5.0 / (3.0 * (1.0 + e))) * c))
               / (nu_k - 2.0 * zeta))
    enskog = 1.0 + 1.2 * f * chi * (1.0 + e)
    kappa = (kappa_k * enskog
             + 256.0 / (25.0 * math.pi) * f * f * chi * (1.0 + e) * (1.0 + 7.0 / 32.0 * c))
    mu_k = (2.0 * ((1.0 + f * dchi / chi) * zeta * kappa_k
                   + (p / 3.0 + 2.0 / 3.0 * f * (1.0 + e) * (chi + f * dchi)) * c
                   - 0.8 * f * chi * (1.0 + 0.5 * f * dchi / chi) * (1.0 + e)
                   * (e * (1.0 - e) + 0.25 * (4.0 / 3.0 + e * (1.0 - e)) * c))
            / (2.0 * nu_k - 3.0 * zeta))
    return kappa, mu_k * enskog


@nb.njit(cache=True)
def dilute_conductivity_kg_m_s(T, prm):
    """kappa_0 (kg/(m s)) = 75 sqrt(pi) rho_s d sqrt(T) / 384, the elastic dilute gas's."""
    return 75.0 * math.sqrt(math.pi) * prm.density_kg_m3 * prm.diameter_m * math.sqrt(
        max(T, 0.0)) / 384.0


@nb.njit(cache=True)
def gd_conductivity_kg_m_s(phi, T, prm):
    """Garzo & Dufty's kappa (kg/(m s)) of q = -kappa grad T - mu_phi grad phi."""
    return heat_flux_factors(phi, prm)[0] * dilute_conductivity_kg_m_s(T, prm)


@nb.njit(cache=True)
def gd_density_coefficient_W_m(phi, T, prm):
    """Garzo & Dufty's mu_phi (W/m) = mu n / phi of the density-gradient term -mu_phi grad phi;
    0 where phi <= 0."""
    if phi <= 0.0:
        return 0.0
    return heat_flux_factors(phi, prm)[1] * dilute_conductivity_kg_m_s(T, prm) * max(T, 0.0) / phi
