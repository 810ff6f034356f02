"""Grid-to-particle transfer (APIC; Jiang et al. 2015, eqs. 10-11) and the point advection.

v_p = sum_i w_ip v_i,  C_p = (4 / dx^2) sum_i w_ip v_i (x_i - x_p)^T  (B_p D_p^-1 with the
quadratic B-spline's D_p = dx^2/4 I), the velocity gradient L_p = sum_i v_i (grad w_ip)^T used
by the constitutive update, and x_p += dt v_p (Sulsky et al. 1994's update with the new velocity).
"""
from __future__ import annotations

import numba as nb

from .grid import bspline_weights


@nb.njit(cache=True)
def g2p(x, v, C, L, gv, x0, z0, dx, dt, periodic, gm, gmv, flip):
    """Gather the grid velocity gv (nx, nz, 2) (m/s) to the points: v (N, 2) m/s, C (N, 4) and
    L (N, 4) [xx, xz, zx, zz] 1/s, written in place; then move the points x (N, 2) by dt v (m).
    periodic: the grid wraps around along x (period nx dx) and so do the points.  L of
    shape (N, 5): an axisymmetric section (x = r >= 0), whose fifth column gets the hoop rate
    L_theta = sum_i w_ip v_r,i / r_p (1/s; Nairn & Guilkey 2015, Int. J. Numer. Meth. Eng.
    101, 127, eq. 20), the point's radius taken before its move."""
    inv = 4.0 / (dx * dx)
    nxg = gv.shape[0]
    period = nxg * dx
    for p in range(x.shape[0]):
        bx, fx, wx0, wx1, wx2, gx0, gx1, gx2 = bspline_weights(x[p, 0], x0, dx)
        bz, fz, wz0, wz1, wz2, gz0, gz1, gz2 = bspline_weights(x[p, 1], z0, dx)
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
        ox = 0.0
        oz = 0.0
        for a in range(3):
            rx = (a - fx) * dx
            # the weights as selects, not small arrays: they stay in registers
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
                if flip > 0.0:
                    mi = gm[i, bz + b]
                    if mi > 0.0:
                        ox += w * gmv[i, bz + b, 0] / mi
                        oz += w * gmv[i, bz + b, 1] / mi
        if flip > 0.0:
            # FLIP-APIC blend: the point keeps the part of its own velocity that the grid's
            # old velocity did not hold, a fraction `flip` of it
            v[p, 0] = vx + flip * (v[p, 0] - ox)
            v[p, 1] = vz + flip * (v[p, 1] - oz)
        else:
            v[p, 0] = vx
            v[p, 1] = vz
        C[p, 0] = inv * cxx
        C[p, 1] = inv * cxz
        C[p, 2] = inv * czx
        C[p, 3] = inv * czz
        L[p, 0] = lxx
        L[p, 1] = lxz
        L[p, 2] = lzx
        L[p, 3] = lzz
        if L.shape[1] > 4:
            L[p, 4] = vx / x[p, 0]
        x[p, 0] += dt * vx
        x[p, 1] += dt * vz
        if periodic:
            x[p, 0] = x0 + (x[p, 0] - x0) % period
