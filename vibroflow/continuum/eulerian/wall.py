"""Wall contact of the Eulerian mesh: the Lagrangian formulation's penalty law on fixed cells.

The same law as vibroflow.continuum.boundary (its `_penalty` kernel is called, not copied): a
constant normal stiffness k_n (Pa/m) on the contact length, a dashpot of damping ratio zeta, an
elastic tangential slip spring truncated at the Coulomb limit mu_w F_n (Bardenhagen, Brackbill &
Sulsky 2000's frictional contact as a penalty).  What differs on a fixed mesh is where the
overclosure comes from: a material point of the Lagrangian method moves into the wall and its
overclosure is geometric; the material of a wall-layer cell (mesh.py) cannot enter the wall
(its faces there are closed), so the overclosure is the wall's own compression at that cell,
delta <- max(0, delta - v_n dt), the displacement of the material into the wall accumulated
while it presses on it (v_n = v . n, n the inward normal) and released as it leaves.  This is
exactly the Lagrangian point's overclosure for material that stays in contact, and it is a
property of the place (the wall), so it is kept per cell and not transported.

Contact: every wall-layer cell holding material presses on the wall, with the contact length
l = fill h, fill = min(1, m / (rho_c h^2)) its share of a cell full at the critical density: a
thin film on the floor is held up by its share of the wall, as a thin material point would be
(below FILL_MIN the cell is empty and its overclosure and slip are reset).  The contact's
frequency sqrt(k_n l / m) <= sqrt(k_n / (rho_c h)) whatever the cell holds (dilated material
included), so the Lagrangian time-step limit (timestep.py, point size h) holds for every cell.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numba as nb
import numpy as np

from vibroflow.errors import InputError

from ..boundary import _penalty

#: a wall-layer cell holding less than this share of a full cell's mass is empty
FILL_MIN = 1.0e-6


@nb.njit(cache=True)
def wall_forces(cells, normal, v, mass, rho_c, h, weight, delta, xi, fext, fn_out, ft_out,
                state_out, kn, kt, zeta, mu, dt):
    """Add the wall's force (N/m) on the wall-layer cells `cells` (indices) to fext (N, 2).
    normal (N, 2) inward unit normals; v (N, 2) m/s; mass (N,) kg/m; rho_c critical density
    (kg/m^3); h cell side (m); delta, xi (N,) normal overclosure and tangential slip (m),
    updated in place; fn_out, ft_out (N,) N/m and state_out (N,) int8 (0 none, 1 stick,
    2 slide) out.  weight (N,): the cells' weights (lagrangian_step.material_fraction), 1 in
    plane strain; in an axisymmetric section the radius r, where a cell's mass is per radian
    and its contact length sweeps l r: the plane law on the mass per metre m / r, its forces
    times r (N per radian)."""
    for j in range(cells.shape[0]):
        p = cells[j]
        nx = normal[p, 0]
        nz = normal[p, 1]
        w = weight[p]
        fill = mass[p] / (rho_c * h * h * w)
        if fill > 1.0:
            fill = 1.0
        if mass[p] <= 0.0 or fill < FILL_MIN:
            delta[p] = 0.0
            xi[p] = 0.0
            fn_out[p] = 0.0
            ft_out[p] = 0.0
            state_out[p] = 0
            continue
        vn = v[p, 0] * nx + v[p, 1] * nz
        d = delta[p] - vn * dt
        if d < 0.0:
            d = 0.0
        delta[p] = d
        l = fill * h
        if d <= 0.0:
            xi[p] = 0.0
        fx, fz, fn, ft, xn, st = _penalty(0.5 * l - d, nx, nz, v[p, 0], v[p, 1], mass[p] / w,
                                          l * l, xi[p], kn, kt, zeta, mu, dt)
        if st == 0:
            xn = 0.0
        fext[p, 0] += fx * w
        fext[p, 1] += fz * w
        xi[p] = xn
        fn_out[p] = fn * w
        ft_out[p] = ft * w
        state_out[p] = st


@dataclass
class MeshWall:
    """The mesh's wall (mesh.py wall layer): contact stiffness (Pa/m), Coulomb friction
    mu_w (-), damping ratio (-), k_t / k_n; the attributes timestep.stable_dt reads."""

    stiffness: float
    friction: float
    damping_ratio: float = 0.16
    tangential_ratio: float = 1.0

    def __post_init__(self):
        for name in ("stiffness", "friction", "damping_ratio", "tangential_ratio"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise InputError(f"wall {name} = {v!r}: must be a finite number >= 0")
        if not self.stiffness > 0:
            raise InputError(f"wall stiffness = {self.stiffness!r}: must be > 0 Pa/m")

    @property
    def tangential_stiffness(self) -> float:
        return self.stiffness * self.tangential_ratio


def wall_force_on_material(cells, normal, hist) -> np.ndarray:
    """(2,) the wall's force (N/m, x and z) on the material of the wall-layer cells `cells`
    (indices): their normal and tangential forces fn, ft (hist, empty_history's) along the
    inward normal n and t = (n_z, -n_x), as wall_forces adds them (boundary._penalty)."""
    fn, ft = hist["fn"][cells], hist["ft"][cells]
    nx, nz = normal[cells, 0], normal[cells, 1]
    return np.array([np.sum(fn * nx + ft * nz), np.sum(fn * nz - ft * nx)])


def wall_forces_by_cell(cells, normal, hist) -> np.ndarray:
    """(M, 2) the wall's force (N/m, x and z) on the material of each wall-layer cell of
    `cells`, the terms that wall_force_on_material sums."""
    fn, ft = hist["fn"][cells], hist["ft"][cells]
    nx, nz = normal[cells, 0], normal[cells, 1]
    return np.stack([fn * nx + ft * nz, fn * nz - ft * nx], axis=1)


def empty_history(n: int) -> dict:
    """Per-cell wall arrays: overclosure delta, slip xi (m), fn, ft (N/m), state (int8)."""
    return {"delta": np.zeros(n), "xi": np.zeros(n), "fn": np.zeros(n), "ft": np.zeros(n),
            "state": np.zeros(n, np.int8)}
