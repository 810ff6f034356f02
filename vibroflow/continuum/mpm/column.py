"""The column collapse's set-up on the material point method (the column and its floor,
continuum.column's module docstring says why each choice): points on a square lattice of
spacing dx/2 (2 x 2 a cell) filling the column, pre-stressed as it stood behind its gate(s)
(bed.lithostatic); the floor a penalty `Plane` with Coulomb friction, its stiffness the P-wave
modulus over the point side, or the no-slip grid floor (MPMSystem.no_slip_below); the wall
variant a penalty `Plane` at x = 0; the axisymmetric column the half-plane r >= 0
(MPMSystem.axisymmetric), points of mass rho_c sp^2 r per radian; the time step the stable
step of timestep.py with the free-fall speed sqrt(2 g H0) as the material speed bound."""
from __future__ import annotations

import math

import numpy as np

from vibroflow.errors import InputError

from ..bed import lithostatic
from ..boundary import Plane
from ..column_setup import G_ACC, check_lengths, default_reach
from ..constitutive import ContinuumMaterial
from ..grid import Grid
from ..grid_update import LabFrame
from ..timestep import stable_dt
from .solver import MPMState, MPMSystem, init_state


def column_points(x0: float, x1: float, H0: float, spacing: float) -> np.ndarray:
    """Points on a square lattice of `spacing` (m) filling [x0, x1] x [0, H0] (m), each at the
    centre of its own square."""
    xs = x0 + (np.arange(int(round((x1 - x0) / spacing))) + 0.5) * spacing
    zs = (np.arange(int(round(H0 / spacing))) + 0.5) * spacing
    X, Z = np.meshgrid(xs, zs, indexing="ij")
    return np.stack([X.ravel(), Z.ravel()], axis=1)


def _check_size(L0, H0, dx):
    """column_setup.check_lengths, and L0 and H0 whole numbers (>= 2) of point spacings."""
    check_lengths(L0, H0, dx)
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
    """The MPM system of a column of half-width L0 and height H0 (m) on grid spacing dx (m): floor z
    = 0 with Coulomb friction `floor_friction`, and no slip if `rough_floor`; symmetric
    (continuum.column), or a wall x = 0 with `wall_friction`; a grid reaching `reach` (m, default
    column_setup.default_reach) from x = 0 (both ways when symmetric); `flip` the FLIP fraction of
    the points' velocity update (MPMSystem.flip; continuum.column); `axisymmetric`: the cylindrical
    column of radius L0 (continuum.column; needs the rough floor, `symmetric` does not apply);
    `transfers`: APIC transfers a step (MPMSystem.transfers; 1, the checks' setting, unless a study
    holds the transfers' damping across grids: benchmarks/column_convergence.py)."""
    _check_size(L0, H0, dx)
    mat = material or ContinuumMaterial()
    for name, mu in (("floor_friction", floor_friction), ("wall_friction", wall_friction)):
        if not (isinstance(mu, (int, float)) and math.isfinite(mu) and mu >= 0):
            raise InputError(f"{name} = {mu!r}: must be a finite number >= 0")
    reach = default_reach(L0, H0) if reach is None else float(reach)
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
    """The column at rest behind its gate(s) (continuum.column): points, lithostatic stress with
    Jaky's K_0, density of that pressure."""
    sp = 0.5 * system.grid.dx
    x = column_points(-L0 if symmetric and not system.axisymmetric else 0.0, L0, H0, sp)
    return lithostatic_state(system, x, np.full(len(x), H0))


def lithostatic_state(system: MPMSystem, x, surface) -> MPMState:
    """Points at x (N, 2) m on the lattice of spacing dx/2, at rest under a free surface at height
    surface (N,) m above each (bed.lithostatic: sigma_zz = -rho_c g (surface - z), sigma_xx =
    sigma_yy = K_0 sigma_zz, the density of that pressure times 1.001); masses rho_c (dx/2)^2 each,
    per metre, or times r per radian in an axisymmetric section."""
    mat = system.material
    sp = 0.5 * system.grid.dx
    axi = system.axisymmetric
    x = np.asarray(x, dtype=float)
    rho_c = mat.critical_density
    stress, rho = lithostatic(rho_c, G_ACC, np.asarray(surface, dtype=float) - x[:, 1],
                              mat.mu_s, mat.bulk_modulus)
    # just above the critical density, so that every point carries stress
    rho = rho * 1.001
    # each point's volume holds the mass of its square at rho_c (mass conserved: m = rho_c sp^2,
    # per radian m = rho_c sp^2 r in an axisymmetric section)
    volume = rho_c * sp * sp / rho
    if axi:
        volume = volume * x[:, 0]
    return init_state(system, x, volume, rho, stress=stress)
