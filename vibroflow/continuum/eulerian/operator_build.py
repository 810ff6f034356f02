"""The fixed cells' transfer operator, built as a pass along the mesh's columns and one across.

The operator (vibroflow.continuum.transfer_operator) is B_ij = sum_p m_p w_ip w_jp (1 + 4/dx^2
r_ip . r_jp).  A cell's weights are the product of its column's and its row's (transfer.py:
cell (i, k) at (xc_i, zc_k)), so with a = the stencil offset of node i along x, c that of
node j, b and d along z, inv = 4/dx^2, each pair factor splits by axis,

    w_ip w_jp (1 + inv r_ip . r_jp) = X1_ac Z0_bd + X0_ac Z1_bd,
    X1 = wx_a wx_c (1 + inv rx_a rx_c),  X0 = wx_a wx_c,
    Z0 = wz_b wz_d,  Z1 = inv wz_b wz_d rz_b rz_d,

and B = sum over the mesh's columns of X1 (S0 of the column) + X0 (S1 of the column), S0 and S1
the column's cells' masses times Z0 and Z1 summed onto the node rows (`operator_columns`), then
summed across the columns node row by node row (`operator_rows`).  A cell's 45 products are
replaced by 30 along its column (15 a factor: three node rows' five partners) and, a node
row, a few vectorised passes over the node columns; each entry is summed in a fixed order (the
columns in increasing order), whatever the threads.  The sums are the points' (transfer_
operator.operator_of_points) in another order: equal to them to roundoff, rows summing to the
node masses (tests/test_eulerian_kernels.py).

Tables (`OperatorTables`, constants of the run): xf (ncx, 2, 3, 5) each cell column's X1 and
X0 of its stencil's offset a and c - a + 2 (zero where c is off the stencil), zf (ncz, 2, 15)
each cell row's Z0 and Z1 of offset b and d - b + 2, flat (5 b + d - b + 2); and the node rows'
columns (transfer.node_row_columns).
"""
from __future__ import annotations

from collections import namedtuple

import numba as nb
import numpy as np

from ..transfer_operator import HALF
from .transfer import T_BASE, T_FX, T_W0, node_top

OperatorTables = namedtuple("OperatorTables", ["xf", "zf"])


@nb.njit(cache=True)
def axis_factors(table, dx, along_x):
    """(n, 2, 3, 5) per-axis pair factors of a weight table's rows (transfer.weight_table):
    [j, q, a, o] for offset a and o = c - a + 2, q = 0, 1: along x X1, X0, along z Z0, Z1
    (module docstring); zero where c is off the stencil (along x only o >= 2 is used: the
    forward offsets)."""
    inv = 4.0 / (dx * dx)
    n = table.shape[0]
    out = np.zeros((n, 2, 3, 5))
    for j in range(n):
        fx = table[j, T_FX]
        for a in range(3):
            for c in range(3):
                wa = table[j, T_W0 + a]
                wc = table[j, T_W0 + c]
                ra = (a - fx) * dx
                rc = (c - fx) * dx
                p = wa * wc
                if along_x:
                    out[j, 0, a, c - a + 2] = p * (1.0 + inv * (ra * rc))
                    out[j, 1, a, c - a + 2] = p
                else:
                    out[j, 0, a, c - a + 2] = p
                    out[j, 1, a, c - a + 2] = p * (inv * (ra * rc))
    return out


def operator_tables(tx, tz, dx: float) -> OperatorTables:
    """The OperatorTables of a mesh's weight tables tx (ncx, 8), tz (ncz, 8) (transfer.
    WeightTables.cx, cz) on a grid of spacing dx (m)."""
    return OperatorTables(axis_factors(tx, dx, True),
                          axis_factors(tz, dx, False).reshape(tz.shape[0], 2, 15))


def empty_tables() -> OperatorTables:
    """The tables of a run that makes one transfer a step (no operator)."""
    return OperatorTables(np.zeros((0, 2, 3, 5)), np.zeros((0, 2, 15)))


