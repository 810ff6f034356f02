"""Cells to nodes and back with the B-spline weights of the fixed mesh, computed once a run.

The Eulerian mesh never moves on the solver's grid (mesh.py), so the quadratic B-spline weights
of its cell centres and face midpoints are constants of the run; the generic transfers
(vibroflow.continuum.p2g, g2p) recompute them for every point and every step, which was a
third of their time.  A cell (i, k) is centred at (xc_i, zc_k), so its weights are the product
of a weight of row i and one of column k: four one-dimensional tables (`WeightTables`: cell
centres and face midpoints along x and along z, a few hundred numbers) hold them all.

Because a cell's weight is its column's times its row's, the cells' scatter, gather and
transfer operator each split into a pass along one axis and one along the other
(column_scatter.py, column_gather.py, operator_build.py): the tables here, and the cell columns
whose stencils hold each node row (`node_row_columns`), which fix the order in which the
passes across the columns sum a node's terms.
"""
from __future__ import annotations

from collections import namedtuple
from dataclasses import dataclass

import numba as nb
import numpy as np

from ..stencil import bspline_weights

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


@nb.njit(cache=True, inline="always")
def stencil_rows(table, j, nxg, periodic):
    """Row j of a weight table along x (`weight_table`): the three node rows of its stencil
    (wrapped on a periodic grid of nxg node rows) and their weights."""
    b = int(table[j, T_BASE])
    n0, n1, n2 = b, b + 1, b + 2
    if periodic:
        n0, n1, n2 = n0 % nxg, n1 % nxg, n2 % nxg
    return n0, n1, n2, table[j, T_W0], table[j, T_W0 + 1], table[j, T_W0 + 2]


@nb.njit(cache=True)
def node_top(ktop, tz):
    """The node rows up to the top of the stencils of the cell rows below ktop (their highest
    node row + 1), tz the cell rows' weight table (WeightTables.cz)."""
    return int(tz[ktop - 1, T_BASE]) + 3 if ktop > 0 else 0


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


#: the node rows' cell columns (`node_row_columns`): cols (nx, w) the cell columns whose
#: stencil holds the node row, in increasing order (-1 beyond ncols), col_a (nx, w) the node
#: row's offset in their stencil, ncols (nx,) how many
NodeRowColumns = namedtuple("NodeRowColumns", ["cols", "col_a", "ncols"])


def node_row_columns(tx, nx: int, periodic: bool) -> NodeRowColumns:
    """The NodeRowColumns of the cell columns' weight table tx (ncx, 8) (WeightTables.cx) on a
    grid of nx node rows, wrapped along x when periodic: the passes across the columns
    (column_scatter.py, operator_build.py) sum each node row's columns in this order."""
    base = tx[:, T_BASE].astype(np.int64)
    lists: list[list[tuple[int, int]]] = [[] for _ in range(nx)]
    for ic, b in enumerate(base):
        for a in range(3):
            i = b + a
            if periodic:
                i %= nx
            elif not 0 <= i < nx:
                raise ValueError(f"cell column {ic}'s stencil leaves the grid's {nx} node rows")
            lists[i].append((ic, a))
    width = max(1, max(len(x) for x in lists))
    cols = np.full((nx, width), -1, np.int64)
    col_a = np.zeros((nx, width), np.int64)
    ncols = np.zeros(nx, np.int64)
    for i, entries in enumerate(sorted(e) for e in lists):
        ncols[i] = len(entries)
        for j, (ic, a) in enumerate(entries):
            cols[i, j] = ic
            col_a[i, j] = a
    return NodeRowColumns(cols, col_a, ncols)
