"""The granular column collapse with the material point method (plane strain, lab frame).

A rectangular column of the continuum, half-width L0 and height H0 (m), stands on a floor z = 0
and is released at t = 0 under gravity: it slumps and spreads until it comes to rest.  This is
the planar column of the channel experiments (Lube, Huppert, Sparks & Freundt 2005, Phys. Rev. E
72, 041301, released on both sides; Lajeunesse, Monnier & Homsy 2005, Phys. Fluids 17, 103302,
against a wall) and of the mu(I) continuum simulations of Lagree, Staron & Popinet (2011,
J. Fluid Mech. 686, 378) and Dunatunga & Kamrin (2015, J. Fluid Mech. 779, 483, section 5.2, the
same elasto-viscoplastic MPM as this package's); its deposit is measured by
`vibroflow.measure.column` from `ColumnRun.deposit_points()`.

Set-up choices, and why:

* symmetric (default): the whole column, width 2 L0 centred on x = 0, spreads both ways, and the
  deposit is folded about x = 0; this is the half-column against a frictionless wall without a
  wall.  The wall variant (`symmetric=False`: the column [0, L0] against a penalty `Plane` at
  x = 0) is kept, but the point-wise penalty contact of boundary.py packs the points that reach
  the wall into a sheet half a cell thick, overlapping one another (at a = 3 on L0/20, 2.5 % of
  the mass, 120 points of full volume, stood within half a cell of the wall, up to 0.85 L0 high,
  beside a void), which read as a peak of the deposit's height at the wall (1.8 L0, against
  0.90 L0 for the symmetric column; the run-out is the same either way);
* floor: a penalty `Plane` with Coulomb friction.  The experiments used rough floors (basal
  friction at least the grains' internal friction); the default floor friction mu_w = 0.40 is
  tub47's ball-lining friction, just above the glass-bead mu_s = 0.382 of the default material
  but below the flowing material's mu(I), so the base slides; a floor that never slides
  (mu_w >= mu_2) runs out much less (at a = 3 on L0/10, 4.5 L0 instead of 7.2 L0).  Its
  stiffness is the P-wave modulus over the point side (the stiffness of the continuum itself
  across one point), as in the block test of tests/test_mpm.py;
* rough floor (`rough_floor=True`): the experiments' rough bed as a no-slip grid condition, the
  nodes on and below z = 0 held still (MPMSystem.no_slip_below; the no-slip base of Lagree,
  Staron & Popinet 2011), on top of the penalty floor that carries the normal load.  A penalty
  floor with mu_w >= mu_2 is not the same: it brakes only the row of points touching the floor,
  and the next row shears past within one cell, so its run-out is not grid-converged (a = 3:
  4.53 L0 on L0/10, 5.80 L0 on L0/20), where the no-slip grid floor's is (5.72, 5.65), though
  still 45 % above Lube et al. 2005 (tests/test_column_collapse.py);
* initial state: the column at the critical density, pre-stressed as it stood behind a gate,
  sigma_zz = -rho g (H0 - z) and sigma_xx = sigma_yy = K_0 sigma_zz with Jaky's
  K_0 = 1 - sin(atan mu_s), and the density rho_c exp(p / K) of that pressure (just above the
  critical density, so every point carries stress); releasing a stress-free column instead would
  first ring with elastic waves of the weight's size;
* points: 2 x 2 a cell (spacing dx/2), as in the other MPM checks;
* time step: the stable step of timestep.py with the free-fall speed sqrt(2 g H0) as the
  material speed bound;
* transfers: APIC by default, whose grid-to-point update replaces each point's velocity by the
  grid's smooth field at every step and so damps the flow at every step: the run-out depends on
  the number of steps, not only on the grid (a = 3, L0/10, rough floor: 5.72 L0 at cfl 0.3,
  4.95 at 0.1, 3.84 at 0.03; at cfl 0.1 the grid refinement to L0/20 gives 6.04, so the
  apparent grid convergence at cfl 0.3, 5.72 -> 5.65, is a coincidence of two errors).  With
  `flip` = 0.99 (a FLIP-APIC blend, MPMSystem.flip) the damping is gone and the run-out is
  time-step converged to 10 % (5.35 at cfl 0.3, 5.88 at 0.03): the mu(I) continuum itself,
  undamped, runs out 35 - 50 % farther than Lube et al. 2005 and stands 40 % lower (height
  0.90 - 0.93 L0 at the symmetry plane against a^(2/5) = 1.55), tests/test_column_collapse.py;
* axisymmetric (`axisymmetric=True`): the cylindrical column of radius L0 = R0 of Lube,
  Huppert, Sparks & Hallworth (2004, J. Fluid Mech. 508, 175) and Lajeunesse, Mangeney-Castelnau
  & Vilotte (2004, Phys. Fluids 16, 2371), the experiments the laws of vibroflow.measure.column
  LUBE_2004 and LAJEUNESSE_2004 were fitted on, as the axisymmetric MPM of
  MPMSystem.axisymmetric: the half-plane r >= 0 of the section, points of mass rho_c sp^2 r
  per radian, the hoop stress K_0 sigma_zz at the start like sigma_xx; the floor is the rough
  (no-slip grid) floor, since the penalty floor is a plane-strain object;
* at rest: after at least `t_min` (default 3 sqrt(H0/g), the collapse time scale of the
  experiments), the run stops at the first check where the kinetic energy is below `ke_fraction`
  of the column's initial potential energy M g H0 / 2; a run that has not come to rest by
  `t_max` says so (`settled` False) instead of pretending.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vibroflow.errors import InputError

from .boundary import Plane
from .constitutive import ContinuumMaterial
from .grid import Grid
from .grid_update import LabFrame
from .mpm import MPMState, MPMSystem, init_state, run_steps
from .timestep import stable_dt

G_ACC = 9.81  # m/s^2


@dataclass
class ColumnRun:
    """A finished column collapse: the final material points and how the run went.

    state: the MPM state (points x (N, 2) m, mass (N,) kg/m, ...); t_end (s); settled: the
    kinetic energy fell below the threshold before t_max; ke_ratio: the last kinetic energy over
    the initial potential energy; history: (t, kinetic energy, front distance (m)) at each
    check."""

    L0: float
    H0: float
    dx: float
    material: ContinuumMaterial
    floor_friction: float
    wall_friction: float
    symmetric: bool
    state: MPMState
    t_end: float
    settled: bool
    ke_ratio: float
    steps: int
    history: list
    axisymmetric: bool = False

    @property
    def aspect_ratio(self) -> float:
        return self.H0 / self.L0

    @property
    def point_side(self) -> float:
        """The initial point spacing dx/2 (m)."""
        return 0.5 * self.dx

    def deposit_points(self) -> tuple[np.ndarray, np.ndarray]:
        """(distance from the wall, symmetry plane or axis (m), area (m^2 per metre)) of every
        point, for vibroflow.measure.column: the area is the point's mass over the critical
        density (the column's, to 1e-3), so the areas of a half-column add up to L0 H0; a
        symmetric run's points are folded about x = 0 with half their area each; an
        axisymmetric run's area is the meridian area V / r of its volume per radian V, so that
        the thickness profile (area per bin width) is the deposit's thickness h(r) (the volume
        h r dr per radian of an annulus over r dr)."""
        x = self.state.x[:, 0]
        area = self.state.mass / self.material.critical_density
        if self.axisymmetric:
            return x.copy(), area / x
        if self.symmetric:
            return np.abs(x), 0.5 * area
        return x.copy(), area

    def deposit(self, wall_window: float | None = None):
        """The deposit measured as every continuum's is (vibroflow.measure.column.
        measure_continuum_deposit of `deposit_points`, grains of the material's diameter; the
        height within `wall_window` (m) of the wall or axis when given)."""
        from vibroflow.measure.column import measure_continuum_deposit

        return measure_continuum_deposit(*self.deposit_points(), self.point_side,
                                         self.material.diameter, wall_window=wall_window)


#: the friction angle (deg) of dry quartz sand, the main material of Lube et al. 2004, as a
#: continuum's mu_s (sand_material).  A typical value for dry sand (30 - 34 deg is the usual
#: range of its angle of repose); the paper's own table of its materials could not be read
#: here, so this is not the measured angle of their sand.  The paper found the deposits "the
#: same" for sand, salt, rice, couscous and sugar.
SAND_FRICTION_DEG = 29.5


def sand_material(friction_deg: float = SAND_FRICTION_DEG) -> ContinuumMaterial:
    """The default continuum with mu_s = tan(friction_deg) and the glass-bead rate dependence
    (mu_2 - mu_s and I_0) kept: the material of the cylinder checks against Lube et al. 2004
    and Lajeunesse et al. 2004 (tests/test_axisymmetric.py, benchmarks/column_convergence.py)."""
    if not (isinstance(friction_deg, (int, float)) and 0 < friction_deg < 90):
        raise InputError(f"friction_deg = {friction_deg!r}: must be an angle in (0, 90) deg")
    base = ContinuumMaterial()
    mu_s = math.tan(math.radians(friction_deg))
    return ContinuumMaterial(mu_s=mu_s, mu_2=mu_s + base.mu_2 - base.mu_s)


def column_points(x0: float, x1: float, H0: float, spacing: float) -> np.ndarray:
    """Points on a square lattice of `spacing` (m) filling [x0, x1] x [0, H0] (m), each at the
    centre of its own square."""
    xs = x0 + (np.arange(int(round((x1 - x0) / spacing))) + 0.5) * spacing
    zs = (np.arange(int(round(H0 / spacing))) + 0.5) * spacing
    X, Z = np.meshgrid(xs, zs, indexing="ij")
    return np.stack([X.ravel(), Z.ravel()], axis=1)


def _check_size(L0, H0, dx):
    for name, v in (("L0", L0), ("H0", H0), ("dx", dx)):
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise InputError(f"column {name} = {v!r}: must be a finite length > 0 m")
    for name, v in (("L0", L0), ("H0", H0)):
        n = v / (0.5 * dx)
        if abs(n - round(n)) > 1e-6 * n or round(n) < 2:
            raise InputError(f"column {name} = {v!r} m: must be a whole number (>= 2) of point "
                             f"spacings dx/2 = {0.5 * dx!r} m")


def column_system(L0: float, H0: float, dx: float, material: ContinuumMaterial | None = None,
                  floor_friction: float = 0.40, wall_friction: float = 0.0,
                  symmetric: bool = True, reach: float | None = None,
                  cfl: float = 0.3, rough_floor: bool = False,
                  flip: float = 0.0, axisymmetric: bool = False,
                  transfers: int = 1) -> MPMSystem:
    """The MPM system of a column of half-width L0 and height H0 (m) on grid spacing dx (m):
    floor z = 0 with Coulomb friction `floor_friction`, and no slip if `rough_floor`;
    symmetric (module docstring), or a wall x = 0 with `wall_friction`; a grid reaching
    `reach` (m, default L0 (2 + 3 H0/L0)) from x = 0 (both ways when symmetric); `flip` the
    FLIP fraction of the points' velocity update (MPMSystem.flip; module docstring);
    `axisymmetric`: the cylindrical column of radius L0 (module docstring; needs the rough
    floor, `symmetric` does not apply); `transfers`: APIC transfers a step (MPMSystem.transfers;
    1, the checks' setting, unless a study holds the transfers' damping across grids:
    benchmarks/column_convergence.py)."""
    _check_size(L0, H0, dx)
    mat = material or ContinuumMaterial()
    for name, mu in (("floor_friction", floor_friction), ("wall_friction", wall_friction)):
        if not (isinstance(mu, (int, float)) and math.isfinite(mu) and mu >= 0):
            raise InputError(f"{name} = {mu!r}: must be a finite number >= 0")
    a = H0 / L0
    reach = L0 * (2.0 + 3.0 * a) if reach is None else float(reach)
    if not reach > L0:
        raise InputError(f"reach = {reach!r} m: must exceed the column's half-width L0 = "
                         f"{L0!r} m")
    sp = 0.5 * dx
    if axisymmetric:
        if not rough_floor:
            raise InputError("axisymmetric = True needs rough_floor = True: the floor of an "
                             "axisymmetric column is the no-slip grid floor")
        walls = []
        grid = Grid.covering(-dx, reach, -dx, H0 + 2.0 * dx, dx)
    else:
        kn = (mat.bulk_modulus + 4.0 * mat.shear_modulus / 3.0) / sp
        walls = [Plane((0.0, 0.0), (0.0, 1.0), kn, friction=floor_friction)]   # floor
        if not symmetric:
            walls.append(Plane((0.0, 0.0), (1.0, 0.0), kn, friction=wall_friction))  # wall
        grid = Grid.covering(-reach if symmetric else -dx, reach, -dx, H0 + 2.0 * dx, dx)
    v_fall = math.sqrt(2.0 * G_ACC * H0)
    dt = stable_dt(mat, dx, sp, walls, v_max=v_fall, cfl=cfl)
    if not (isinstance(flip, (int, float)) and 0.0 <= flip <= 1.0):
        raise InputError(f"flip = {flip!r}: must be in [0, 1] (0: APIC, 1: FLIP)")
    return MPMSystem(grid, mat, dt, frame=LabFrame((0.0, -G_ACC)), boundaries=walls,
                     no_slip_below=0.0 if rough_floor else None, flip=float(flip),
                     axisymmetric=bool(axisymmetric), transfers=transfers)


def column_state(system: MPMSystem, L0: float, H0: float, symmetric: bool = True) -> MPMState:
    """The column at rest behind its gate(s) (module docstring): points, lithostatic stress with
    Jaky's K_0, density of that pressure."""
    sp = 0.5 * system.grid.dx
    x = column_points(-L0 if symmetric and not system.axisymmetric else 0.0, L0, H0, sp)
    return lithostatic_state(system, x, np.full(len(x), H0))


