"""Kinetic theory's closures of the granular temperature balance, compiled.

The fluctuation energy of a granular continuum, per unit volume (3/2) rho_s phi T, obeys

    (3/2) rho_s phi dT/dt = sigma : D - div q - Gamma,   q = -kappa grad T,

with T (m^2/s^2) the granular temperature (one third of the mean squared velocity
fluctuation), phi the solid fraction, rho_s (kg/m^3) the grains' density and d (m) their
diameter.  The closures here are those of smooth inelastic spheres of normal restitution e, as
the two-fluid codes (MFiX, OpenFOAM's kineticTheoryModels, sedFoam) use them:

* radial distribution at contact g0(phi): Chialvo & Sundaresan (2013, Phys. Fluids 25,
  070603), the Carnahan-Starling value plus a term that diverges at random close packing,
      g0 = (2 - phi) / (2 (1 - phi)^3) + 1.1596 phi^2 / (phi_rcp - phi)^(3/2);
  or (option) Lun & Savage (1986, Acta Mech. 63, 15), g0 = (1 - phi / phi_rcp)^(-5 phi_rcp / 2);
* pressure (Lun, Savage, Jeffrey & Chepurniy 1984, J. Fluid Mech. 140, 223):
      p = rho_s phi T (1 + 2 (1 + e) phi g0);
* shear viscosity (Gidaspow 1994, "Multiphase Flow and Fluidization", Academic Press, ch. 9):
      eta = (4/5) phi^2 rho_s d g0 (1 + e) sqrt(T / pi)
            + 10 sqrt(pi) rho_s d sqrt(T) / (96 (1 + e) g0) (1 + (4/5) phi g0 (1 + e))^2;
* bulk viscosity (Lun et al. 1984): lambda = (4/3) phi^2 rho_s d g0 (1 + e) sqrt(T / pi);
* conductivity (Gidaspow 1994):
      kappa = 150 sqrt(pi) rho_s d sqrt(T) / (384 (1 + e) g0) (1 + (6/5) phi g0 (1 + e))^2
              + 2 phi^2 rho_s d g0 (1 + e) sqrt(T / pi);
* collisional dissipation (Lun et al. 1984; Gidaspow 1994):
      Gamma = 12 (1 - e^2) phi^2 rho_s g0 T^(3/2) / (d sqrt(pi)),
  divided, as an option, by Jenkins' (2006, Phys. Fluids 18, 103307; 2007, Granular Matter 10,
  47) correlation length in diameters L/d = max(1, c_L d gamma_dot / sqrt(T)): in dense shear
  the grains' velocities are correlated over L > d and collisions dissipate less.  Jenkins'
  dependence of L on e and on the viscosity's collisional factor is folded into c_L, which the
  DEM shear cell measures; c_L = 0 is the plain theory;
* dense (sliding) dissipation, an option: the enduring contacts of a pressed packing slip at
  about sqrt(T) under forces of about p d^2, so they lose
      Gamma_f = k_f p sqrt(T) / d,
  p (Pa) the material's compressive mean stress; k_f (-) from the DEM shear cell, where it
  closes steady shear's balance tau gamma_dot = Gamma + Gamma_f at one constant from I = 0.03 to
  0.3 (calibration.shear_temperature.dense_dissipation_coefficient; docs/validation.md
  section 29); k_f = 0 (off) by default;
* frictional pressure of enduring contacts below packing (Johnson & Jackson 1987, J. Fluid
  Mech. 176, 67):
      p_f = Fr (phi - phi_min)^n / (phi_rcp - phi)^p   for phi > phi_min, else 0,
  Fr (Pa) = 0 (off) by default; Fr and phi_min fitted with phi_rcp to the DEM's coarse-grained
  cells (vibroflow.calibration.kinetic), n = 2 and p = 5 Johnson & Jackson's exponents.

Divided by the heat capacity per volume (3/2) rho_s phi, the dissipation is
dT/dt = -a T^(3/2) with a = 8 (1 - e^2) phi g0 / (d sqrt(pi)) (`cooling_coefficient`), whose
homogeneous solution is Haff's law T = T0 / (1 + t / tau)^2, tau = 2 / (a sqrt(T0)).

SI units throughout: T in m^2/s^2, p in Pa, eta and lambda in Pa s, kappa in kg/(m s) (so that
kappa grad T is W/m^2), Gamma in W/m^3.  A solid fraction at or above phi_rcp is clamped just
below it (`PHI_GAP`), where g0 is large and finite: the dense core's stiffness, not a blow-up.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb

#: g0 forms (KineticParameters.g0_form)
CHIALVO_SUNDARESAN = 0
LUN_SAVAGE = 1
#: the g0 forms by name, as calibration.toml's [kinetic] g0_form spells them
G0_FORMS = {"chialvo_sundaresan": CHIALVO_SUNDARESAN, "lun_savage": LUN_SAVAGE}

#: the closest a solid fraction comes to phi_rcp (-): g0 stays finite
PHI_GAP = 1e-6

_SQRT_PI = math.sqrt(math.pi)


class KineticParameters(NamedTuple):
    """The grains and the closures' choices (SI).

    diameter_m, density_kg_m3: the grains (tub47: 6.35 mm steel, 7800 kg/m^3);
    restitution: normal restitution e between grains (-), 0 < e <= 1 (1: no dissipation);
    phi_rcp: the solid fraction where g0 diverges (-), random close packing of the grains;
    g0_form: CHIALVO_SUNDARESAN (default) or LUN_SAVAGE;
    correlation_coefficient: Jenkins' c_L (-), 0 = off (default);
    frictional_Pa, frictional_phi_min, frictional_n, frictional_p: Johnson & Jackson's Fr (Pa,
    0 = no frictional pressure, default), phi_min (-) and exponents n, p (-);
    sliding_coefficient: k_f (-) of the dense sliding loss k_f p sqrt(T) / d, 0 = off (default).
    """

    diameter_m: float = 0.00635
    density_kg_m3: float = 7800.0
    restitution: float = 0.9
    phi_rcp: float = 0.64
    g0_form: int = CHIALVO_SUNDARESAN
    correlation_coefficient: float = 0.0
    frictional_Pa: float = 0.0
    frictional_phi_min: float = 0.5
    frictional_n: float = 2.0
    frictional_p: float = 5.0
    sliding_coefficient: float = 0.0


@nb.njit(cache=True)
def carnahan_starling(phi):
    """Carnahan & Starling's (1969) g0 of elastic hard spheres, (2 - phi) / (2 (1 - phi)^3) (-)."""
    return (2.0 - phi) / (2.0 * (1.0 - phi) ** 3)


