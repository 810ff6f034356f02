"""The quadratic B-spline stencil of one point on the grid, shared by both formulations.

A point's weights on the grid are products of one-dimensional quadratic B-splines (Steffen,
Kirby & Berzins 2008), C1 and positive, over the 3 x 3 nodes around it (`bspline_weights`: the
base node, the offset and the three weights and derivatives along one axis).  On that stencil:

* `scatter_point`: the APIC particle-to-grid transfer of one point (Jiang, Schroeder, Selle,
  Teran & Stomakhin 2015, "The affine particle-in-cell method", ACM TOG 34(4), eqs. 8-9): mass
  m w_ip, momentum m w_ip (v_p + C_p (x_i - x_p)), the internal force -V_p sigma_p grad w_ip
  (Sulsky, Chen & Schreyer 1994) and the point force w_ip f_p;
* `gather_point`: the grid-to-particle transfer (Jiang et al. 2015, eqs. 10-11): v_p =
  sum_i w_ip v_i, C_p = (4 / dx^2) sum_i w_ip v_i (x_i - x_p)^T (the quadratic B-spline's
  D_p = dx^2/4 I) and the velocity gradient L_p = sum_i v_i (grad w_ip)^T;
* `gather_old_velocity`: sum_i w_ip v_i^old of the grid's momentum before the update, the
  FLIP blend's part (g2p.py).

The material point method (p2g.py, g2p.py) computes the weights of each point every step; the
Eulerian mesh reads them from constant tables of its fixed cells (eulerian/transfer.py).  Both
call these functions, so they give the same numbers bit for bit.

A point's weights travel as the tuple `bspline_weights` returns, (base, fx, w0, w1, w2, g0, g1,
g2), one per axis; the weights are picked by selects rather than small arrays so that they stay
in registers, and the kernels are inlined into their callers.
"""
from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(cache=True, inline="always")
def bspline_weights(xp, x0, dx):
    """Base node index and the 3 quadratic B-spline weights and derivatives (1/m) of a point at
    coordinate xp (m) along one axis of a grid with origin x0 (m) and spacing dx (m).

    Returns (base, fx, w0, w1, w2, g0, g1, g2): nodes base, base+1, base+2; fx = xp/dx - base
    in [0.5, 1.5), so node base + a lies at (a - fx) dx from the point."""
    X = (xp - x0) / dx
    base = int(np.floor(X - 0.5))
    fx = X - base
    w0 = 0.5 * (1.5 - fx) ** 2
    w1 = 0.75 - (fx - 1.0) ** 2
    w2 = 0.5 * (fx - 0.5) ** 2
    g0 = (fx - 1.5) / dx
    g1 = -2.0 * (fx - 1.0) / dx
    g2 = (fx - 0.5) / dx
    return base, fx, w0, w1, w2, g0, g1, g2


@nb.njit(cache=True, inline="always")
def scatter_point(wx, wz, dx, periodic, m, vol, sxx, szz, sxz, vx, vz, cxx, cxz, czx, czz,
                  fex, fez, gm, gmv, gf):
    """Add one point's APIC mass, momentum and force to the grid (module docstring).

    wx, wz: its `bspline_weights` along x and z; dx (m) the spacing; periodic: the grid wraps
    around along x.  The point's mass m (kg/m), volume vol (m^2), stress sxx, szz, sxz (Pa),
    velocity vx, vz (m/s), affine matrix cxx, cxz, czx, czz (1/s, C_ab multiplying r_b) and
    point force fex, fez (N/m) are passed as numbers: the compiler cannot tell that the grid
    arrays gm (nx, nz), gmv, gf (nx, nz, 2) written here do not alias the point's arrays, and
    would load them again for every node."""
    bx, fx, wx0, wx1, wx2, gx0, gx1, gx2 = wx
    bz, fz, wz0, wz1, wz2, gz0, gz1, gz2 = wz
    nxg = gm.shape[0]
    for a in range(3):
        rx = (a - fx) * dx
        wa = wx0 if a == 0 else (wx1 if a == 1 else wx2)
        ga = gx0 if a == 0 else (gx1 if a == 1 else gx2)
        i = bx + a
        if periodic:
            i = i % nxg
        for b in range(3):
            rz = (b - fz) * dx
            wb = wz0 if b == 0 else (wz1 if b == 1 else wz2)
            gb = gz0 if b == 0 else (gz1 if b == 1 else gz2)
            w = wa * wb
            gwx = ga * wb
            gwz = wa * gb
            k = bz + b
            gm[i, k] += w * m
            gmv[i, k, 0] += w * m * (vx + cxx * rx + cxz * rz)
            gmv[i, k, 1] += w * m * (vz + czx * rx + czz * rz)
            gf[i, k, 0] += -vol * (sxx * gwx + sxz * gwz) + w * fex
            gf[i, k, 1] += -vol * (sxz * gwx + szz * gwz) + w * fez


