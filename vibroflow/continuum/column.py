"""The granular column collapse, by any continuum formulation (continuum.formulation; plane
strain or axisymmetric, lab frame).

A rectangular column of the continuum, half-width L0 and height H0 (m), stands on a floor z = 0
and is released at t = 0 under gravity: it slumps and spreads until it comes to rest.  This is
the planar column of the channel experiments (Lube, Huppert, Sparks & Freundt 2005, Phys. Rev. E
72, 041301, released on both sides; Lajeunesse, Monnier & Homsy 2005, Phys. Fluids 17, 103302,
against a wall) and of the mu(I) continuum simulations of Lagree, Staron & Popinet (2011,
J. Fluid Mech. 686, 378) and Dunatunga & Kamrin (2015, J. Fluid Mech. 779, 483, section 5.2, the
same elasto-viscoplastic MPM as this package's); its deposit is measured by
`vibroflow.measure.column` from `ColumnRun.deposit_points()`.  `run_column` runs it with the
material point method (method "lagrangian", mpm/column.py) or on the fixed mesh ("eulerian",
eulerian/column.py: a box mesh whose walls share the floor's law, the same floor, initial state
and stopping rule).  The figures below are the material point method's.

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
  across one point), as in the block test of tests/test_continuum_walls.py;
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
  first ring with elastic waves of the weight's size (bed.lithostatic);
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
from vibroflow.measure.column import measure_continuum_deposit

from .column_setup import G_ACC
from .constitutive import ContinuumMaterial
from .formulation import formulation


@dataclass
class ColumnRun:
    """A finished column collapse: the final state and how the run went.

    method: the formulation; system, state: its records (points or cells: x (N, 2) m, mass (N,)
    kg/m or kg/rad, ...); t_end (s); settled: the kinetic energy fell below the threshold
    before t_max; ke_ratio: the last kinetic energy over the initial potential energy;
    mass_error: (M_end - M_0) / M_0; history: (t, kinetic energy, front distance (m)) at each
    check."""

    method: str
    L0: float
    H0: float
    dx: float
    material: ContinuumMaterial
    floor_friction: float
    wall_friction: float
    symmetric: bool
    axisymmetric: bool
    system: object
    state: object
    t_end: float
    settled: bool
    ke_ratio: float
    mass_error: float
    steps: int
    history: list

    @property
    def aspect_ratio(self) -> float:
        return self.H0 / self.L0

    @property
    def point_side(self) -> float:
        """The initial point spacing, or the mesh's cell side, dx/2 (m)."""
        return 0.5 * self.dx

    def deposit_points(self) -> tuple[np.ndarray, np.ndarray]:
        """(distance from the wall, symmetry plane or axis (m), area (m^2 per metre)) of every
        point or cell holding material, for vibroflow.measure.column: the area is its mass over
        the critical density (the column's, to 1e-3), so the areas of a half-column add up to
        L0 H0; a symmetric run's are folded about x = 0 with half their area each; an
        axisymmetric run's area is the meridian area V / r of its volume per radian V, so that
        the thickness profile (area per bin width) is the deposit's thickness h(r) (the volume
        h r dr per radian of an annulus over r dr)."""
        x, mass, _ = formulation(self.method).column_deposit(self.system, self.state)
        area = mass / self.material.critical_density
        if self.axisymmetric:
            return x.copy(), area / x
        if self.symmetric:
            return np.abs(x), 0.5 * area
        return x.copy(), area

    def deposit(self, wall_window: float | None = None):
        """The deposit measured as every continuum's is (vibroflow.measure.column.
        measure_continuum_deposit of `deposit_points` on the point or cell side, grains of the
        material's diameter; the height within `wall_window` (m) of the wall or axis when
        given)."""
        side = formulation(self.method).column_deposit(self.system, self.state)[2]
        return measure_continuum_deposit(*self.deposit_points(), side, self.material.diameter,
                                         wall_window=wall_window)


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



def run_column(L0: float, H0: float, dx: float, material: ContinuumMaterial | None = None,
               floor_friction: float = 0.40, wall_friction: float = 0.0,
               symmetric: bool = True, t_min: float | None = None, t_max: float | None = None,
               ke_fraction: float = 1.0e-4, check_every: float | None = None,
               reach: float | None = None, cfl: float = 0.3,
               rough_floor: bool = False, flip: float = 0.0,
               axisymmetric: bool = False, transfers: int = 1,
               method: str = "lagrangian") -> ColumnRun:
    """Release the column and run it with the formulation `method` until it is at rest (module
    docstring).  Times in s; default t_min = 3 sqrt(H0/g), t_max = 30 sqrt(H0/g), checks every
    0.1 sqrt(H0/g).  The set-up's arguments: Formulation.column_system (mpm/column.py,
    eulerian/column.py)."""
    form = formulation(method)
    system = form.column_system(L0, H0, dx, material, floor_friction, wall_friction, symmetric,
                                reach, cfl, rough_floor, flip, axisymmetric, transfers)
    state = form.column_state(system, L0, H0, symmetric)
    tau = math.sqrt(H0 / G_ACC)
    t_min = 3.0 * tau if t_min is None else float(t_min)
    t_max = 30.0 * tau if t_max is None else float(t_max)
    check = 0.1 * tau if check_every is None else float(check_every)
    if not 0 < ke_fraction < 1:
        raise InputError(f"ke_fraction = {ke_fraction!r}: must be in (0, 1)")
    if not 0 < t_min <= t_max:
        raise InputError(f"t_min = {t_min!r} s, t_max = {t_max!r} s: need 0 < t_min <= t_max")
    m0 = float(state.mass.sum())
    pe0 = m0 * G_ACC * 0.5 * H0   # per metre, or per radian
    n_check = max(int(round(check / system.dt)), 1)
    history = []
    settled = False
    ke = state.kinetic_energy()
    while state.t < t_max - 0.5 * system.dt:
        form.advance(system, state, n_check)
        ke = state.kinetic_energy()
        history.append((state.t, ke, float(np.abs(state.x[state.mass > 0, 0]).max())))
        if state.t >= t_min - 0.5 * system.dt and ke < ke_fraction * pe0:
            settled = True
            break
    return ColumnRun(method=method, L0=L0, H0=H0, dx=dx, material=system.material,
                     floor_friction=floor_friction, wall_friction=wall_friction,
                     symmetric=symmetric, axisymmetric=bool(axisymmetric), system=system,
                     state=state, t_end=state.t, settled=settled, ke_ratio=ke / pe0,
                     mass_error=(float(state.mass.sum()) - m0) / m0, steps=state.step,
                     history=history)
