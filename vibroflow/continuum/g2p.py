"""Grid-to-particle transfer (APIC; Jiang et al. 2015, eqs. 10-11) and the point advection.

v_p = sum_i w_ip v_i,  C_p = (4 / dx^2) sum_i w_ip v_i (x_i - x_p)^T  (B_p D_p^-1 with the
quadratic B-spline's D_p = dx^2/4 I), the velocity gradient L_p = sum_i v_i (grad w_ip)^T used
by the constitutive update (stencil.gather_point), and x_p += dt v_p (Sulsky et al. 1994's update
with the new velocity).
"""
from __future__ import annotations

import numba as nb

from .stencil import bspline_weights, gather_old_velocity, gather_point


@nb.njit(cache=True, inline="always")
def store_gather(p, vx, vz, g, v, C, L):
    """Row p of v (N, 2) (m/s), C and L (N, 4 or 5) (1/s) from one point's gather: its new
    velocity (vx, vz) (m/s) and the affine matrix and velocity gradient of its
    stencil.gather_point tuple g."""
    v[p, 0] = vx
    v[p, 1] = vz
    C[p, 0] = g[2]
    C[p, 1] = g[3]
    C[p, 2] = g[4]
    C[p, 3] = g[5]
    L[p, 0] = g[6]
    L[p, 1] = g[7]
    L[p, 2] = g[8]
    L[p, 3] = g[9]


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
        g = gather_point(wx, wz, dx, periodic, gv)
        vx = g[0]
        vz = g[1]
        ux = vx
        uz = vz
        if flip > 0.0:
            # FLIP-APIC blend: the point keeps the part of its own velocity that the grid's
            # old velocity did not hold, a fraction `flip` of it
            ox, oz = gather_old_velocity(wx, wz, periodic, gm, gmv)
            ux = vx + flip * (v[p, 0] - ox)
            uz = vz + flip * (v[p, 1] - oz)
        store_gather(p, ux, uz, g, v, C, L)
        if L.shape[1] > 4:
            L[p, 4] = vx / x[p, 0]
        x[p, 0] += dt * vx
        x[p, 1] += dt * vz
        if periodic:
            x[p, 0] = x0 + (x[p, 0] - x0) % period
