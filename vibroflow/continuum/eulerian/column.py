"""The column collapse's set-up on the Eulerian mesh (plane strain or axisymmetric, lab frame).

The material point method's set-up (vibroflow.continuum.column: a column of half-width L0 and
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

The deposit is measured by vibroflow.measure.column from continuum.column.ColumnRun.
deposit_points: each cell holding material stands for its mass over the critical density (m^2
per metre of thickness), as the material point method's points.
"""
from __future__ import annotations

import math

import numpy as np

from ..bed import lithostatic
from ..column_setup import G_ACC, check_lengths, default_reach
from ..constitutive import ContinuumMaterial
from ..grid_update import LabFrame
from ..timestep import stable_dt
from .mesh import EulerianMesh
from .solver import EulerianState, EulerianSystem, init_state
from .wall import MeshWall


def column_system(L0: float, H0: float, dx: float, material: ContinuumMaterial | None = None,
                  floor_friction: float = 0.40, symmetric: bool = True,
                  reach: float | None = None, cfl: float = 0.3,
                  rough_floor: bool = False, axisymmetric: bool = False,
                  transfers: int = 1) -> EulerianSystem:
    """The Eulerian system of the column (module docstring); reach (m, from x = 0) default
    column_setup.default_reach, the material point method's; `rough_floor`: the no-slip grid floor;
    `axisymmetric`: a cylinder about x = 0 (`symmetric` is then ignored); `transfers`: APIC
    transfers a step (EulerianSystem.transfers; 1, the checks' setting)."""
    check_lengths(L0, H0, dx)
    mat = material or ContinuumMaterial()
    h = 0.5 * dx
    reach = default_reach(L0, H0) if reach is None else float(reach)
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
    of that pressure (the material point method's column_state)."""
    mesh = system.mesh
    mat = system.material
    h = mesh.h
    c = system.x
    xc = np.abs(c[:, 0]) if symmetric and not system.axisymmetric else c[:, 0]
    fx = np.clip((L0 - (xc - 0.5 * h)) / h, 0.0, 1.0)
    fz = np.clip((H0 - (c[:, 1] - 0.5 * h)) / h, 0.0, 1.0)
    frac = fx * fz
    stress, rho = lithostatic(mat.critical_density, G_ACC, np.clip(H0 - c[:, 1], 0.0, None),
                              mat.mu_s, mat.bulk_modulus, mask=frac > 0)
    rho = rho * 1.001  # the material point method's column_state
    return init_state(system, frac * rho * h * h * system.cell_weight, rho, stress=stress)