def operator_work(ncx: int, nx: int, nz: int):
    """The build's work arrays (`operator_columns`, `operator_rows`): S (ncx, 2, 5 nz) and the
    node rows' sums rows (nx, 3, 5 nz) (flat along k and db: numba's reshape of a view costs a
    call)."""
    return np.zeros((ncx, 2, 5 * nz)), np.zeros((nx, 3, 5 * nz))


@nb.njit(cache=True)
def operator_columns(c0, c1, ktop, mass2, tz, zf, S):
    """S (ncx, 2, 5 nz) of the cell columns c0:c1: each column's cells below row ktop of mass
    mass2 (ncx, ncz) (kg/m; those holding none left out) times their (Z0, Z1) summed onto the
    node rows of their stencil, S[ic, q, 5 k + db + 2] the sum for node row k and its partner
    k + db, up to the cells' stencils' top (transfer.node_top).  A cell adds its three node
    rows' 15 factors (zero off its stencil) in one run, two cells of a grid cell (the same
    base node row) together."""
    ne = 5 * node_top(ktop, tz)
    for ic in range(c0, c1):
        s0 = S[ic, 0]
        s1 = S[ic, 1]
        # (flat loops: numba's slice assignment is several times slower)
        for e in range(ne):
            s0[e] = 0.0
            s1[e] = 0.0
        kc = 0
        while kc < ktop:
            m = mass2[ic, kc]
            bz = int(tz[kc, T_BASE])
            two = kc + 1 < ktop and int(tz[kc + 1, T_BASE]) == bz
            m2 = mass2[ic, kc + 1] if two else 0.0
            m = m if m > 0.0 else 0.0
            m2 = m2 if m2 > 0.0 else 0.0
            if m > 0.0 or m2 > 0.0:
                e0 = bz * 5
                z0a, z1a = zf[kc, 0], zf[kc, 1]
                if two:
                    z0b, z1b = zf[kc + 1, 0], zf[kc + 1, 1]
                    for e in range(15):
                        s0[e0 + e] += m * z0a[e] + m2 * z0b[e]
                        s1[e0 + e] += m * z1a[e] + m2 * z1b[e]
                else:
                    for e in range(15):
                        s0[e0 + e] += m * z0a[e]
                        s1[e0 + e] += m * z1a[e]
            kc += 2 if two else 1


@nb.njit(cache=True)
def operator_rows(i0, i1, ktop, tz, S, xf, cols, col_a, ncols, rows, B):
    """Node rows i0:i1 of the operator B (nx, nz, HALF) (the stored forward half, transfer_
    operator.half_slot: slots db of da = 0, then 3 + 5 (da - 1) + db + 2) from the columns'
    sums S (`operator_columns`, cell rows below ktop, weight table tz), each entry summed over
    the node row's columns in increasing order, zero above the cells' stencils; rows (nx, 3,
    5 nz) a work array, row i's sums by da and 5 k + db + 2; xf the OperatorTables', cols,
    col_a, ncols the node rows' columns (transfer.node_row_columns)."""
    nz = B.shape[1]
    kk = node_top(ktop, tz)
    ne = kk * 5
    for i in range(i0, i1):
        t = rows[i]
        for da in range(3):
            td = t[da]
            for e in range(ne):
                td[e] = 0.0
        for j in range(ncols[i]):
            a = col_a[i, j]
            ic = cols[i, j]
            s0 = S[ic, 0]
            s1 = S[ic, 1]
            for da in range(3 - a):
                x1 = xf[ic, 0, a, da + 2]
                x0 = xf[ic, 1, a, da + 2]
                td = t[da]
                for e in range(ne):
                    td[e] += x1 * s0[e] + x0 * s1[e]
        for k in range(kk):
            for o in range(3):
                B[i, k, o] = t[0, 5 * k + o + 2]
            for o in range(5):
                B[i, k, 3 + o] = t[1, 5 * k + o]
                B[i, k, 8 + o] = t[2, 5 * k + o]
        for k in range(kk, nz):
            for o in range(HALF):
                B[i, k, o] = 0.0
