"""The granular column collapse on the Eulerian mesh (plane strain, lab frame).

The set-up of the Lagrangian check (vibroflow.continuum.column: a column of half-width L0 and
height H0 (m) on a floor z = 0, released at t = 0 under gravity, pre-stressed as it stood
behind its gates, run until its kinetic energy falls below a fraction of its initial potential
energy), on a fixed box mesh (mesh.EulerianMesh.box):

* symmetric (default, as the Lagrangian check): the whole column [-L0, L0] spreads both ways
  and the deposit is folded about x = 0 (the half-column against a frictionless wall); or the
  column [0, L0] against the mesh's wall at x = 0 (`symmetric=False`), which has the floor's
  friction (the mesh's walls share one law);
* the box's walls are the floor, the far ends at +-`reach` and a lid at 2 H0, all with the
  Coulomb friction `floor_friction` (0.40 by default, the Lagrangian check's) and the
  Lagrangian check's stiffness (the P-wave modulus over the cell side);
* rough floor (`rough_floor=True`): the experiments' rough bed as the Lagrangian check's
  no-slip grid condition (EulerianSystem.no_slip_below = 0: the solver grid's nodes on and
  below the floor held still), on top of the floor wall that carries the normal load, so that
  both formulations are run on the same floor (vibroflow.continuum.column, "rough floor");
* axisymmetric (`axisymmetric=True`): a cylinder of radius L0 about the axis x = r = 0
  (EulerianSystem.axisymmetric), the axisymmetric experiments of Lube et al. 2004 and
  Lajeunesse et al. 2004, as the Lagrangian check's; the mesh [0, reach] has no wall on the
  axis (mesh.EulerianMesh.box with axis=True).

The deposit is measured by vibroflow.measure.column from `deposit_points()`: each cell stands
for its mass over the critical density (m^2 per metre of thickness), as the Lagrangian's points.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vibroflow.errors import InputError

from ..constitutive import ContinuumMaterial
from ..grid_update import LabFrame
from ..timestep import stable_dt
from .mesh import EulerianMesh
from .solver import EulerianState, EulerianSystem, init_state, run_steps
from .wall import MeshWall

G_ACC = 9.81  # m/s^2


@dataclass
class EulerianColumnRun:
    """A finished column collapse: the final state, and how the run went (t_end s; settled:
    the kinetic energy fell below the threshold before t_max; ke_ratio: the last kinetic energy
    over the initial potential energy; mass_error: (M_end - M_0) / M_0)."""

    L0: float
    H0: float
    dx: float
    symmetric: bool
    axisymmetric: bool
    system: EulerianSystem
    state: EulerianState
    t_end: float
    settled: bool
    ke_ratio: float
    mass_error: float

    @property
    def aspect_ratio(self) -> float:
        return self.H0 / self.L0

    def deposit_points(self) -> tuple[np.ndarray, np.ndarray]:
        """(distance from the wall or symmetry plane (m), area (m^2 per metre)) of every cell
        holding material, for vibroflow.measure.column: its mass over the critical density
        (so the areas of a half-column add up to L0 H0); a symmetric run's cells are folded
        about x = 0 with half their area each; an axisymmetric run's cell stands for its
        meridian area, its mass per radian over rho_c r (the Lagrangian check's)."""
        st = self.state
        has = st.mass > 0
        x = st.x[has, 0]
        area = st.mass[has] / self.system.material.critical_density
        if self.axisymmetric:
            return x.copy(), area / x
        if self.symmetric:
            return np.abs(x), 0.5 * area
        return x.copy(), area

    def deposit(self, wall_window: float | None = None):
        """The deposit measured as every continuum's is (vibroflow.measure.column.
        measure_continuum_deposit of `deposit_points` on the mesh's cell side, grains of the
        material's diameter; the height within `wall_window` (m) of the wall or axis when
        given), as the Lagrangian ColumnRun.deposit."""
        from vibroflow.measure.column import measure_continuum_deposit

        return measure_continuum_deposit(*self.deposit_points(), self.system.mesh.h,
                                         self.system.material.diameter,
                                         wall_window=wall_window)


def column_system(L0: float, H0: float, dx: float, material: ContinuumMaterial | None = None,
                  floor_friction: float = 0.40, symmetric: bool = True,
                  reach: float | None = None, cfl: float = 0.3,
                  rough_floor: bool = False, axisymmetric: bool = False,
                  transfers: int = 1) -> EulerianSystem:
    """The Eulerian system of the column (module docstring); reach (m, from x = 0) default
    L0 (2 + 3 H0/L0), the Lagrangian check's; `rough_floor`: the no-slip grid floor;
    `axisymmetric`: a cylinder about x = 0 (`symmetric` is then ignored); `transfers`: APIC
    transfers a step (EulerianSystem.transfers; 1, the checks' setting)."""
    for name, v in (("L0", L0), ("H0", H0), ("dx", dx)):
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise InputError(f"column {name} = {v!r}: must be a finite length > 0 m")
    mat = material or ContinuumMaterial()
    h = 0.5 * dx
    reach = L0 * (2.0 + 3.0 * H0 / L0) if reach is None else float(reach)
    reach = h * math.ceil(reach / h - 1e-9)
    top = h * math.ceil(2.0 * H0 / h - 1e-9)
    if axisymmetric:
        mesh = EulerianMesh.box(0.0, reach, 0.0, top, dx, axis=True)
    else:
        mesh = EulerianMesh.box(-reach if symmetric else 0.0, reach, 0.0, top, dx)
    kn = (mat.bulk_modulus + 4.0 * mat.shear_modulus / 3.0) / h
    wall = MeshWall(stiffness=kn, friction=floor_friction, damping_ratio=0.5)
    dt = stable_dt(mat, dx, h, [wall], v_max=math.sqrt(2.0 * G_ACC * H0), cfl=cfl)
    return EulerianSystem(mesh, mat, dt, frame=LabFrame((0.0, -G_ACC)), wall=wall,
                          no_slip_below=0.0 if rough_floor else None,
                          axisymmetric=bool(axisymmetric), transfers=transfers)


def column_state(system: EulerianSystem, L0: float, H0: float,
                 symmetric: bool = True) -> EulerianState:
    """The column at rest behind its gates: cells of [-L0 or 0, L0] x [0, H0] filled (partly at
    its edges) at the critical density, the lithostatic stress with Jaky's K_0 and the density
    of that pressure (the Lagrangian check's column_state)."""
    mesh = system.mesh
    mat = system.material
    h = mesh.h
    c = system.x
    xc = np.abs(c[:, 0]) if symmetric and not system.axisymmetric else c[:, 0]
    fx = np.clip((L0 - (xc - 0.5 * h)) / h, 0.0, 1.0)
    fz = np.clip((H0 - (c[:, 1] - 0.5 * h)) / h, 0.0, 1.0)
    frac = fx * fz
    rho_c = mat.critical_density
    k0 = 1.0 - math.sin(math.atan(mat.mu_s))
    szz = -rho_c * G_ACC * np.clip(H0 - c[:, 1], 0.0, None) * (frac > 0)
    stress = np.zeros((mesh.n, 4))
    stress[:, 1] = szz
    stress[:, 0] = stress[:, 3] = k0 * szz
    p = -(stress[:, 0] + stress[:, 1] + stress[:, 3]) / 3.0
    rho = rho_c * np.exp(p / mat.bulk_modulus) * 1.001
    return init_state(system, frac * rho * h * h * system.cell_weight, rho, stress=stress)


def run_column(L0: float, H0: float, dx: float, material: ContinuumMaterial | None = None,
               floor_friction: float = 0.40, symmetric: bool = True,
               t_min: float | None = None, t_max: float | None = None,
               ke_fraction: float = 1.0e-4, reach: float | None = None,
               cfl: float = 0.3, rough_floor: bool = False,
               axisymmetric: bool = False, transfers: int = 1) -> EulerianColumnRun:
    """Release the column and run until it is at rest (the Lagrangian run_column's rule:
    after t_min = 3 sqrt(H0/g), the first check, every 0.1 sqrt(H0/g), with kinetic energy
    below ke_fraction M g H0 / 2; at most t_max = 30 sqrt(H0/g))."""
    system = column_system(L0, H0, dx, material, floor_friction, symmetric, reach, cfl,
                           rough_floor, axisymmetric, transfers)
    state = column_state(system, L0, H0, symmetric)
    tau = math.sqrt(H0 / G_ACC)
    t_min = 3.0 * tau if t_min is None else float(t_min)
    t_max = 30.0 * tau if t_max is None else float(t_max)
    if not 0 < ke_fraction < 1:
        raise InputError(f"ke_fraction = {ke_fraction!r}: must be in (0, 1)")
    pe0 = state.total_mass() * G_ACC * 0.5 * H0
    n_check = max(int(round(0.1 * tau / system.dt)), 1)
    settled = False
    ke = state.kinetic_energy()
    while state.t < t_max - 0.5 * system.dt:
        run_steps(system, state, n_check)
        ke = state.kinetic_energy()
        if state.t >= t_min - 0.5 * system.dt and ke < ke_fraction * pe0:
            settled = True
            break
    return EulerianColumnRun(L0=L0, H0=H0, dx=dx, symmetric=symmetric and not axisymmetric,
                             axisymmetric=bool(axisymmetric), system=system,
                             state=state, t_end=state.t,
                             settled=settled, ke_ratio=ke / pe0, mass_error=state.mass_error())