@nb.njit(cache=True)
def radial_distribution(phi, prm):
    """g0(phi) (-) of the form prm.g0_form, phi clamped to [0, phi_rcp - PHI_GAP]."""
    phi_c = prm.phi_rcp
    f = min(max(phi, 0.0), phi_c - PHI_GAP)
    if prm.g0_form == LUN_SAVAGE:
        return (1.0 - f / phi_c) ** (-2.5 * phi_c)
    return carnahan_starling(f) + 1.1596 * f * f / (phi_c - f) ** 1.5


@nb.njit(cache=True)
def pressure_Pa(phi, T, prm):
    """Kinetic-collisional pressure (Pa), Lun et al. (1984): rho_s phi T (1 + 2 (1 + e) phi g0)."""
    e = prm.restitution
    return prm.density_kg_m3 * phi * T * (1.0 + 2.0 * (1.0 + e) * phi
                                          * radial_distribution(phi, prm))


@nb.njit(cache=True)
def frictional_pressure_Pa(phi, prm):
    """Johnson & Jackson's (1987) frictional pressure (Pa), Fr (phi - phi_min)^n /
    (phi_rcp - phi)^p above phi_min (phi clamped below phi_rcp as in g0), else 0."""
    if prm.frictional_Pa <= 0.0 or phi <= prm.frictional_phi_min:
        return 0.0
    f = min(phi, prm.phi_rcp - PHI_GAP)
    return (prm.frictional_Pa * (f - prm.frictional_phi_min) ** prm.frictional_n
            / (prm.phi_rcp - f) ** prm.frictional_p)


