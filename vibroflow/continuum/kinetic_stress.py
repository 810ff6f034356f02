"""How the granular temperature enters the stress (docs/models.md 5.7, "The stress").

Three couplings of T (m^2/s^2) into the stress the grid sees, computed per point (or cell)
before each step from its state after the last one (the stress, the velocity gradient L, the
plastic rate and the phase of stress_update.py), so that the compiled step only adds a
given stress to the scattered one and reads one number in its return map:

1. Kinetic pressure (Lun et al. 1984, kinetic_theory.pressure_Pa) wherever T > 0, at the
   solid fraction phi = rho / rho_s capped at the material's connection packing
   phi_cap = rho_c / rho_s: above it the grains are in enduring contact and the elastic-plastic
   pressure carries the compression, so g0 is never read nearer close packing than phi_cap
   and T is read at most at T_cap, the temperature at which the kinetic pressure's wave is as
   fast as the elastic one the step is set for (timestep.kinetic_temperature_limit).
2. In the gas (the elastic-plastic state disconnected: phase 0, the density below rho_c or a
   tensile trial state) the frictional pressure of Johnson & Jackson (1987,
   kinetic_theory.frictional_pressure_Pa), read at phi capped at phi_cap as Lun's (a gas cell
   compressed past it in one step would otherwise read (phi_rcp - phi)^-5 near close packing,
   ~1e17 Pa on tub47-quick's calibration), and the kinetic-theory shear viscosity of Gidaspow
   (1994, kinetic_theory.shear_viscosity_Pa_s): a deviatoric stress 2 eta_k D', D' the
   deviator of the last step's rate of deformation (plane strain, D_yy from L[:, 4] where
   given).  eta_k is capped at eta_max = C rho dx^2 / dt, C = VISCOSITY_CAP = 3/160.  C is
   measured, not derived: a tenth of the 2D finite-difference bound of explicit viscous
   diffusion ((4/3) nu dt / dx^2 <= 1/4, C = 3/16).  With that bound tub47-quick's Eulerian
   run at the default cfl heated a surface cell that flickers between connected and
   disconnected (phi at phi_c, where g0 and eta_k are large) without limit and blew up at
   t = 0.84 s; with 3/160 its T stayed below 0.01 m^2/s^2 there.  Connected material carries
   none of this: its deviatoric stress is the elastic-plastic law's.
3. In connected material the mu(I) law's rate dependence is read from T (Kim & Kamrin 2020,
   Phys. Rev. Lett. 125, 088002: the velocity fluctuation, not the pressure alone, sets the
   inertial time).  The return map uses mu(r I), r = sqrt(T_bal / T), with T_bal the
   temperature at which the plastic work balances the dissipation at the point's stress and
   last plastic rate, tau gamma_dot_p = Gamma(phi, T_bal, gamma_dot_p) + Gamma_f(p, T_bal)
   (`balance_temperature`): the dissipation of the balance that carries T, the dense sliding
   loss Gamma_f at the point's pressure p included where it is on, so that T_bal is where
   that balance would rest.
   Where T = T_bal (steady shear) r = 1 and the law is the calibrated mu(I) exactly; where
   the material is hotter than its shear keeps it (vibrated) r < 1 and it flows at a lower
   friction, down to mu_s (Irmer, Brodsky & Clark 2024, arXiv 2405.13236: fluctuations
   lower the friction); T = 0 gives r = 1, the plain law.  The ratio is lagged one step (the
   last step's gamma_dot_p), which keeps the return map's quadratic.

The work of these stresses on the step's deformation, sigma_k : D, is the temperature's
production besides the plastic work (temperature_field.production_W_m3).

Eulerian cells (`kinetic_stress_cells`).  A cell holds material at its density rho filling a
fraction f = min(1, m / (rho h^2)) of it; material that opens a void stays a hair below rho_c
(eulerian/lagrangian_step.void_first), so rho / rho_s is phi_c in every partly filled cell.
The pressure and the gas's viscosity read the cell's solid fraction phi = f rho / rho_s, the
one its balance reads (capacity, dissipation, conduction), and act through the material's
volume f h^2 as the cell's whole, p(phi) h^2: the stress is theirs over f, so the work the
step takes from T, f sigma_k : D per cell area, is the work the stress does on the grid.  Read
at rho / rho_s, tub47's surface cells (phi 0.005 - 0.37) carry the pressure of a gas at phi_c
and the limit T, 41 kPa, four times the bed's weight on the floor, and throw the bed to the
rim (docs/validation.md section 22).  The return map's rate ratio reads the connected
material's own packing, its plastic work being per volume of material.
"""
from __future__ import annotations

