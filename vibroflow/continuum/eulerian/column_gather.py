"""The cells' APIC gather (g2p) as a pass along the node rows and one across the mesh's columns.

A point's gather (stencil.gather_point) sums over its 3 x 3 nodes w_a w_b u, w_a w_b u r and
the gradient's (g_a w_b, w_a g_b) u.  A fixed cell's weights are its column's times its row's
(transfer.py), so each sum splits: along z first, for each node row i and cell row kc,

    Zu = sum_b wz_b u[i, bz + b],  Zr = sum_b wz_b rz_b u[i, bz + b],  Zg = sum_b gz_b u[i, bz + b]

for both velocity components (`gather_rows`: shared by the two cell columns of a grid cell and by
the three columns whose stencil holds the node row), then across x for each cell (`gather_
columns`):

    v = sum_a wx_a Zu_a,   C = 4/dx^2 [sum_a wx_a rx_a Zu_a, sum_a wx_a Zr_a],
    L = [sum_a gx_a Zu_a, sum_a wx_a Zg_a]

(a the column's node rows).  84 products a cell instead of 126, and the pass across runs along
the column's cells, which lie one after the other in memory, in a loop that vectorises.  The
sums are gather_point's in another order: equal to its roundoff (tests/test_eulerian_kernels.py).
Only the cells holding material are written: the others keep what they hold.
"""
from __future__ import annotations

import numba as nb
import numpy as np

from .transfer import T_BASE, T_FX, T_G0, T_W0, stencil_rows

#: the row sums a node row holds for each cell row: Zu, Zr, Zg of each velocity component;
#: and for each z-face row, the vertical velocity's sum with the face row's weights (the face
#: velocities' pass along z: face_velocity.py)
ZU_X, ZU_Z, ZR_X, ZR_Z, ZG_X, ZG_Z, ZF_Z = range(7)


def gather_work(nx: int, ncz: int) -> np.ndarray:
    """The node rows' sums (nx, 7, ncz + 1) (`gather_rows`, m/s, m^2/s and 1/s)."""
    return np.zeros((nx, 7, ncz + 1))


@nb.njit(cache=True)
def gather_rows(i0, i1, ktop, tz, tfz, dx, gv, Z):
    """The sums along z (module docstring) of node rows i0:i1 of the grid velocity gv (nx, nz,
    2) (m/s) for the cell rows below ktop, with their weight table tz (transfer.WeightTables.
    cz) on a grid of spacing dx (m), into Z (nx, 7, ncz + 1); and Z[:, ZF_Z] of the z-face
    rows up to ktop (the top face of the highest cell holding material) with theirs, tfz
    (WeightTables.fz)."""
    nf = min(ktop + 1, tfz.shape[0])
    for i in range(i0, i1):
        zi = Z[i]
        gi = gv[i]
        for kc in range(ktop):
            bz = int(tz[kc, T_BASE])
            fz = tz[kc, T_FX]
            ux = 0.0
            uz = 0.0
            rx = 0.0
            rz = 0.0
            gx = 0.0
            gz = 0.0
            for b in range(3):
                w = tz[kc, T_W0 + b]
                g = tz[kc, T_G0 + b]
                wr = w * ((b - fz) * dx)
                u0 = gi[bz + b, 0]
                u1 = gi[bz + b, 1]
                ux += w * u0
                uz += w * u1
                rx += wr * u0
                rz += wr * u1
                gx += g * u0
                gz += g * u1
            zi[ZU_X, kc] = ux
            zi[ZU_Z, kc] = uz
            zi[ZR_X, kc] = rx
            zi[ZR_Z, kc] = rz
            zi[ZG_X, kc] = gx
            zi[ZG_Z, kc] = gz
        for kf in range(nf):
            bz = int(tfz[kf, T_BASE])
            s = 0.0
            for b in range(3):
                s += tfz[kf, T_W0 + b] * gi[bz + b, 1]
            zi[ZF_Z, kf] = s


@nb.njit(cache=True)
def gather_columns(c0, c1, ktop, ncz, tx, dx, periodic, Z, mass, v, C, L):
    """g2p of the cells of columns c0:c1 below cell row ktop that hold material (mass (N,)
    > 0): v (N, 2) m/s, C and L (N, 4) 1/s written in place from the node rows' sums Z
    (`gather_rows`), the columns' weights from tx (transfer.WeightTables.cx) on a grid of spacing
    dx (m), wrapped along x when periodic."""
    nxg = Z.shape[0]
    inv = 4.0 / (dx * dx)
    for ic in range(c0, c1):
        i0, i1, i2, w0, w1, w2 = stencil_rows(tx, ic, nxg, periodic)
        fx = tx[ic, T_FX]
        g0, g1, g2 = tx[ic, T_G0], tx[ic, T_G0 + 1], tx[ic, T_G0 + 2]
        r0, r1, r2 = w0 * ((0.0 - fx) * dx), w1 * ((1.0 - fx) * dx), w2 * ((2.0 - fx) * dx)
        za, zb, zc = Z[i0], Z[i1], Z[i2]
        p0 = ic * ncz
        for kc in range(ktop):
            p = p0 + kc
            if not mass[p] > 0.0:
                continue
            ax, bx_, cx = za[ZU_X, kc], zb[ZU_X, kc], zc[ZU_X, kc]
            az, bz, cz = za[ZU_Z, kc], zb[ZU_Z, kc], zc[ZU_Z, kc]
            v[p, 0] = w0 * ax + w1 * bx_ + w2 * cx
            v[p, 1] = w0 * az + w1 * bz + w2 * cz
            C[p, 0] = inv * (r0 * ax + r1 * bx_ + r2 * cx)
            C[p, 1] = inv * (w0 * za[ZR_X, kc] + w1 * zb[ZR_X, kc] + w2 * zc[ZR_X, kc])
            C[p, 2] = inv * (r0 * az + r1 * bz + r2 * cz)
            C[p, 3] = inv * (w0 * za[ZR_Z, kc] + w1 * zb[ZR_Z, kc] + w2 * zc[ZR_Z, kc])
            L[p, 0] = g0 * ax + g1 * bx_ + g2 * cx
            L[p, 1] = w0 * za[ZG_X, kc] + w1 * zb[ZG_X, kc] + w2 * zc[ZG_X, kc]
            L[p, 2] = g0 * az + g1 * bz + g2 * cz
            L[p, 3] = w0 * za[ZG_Z, kc] + w1 * zb[ZG_Z, kc] + w2 * zc[ZG_Z, kc]


def gather(ktop, tx, tz, tfz, dx, periodic, gv, Z, mass, v, C, L):
    """The whole gather on one thread: `gather_rows` over every node row, then
    `gather_columns` over every column; arguments as theirs."""
    gather_rows(0, Z.shape[0], ktop, tz, tfz, dx, gv, Z)
    gather_columns(0, tx.shape[0], ktop, tz.shape[0], tx, dx, periodic, Z, mass, v, C, L)
