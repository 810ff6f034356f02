"""Particle-to-grid transfer with the affine particle-in-cell method (APIC; Jiang, Schroeder,
Selle, Teran & Stomakhin 2015, "The affine particle-in-cell method", ACM TOG 34(4), eqs. 8-9).

Each point p carries, besides its velocity v_p, an affine velocity matrix C_p (1/s); its momentum
reaches node i as m_p w_ip (v_p + C_p (x_i - x_p)).  With the quadratic B-spline's inertia tensor
D = dx^2/4 I this transfer, and its inverse in g2p.py, conserve linear and angular momentum
exactly (Jiang et al. 2015, section 5.3).  The internal force is the usual MPM divergence of the
points' Cauchy stress, f_i = -sum_p V_p sigma_p grad w_ip (Sulsky et al. 1994), which has zero net
force and torque for a symmetric stress; external point forces f_p (walls, partitions) are spread
with the weights.

Units: 2D per metre of thickness (y): masses kg/m, volumes m^2, forces N/m.
"""
from __future__ import annotations

import numba as nb
import numpy as np

from .grid import bspline_weights


@nb.njit(cache=True)
def p2g(x, v, C, mass, volume, stress, fext, x0, z0, dx, periodic, gm, gmv, gf):
    """Scatter the points to the grid (accumulates into gm, gmv, gf; zero them first).

    x, v (N, 2) position (m) and velocity (m/s) [x, z]; C (N, 4) affine matrix [xx, xz, zx, zz]
    (1/s) with C_ab multiplying r_b; mass (N,) kg/m; volume (N,) m^2; stress (N, 4)
    [xx, zz, xz, yy] (Pa); fext (N, 2) N/m.  Grid origin (x0, z0) and spacing dx (m); periodic:
    the grid wraps around along x (period nx dx); gm (nx, nz), gmv (nx, nz, 2), gf (nx, nz, 2).
    """
    nxg = gm.shape[0]
    wx = np.empty(3)
    wz = np.empty(3)
    gx = np.empty(3)
    gz = np.empty(3)
    for p in range(x.shape[0]):
        bx, fx, wx0, wx1, wx2, gx0, gx1, gx2 = bspline_weights(x[p, 0], x0, dx)
        bz, fz, wz0, wz1, wz2, gz0, gz1, gz2 = bspline_weights(x[p, 1], z0, dx)
        wx[0], wx[1], wx[2] = wx0, wx1, wx2
        wz[0], wz[1], wz[2] = wz0, wz1, wz2
        gx[0], gx[1], gx[2] = gx0, gx1, gx2
        gz[0], gz[1], gz[2] = gz0, gz1, gz2
        m = mass[p]
        vol = volume[p]
        sxx = stress[p, 0]
        szz = stress[p, 1]
        sxz = stress[p, 2]
        for a in range(3):
            rx = (a - fx) * dx
            for b in range(3):
                rz = (b - fz) * dx
                w = wx[a] * wz[b]
                gwx = gx[a] * wz[b]
                gwz = wx[a] * gz[b]
                i = bx + a
                if periodic:
                    i = i % nxg
                k = bz + b
                gm[i, k] += w * m
                gmv[i, k, 0] += w * m * (v[p, 0] + C[p, 0] * rx + C[p, 1] * rz)
                gmv[i, k, 1] += w * m * (v[p, 1] + C[p, 2] * rx + C[p, 3] * rz)
                gf[i, k, 0] += -vol * (sxx * gwx + sxz * gwz) + w * fext[p, 0]
                gf[i, k, 1] += -vol * (sxz * gwx + szz * gwz) + w * fext[p, 1]