def lithostatic_state(system: MPMSystem, x, surface) -> MPMState:
    """Points at x (N, 2) m on the lattice of spacing dx/2, at rest under a free surface at
    height surface (N,) m above each: sigma_zz = -rho_c g (surface - z), sigma_xx = sigma_yy =
    K_0 sigma_zz with Jaky's K_0 = 1 - sin(atan mu_s), the density rho_c exp(p / K) of that
    pressure (module docstring, "initial state"); masses rho_c (dx/2)^2 each, per metre, or
    times r per radian in an axisymmetric section."""
    mat = system.material
    sp = 0.5 * system.grid.dx
    axi = system.axisymmetric
    x = np.asarray(x, dtype=float)
    rho_c = mat.critical_density
    k0 = 1.0 - math.sin(math.atan(mat.mu_s))
    szz = -rho_c * G_ACC * (np.asarray(surface, dtype=float) - x[:, 1])
    stress = np.zeros((len(x), 4))
    stress[:, 1] = szz
    stress[:, 0] = stress[:, 3] = k0 * szz
    p = -(stress[:, 0] + stress[:, 1] + stress[:, 3]) / 3.0
    rho = rho_c * np.exp(p / mat.bulk_modulus) * 1.001
    # each point's volume holds the mass of its square at rho_c (mass conserved: m = rho_c sp^2,
    # per radian m = rho_c sp^2 r in an axisymmetric section)
    volume = rho_c * sp * sp / rho
    if axi:
        volume = volume * x[:, 0]
    return init_state(system, x, volume, rho, stress=stress)


