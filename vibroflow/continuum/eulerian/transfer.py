"""Cells to nodes and back with the B-spline weights of the fixed mesh, computed once a run.

The Eulerian mesh never moves on the solver's grid (mesh.py), so the quadratic B-spline weights
of its cell centres and face midpoints are constants of the run; the generic transfers
(vibroflow.continuum.p2g, g2p) recompute them for every point and every step, which was a
third of their time.  A cell (i, k) is centred at (xc_i, zc_k), so its weights are the product
of a weight of row i and one of column k: four one-dimensional tables (`WeightTables`: cell
centres and face midpoints along x and along z, a few hundred numbers) hold them all.

The kernels here are p2g.p2g and g2p.g2p on the cells holding material, the weights read from
the tables instead of computed and the stencil the same (stencil.scatter_point, gather_point),
so they give the generic kernels' numbers bit for bit (tests/test_eulerian_kernels.py); they
read and write the per-cell arrays through the cells' indices, so the cells' fields need not be
copied into compact arrays first.  The cells stay put: no point advection, no FLIP blend (the
Eulerian's g2p is APIC), plane strain.  For the same reason the transfer operator's pair
factors of every cell (vibroflow.continuum.transfer_operator) are made once a run
(`operator_factors`), and a step's operator is the cells' masses times them
(`operator_of_cells`), operator_of_points' numbers bit for bit.
"""
from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

from ..g2p import store_gather
from ..stencil import bspline_weights, gather_point, scatter_point
from ..transfer_operator import PAIRS, add_factors, point_factors

#: columns of a weight table's row: the base node (an integer stored as a float), fx, the
#: three weights and their three derivatives (1/m), as stencil.bspline_weights returns them
T_BASE, T_FX, T_W0, T_W1, T_W2, T_G0, T_G1, T_G2 = range(8)


@nb.njit(cache=True)
def weight_table(coords, x0, dx):
    """(n, 8) rows of stencil.bspline_weights (T_* columns) of the coordinates (n,) (m) on a
    grid axis of origin x0 and spacing dx (m)."""
    out = np.empty((coords.shape[0], 8))
    for j in range(coords.shape[0]):
        b, f, w0, w1, w2, g0, g1, g2 = bspline_weights(coords[j], x0, dx)
        out[j, T_BASE] = b
        out[j, T_FX] = f
        out[j, T_W0] = w0
        out[j, T_W1] = w1
        out[j, T_W2] = w2
        out[j, T_G0] = g0
        out[j, T_G1] = g1
        out[j, T_G2] = g2
    return out


@nb.njit(cache=True)
def _face_coords(lo, h, n):
    """lo + i h for i < n (m): the face positions as face_velocity.face_velocities computed them,
    the same floating-point operations, so the tables hold the same weights."""
    out = np.empty(n)
    for i in range(n):
        out[i] = lo + i * h
    return out


@dataclass
class WeightTables:
    """B-spline weight tables (weight_table rows) of a mesh on its grid: cx (ncx, 8) of the
    cell centres' x, cz (ncz, 8) of their z, fx (ncx + 1, 8) of the x-faces' x, fz (ncz + 1, 8)
    of the z-faces' z."""

    cx: np.ndarray
    cz: np.ndarray
    fx: np.ndarray
    fz: np.ndarray

    @classmethod
    def of_mesh(cls, mesh, centres) -> "WeightTables":
        """The tables of an EulerianMesh whose cell centres are `centres` (N, 2) (m, mesh.
        centres(): cell (i, k)'s x is the same number for every k, its z for every i)."""
        g = mesh.grid
        c = centres.reshape(mesh.ncx, mesh.ncz, 2)
        return cls(weight_table(np.ascontiguousarray(c[:, 0, 0]), g.x0, g.dx),
                   weight_table(np.ascontiguousarray(c[0, :, 1]), g.z0, g.dx),
                   weight_table(_face_coords(mesh.xmin, mesh.h, mesh.ncx + 1), g.x0, g.dx),
                   weight_table(_face_coords(mesh.zmin, mesh.h, mesh.ncz + 1), g.z0, g.dx))


@nb.njit(cache=True, inline="always")
def table_row(table, j):
    """Row j of a weight_table as stencil.bspline_weights returns it: (base node, fx, the three
    weights, their three derivatives)."""
    return (int(table[j, T_BASE]), table[j, T_FX], table[j, T_W0], table[j, T_W1],
            table[j, T_W2], table[j, T_G0], table[j, T_G1], table[j, T_G2])