import math

import numba as nb

from .kinetic_theory import (correlation_length_ratio, frictional_pressure_Pa,
                             pressure_Pa, radial_distribution, shear_viscosity_Pa_s)

_SQRT_PI = math.sqrt(math.pi)

#: the gas viscosity's cap eta_max = VISCOSITY_CAP rho dx^2 / dt (module docstring)
VISCOSITY_CAP = 3.0 / 160.0

#: columns of the kinetic stress array: [xx, zz, xz, yy] (Pa), then the rate ratio r (-)
RATE_RATIO = 4
KINETIC_COLUMNS = 5


@nb.njit(cache=True)
def balance_temperature(phi, tau, gamma_dot, prm, pressure=0.0):
    """T_bal (m^2/s^2) at which the plastic work tau gamma_dot (Pa, 1/s) equals the
    dissipation of the temperature's own balance: Lun's over Jenkins' L/d, (3/2) rho_s phi a0
    T^(3/2) min(1, sqrt(T) / (c_L d gamma_dot)), a0 = 8 (1 - e^2) phi g0 / (d sqrt(pi)), plus
    the dense sliding loss k_f p sqrt(T) / d at the compressive mean stress `pressure` (Pa)
    where prm.sliding_coefficient = k_f > 0 (kinetic_theory.sliding_dissipation_W_m3), so that
    T_bal is where the balance that carries T comes to rest.  0 where no work is done or
    nothing dissipates."""
    work = tau * gamma_dot
    e = prm.restitution
    a0 = 8.0 * (1.0 - e * e) * phi * radial_distribution(phi, prm) / (prm.diameter_m * _SQRT_PI)
    cap = 1.5 * prm.density_kg_m3 * phi * a0
    if work <= 0.0 or cap <= 0.0:
        return 0.0
    sliding = prm.sliding_coefficient * max(pressure, 0.0) / prm.diameter_m
    if sliding > 0.0:
        return _balance_with_sliding(work, cap, sliding, gamma_dot, prm)
    T1 = (work / cap) ** (2.0 / 3.0)
    if correlation_length_ratio(T1, gamma_dot, prm) <= 1.0:
        return T1
    # L/d = c_L d gamma_dot / sqrt(T) > 1: Gamma = cap T^2 / (c_L d gamma_dot)
    return math.sqrt(work * prm.correlation_coefficient * prm.diameter_m * gamma_dot / cap)


@nb.njit(cache=True)
def _convex_root(a, n, b, w, x):
    """The positive root of a x^n + b x = w (a, b, w > 0, n > 1) by Newton's method from x,
    an upper bound: the left side is convex and increasing, so the iterates fall to the root
    monotonically (quadratically near it)."""
    for _ in range(200):
        xn = x ** (n - 1)
        step = (a * xn * x + b * x - w) / (n * a * xn + b)
        if not step > 1e-15 * x:
            break
        x -= step
    return x


@nb.njit(cache=True)
def _balance_with_sliding(work, cap, sliding, gamma_dot, prm):
    """`balance_temperature` with the sliding loss: in s = sqrt(T), cap s^3 min(1, s / s_c) +
    sliding s = work, s_c = c_L d gamma_dot Jenkins' crossover (none without c_L).  The left side
    increases with s, so the root is unique: first on the uncorrelated branch, cap s^3; if it
    falls below s_c, on the correlated one, (cap / s_c) s^4, between it and s_c."""
    s = _convex_root(cap, 3.0, sliding, work, min((work / cap) ** (1.0 / 3.0), work / sliding))
    s_c = prm.correlation_coefficient * prm.diameter_m * abs(gamma_dot)
    if s >= s_c:
        return s * s
    s = _convex_root(cap / s_c, 4.0, sliding, work, s_c)
    return s * s


@nb.njit(cache=True, inline="always")
def _tau(s):
    pm = -(s[0] + s[1] + s[3]) / 3.0
    dxx, dzz, dyy = s[0] + pm, s[1] + pm, s[3] + pm
    return math.sqrt(0.5 * (dxx * dxx + dzz * dzz + dyy * dyy) + s[2] * s[2])


