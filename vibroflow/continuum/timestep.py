"""The stable time step of the explicit MPM.

* Elastic waves (Courant-Friedrichs-Lewy): dt <= cfl dx / (c + v_max) with the P-wave speed
  c = sqrt((K + 4 G / 3) / rho_c) at the critical density (the lowest density that carries
  stress, so the fastest wave), dx the grid spacing (m) and v_max a bound on the material speed.
* Penalty walls: a point of side l on a wall of stiffness k_n (Pa/m) is an oscillator of
  frequency omega = sqrt(k_n l / m) = sqrt(k_n / (rho l)); the explicit update of a damped
  oscillator is stable for omega dt < 2 (sqrt(1 + zeta^2) - zeta); the step keeps the fraction
  cfl of that.

Which bound binds, and how tight it is (tub47-quick with its DEM calibration: K = 1.04 MPa,
G = 0.097 MPa, rho_c = 4434 kg/m^3, so c = 16.2 m/s; dx the grid, points of side dx/2): the
default wall stiffness (K + 4G/3) / (dx/2) makes the wall oscillator's omega = 2 c / dx, and its
limit cfl 2 (sqrt(1 + zeta^2) - zeta) / omega = 0.85 cfl dx / c (zeta = 0.16) is a little below
the elastic cfl dx / (c + v_max); the step is then rounded down to divide the sampling interval.
Neither is the stability limit itself: the quadratic B-spline stiffness with lumped mass has
its highest elastic frequency sqrt(4/3) c / dx (the grid-scale mode's Fourier symbol,
4/3 (K + 4G/3) / (rho dx^2)), the wall adds at most omega = 2 c / dx in quadrature, so the
damped explicit update is stable to about 0.85 x 2 / (2.3 c / dx) = 0.74 dx / c, 3 times the
step at cfl 0.3 (0.25 dx / c); the mu(I) viscous stress adds no bound, the return map being
implicit in the plastic rate (constitutive.py), so its tangent never exceeds G.  A tub run's
default cfl is this function's 0.3 (continuum.options.DEFAULT_CFL), inside these bounds.  At 0.6
(the stability margin alone) a point of tub47 at amplitude factor 1.5 can pass through the U
wall.

The granular temperature's kinetic pressure (kinetic_stress.py) is a second, T-dependent
stiffness: p_k = rho_s T phi F(phi) (Lun et al. 1984) carries waves at c_k^2 = dp_k/drho =
T d(phi F)/dphi (`kinetic_wave_speed`), which grows without bound as phi nears phi_rcp (g0
diverges there) and with T.  Two things keep it inside the elastic step without a smaller step:
Lun's pressure is read at phi <= phi_cap = rho_c / rho_s, the connection packing (above it the
elastic-plastic pressure carries the compression), where d(phi F)/dphi is largest; and its T is
read at most at `kinetic_temperature_limit`, the T at which c_k(phi_cap) equals the elastic
P-wave speed c, so the kinetic wave is never faster than the one the step is set for.  For
tub47-quick's calibration (phi_cap = 0.568, phi_rcp = 0.64, e = 0.85, c = 16.2 m/s) the limit
is T = 0.35 m^2/s^2, sqrt(T) = 0.59 m/s, six times the DEM's bed (sqrt(T) 80 - 110 mm/s).
Without the cap an Eulerian cell compressed towards phi_rcp (the remap's density overshoot)
read g0 ~ 1e8 at the clamp PHI_GAP, a kinetic pressure of ~1e10 Pa and a wave far faster than
any step: the blow-up of the Eulerian formulation with T at the default cfl.

The APIC transfers' damping is not the step's business: a step makes `transfers_per_step`
transfers (mpm.MPMSystem.transfers, transfer_operator.py), so that the damping per second is
that of a one-transfer step of Courant number transfer_cfl, whatever the step, and the step is
set by stability alone (docs/decisions/transfer-rate.md).
"""
from __future__ import annotations

import math

from vibroflow.errors import InputError

from .kinetic_theory import pressure_Pa


def stable_dt(material, dx: float, point_size: float, boundaries=(), v_max: float = 0.0,
              cfl: float = 0.3) -> float:
    """Largest stable time step (s) for grid spacing dx (m), smallest point side point_size (m),
    the walls in `boundaries` (those with a `stiffness`) and material speeds up to v_max (m/s)."""
    if not 0 < cfl <= 1:
        raise InputError(f"cfl = {cfl!r}: must be in (0, 1]")
    c = material.p_wave_speed()
    dt = cfl * dx / (c + max(v_max, 0.0))
    rho = material.critical_density
    for b in boundaries:
        k = getattr(b, "stiffness", None)
        if k is None:
            continue
        for kk in (k, k * getattr(b, "tangential_ratio", 1.0)):
            if kk <= 0:
                continue
            omega = math.sqrt(kk / (rho * point_size))
            z = b.damping_ratio
            dt = min(dt, cfl * 2.0 * (math.sqrt(1.0 + z * z) - z) / omega)
    eta = getattr(material, "bed_viscosity", 0.0)
    if eta > 0:
        # the bed viscosity's explicit diffusion of momentum (stress_update.damped_stress): its
        # longitudinal coefficient 7/3 eta; dt <= C rho dx^2 / eta_L.  C = (20/3) cfl (2 at
        # the default cfl 0.3) is measured, not derived: the quadratic B-spline grid's highest
        # mode is slower than a finite-difference stencil's, and tub47's strip
        # (benchmarks/strip_damping.py, dx 18.75 mm, dt 0.27 ms) ran stable up to 10 kPa s
        # (C = 3.7 at the step it ran) and blew up at 30 kPa s (C = 11)
        dt = min(dt, cfl * (20.0 / 3.0) * rho * dx * dx / (7.0 / 3.0 * eta))
    return dt


