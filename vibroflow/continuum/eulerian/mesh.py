"""The fixed Eulerian mesh: finite-volume cells that are also the fixed integration points.

The mesh is a structured lattice of square cells of side h = dx / 2 (m) on top of the solver's
node grid (vibroflow.continuum.grid, spacing dx), fixed in the solver's frame (the tub frame in
a tub run, so the walls never move on it).  Cell (i, k) is centred at
(xmin + (i + 1/2) h, zmin + (k + 1/2) h); it is a fixed integration point of the quadratic
B-spline finite elements of the nodes (2 x 2 points per element: the B-spline basis is fully
integrated, so the one-point-quadrature hourglass modes of bilinear elements never arise) and a
control volume of the conservative transport (advection.py).  Fields are kept per cell in flat
arrays indexed p = i * ncz + k.

Inside / wall: a cell is part of the material domain when its centre lies inside the container
(a level set: the signed distance to the wall, positive inside, e.g. vibroflow.tub.geometry's U).
A face between two domain cells is open; every other face is closed (no flux: the wall is
impermeable to mass).  Domain cells whose centre is less than h from the wall form the wall
layer: they carry the wall's penalty contact (wall.py) along the level set's inward normal.

Parts (continuum/part_obstacle.py): a tub's mesh with parts takes the least of the U's and the
parts' level sets (a part's signed distance is positive outside it, in the material): the cells
whose centre lies inside a part are outside the domain, their faces closed, and the domain
cells within h of the part form its wall layer, with the part's outward normal; `part_of` says
which part's (-1: the U's).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vibroflow.errors import InputError
from vibroflow.tub.geometry import distance_to_wall_np, u_wall_nearest

from ..boundary import part_section_nearest_np as section_nearest
from ..grid import Grid
from ..part_obstacle import packed_section


@dataclass
class EulerianMesh:
    """Cells of side h (m) covering [xmin, xmin + ncx h] x [zmin, zmin + ncz h] (m); grid: the
    node grid (spacing 2 h); inside (N,) bool; open_x (ncx + 1, ncz), open_z (ncx, ncz + 1) bool
    faces; wall (N,) bool wall layer with inward unit normals normal (N, 2); arc (N,) arc-length
    coordinate (m) of the nearest wall point (0 where unknown); periodic along x; part_of (N,)
    int64 the part whose wall layer a wall cell is in (-1: the U's; None: no parts)."""

    xmin: float
    zmin: float
    h: float
    ncx: int
    ncz: int
    grid: Grid
    inside: np.ndarray
    open_x: np.ndarray
    open_z: np.ndarray
    wall: np.ndarray
    normal: np.ndarray
    arc: np.ndarray
    periodic: bool = False
    part_of: np.ndarray | None = None

    @property
    def n(self) -> int:
        return self.ncx * self.ncz

    def centres(self) -> np.ndarray:
        """Cell centres (N, 2) (m), p = i * ncz + k."""
        xs = self.xmin + (np.arange(self.ncx) + 0.5) * self.h
        zs = self.zmin + (np.arange(self.ncz) + 0.5) * self.h
        X, Z = np.meshgrid(xs, zs, indexing="ij")
        return np.ascontiguousarray(np.stack([X.ravel(), Z.ravel()], axis=1))

    @classmethod
    def from_level_set(cls, xmin, xmax, zmin, zmax, dx, level_set, periodic=False):
        """Cells of side dx/2 covering [xmin, xmax] x [zmin, zmax] (m, widths multiples of
        dx/2); level_set(x, z) -> (gap (m, positive inside), nx, nz (inward normal), arc (m))
        on numpy arrays.  periodic: along x, with period xmax - xmin."""
        if not dx > 0:
            raise InputError(f"dx = {dx!r}: must be a length > 0 m")
        h = 0.5 * dx
        ncx = int(round((xmax - xmin) / h))
        ncz = int(round((zmax - zmin) / h))
        if ncx < 2 or ncz < 2:
            raise InputError(f"dx = {dx!r} m: the domain [{xmin}, {xmax}] x [{zmin}, {zmax}] "
                             "m must hold at least 2 cells each way")
        if periodic:
            grid = Grid.periodic_strip(ncx * h, zmin, zmin + ncz * h, dx)
            if abs(grid.x0 - xmin) > 1e-12:
                raise InputError(f"periodic mesh: xmin = {xmin!r} must be 0")
        else:
            grid = Grid.covering(xmin, xmin + ncx * h, zmin, zmin + ncz * h, dx)
        mesh = cls(xmin, zmin, h, ncx, ncz, grid, np.zeros(0, bool), np.zeros((0, 0), bool),
                   np.zeros((0, 0), bool), np.zeros(0, bool), np.zeros((0, 2)), np.zeros(0),
                   periodic)
        c = mesh.centres()
        gap, nx, nz, arc = level_set(c[:, 0], c[:, 1])
        inside = np.asarray(gap) > 0.0
        ins2 = inside.reshape(ncx, ncz)
        open_x = np.zeros((ncx + 1, ncz), bool)
        open_x[1:ncx] = ins2[:-1] & ins2[1:]
        if periodic:
            open_x[0] = open_x[ncx] = ins2[-1] & ins2[0]
        open_z = np.zeros((ncx, ncz + 1), bool)
        open_z[:, 1:ncz] = ins2[:, :-1] & ins2[:, 1:]
        wall = inside & (np.asarray(gap) < h)
        normal = np.zeros((mesh.n, 2))
        normal[wall, 0] = np.asarray(nx)[wall]
        normal[wall, 1] = np.asarray(nz)[wall]
        mesh.inside, mesh.open_x, mesh.open_z = inside, open_x, open_z
        mesh.wall, mesh.normal = wall, normal
        mesh.arc = np.where(wall, np.asarray(arc, dtype=float), 0.0)
        return mesh

    @classmethod
    def tub(cls, geometry, dx: float, parts: tuple = (), packed: tuple | None = None
            ) -> "EulerianMesh":
        """The U of vibroflow.tub.geometry (tub frame) up to its rim, cells of side dx/2 (m);
        dx must divide the tub's width 2R into an even number of cells.  parts (tub.parts.Part,
        spanning the slice) with their packing (part_obstacle.packed_section): obstacles in the
        U (module docstring), their section at the slice's middle (packed: computed when not
        given)."""
        R = geometry.radius
        h = 0.5 * dx
        n = 2.0 * R / h
        if abs(n - round(n)) > 1e-6:
            raise InputError(f"dx = {dx!r} m: must divide the tub's width {2 * R!r} m into "
                             "whole cells of dx/2")
        zmax = h * math.ceil(geometry.rim_height / h - 1e-9)

        y = 0.5 * geometry.length
        if parts and packed is None:
            packed = packed_section(parts)
        which = {}

        def level_set(x, z):
            out = np.array([u_wall_nearest(a, b, R) for a, b in zip(x, z)])
            gap = distance_to_wall_np(x, z, R)
            nx, nz, arc = out[:, 1], out[:, 2], out[:, 5]
            owner = np.full(np.shape(x), -1, np.int64)
            for k in range(len(parts)):
                pg, pnx, pnz = section_nearest(packed, k, y, x, z)
                nearer = pg < gap
                gap = np.where(nearer, pg, gap)
                nx, nz = np.where(nearer, pnx, nx), np.where(nearer, pnz, nz)
                arc = np.where(nearer, 0.0, arc)
                owner = np.where(nearer, k, owner)
            which["owner"] = owner
            return gap, nx, nz, arc

        mesh = cls.from_level_set(-R, R, 0.0, zmax, dx, level_set)
        if parts:
            mesh.part_of = np.where(mesh.wall, which["owner"], -1).astype(np.int64)
        return mesh

    @classmethod
    def box(cls, xmin, xmax, zmin, zmax, dx, periodic=False, axis=False) -> "EulerianMesh":
        """A rectangular container (walls on its four sides; periodic along x: the floor and
        the lid only; axis: no wall at x = xmin, the axis of an axisymmetric section, whose
        face there is closed but is not a wall (solver.EulerianSystem.axisymmetric)), cells of
        side dx/2 (m)."""
        def level_set(x, z):
            cand = [(z - zmin, 0.0, 1.0), (zmax - z, 0.0, -1.0)]
            if not periodic:
                if not axis:
                    cand.append((x - xmin, 1.0, 0.0))
                cand.append((xmax - x, -1.0, 0.0))
            d = np.stack([np.broadcast_to(c[0], x.shape) for c in cand])
            j = np.argmin(d, axis=0)
            nx = np.array([c[1] for c in cand])[j]
            nz = np.array([c[2] for c in cand])[j]
            return d.min(axis=0), nx, nz, np.where(j == 0, x, 0.0)

        return cls.from_level_set(xmin, xmax, zmin, zmax, dx, level_set, periodic=periodic)