@nb.njit(cache=True)
def kinetic_stress(density, T, L, stress, gamma_dot, phase, prm, phi_cap, T_cap,
                   eta_max_factor, out):
    """out (N, 5): the stress added to the scattered one, [xx, zz, xz, yy] (Pa), and the rate
    ratio r (-) of the return map, per point (module docstring).  density (N,) kg/m^3, T (N,)
    m^2/s^2, L (N, 4 or 5) [xx, xz, zx, zz(, yy)] 1/s of the last step, stress (N, 4) Pa,
    gamma_dot (N,) its plastic rate 1/s, phase (N,) int8; prm kinetic_theory.KineticParameters;
    phi_cap (-) the connection packing rho_c / rho_s; T_cap (m^2/s^2) the highest T the
    kinetic pressure reads (timestep.kinetic_temperature_limit); eta_max_factor (m^2/s)
    dx^2 / dt, the viscosity cap being VISCOSITY_CAP rho eta_max_factor."""
    _kinetic_stress(density, density, False, 1.0, T, L, stress, gamma_dot, phase, prm, phi_cap,
                    T_cap, eta_max_factor, out)


@nb.njit(cache=True)
def kinetic_stress_cells(density, mass, h, T, L, stress, gamma_dot, phase, prm, phi_cap, T_cap,
                         eta_max_factor, out):
    """`kinetic_stress` of Eulerian cells of side h (m) holding mass (N,) kg/m of material at
    density (N,) kg/m^3, a fraction f = min(1, m / (rho h^2)) of the cell (module docstring,
    "Eulerian cells"): the pressure and the gas's viscosity at the cell's solid fraction
    phi = f rho / rho_s, the one its balance reads, and acting through the material's volume
    f h^2 as the cell's whole (stress over f); a full cell's is `kinetic_stress`'s."""
    _kinetic_stress(density, mass, True, h * h, T, L, stress, gamma_dot, phase, prm, phi_cap,
                    T_cap, eta_max_factor, out)


@nb.njit(cache=True)
def _kinetic_stress(density, mass, cells, area, T, L, stress, gamma_dot, phase, prm, phi_cap,
                    T_cap, eta_max_factor, out):
    """`kinetic_stress`, or with `cells` `kinetic_stress_cells` (mass (N,) kg/m, area the cell's
    h^2 m^2; mass is not read without `cells`)."""
    hoop = L.shape[1] > 4
    rho_s = prm.density_kg_m3
    for p in range(T.shape[0]):
        for c in range(4):
            out[p, c] = 0.0
        out[p, RATE_RATIO] = 1.0
        t = T[p]
        rho = density[p]
        if not (t > 0.0 and rho > 0.0):
            continue
        f = 1.0
        if cells:
            f = min(1.0, mass[p] / (rho * area))
            if not f > 0.0:
                continue
        phi = f * rho / rho_s
        pk = pressure_Pa(min(phi, phi_cap), min(t, T_cap), prm) / f
        if phase[p] == 0:
            pk += frictional_pressure_Pa(min(phi, phi_cap), prm) / f
            eta = min(shear_viscosity_Pa_s(phi, t, prm) / f,
                      VISCOSITY_CAP * rho * eta_max_factor)
            dxx = L[p, 0]
            dzz = L[p, 3]
            dxz = 0.5 * (L[p, 1] + L[p, 2])
            dyy = L[p, 4] if hoop else 0.0
            third = (dxx + dzz + dyy) / 3.0
            out[p, 0] = 2.0 * eta * (dxx - third)
            out[p, 1] = 2.0 * eta * (dzz - third)
            out[p, 2] = 2.0 * eta * dxz
            out[p, 3] = 2.0 * eta * (dyy - third)
        else:
            # the connected material's own packing: its return map's plastic work is per
            # volume of material
            sp = stress[p]
            tb = balance_temperature(min(rho / rho_s, phi_cap), _tau(sp), gamma_dot[p], prm,
                                     -(sp[0] + sp[1] + sp[3]) / 3.0)
            out[p, RATE_RATIO] = math.sqrt(tb / t)
        out[p, 0] -= pk
        out[p, 1] -= pk
        out[p, 3] -= pk
