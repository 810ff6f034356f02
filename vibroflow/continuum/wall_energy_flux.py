"""The fluctuation energy the walls feed into the continuum's granular temperature, compiled.

Johnson & Jackson (1987, J. Fluid Mech. 176, 67; the form of MFiX and of OpenFOAM's
JohnsonJacksonParticleTheta condition) give the flux of fluctuation energy into the material
through a wall (W/m^2, positive inwards) as slip production minus the wall collisions' loss:

    q = (pi sqrt(3) / 6) phi' rho_s phi g0 sqrt(T) |u_slip|^2 / phi_max
        - (sqrt(3) pi / 4) (1 - e_w^2) rho_s phi g0 T^(3/2) / phi_max,

phi' the specularity (0: smooth wall, 1: fully diffuse), e_w the ball-wall restitution,
phi_max = the closures' phi_rcp and u_slip the material's velocity relative to the WALL (both
formulations' walls are at rest in their frame, a Plane moves with its own velocity), so a wall
and a bed moving together feed nothing (Galilean invariance).  The loss is stiff (T^(3/2) on a
thin wall cell): it is folded into the cell's cooling coefficient a of dT/dt = -a T^(3/2), which
temperature_step integrates exactly, as it does the collisions' dissipation
(`wall_cooling_coefficient`).

The specularity: a given phi' in [0, 1], or (`FRICTION_RULE`) the rule that the slip production
is the work of the wall's own Coulomb friction on the slip, |F_t| |u_slip| per wall length (the
energy the mean flow loses at the wall, the DEM's -F . V of calibration/wall_energy.py), capped
at phi' = 1: phi' follows from the wall's calibrated friction mu_w and restitution, not from a
fit.

The vibrating wall's normal feed (Kumaran 1998, J. Fluid Mech. 364, 163; Warr, Huntley &
Jacques 1995, Phys. Rev. E 52, 5583) emerges from the resolved wall motion: at each landing the
material's normal velocity relative to the wall is stopped by the penalty contact (boundary.py),
whose dashpot of damping c = 2 zeta sqrt(m k_n l) takes the power c v_n^2 from the mean motion
while the material moves into the wall (v_n < 0), at most its normal kinetic energy m v_n^2 / 2
a step; that inelastic jump's energy becomes fluctuation energy (the "landing" source).  The
Eulerian wall layer (eulerian/solver.py) is held by its closed faces, not by the dashpot, so
its landing is measured instead (`landing_terms`): the normal kinetic energy relative to the
wall that a wall cell approaching it (v_n < 0 at the step's start) has lost by the step's end,
at most the m v_n^2 / 2 it had.

Per contact (a material point or a wall-layer cell touching a wall: normal force > 0) the
kernel `contact_terms` gives its wall length l (m), l |u_slip|^2 (m^3/s^2), the friction power
|F_t| |u_slip| (W/m) and the landing power (W/m); `cell_wall_terms` turns their sums over a
cell of side h into the cell's heating (W/m^3) and wall cooling coefficient.  Energies are per
metre of thickness (plane strain).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

from vibroflow.scenario.checks import find_contact

from .kinetic_theory import radial_distribution

#: WallEnergy.specularity: the slip production is the wall friction's work (module docstring)
FRICTION_RULE = -1.0

#: Johnson & Jackson's coefficients: slip production pi sqrt(3) / 6, collision loss sqrt(3) pi / 4
JJ_SLIP = math.pi * math.sqrt(3.0) / 6.0
JJ_LOSS = math.sqrt(3.0) * math.pi / 4.0


class WallEnergy(NamedTuple):
    """The walls' feed of fluctuation energy: restitution e_w (-) of the balls on the wall,
    0 <= e_w <= 1; specularity phi' (-) in [0, 1] or FRICTION_RULE (default); landing: the
    landing's normal velocity jump becomes T (default True); columns: the Eulerian landing
    above the wall row is counted along each column of cells by the impulse through its z
    faces (column_landing.py) rather than by the pairs across them (compaction_landing.py;
    default False: docs/decisions/granular-temperature-closures.md)."""

    restitution: float
    specularity: float = FRICTION_RULE
    landing: bool = True
    columns: bool = False


@nb.njit(cache=True)
def slip_production_W_m2(specularity, phi, T, slip_m_s, prm):
    """Johnson & Jackson's slip production (W/m^2): (pi sqrt(3) / 6) phi' rho_s phi g0 sqrt(T)
    |u_slip|^2 / phi_max; prm a KineticParameters."""
    if T <= 0.0 or phi <= 0.0:
        return 0.0
    return (JJ_SLIP * specularity * prm.density_kg_m3 * phi * radial_distribution(phi, prm)
            * math.sqrt(T) * slip_m_s * slip_m_s / prm.phi_rcp)


@nb.njit(cache=True)
def collision_loss_W_m2(restitution, phi, T, prm):
    """Johnson & Jackson's wall-collision loss (W/m^2): (sqrt(3) pi / 4) (1 - e_w^2) rho_s phi
    g0 T^(3/2) / phi_max."""
    if T <= 0.0 or phi <= 0.0:
        return 0.0
    return (JJ_LOSS * (1.0 - restitution * restitution) * prm.density_kg_m3 * phi
            * radial_distribution(phi, prm) * T * math.sqrt(T) / prm.phi_rcp)


@nb.njit(cache=True)
def johnson_jackson_flux_W_m2(specularity, restitution, phi, T, slip_m_s, prm):
    """The wall's flux of fluctuation energy into the material (W/m^2): slip production minus
    collision loss (module docstring)."""
    return (slip_production_W_m2(specularity, phi, T, slip_m_s, prm)
            - collision_loss_W_m2(restitution, phi, T, prm))


@nb.njit(cache=True)
def wall_cooling_coefficient(restitution, phi, length_m, h, prm):
    """a_w (1/(s sqrt(m^2/s^2))) of the wall loss dT/dt = -a_w T^(3/2) of a cell of side h (m)
    touching walls over length_m (m): the loss times the length over the cell's area and its
    heat capacity (3/2) rho_s phi, (pi sqrt(3) / 6) (1 - e_w^2) g0 length / (phi_max h^2)."""
    if phi <= 0.0 or length_m <= 0.0:
        return 0.0
    return (2.0 / 3.0 * JJ_LOSS * (1.0 - restitution * restitution)
            * radial_distribution(phi, prm) * length_m / (prm.phi_rcp * h * h))


@nb.njit(cache=True)
def contact_terms(fn, ft, normal, v_rel, mass, length, kn, zeta, dt, out):
    """Adds per contact the sums `cell_wall_terms` needs to out (N, 4): wall length l (m),
    l |u_slip|^2 (m^3/s^2), the friction power |F_t u_slip| (W/m) and the landing power
    c v_n^2 (W/m), c = 2 zeta sqrt(m k_n l), while the material still moves into the wall
    (v_n < 0) and at most its normal kinetic energy m v_n^2 / 2 over the step dt (s): a landing
    cannot turn more into T than the jump it stops; nothing where fn <= 0 (no contact).  fn, ft (N,)
    the wall's normal and tangential force (N/m), normal (N, 2) the wall's unit normal into the
    material, v_rel (N, 2) the velocity relative to the wall (m/s), mass (N,) kg/m, length (N,)
    contact lengths (m), kn (Pa/m), zeta (-)."""
    for p in range(fn.shape[0]):
        if fn[p] <= 0.0:
            continue
        nx = normal[p, 0]
        nz = normal[p, 1]
        vn = v_rel[p, 0] * nx + v_rel[p, 1] * nz
        vt = v_rel[p, 0] * nz - v_rel[p, 1] * nx
        l = length[p]
        out[p, 0] += l
        out[p, 1] += l * vt * vt
        out[p, 2] += abs(ft[p] * vt)
        if vn < 0.0:
            out[p, 3] += min(2.0 * zeta * math.sqrt(mass[p] * kn * l), 0.5 * mass[p] / dt) * vn * vn


@nb.njit(cache=True)
def landing_terms(v0, m0, v1, m1, normal, fn, dt, out):
    """Adds the Eulerian wall cells' landing power (W/m) to out[:, 3] (`contact_terms`' column):
    the normal kinetic energy relative to the wall lost over the step of dt (s) by a cell whose
    material approached the wall, E_0 = m_0 v_n0^2 / 2 with v_n0 < 0 at the step's start, less
    what is left of it at the end, E_1 = m_1 min(v_n1, 0)^2 / 2, clipped to [0, E_0], over dt:
    the inelastic normal jump of the landing, which a cell leaving the wall (v_n1 > 0) or still
    falling faster (E_1 > E_0) does not make; only where the cell touches the wall (fn > 0).
    v0, v1 (N, 2) the cells' velocities relative to the wall (m/s) and m0, m1 (N,) their
    masses (kg/m) at the step's start and end, normal (N, 2) the wall's inward unit normal,
    fn (N,) its normal force (N/m)."""
    for p in range(fn.shape[0]):
        vn0 = v0[p, 0] * normal[p, 0] + v0[p, 1] * normal[p, 1]
        vn1 = min(v1[p, 0] * normal[p, 0] + v1[p, 1] * normal[p, 1], 0.0)
        e0 = 0.5 * m0[p] * vn0 * vn0 if (vn0 < 0.0 and fn[p] > 0.0) else 0.0
        lost = min(max(e0 - 0.5 * m1[p] * vn1 * vn1, 0.0), e0)
        out[p, 3] += lost / dt


def normal_of_force(f, fn, ft) -> np.ndarray:
    """The wall's unit normal (N, 2) into the material from its force f = fn n + ft t,
    t = (n_z, -n_x) (boundary._penalty), (0, 0) where fn <= 0."""
    f = np.asarray(f, float)
    r2 = fn * fn + ft * ft
    ok = fn > 0.0
    out = np.zeros((fn.size, 2))
    out[ok, 0] = (fn[ok] * f[ok, 0] - ft[ok] * f[ok, 1]) / r2[ok]
    out[ok, 1] = (ft[ok] * f[ok, 0] + fn[ok] * f[ok, 1]) / r2[ok]
    return out


@nb.njit(cache=True)
def partition_terms(v, mass, volume, stress, friction, spacing_m, dt, out):
    """Adds the partitions' contacts to out (N, 4) (`contact_terms`): a material's column of
    cross-section V_p between partitions L_y apart touches them over l = 2 V_p / L_y per metre
    (the two faces), where its pressure is positive; the slip is its whole velocity (the
    partitions move with the tub, in whose frame v is) and the friction power that of
    boundary.partition_forces, f |v| with f = min(2 mu_p p V_p / L_y, m |v| / dt); no landing
    (the partitions move in their own plane)."""
    for q in range(v.shape[0]):
        p = -(stress[q, 0] + stress[q, 1] + stress[q, 3]) / 3.0
        if not p > 0.0:
            continue
        sp2 = v[q, 0] * v[q, 0] + v[q, 1] * v[q, 1]
        sp = math.sqrt(sp2)
        l = 2.0 * volume[q] / spacing_m
        f = min(friction * l * p, mass[q] * sp / dt)
        out[q, 0] += l
        out[q, 1] += l * sp2
        out[q, 2] += f * sp


@nb.njit(cache=True)
def cell_wall_terms(phi, T, sums, h, restitution, specularity, landing, void, prm):
    """The cells' wall heating (W/m^3) and wall cooling coefficient a_w (module docstring),
    both (nx, nz), from the cells' solid fraction phi, temperature T (m^2/s^2) and per-cell sums
    (nx, nz, 4) of `contact_terms`; h cell side (m); a cell below the void solid fraction gets
    nothing, a cell touching no wall only its landing column (the material stopped in it:
    compaction_landing.py)."""
    nx, nz = phi.shape
    heat = np.zeros((nx, nz))
    cool = np.zeros((nx, nz))
    area = h * h
    for i in range(nx):
        for k in range(nz):
            f = phi[i, k]
            if f < void:
                continue
            if sums[i, k, 0] <= 0.0:
                # no wall here: only the landing of the material stopped in the cell
                # (compaction_landing.py)
                if landing and sums[i, k, 3] > 0.0:
                    heat[i, k] = sums[i, k, 3] / area
                continue
            if specularity >= 0.0:
                q = slip_production_W_m2(specularity, f, T[i, k], 1.0, prm) * sums[i, k, 1]
            else:
                q = min(slip_production_W_m2(1.0, f, T[i, k], 1.0, prm) * sums[i, k, 1],
                        sums[i, k, 2])
            if landing:
                q += sums[i, k, 3]
            heat[i, k] = q / area
            cool[i, k] = wall_cooling_coefficient(restitution, f, sums[i, k, 0], h, prm)
    return heat, cool


def wall_energy_of(scenario) -> WallEnergy:
    """The scenario's walls as a WallEnergy: e_w the ball-tub wall contact's restitution (the
    DEM's, calibration.toml's [scenario.media] ball_wall_restitution; without a tub or its
    contact law, the ball-ball restitution), the friction rule."""
    ball = scenario.fill.material
    tub = getattr(scenario, "tub", None)
    pair = find_contact(scenario, ball, tub.wall_material) if tub is not None else None
    if pair is None:
        pair = find_contact(scenario, ball, ball)
    return WallEnergy(restitution=float(pair.restitution))