@nb.njit(cache=True, inline="always")
def gather_point(wx, wz, dx, periodic, gv):
    """One point's APIC gather from the grid velocity gv (nx, nz, 2) (m/s; module docstring):
    (vx, vz) m/s, the affine matrix (cxx, cxz, czx, czz) and the velocity gradient
    (lxx, lxz, lzx, lzz) 1/s.  wx, wz, dx, periodic as `scatter_point`'s."""
    bx, fx, wx0, wx1, wx2, gx0, gx1, gx2 = wx
    bz, fz, wz0, wz1, wz2, gz0, gz1, gz2 = wz
    nxg = gv.shape[0]
    vx = 0.0
    vz = 0.0
    cxx = 0.0
    cxz = 0.0
    czx = 0.0
    czz = 0.0
    lxx = 0.0
    lxz = 0.0
    lzx = 0.0
    lzz = 0.0
    for a in range(3):
        rx = (a - fx) * dx
        wa = wx0 if a == 0 else (wx1 if a == 1 else wx2)
        ga = gx0 if a == 0 else (gx1 if a == 1 else gx2)
        i = bx + a
        if periodic:
            i = i % nxg
        for b in range(3):
            rz = (b - fz) * dx
            wb = wz0 if b == 0 else (wz1 if b == 1 else wz2)
            gb = gz0 if b == 0 else (gz1 if b == 1 else gz2)
            w = wa * wb
            gwx = ga * wb
            gwz = wa * gb
            ux = gv[i, bz + b, 0]
            uz = gv[i, bz + b, 1]
            vx += w * ux
            vz += w * uz
            cxx += w * ux * rx
            cxz += w * ux * rz
            czx += w * uz * rx
            czz += w * uz * rz
            lxx += ux * gwx
            lxz += ux * gwz
            lzx += uz * gwx
            lzz += uz * gwz
    inv = 4.0 / (dx * dx)
    return (vx, vz, inv * cxx, inv * cxz, inv * czx, inv * czz, lxx, lxz, lzx, lzz)


@nb.njit(cache=True, inline="always")
def gather_old_velocity(wx, wz, periodic, gm, gmv):
    """sum_i w_ip gmv_i / gm_i over the point's nodes holding mass (m/s): the grid's velocity
    before the update at the point, from its mass gm (nx, nz) and momentum gmv (nx, nz, 2)."""
    bx, _, wx0, wx1, wx2, _, _, _ = wx
    bz, _, wz0, wz1, wz2, _, _, _ = wz
    nxg = gm.shape[0]
    ox = 0.0
    oz = 0.0
    for a in range(3):
        wa = wx0 if a == 0 else (wx1 if a == 1 else wx2)
        i = bx + a
        if periodic:
            i = i % nxg
        for b in range(3):
            wb = wz0 if b == 0 else (wz1 if b == 1 else wz2)
            w = wa * wb
            mi = gm[i, bz + b]
            if mi > 0.0:
                ox += w * gmv[i, bz + b, 0] / mi
                oz += w * gmv[i, bz + b, 1] / mi
    return ox, oz