def run_column(L0: float, H0: float, dx: float, material: ContinuumMaterial | None = None,
               floor_friction: float = 0.40, wall_friction: float = 0.0,
               symmetric: bool = True, t_min: float | None = None, t_max: float | None = None,
               ke_fraction: float = 1.0e-4, check_every: float | None = None,
               reach: float | None = None, cfl: float = 0.3,
               rough_floor: bool = False, flip: float = 0.0,
               axisymmetric: bool = False, transfers: int = 1) -> ColumnRun:
    """Release the column and run until it is at rest (module docstring).  Times in s; default
    t_min = 3 sqrt(H0/g), t_max = 30 sqrt(H0/g), checks every 0.1 sqrt(H0/g)."""
    system = column_system(L0, H0, dx, material, floor_friction, wall_friction, symmetric,
                           reach, cfl, rough_floor, flip, axisymmetric, transfers)
    state = column_state(system, L0, H0, symmetric)
    tau = math.sqrt(H0 / G_ACC)
    t_min = 3.0 * tau if t_min is None else float(t_min)
    t_max = 30.0 * tau if t_max is None else float(t_max)
    check = 0.1 * tau if check_every is None else float(check_every)
    if not 0 < ke_fraction < 1:
        raise InputError(f"ke_fraction = {ke_fraction!r}: must be in (0, 1)")
    if not 0 < t_min <= t_max:
        raise InputError(f"t_min = {t_min!r} s, t_max = {t_max!r} s: need 0 < t_min <= t_max")
    pe0 = float(state.mass.sum()) * G_ACC * 0.5 * H0   # per metre, or per radian
    n_check = max(int(round(check / system.dt)), 1)
    history = []
    settled = False
    ke = state.kinetic_energy()
    while state.t < t_max - 0.5 * system.dt:
        run_steps(system, state, n_check)
        ke = state.kinetic_energy()
        history.append((state.t, ke, float(np.abs(state.x[:, 0]).max())))
        if state.t >= t_min - 0.5 * system.dt and ke < ke_fraction * pe0:
            settled = True
            break
    return ColumnRun(L0=L0, H0=H0, dx=dx, material=system.material,
                     floor_friction=floor_friction, wall_friction=wall_friction,
                     symmetric=symmetric, state=state, t_end=state.t, settled=settled,
                     ke_ratio=ke / pe0, steps=state.step, history=history,
                     axisymmetric=bool(axisymmetric))
