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
g2), one per axis; `axis_node` gives every loop over the stencil its nodes along each axis
(index, offset, weight and derivative), the weights picked by selects rather than small arrays
so that they stay in registers.  The weights, the node and the scatter are inlined into their
callers by numba (inline="always"); the gathers are left to LLVM's inliner, which compiles
the Eulerian cells' gather a third faster than numba's inlining does
(benchmarks/continuum_speed.py --kernels).
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
def axis_node(w, a, dx, periodic, n):
    """Node a (0, 1, 2) of a point's stencil along one axis, from its `bspline_weights` w on
    an axis of spacing dx (m) and n nodes (wrapped around when periodic): the node's index, its
    offset (a - fx) dx (m) from the point, its weight and the weight's derivative (1/m).  A
    node's weight w_ip is the product of its two axes' weights, its gradient (g_a w_b, w_a g_b)."""
    base, fx, w0, w1, w2, g0, g1, g2 = w
    i = base + a
    if periodic:
        i = i % n
    return (i, (a - fx) * dx, w0 if a == 0 else (w1 if a == 1 else w2),
            g0 if a == 0 else (g1 if a == 1 else g2))


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
    nxg = gm.shape[0]
    for a in range(3):
        i, rx, wa, ga = axis_node(wx, a, dx, periodic, nxg)
        for b in range(3):
            k, rz, wb, gb = axis_node(wz, b, dx, False, 0)
            w, gwx, gwz = wa * wb, ga * wb, wa * gb
            gm[i, k] += w * m
            gmv[i, k, 0] += w * m * (vx + cxx * rx + cxz * rz)
            gmv[i, k, 1] += w * m * (vz + czx * rx + czz * rz)
            gf[i, k, 0] += -vol * (sxx * gwx + sxz * gwz) + w * fex
            gf[i, k, 1] += -vol * (sxz * gwx + szz * gwz) + w * fez


@nb.njit(cache=True)
def gather_point(wx, wz, dx, periodic, gv):
    """One point's APIC gather from the grid velocity gv (nx, nz, 2) (m/s; module docstring):
    (vx, vz) m/s, the affine matrix (cxx, cxz, czx, czz) and the velocity gradient
    (lxx, lxz, lzx, lzz) 1/s.  wx, wz, dx, periodic as `scatter_point`'s."""
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
        i, rx, wa, ga = axis_node(wx, a, dx, periodic, nxg)
        for b in range(3):
            k, rz, wb, gb = axis_node(wz, b, dx, False, 0)
            w, gwx, gwz = wa * wb, ga * wb, wa * gb
            ux = gv[i, k, 0]
            uz = gv[i, k, 1]
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


@nb.njit(cache=True)
def gather_old_velocity(wx, wz, periodic, gm, gmv):
    """sum_i w_ip gmv_i / gm_i over the point's nodes holding mass (m/s): the grid's velocity
    before the update at the point, from its mass gm (nx, nz) and momentum gmv (nx, nz, 2)."""
    nxg = gm.shape[0]
    ox = 0.0
    oz = 0.0
    for a in range(3):
        i, _, wa, _ = axis_node(wx, a, 0.0, periodic, nxg)
        for b in range(3):
            k, _, wb, _ = axis_node(wz, b, 0.0, False, 0)
            w = wa * wb
            mi = gm[i, k]
            if mi > 0.0:
                ox += w * gmv[i, k, 0] / mi
                oz += w * gmv[i, k, 1] / mi
    return ox, oz
