"""The granular temperature of steady simple shear: what the DEM shear cell measures
(vibroflow.calibration.shear_cell) beside what the continuum's kinetic-theory closure
(vibroflow.continuum.kinetic_theory) balances.

Measured: the shear cell records T = <m |v - u(z)|^2> / (3 <m>), the balls' translational
fluctuation about the imposed profile u_x = gamma_dot (z - L_z/2) (m^2/s^2), averaged over
every step of the steady window, and the slope of the balls' own mean profile
(`profile_shear_rate`), which tells whether the flow follows the imposed shear rate.

Closure: in steady homogeneous shear conduction vanishes and the balance (3/2) rho_s phi dT/dt
= sigma : D - Gamma reduces to eta(phi, T) gamma_dot^2 = Gamma(phi, T, gamma_dot), with
Gidaspow's viscosity and Lun et al.'s dissipation over Jenkins' correlation length L/d =
max(1, c_L d gamma_dot / sqrt(T)).  Both sides scale with T (eta ~ sqrt(T), Gamma ~ T^(3/2) / L),
so the root is unique; `closure_temperature` finds it by bisection in ln T.

The dense dissipation (`dense_dissipation_coefficient`): the shear cell's balls spend their
shear work tau gamma_dot mostly in sliding contacts, which Lun's Gamma omits.  A contact pressed
with a force ~ p d^2 slipping at ~ sqrt(T) loses ~ mu p d^2 sqrt(T), so per volume the sliding
loss is Gamma_f = k_f p sqrt(T) / d; in steady shear tau gamma_dot = Gamma + Gamma_f gives
k_f = (tau gamma_dot - Gamma(phi, T)) d / (p sqrt(T)) from one measured point.

Jenkins' c_L from the shear cell (`fit_correlation_coefficient`): the c_L at which the closure's
T equals the measured T of one point, c_L = (L/d) sqrt(T) / (d gamma_dot) with L/d =
Gamma_plain(T) / (eta(T) gamma_dot^2); zero when the plain closure's T is already below the
measured one (L/d > 1 can only raise T).  It is a constant from the DEM, never from the tub.
"""
from __future__ import annotations

import math

import numpy as np

from vibroflow.continuum.kinetic_theory import (KineticParameters, dissipation_W_m3,
                                                shear_viscosity_Pa_s)


def profile_shear_rate(box) -> float:
    """The slope d<v_x>/dz (1/s) of the balls' mean velocity profile now: the mass-weighted least
    squares line of v_x against z over the balls of a PeriodicBox (positions and velocities
    wrapped into the box, where they are consistent with the Lees-Edwards images)."""
    m, z, vx = box.mass, box.pos[:, 2], box.vel[:, 0]
    zc = z - np.average(z, weights=m)
    return float((m * zc * vx).sum() / (m * zc * zc).sum())


def shear_rate_record(slopes, batches: int) -> dict:
    """shear_rate_measured (1/s): the mean slope of the instantaneous profiles over the steady
    window, with its batch-means standard error (fewer batches if there are fewer profiles)."""
    x = np.asarray(slopes, float)
    if len(x) < 2:
        return {"shear_rate_measured": float(x.mean()) if len(x) else math.nan,
                "shear_rate_measured_stderr": math.nan}
    nb = min(int(batches), len(x))
    k = len(x) // nb
    b = x[: k * nb].reshape(nb, k).mean(axis=1)
    return {"shear_rate_measured": float(x.mean()),
            "shear_rate_measured_stderr": float(b.std(ddof=1) / math.sqrt(nb))}


def kinetic_parameters(diameter: float, density: float, restitution: float,
                       phi_rcp: float = 0.64, correlation_coefficient: float = 0.0
                       ) -> KineticParameters:
    """The closure's parameters for balls of `diameter` (m) and `density` (kg/m^3) whose
    ball-ball contact law has normal restitution `restitution` (-)."""
    return KineticParameters(diameter_m=float(diameter), density_kg_m3=float(density),
                             restitution=float(restitution), phi_rcp=float(phi_rcp),
                             correlation_coefficient=float(correlation_coefficient))


