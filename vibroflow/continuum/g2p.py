"""Grid-to-particle transfer (APIC; Jiang et al. 2015, eqs. 10-11) and the point advection.

v_p = sum_i w_ip v_i,  C_p = (4 / dx^2) sum_i w_ip v_i (x_i - x_p)^T  (B_p D_p^-1 with the
quadratic B-spline's D_p = dx^2/4 I), the velocity gradient L_p = sum_i v_i (grad w_ip)^T used
by the constitutive update (stencil.gather_point), and x_p += dt v_p (Sulsky et al. 1994's update
with the new velocity).
"""
from __future__ import annotations

import numba as nb

from .stencil import bspline_weights, gather_old_velocity, gather_point


@nb.njit(cache=True)
def g2p(x, v, C, L, gv, x0, z0, dx, dt, periodic, gm, gmv, flip):
    """Gather the grid velocity gv (nx, nz, 2) (m/s) to the points: v (N, 2) m/s, C (N, 4) and
    L (N, 4) [xx, xz, zx, zz] 1/s, written in place; then move the points x (N, 2) by dt v (m).
    periodic: the grid wraps around along x (period nx dx) and so do the points.  L of
    shape (N, 5): an axisymmetric section (x = r >= 0), whose fifth column gets the hoop rate
    L_theta = sum_i w_ip v_r,i / r_p (1/s; Nairn & Guilkey 2015, Int. J. Numer. Meth. Eng.
    101, 127, eq. 20), the point's radius taken before its move."""
    nxg = gv.shape[0]
    period = nxg * dx
    for p in range(x.shape[0]):
        wx = bspline_weights(x[p, 0], x0, dx)
        wz = bspline_weights(x[p, 1], z0, dx)
        vx, vz, cxx, cxz, czx, czz, lxx, lxz, lzx, lzz = gather_point(wx, wz, dx, periodic,
                                                                      gv)
        if flip > 0.0:
            # FLIP-APIC blend: the point keeps the part of its own velocity that the grid's
            # old velocity did not hold, a fraction `flip` of it
            ox, oz = gather_old_velocity(wx, wz, periodic, gm, gmv)
            v[p, 0] = vx + flip * (v[p, 0] - ox)
            v[p, 1] = vz + flip * (v[p, 1] - oz)
        else:
            v[p, 0] = vx
            v[p, 1] = vz
        C[p, 0] = cxx
        C[p, 1] = cxz
        C[p, 2] = czx
        C[p, 3] = czz
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
