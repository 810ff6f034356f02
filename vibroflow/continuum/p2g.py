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

from .stencil import bspline_weights, scatter_point


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
    for p in range(x.shape[0]):
        hoop = -volume[p] * stress[p, 3] / x[p, 0] if axisymmetric else 0.0
        scatter_point(bspline_weights(x[p, 0], x0, dx), bspline_weights(x[p, 1], z0, dx), dx,
                      periodic, mass[p], volume[p], stress[p, 0], stress[p, 1], stress[p, 2],
                      v[p, 0], v[p, 1], C[p, 0], C[p, 1], C[p, 2], C[p, 3], fext[p, 0] + hoop,
                      fext[p, 1], gm, gmv, gf)
