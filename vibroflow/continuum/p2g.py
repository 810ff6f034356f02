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

from .grid import bspline_weights


@nb.njit(cache=True)
def p2g(x, v, C, mass, volume, stress, fext, x0, z0, dx, periodic, gm, gmv, gf,
        axisymmetric=False):
    """Scatter the points to the grid (accumulates into gm, gmv, gf; zero them first).

    x, v (N, 2) position (m) and velocity (m/s) [x, z]; C (N, 4) affine matrix [xx, xz, zx, zz]
    (1/s) with C_ab multiplying r_b; mass (N,) kg/m; volume (N,) m^2; stress (N, 4)
    [xx, zz, xz, yy] (Pa); fext (N, 2) N/m.  Grid origin (x0, z0) and spacing dx (m); periodic:
    the grid wraps around along x (period nx dx); gm (nx, nz), gmv (nx, nz, 2), gf (nx, nz, 2).

    axisymmetric: x is the radius r >= 0 of a section of revolution about the z axis, masses
    (kg), volumes (m^3) and forces (N) are per radian, and the hoop stress sigma_yy =
    sigma_theta adds the radial force -V_p sigma_theta w_ip / r_p (the 1/r term of the
    divergence in cylindrical coordinates; Nairn & Guilkey 2015, eq. 16).
    """
    nxg = gm.shape[0]
    for p in range(x.shape[0]):
        bx, fx, wx0, wx1, wx2, gx0, gx1, gx2 = bspline_weights(x[p, 0], x0, dx)
        bz, fz, wz0, wz1, wz2, gz0, gz1, gz2 = bspline_weights(x[p, 1], z0, dx)
        # the point's values in locals: the compiler cannot tell that the grid arrays written
        # below do not alias them, and would load them again for every node (~25 % of the
        # scatter's time)
        m = mass[p]
        vol = volume[p]
        sxx = stress[p, 0]
        szz = stress[p, 1]
        sxz = stress[p, 2]
        vx = v[p, 0]
        vz = v[p, 1]
        cxx = C[p, 0]
        cxz = C[p, 1]
        czx = C[p, 2]
        czz = C[p, 3]
        fex = fext[p, 0]
        fez = fext[p, 1]
        hoop = -vol * stress[p, 3] / x[p, 0] if axisymmetric else 0.0
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
                gf[i, k, 0] += -vol * (sxx * gwx + sxz * gwz) + w * (fex + hoop)
                gf[i, k, 1] += -vol * (sxz * gwx + szz * gwz) + w * fez
