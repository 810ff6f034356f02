"""The cells' APIC scatter (p2g) as a pass along each column and one across the node rows.

A point adds to each node of its 3 x 3 stencil (stencil.scatter_point) its mass w m, momentum
w m (v + C r) and force -V sigma grad w + w f.  A fixed cell's weight is its column's times its
row's (transfer.py), w = wx_a wz_b, grad w = (gx_a wz_b, wx_a gz_b), r = (rx_a, rz_b), so
with the cell's P = m v, A = m C, S = -V sigma (Pa m^2/m) each sum splits, along the column
first (`scatter_columns`: for each cell column and node row k, over the cells whose stencil
holds k)

    Zm = sum wz_b m,
    Z1x = sum wz_b (Px + rz_b Axz),  Z2x = sum wz_b Axx,  Z3x = sum wz_b Sxx,
    Z4x = sum gz_b Sxz + wz_b fx,    and the same along z (Azz, Azx, Sxz, gz_b Szz + wz_b fz),

then across the columns for each node (`scatter_rows`, in the node row's columns' fixed order,
transfer.node_row_columns):

    m_i = sum wx_a Zm,  (m v)_i = sum wx_a Z1 + wx_a rx_a Z2,  f_i = sum gx_a Z3 + wx_a Z4.

27 products a cell along its column, and the pass across runs along the node rows in a loop
that vectorises, each node written by one thread: no per-chunk buffers to sum.  The sums are
scatter_point's in another order: equal to its roundoff (tests/test_eulerian_kernels.py).  An
axisymmetric section's radial force gains p2g.p2g's hoop term -V sigma_theta w / r (inv_r = 1/r
of the cell's centre; 0 in plane strain).
"""
from __future__ import annotations

import numba as nb
import numpy as np

from .transfer import T_BASE, T_FX, T_G0, T_W0, node_top

#: the sums a column holds for each node row (module docstring)
Z_M, Z1_X, Z2_X, Z1_Z, Z2_Z, Z3_X, Z4_X, Z3_Z, Z4_Z = range(9)


def scatter_work(ncx: int, nz: int) -> np.ndarray:
    """The columns' sums (ncx, 9, nz) (`scatter_columns`; kg/m, kg/s, N/m)."""
    return np.zeros((ncx, 9, nz))


@nb.njit(cache=True)
def scatter_columns(c0, c1, ktop, tz, dx, mass, volume, v, C, stress, fext, inv_r, Zs):
    """The sums along z (module docstring) of the cell columns c0:c1, their cells below row
    ktop that hold material (mass (N,) kg/m > 0; volume (N,) m^2, v (N, 2) m/s, C (N, 4)
    1/s, stress (N, 4) [xx, zz, xz, theta] Pa, fext (N, 2) N/m, inv_r (N,) 1/m), into Zs
    (ncx, 9, nz), with the cell rows' weight table tz on a grid of spacing dx (m)."""
    ncz = tz.shape[0]
    kn = node_top(ktop, tz)
    for ic in range(c0, c1):
        zs = Zs[ic]
        for q in range(9):
            zq = zs[q]
            for k in range(kn):
                zq[k] = 0.0
        for kc in range(ktop):
            p = ic * ncz + kc
            m = mass[p]
            if not m > 0.0:
                continue
            vol = volume[p]
            # (+ 0.0: a plane section's -0.0 made +0.0, so that fx + hoop is fx bit for bit)
            hoop = -vol * stress[p, 3] * inv_r[p] + 0.0
            fx = fext[p, 0] + hoop
            fz = fext[p, 1]
            px = m * v[p, 0]
            pz = m * v[p, 1]
            axx = m * C[p, 0]
            axz = m * C[p, 1]
            azx = m * C[p, 2]
            azz = m * C[p, 3]
            sxx = -vol * stress[p, 0]
            szz = -vol * stress[p, 1]
            sxz = -vol * stress[p, 2]
            bz = int(tz[kc, T_BASE])
            fzc = tz[kc, T_FX]
            for b in range(3):
                k = bz + b
                w = tz[kc, T_W0 + b]
                g = tz[kc, T_G0 + b]
                wr = w * ((b - fzc) * dx)
                zs[Z_M, k] += w * m
                zs[Z1_X, k] += w * px + wr * axz
                zs[Z2_X, k] += w * axx
                zs[Z1_Z, k] += w * pz + wr * azz
                zs[Z2_Z, k] += w * azx
                zs[Z3_X, k] += w * sxx
                zs[Z4_X, k] += g * sxz + w * fx
                zs[Z3_Z, k] += w * sxz
                zs[Z4_Z, k] += g * szz + w * fz


@nb.njit(cache=True)
def scatter_rows(i0, i1, ktop, tx, tz, dx, cols, col_a, ncols, Zs, gm, gmv, gf):
    """Node rows i0:i1 of the grid's mass gm (nx, nz) kg/m, momentum gmv and force gf (nx, nz,
    2) (kg/s, N/m) from the columns' sums Zs (`scatter_columns`, cell rows below ktop), summed
    over the node row's columns cols, col_a, ncols (transfer.node_row_columns) in their
    order, the columns' weights from tx on a grid of spacing dx (m); the nodes above the
    cells' stencils zero."""
    nz = gm.shape[1]
    kn = node_top(ktop, tz)
    for i in range(i0, i1):
        m_i = gm[i]
        mv = gmv[i]
        f = gf[i]
        for k in range(nz):
            m_i[k] = 0.0
            mv[k, 0] = 0.0
            mv[k, 1] = 0.0
            f[k, 0] = 0.0
            f[k, 1] = 0.0
        for j in range(ncols[i]):
            ic = cols[i, j]
            a = col_a[i, j]
            wa = tx[ic, T_W0 + a]
            ga = tx[ic, T_G0 + a]
            wr = wa * ((a - tx[ic, T_FX]) * dx)
            zs = Zs[ic]
            for k in range(kn):
                m_i[k] += wa * zs[Z_M, k]
                mv[k, 0] += wa * zs[Z1_X, k] + wr * zs[Z2_X, k]
                mv[k, 1] += wa * zs[Z1_Z, k] + wr * zs[Z2_Z, k]
                f[k, 0] += ga * zs[Z3_X, k] + wa * zs[Z4_X, k]
                f[k, 1] += ga * zs[Z3_Z, k] + wa * zs[Z4_Z, k]


def scatter(ktop, tx, tz, dx, columns, mass, volume, v, C, stress, fext, inv_r, Zs, gm, gmv,
            gf):
    """The whole scatter on one thread: `scatter_columns` over every column, then
    `scatter_rows` over every node row (columns: transfer.NodeRowColumns); arguments as
    theirs."""
    scatter_columns(0, tx.shape[0], ktop, tz, dx, mass, volume, v, C, stress, fext, inv_r, Zs)
    scatter_rows(0, gm.shape[0], ktop, tx, tz, dx, *columns, Zs, gm, gmv, gf)