@nb.njit(cache=True)
def p2g_cells(cells, ncz, tx, tz, v, C, mass, volume, stress, fext, dx, periodic, inv_r, gm,
              gmv, gf):
    """p2g.p2g of the cells `cells` (indices p = i * ncz + k, in the order given) with the
    weights of rows tx[i] and tz[k] (WeightTables.cx, cz): accumulates into gm, gmv, gf (zero
    them first).  v (N, 2), C (N, 4), mass, volume (N,), stress (N, 4), fext (N, 2) the
    per-cell arrays (units as p2g.p2g); inv_r (N,): 0 in plane strain, 1 / r of the cells'
    centres in an axisymmetric section (masses and volumes per radian), whose radial force
    gains p2g.p2g's hoop term -V sigma_theta w / r (sigma_theta the stress's yy slot)."""
    for j in range(cells.shape[0]):
        p = cells[j]
        ic = p // ncz
        kc = p - ic * ncz
        # (+ 0.0: a plane section's -0.0 made +0.0, so that fex + hoop is fex bit for bit)
        hoop = -volume[p] * stress[p, 3] * inv_r[p] + 0.0
        scatter_point(table_row(tx, ic), table_row(tz, kc), dx, periodic, mass[p], volume[p],
                      stress[p, 0], stress[p, 1], stress[p, 2], v[p, 0], v[p, 1], C[p, 0],
                      C[p, 1], C[p, 2], C[p, 3], fext[p, 0] + hoop, fext[p, 1], gm, gmv, gf)


@nb.njit(cache=True)
def g2p_cells(cells, ncz, tx, tz, v, C, L, gv, dx, periodic):
    """g2p.g2p (APIC, no FLIP blend, the points not moved) of the cells `cells` (indices) with
    the weights of rows tx[i] and tz[k]: their v (N, 2) m/s, C and L (N, 4) 1/s written in
    place from the grid velocity gv (nx, nz, 2) (m/s)."""
    for j in range(cells.shape[0]):
        p = cells[j]
        ic = p // ncz
        kc = p - ic * ncz
        g = gather_point(table_row(tx, ic), table_row(tz, kc), dx, periodic, gv)
        store_gather(p, g[0], g[1], g, v, C, L)


@nb.njit(cache=True)
def operator_factors(ncx, ncz, tx, tz, dx):
    """(ncx ncz, PAIRS) the transfer operator's pair factors of every cell p = i * ncz + k
    (transfer_operator.point_factors) with the weights of rows tx[i] and tz[k]: constants of
    the run, as the weights are, so that a step's operator is only the masses times them."""
    out = np.empty((ncx * ncz, PAIRS))
    for ic in range(ncx):
        _, fx, wx0, wx1, wx2, _, _, _ = table_row(tx, ic)
        for kc in range(ncz):
            _, fz, wz0, wz1, wz2, _, _, _ = table_row(tz, kc)
            point_factors(fx, wx0, wx1, wx2, fz, wz0, wz1, wz2, dx, out[ic * ncz + kc])
    return out


@nb.njit(cache=True)
def operator_of_cells(cells, ncz, tx, tz, factors, mass, periodic, B):
    """Accumulate the transfer operator (vibroflow.continuum.transfer_operator) of the cells
    `cells` (indices p = i * ncz + k) of masses mass (N,) (kg/m) into B (nx, nz, HALF) (zero
    it first), with the base nodes of rows tx[i] and tz[k] and the cells' pair factors
    (`operator_factors`): transfer_operator.operator_of_points of the cell centres, bit for
    bit.  Two cells next to each other in a column whose stencils share their base nodes (two
    of a grid cell's, the cells being half its size) are added in one pass (add_factors:
    the same terms in the same order, each entry read and written once instead of twice)."""
    n = cells.shape[0]
    j = 0
    while j < n:
        p = cells[j]
        ic = p // ncz
        kc = p - ic * ncz
        bx = int(tx[ic, T_BASE])
        bz = int(tz[kc, T_BASE])
        two = j + 1 < n and cells[j + 1] == p + 1 and kc + 1 < ncz and \
            int(tz[kc + 1, T_BASE]) == bz
        q = p + 1 if two else p
        add_factors(B, bx, bz, periodic, mass[p], factors[p], mass[q], factors[q], two)
        j += 2 if two else 1