@nb.njit(cache=True)
def shear_viscosity_Pa_s(phi, T, prm):
    """Shear viscosity eta (Pa s), Gidaspow (1994): collisional plus kinetic part."""
    e = prm.restitution
    g0 = radial_distribution(phi, prm)
    rd = prm.density_kg_m3 * prm.diameter_m * math.sqrt(max(T, 0.0))
    collisional = 0.8 * phi * phi * rd * g0 * (1.0 + e) / _SQRT_PI
    kinetic = 10.0 * _SQRT_PI * rd / (96.0 * (1.0 + e) * g0) * (1.0 + 0.8 * phi * g0 * (1.0 + e)) ** 2
    return collisional + kinetic


@nb.njit(cache=True)
def conductivity_kg_m_s(phi, T, prm):
    """Conductivity kappa (kg/(m s)) of the fluctuation energy, Gidaspow (1994)."""
    e = prm.restitution
    g0 = radial_distribution(phi, prm)
    rd = prm.density_kg_m3 * prm.diameter_m * math.sqrt(max(T, 0.0))
    kinetic = 150.0 * _SQRT_PI * rd / (384.0 * (1.0 + e) * g0) * (1.0 + 1.2 * phi * g0 * (1.0 + e)) ** 2
    collisional = 2.0 * phi * phi * rd * g0 * (1.0 + e) / _SQRT_PI
    return kinetic + collisional


@nb.njit(cache=True)
def correlation_length_ratio(T, shear_rate, prm):
    """Jenkins' L/d = max(1, c_L d gamma_dot / sqrt(T)) (-); 1 when c_L = 0 or T = 0.
    shear_rate = gamma_dot (1/s)."""
    c = prm.correlation_coefficient
    if c <= 0.0 or T <= 0.0:
        return 1.0
    return max(1.0, c * prm.diameter_m * abs(shear_rate) / math.sqrt(T))


@nb.njit(cache=True)
def cooling_coefficient(phi, T, shear_rate, prm):
    """a (1/(s sqrt(m^2/s^2))) of dT/dt = -a T^(3/2): Gamma / ((3/2) rho_s phi T^(3/2)) =
    8 (1 - e^2) phi g0 / (d sqrt(pi) L/d).  T and shear_rate (1/s) enter only through Jenkins'
    L/d."""
    e = prm.restitution
    g0 = radial_distribution(phi, prm)
    a = 8.0 * (1.0 - e * e) * max(phi, 0.0) * g0 / (prm.diameter_m * _SQRT_PI)
    return a / correlation_length_ratio(T, shear_rate, prm)


@nb.njit(cache=True)
def dissipation_W_m3(phi, T, shear_rate, prm):
    """Collisional dissipation Gamma (W/m^3): 12 (1 - e^2) phi^2 rho_s g0 T^(3/2) / (d sqrt(pi))
    over Jenkins' L/d."""
    Tp = max(T, 0.0)
    return (1.5 * prm.density_kg_m3 * phi * cooling_coefficient(phi, Tp, shear_rate, prm)
            * Tp * math.sqrt(Tp))


@nb.njit(cache=True)
def sliding_dissipation_W_m3(pressure, T, prm):
    """The dense sliding loss Gamma_f = k_f p sqrt(T) / d (W/m^3) at the compressive mean stress
    pressure (Pa; tension counts 0) and T (m^2/s^2)."""
    return (prm.sliding_coefficient * max(pressure, 0.0) * math.sqrt(max(T, 0.0))
            / prm.diameter_m)


@nb.njit(cache=True)
def sliding_rate(phi, pressure, prm):
    """b (m/s^2) of dT/dt = -b sqrt(T): Gamma_f / ((3/2) rho_s phi sqrt(T)); 0 without
    material or without the option."""
    if phi <= 0.0 or prm.sliding_coefficient <= 0.0:
        return 0.0
    return (prm.sliding_coefficient * max(pressure, 0.0)
            / (prm.diameter_m * 1.5 * prm.density_kg_m3 * phi))