def closure_temperature(phi: float, shear_rate: float, prm: KineticParameters) -> float:
    """T (m^2/s^2) where production eta(phi, T) gamma_dot^2 balances the dissipation
    Gamma(phi, T, gamma_dot) of the closure, at solid fraction phi (-) and shear rate (1/s)."""
    gd = abs(float(shear_rate))
    if gd == 0.0 or phi <= 0.0:
        return 0.0

    def excess(T):   # production minus dissipation, positive below the root
        return shear_viscosity_Pa_s(phi, T, prm) * gd * gd - dissipation_W_m3(phi, T, gd, prm)

    lo = hi = (prm.diameter_m * gd) ** 2
    while excess(lo) <= 0.0:
        lo *= 0.1
    while excess(hi) > 0.0:
        hi *= 10.0
    for _ in range(200):
        mid = math.sqrt(lo * hi)
        lo, hi = (mid, hi) if excess(mid) > 0.0 else (lo, mid)
        if hi / lo < 1.0 + 1e-12:
            break
    return math.sqrt(lo * hi)


def fit_correlation_coefficient(phi: float, shear_rate: float, temperature: float,
                                prm: KineticParameters) -> float:
    """Jenkins' c_L (-) at which the closure's steady T equals `temperature` (m^2/s^2, the shear
    cell's) at phi (-) and shear_rate (1/s); 0 when the plain closure's T is already lower."""
    gd, T = abs(float(shear_rate)), float(temperature)
    plain = prm._replace(correlation_coefficient=0.0)
    ratio = dissipation_W_m3(phi, T, gd, plain) / (shear_viscosity_Pa_s(phi, T, plain) * gd * gd)
    if ratio <= 1.0:
        return 0.0
    return ratio * math.sqrt(T) / (prm.diameter_m * gd)


def dense_dissipation_coefficient(phi: float, shear_rate: float, temperature: float,
                                  shear_stress: float, pressure: float,
                                  prm: KineticParameters) -> float:
    """k_f (-) of the sliding loss Gamma_f = k_f p sqrt(T) / d (module notes) that closes
    steady shear's balance tau gamma_dot = Gamma(phi, T) + Gamma_f at the shear cell's measured
    phi (-), shear_rate (1/s), temperature (m^2/s^2), shear_stress tau and pressure p (Pa);
    Lun's Gamma without Jenkins' length."""
    gd, T, p = abs(float(shear_rate)), float(temperature), float(pressure)
    if not (T > 0 and p > 0):
        raise ValueError(f"temperature, pressure = {temperature!r}, {pressure!r}: must be > 0")
    plain = prm._replace(correlation_coefficient=0.0)
    work = float(shear_stress) * gd
    return (work - dissipation_W_m3(phi, T, gd, plain)) * prm.diameter_m / (p * math.sqrt(T))


def sliding_table(rows, diameter: float, density: float, restitution: float,
                  phi_rcp: float = 0.64) -> dict | None:
    """The [kinetic] keys of the dense sliding loss from the shear cell's steady points (rows
    of shear_cell.run_shear_cell: phi, shear_rate, granular_temperature, mu_eq and
    mean_pressure, so tau = mu_eq p): sliding_coefficient, the mean of each point's k_f
    (dense_dissipation_coefficient), its standard error (the points' scatter over sqrt(n)),
    the per-point values and the source; dense_dissipation = false (the balance takes k_f only
    when it is set true).  None without steady points."""
    prm = kinetic_parameters(diameter, density, restitution, phi_rcp)
    ks = []
    for r in rows:
        if not r.get("steady", True):
            continue
        p = float(r["mean_pressure"])
        ks.append(dense_dissipation_coefficient(r["phi"], r["shear_rate"],
                                                r["granular_temperature"], r["mu_eq"] * p, p,
                                                prm))
    if not ks:
        return None
    k = np.asarray(ks)
    se = float(k.std(ddof=1) / math.sqrt(k.size)) if k.size >= 2 else math.nan
    return {"sliding_coefficient": float(k.mean()), "sliding_coefficient_stderr": se,
            "sliding_coefficient_source": (
                "DEM shear cell: tau gamma_dot = Gamma_Lun(phi, T) + k_f p sqrt(T) / d at each "
                "steady point, k_f = " + ", ".join(f"{v:.4g}" for v in k)),
            "dense_dissipation": False}
