"""Continuum fields on the background grid (their ParaView files: continuum.paraview).

At an instant the points are scattered to the grid nodes with the solver's quadratic B-spline
weights w_ip (stencil.py):

* node mass per area rho_i = sum_p w_ip m_p / dx^2 (kg/m^3, per metre of thickness, so a bulk
  density), and the solid fraction phi_i = rho_i / rho_s;
* mass-weighted averages of the points' velocity (m/s, relative to the tub in tub axes: the
  solver's velocity), pressure p = -tr(sigma)/3 (Pa) and shear rate sqrt(2 D':D') (1/s):
  a_i = sum_p w_ip m_p a_p / sum_p w_ip m_p, zero at nodes with no mass.
"""
from __future__ import annotations

import numba as nb
import numpy as np

from .grid import Grid
from .stencil import bspline_weights


@nb.njit(cache=True)
def _scatter(x, v, mass, pressure, rate, x0, z0, dx, periodic, gm, gv, gp, gr):
    nxg = gm.shape[0]
    for p in range(x.shape[0]):
        bx, fx, wx0, wx1, wx2, _, _, _ = bspline_weights(x[p, 0], x0, dx)
        bz, fz, wz0, wz1, wz2, _, _, _ = bspline_weights(x[p, 1], z0, dx)
        for a in range(3):
            wa = wx0 if a == 0 else (wx1 if a == 1 else wx2)
            for b in range(3):
                wb = wz0 if b == 0 else (wz1 if b == 1 else wz2)
                i = bx + a
                if periodic:
                    i = i % nxg
                k = bz + b
                wm = wa * wb * mass[p]
                gm[i, k] += wm
                gv[i, k, 0] += wm * v[p, 0]
                gv[i, k, 1] += wm * v[p, 1]
                gp[i, k] += wm * pressure[p]
                gr[i, k] += wm * rate[p]


def grid_fields(grid: Grid, x, v, mass, pressure, rate, solid_density: float) -> dict:
    """Node fields (module docstring) of points at x (N, 2) m with velocities v (N, 2) m/s,
    masses (N,) kg/m, pressures (N,) Pa and shear rates (N,) 1/s: a dict of (nx, nz) arrays
    "density" (kg/m^3), "solid_fraction", "pressure" (Pa), "shear_rate" (1/s) and "velocity"
    (nx, nz, 2) m/s [x, z]."""
    gm = np.zeros((grid.nx, grid.nz))
    gv = np.zeros((grid.nx, grid.nz, 2))
    gp = np.zeros_like(gm)
    gr = np.zeros_like(gm)
    _scatter(np.ascontiguousarray(x, dtype=np.float64), np.ascontiguousarray(v, dtype=np.float64),
             np.ascontiguousarray(mass, dtype=np.float64),
             np.ascontiguousarray(pressure, dtype=np.float64),
             np.ascontiguousarray(rate, dtype=np.float64), grid.x0, grid.z0, grid.dx,
             grid.periodic, gm, gv, gp, gr)
    has = gm > 0
    inv = np.where(has, 1.0 / np.where(has, gm, 1.0), 0.0)
    density = gm / grid.dx**2
    return {"density": density, "solid_fraction": density / solid_density,
            "velocity": gv * inv[:, :, None], "pressure": gp * inv, "shear_rate": gr * inv}