#: the most time steps a continuum run takes (tub47 takes 11 468; at ~0.2 ms a step the
#: bound is about six hours): beyond it a setting, not the physics, sets the step
MAX_STEPS = 1.0e8
#: the most APIC transfers a step makes (the defaults make 8 and 20)
MAX_TRANSFERS = 1000


def run_step(material, dx: float, point_size: float, boundaries, scenario, options) -> float:
    """The step (s) of a tub run: `stable_dt` at material speeds up to 2 m/s and the options'
    cfl, rounded down to a whole number of steps between samples (so that every sample falls
    on a step), its step count checked (`check_step_count`) over the settling and the run."""
    dt = stable_dt(material, dx, point_size, boundaries, v_max=2.0, cfl=options.cfl)
    interval = 1.0 / (scenario.motion.frequency * scenario.run.phases_per_cycle)
    dt = interval / math.ceil(interval / dt)
    check_step_count(dt, scenario.run.duration + options.settle_time, options)
    return dt


def check_step_count(dt: float, duration_s: float, options) -> None:
    """InputError (one line) when a run of duration_s (s) takes more than MAX_STEPS steps of
    dt (s): the step is set by the options (cfl, dx, wall_stiffness, bed_viscosity)."""
    steps = duration_s / dt
    if not steps <= MAX_STEPS:
        raise InputError(f"cfl = {options.cfl!r}, dx = {options.dx!r}, wall_stiffness = "
                         f"{options.wall_stiffness!r}, bed_viscosity = {options.bed_viscosity!r}"
                         f": a stable step of {dt:.3g} s makes {steps:.3g} steps of the "
                         f"{duration_s:g} s run; at most {MAX_STEPS:g} (raise cfl or dx, or "
                         "lower wall_stiffness or bed_viscosity)")


def transfers_per_step(cfl: float, transfer_cfl: float | None) -> int:
    """The APIC transfers a step of Courant number cfl makes (mpm.MPMSystem.transfers,
    transfer_operator.py) so that they damp as a one-transfer APIC step of Courant number
    transfer_cfl would: round(cfl / transfer_cfl), at least 1; None or 0: one transfer a step.
    The rate of transfers is then that of the one-transfer step to within the rounding,
    1 / (2 n) of it at most (and the step's own rounding to divide the sampling interval)."""
    if transfer_cfl is None:
        return 1
    if isinstance(transfer_cfl, bool) or not (
            isinstance(transfer_cfl, (int, float)) and math.isfinite(transfer_cfl)
            and transfer_cfl >= 0):
        raise InputError(f"transfer_cfl = {transfer_cfl!r}: must be a Courant number > 0, or 0 "
                         "(or none) for one transfer a step")
    if transfer_cfl == 0:
        return 1
    n = cfl / transfer_cfl
    if not n <= MAX_TRANSFERS + 0.5:
        raise InputError(f"transfer_cfl = {transfer_cfl:.3g} (on this grid): {n:.3g} APIC "
                         f"transfers a step of cfl = {cfl!r}; at most {MAX_TRANSFERS} (raise "
                         "transfer_cfl, or lower damping_length)")
    return max(1, int(round(n)))


def kinetic_wave_speed(phi: float, T: float, prm) -> float:
    """c_k = sqrt(dp_k / drho) (m/s) of Lun's pressure p_k (kinetic_theory.pressure_Pa) at
    solid fraction phi (-) and temperature T (m^2/s^2), by a central difference in phi (its
    step 1e-7, inside phi_rcp's clamp); prm a KineticParameters."""
    h = 1e-7
    dp = pressure_Pa(phi + h, T, prm) - pressure_Pa(phi - h, T, prm)
    return math.sqrt(max(dp, 0.0) / (2.0 * h * prm.density_kg_m3))


def kinetic_temperature_limit(wave_speed: float, phi_cap: float, prm) -> float:
    """The T (m^2/s^2) at which the kinetic pressure's wave speed at phi_cap equals wave_speed
    (m/s): c_k^2 is linear in T, so T = wave_speed^2 / c_k(phi_cap, T = 1)^2 (module
    docstring)."""
    c1 = kinetic_wave_speed(min(phi_cap, prm.phi_rcp - 2e-6), 1.0, prm)
    return wave_speed * wave_speed / (c1 * c1) if c1 > 0 else math.inf
