"""The background grid of the material point method (Sulsky, Chen & Schreyer 1994).

A uniform Cartesian grid of nodes x_i = x0 + i dx, z_k = z0 + k dx (m), i < nx, k < nz, in the
frame the solver works in (the tub frame for tub runs).  Shape functions are quadratic B-splines
(Steffen, Kirby & Berzins 2008; stencil.py), C1 and positive, so a point's 3 x 3 nodes carry its
mass and the grid velocity gradient is continuous; for them the APIC inertia tensor is
D = dx^2/4 I (Jiang et al. 2015, section 5.1).

Grid arrays are (nx, nz) node masses (kg per metre of thickness), (nx, nz, 2) momenta and forces;
the solver reuses them every step.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vibroflow.errors import InputError

#: nodes kept free of material at each edge of the grid (a point's stencil reaches 1 node beyond
#: its cell, and the outermost nodes are held still)
GUARD = 3


@dataclass(frozen=True)
class Grid:
    """Uniform grid: origin (x0, z0) (m), spacing dx (m), nx x nz nodes; periodic: wraps
    around along x with period nx dx (node nx is node 0)."""

    x0: float
    z0: float
    dx: float
    nx: int
    nz: int
    periodic: bool = False

    def __post_init__(self):
        if not self.dx > 0:
            raise InputError(f"grid spacing dx = {self.dx!r}: must be > 0 m")
        if self.nx < (3 if self.periodic else 2 * GUARD + 1) or self.nz < 2 * GUARD + 1:
            raise InputError(f"grid = {self.nx} x {self.nz} nodes: must be at least "
                             f"{2 * GUARD + 1} each way")

    @classmethod
    def covering(cls, xmin: float, xmax: float, zmin: float, zmax: float, dx: float) -> "Grid":
        """A grid with node spacing dx (m) covering [xmin, xmax] x [zmin, zmax] (m) with GUARD
        extra nodes on every side; nodes sit on multiples of dx."""
        if not dx > 0:
            raise InputError(f"grid spacing dx = {dx!r}: must be > 0 m")
        i0 = int(np.floor(xmin / dx)) - GUARD
        k0 = int(np.floor(zmin / dx)) - GUARD
        i1 = int(np.ceil(xmax / dx)) + GUARD
        k1 = int(np.ceil(zmax / dx)) + GUARD
        return cls(i0 * dx, k0 * dx, dx, i1 - i0 + 1, k1 - k0 + 1)

    @classmethod
    def periodic_strip(cls, width: float, zmin: float, zmax: float, dx: float) -> "Grid":
        """A grid periodic along x over [0, width) (width a multiple of dx, m) covering
        [zmin, zmax] (m) with GUARD extra nodes below and above."""
        n = int(round(width / dx))
        if n < 3 or abs(n * dx - width) > 1e-9 * width:
            raise InputError(f"periodic width = {width!r} m: must be a multiple (>= 3) of "
                             f"dx = {dx!r} m")
        k0 = int(np.floor(zmin / dx)) - GUARD
        k1 = int(np.ceil(zmax / dx)) + GUARD
        return cls(0.0, k0 * dx, dx, n, k1 - k0 + 1, periodic=True)

    def zeros(self):
        """Fresh grid arrays (mass (nx, nz), momentum (nx, nz, 2), force (nx, nz, 2),
        velocity (nx, nz, 2))."""
        return (np.zeros((self.nx, self.nz)), np.zeros((self.nx, self.nz, 2)),
                np.zeros((self.nx, self.nz, 2)), np.zeros((self.nx, self.nz, 2)))

    def node_x(self) -> np.ndarray:
        return self.x0 + self.dx * np.arange(self.nx)

    def node_z(self) -> np.ndarray:
        return self.z0 + self.dx * np.arange(self.nz)

    def rows_at_or_below(self, z, name: str = "no_slip_below") -> int:
        """The number of node rows k with z0 + k dx <= z (m; a node on z included): the rows a
        no-slip floor at height z holds still.  `name` is the field the one-line error names."""
        if not (isinstance(z, (int, float)) and math.isfinite(z) and self.z0 <= z):
            raise InputError(f"{name} = {z!r} m: must be a finite height at or above the "
                             f"grid's bottom {self.z0!r} m")
        return int(math.floor((z - self.z0) / self.dx + 1e-9)) + 1

    def inner_bounds(self):
        """(xmin, xmax, zmin, zmax) (m) of the region points may occupy (GUARD nodes in; the
        whole period along x on a periodic grid)."""
        if self.periodic:
            return (self.x0, self.x0 + self.nx * self.dx, self.z0 + GUARD * self.dx,
                    self.z0 + (self.nz - 1 - GUARD) * self.dx)
        return (self.x0 + GUARD * self.dx, self.x0 + (self.nx - 1 - GUARD) * self.dx,
                self.z0 + GUARD * self.dx, self.z0 + (self.nz - 1 - GUARD) * self.dx)
