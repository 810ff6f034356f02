"""The remap step: conservative transport of the material through the fixed mesh.

After the Lagrangian step (lagrangian_step.py) the material has moved by v dt relative to the
fixed cells; the remap brings it back onto them, as the Eulerian hydrocodes do (Benson 1992,
Comput. Methods Appl. Mech. Eng. 99, 235, "Computational methods in Lagrangian and Eulerian
hydrocodes", section 5: the operator split into a Lagrangian and a transport step).  The
transport is a finite-volume donor-cell scheme of second order (MUSCL, van Leer 1979) with the
monotonised-central limiter (van Leer 1977), unsplit in x and z (the advective Courant numbers
of a run are ~1e-3, far inside its stability limit, so neither dimensional splitting nor
corner-transport terms are needed):

* the conserved quantity is the cell mass m (kg per metre of thickness); the face flux is
  F = u_f dt h rho_f, with u_f the face-normal velocity (face_velocities: the nodal velocity
  field interpolated at the face's midpoint) and rho_f = m / h^2 reconstructed on the upwind
  side with the limited slope;
* every other field q (velocity, APIC affine matrix, stress: the material's intensive
  properties) is carried mass-weighted, (m q)_new = m q - sum F q_f, with q_f the limited
  upwind reconstruction of q itself (bounded by its neighbours, so the transport creates no new
  extrema of stress or velocity): this is the stress advection that the rate form of the
  elasto-plastic law needs in a fixed mesh;
* closed faces (mesh.py: the wall) carry no flux, and a slope is not taken across them or
  across an empty neighbour.

Each face flux is added to one cell and taken from the other, so the total mass is conserved to
round-off; nothing is clipped (the Courant numbers keep every cell's mass >= 0; a negative one
is reported by the solver).  The volume fraction f = min(1, m / (rho h^2)) (solver.py) is
computed from the transported mass and density, so it is transported without losing mass too.
"""
from __future__ import annotations

import math

import numba as nb
import numpy as np

from ..grid import bspline_weights

#: a cell with less mass than this fraction of a full cell is empty
EMPTY = 1.0e-12


@nb.njit(cache=True, inline="always")
def _mc(a, b):
    """Monotonised-central limited slope of the two one-sided differences a, b: 0 when they
    differ in sign, else their mean clipped to twice the smaller (written without branches on
    the data, which the slopes' loop would mispredict)."""
    s = 0.5 * (a + b)
    lim = 2.0 * min(abs(a), abs(b))
    r = math.copysign(min(abs(s), lim), s)
    return r if a * b > 0.0 else 0.0


#: cell rows (x) or columns (z) per block of the parallel loops: blocks own whole rows or
#: columns, so every cell's sums run in the serial order whatever thread takes them
BLOCK = 8


@nb.njit(cache=True)
def _interp(gv, xp, zp, x0, z0, dx, periodic, comp):
    nxg = gv.shape[0]
    bx, fx, wx0, wx1, wx2, _, _, _ = bspline_weights(xp, x0, dx)
    bz, fz, wz0, wz1, wz2, _, _, _ = bspline_weights(zp, z0, dx)
    s = 0.0
    for a in range(3):
        wa = wx0 if a == 0 else (wx1 if a == 1 else wx2)
        i = bx + a
        if periodic:
            i = i % nxg
        for b in range(3):
            wb = wz0 if b == 0 else (wz1 if b == 1 else wz2)
            s += wa * wb * gv[i, bz + b, comp]
    return s


@nb.njit(cache=True, parallel=True)
def face_velocities(gv, x0, z0, dx, periodic, xmin, zmin, h, open_x, open_z, m, ux, uz):
    """Face-normal velocities (m/s): ux (ncx + 1, ncz) on the x-faces (x = xmin + i h),
    uz (ncx, ncz + 1) on the z-faces, the node velocities gv (nx, nz, 2) of the grid (origin
    (x0, z0), spacing dx, m) interpolated at the face midpoints, on the open faces of a cell
    holding material (mass m (ncx, ncz) kg/m > 0); 0 elsewhere.  A face between two empty
    cells carries no flux (`advect` takes nothing from an empty upwind cell), and its
    divergence would only reach the velocity gradient of empty cells, which carry no stress
    (density 0: disconnected) and no weight in any output: skipping it spares about half the
    interpolations (the tub above the bed is empty).  Each face on its own (parallel over
    rows)."""
    ncx1, ncz = ux.shape
    ncx = ncx1 - 1
    for i in nb.prange(ncx1):
        # the cells left and right of face i (wrapped on a periodic mesh; a closed face's
        # neighbours are never read)
        il = (i + ncx - 1) % ncx
        ir = i % ncx
        for k in range(ncz):
            if open_x[i, k] and (m[il, k] > 0.0 or m[ir, k] > 0.0):
                ux[i, k] = _interp(gv, xmin + i * h, zmin + (k + 0.5) * h, x0, z0, dx,
                                   periodic, 0)
            else:
                ux[i, k] = 0.0
    ncz1 = uz.shape[1]
    for i in nb.prange(ncx):
        for k in range(ncz1):
            if open_z[i, k] and (m[i, k - 1] > 0.0 or m[i, k] > 0.0):
                uz[i, k] = _interp(gv, xmin + (i + 0.5) * h, zmin + k * h, x0, z0, dx,
                                   periodic, 1)
            else:
                uz[i, k] = 0.0


@nb.njit(cache=True)
def match_divergence(L, ux, uz, h, periodic):
    """Replace the trace of each cell's velocity gradient L (N, 4) [xx, xz, zx, zz] (1/s,
    p = i * ncz + k) by the finite-volume divergence of its face velocities (1/s), split
    equally between L_xx and L_zz, so that the volume change the stress update sees is the one
    the mass transport makes.  In the domain's interior the two are equal (the quadratic
    B-spline velocity differenced over a cell that lies within one knot span); they differ next
    to the wall, whose closed faces pass no material while the nodal field beyond them moves."""
    ncx, ncz = uz.shape[0], ux.shape[1]
    for i in range(ncx):
        ir = i + 1
        for k in range(ncz):
            div = (ux[ir, k] - ux[i, k] + uz[i, k + 1] - uz[i, k]) / h
            p = i * ncz + k
            d = 0.5 * (div - L[p, 0] - L[p, 3])
            L[p, 0] += d
            L[p, 3] += d


@nb.njit(cache=True)
def _slopes(i0, i1, rho, q, open_x, open_z, rho_empty, periodic, srx, srz, sqx, sqz):
    """Limited slopes (per cell, times h) of rho and of each q field along x and z, rows
    i0:i1."""
    ncx, ncz = rho.shape
    nq = q.shape[2]
    for i in range(i0, i1):
        for k in range(ncz):
            if rho[i, k] <= 0.0:
                # an empty cell is never upwind of a flux (advect skips it), so its slopes are
                # never used
                srx[i, k] = 0.0
                srz[i, k] = 0.0
                continue
            # x: left face i, right face i + 1
            il = i - 1
            ir = i + 1
            if periodic:
                il = il % ncx
                ir = ir % ncx
            okl = open_x[i, k]
            okr = open_x[i + 1, k]
            a = rho[i, k] - rho[il, k] if okl else 0.0
            b = rho[ir, k] - rho[i, k] if okr else 0.0
            srx[i, k] = _mc(a, b)
            okl = okl and rho[il, k] > rho_empty
            okr = okr and rho[ir, k] > rho_empty
            for j in range(nq):
                a = q[i, k, j] - q[il, k, j] if okl else 0.0
                b = q[ir, k, j] - q[i, k, j] if okr else 0.0
                sqx[i, k, j] = _mc(a, b)
            # z
            okd = open_z[i, k]
            oku = open_z[i, k + 1]
            a = rho[i, k] - rho[i, k - 1] if okd else 0.0
            b = rho[i, k + 1] - rho[i, k] if oku else 0.0
            srz[i, k] = _mc(a, b)
            okd = okd and rho[i, k - 1] > rho_empty
            oku = oku and rho[i, k + 1] > rho_empty
            for j in range(nq):
                a = q[i, k, j] - q[i, k - 1, j] if okd else 0.0
                b = q[i, k + 1, j] - q[i, k, j] if oku else 0.0
                sqz[i, k, j] = _mc(a, b)


@nb.njit(cache=True)
def _x_fluxes(k0, k1, q, ux, h, dt, periodic, work_rho, srx, sqx, dm, dq):
    """Fluxes through the x-faces of columns k0:k1 into dm, dq (face i between cells i - 1
    and i), faces in ascending i."""
    ncx = work_rho.shape[0]
    nq = q.shape[2]
    for i in range(ux.shape[0]):
        for k in range(k0, k1):
            u = ux[i, k]
            if u == 0.0:
                continue
            il = i - 1
            ir = i
            if periodic:
                il = il % ncx
                ir = ir % ncx
            elif i == 0 or i == ncx:
                continue
            c = abs(u) * dt / h
            if u > 0.0:
                up = il
                sgn = 1.0
            else:
                up = ir
                sgn = -1.0
            if work_rho[up, k] <= 0.0:
                continue  # nothing to carry (the limited slope of an empty cell is 0 too)
            rf = work_rho[up, k] + sgn * 0.5 * (1.0 - c) * srx[up, k]
            F = u * dt * h * rf  # kg/m from left to right
            dm[il, k] -= F
            dm[ir, k] += F
            for j in range(nq):
                qf = q[up, k, j] + sgn * 0.5 * (1.0 - c) * sqx[up, k, j]
                dq[il, k, j] -= F * qf
                dq[ir, k, j] += F * qf
        if periodic and i == ux.shape[0] - 2:
            break  # face ncx is face 0 on a periodic mesh


@nb.njit(cache=True)
def _z_fluxes(i0, i1, q, uz, h, dt, work_rho, srz, sqz, dm, dq):
    """Fluxes through the z-faces of rows i0:i1 into dm, dq (face k between cells k - 1 and
    k), faces in ascending k."""
    ncz = work_rho.shape[1]
    nq = q.shape[2]
    for i in range(i0, i1):
        for k in range(1, ncz):
            u = uz[i, k]
            if u == 0.0:
                continue
            c = abs(u) * dt / h
            if u > 0.0:
                up = k - 1
                sgn = 1.0
            else:
                up = k
                sgn = -1.0
            if work_rho[i, up] <= 0.0:
                continue
            rf = work_rho[i, up] + sgn * 0.5 * (1.0 - c) * srz[i, up]
            F = u * dt * h * rf
            dm[i, k - 1] -= F
            dm[i, k] += F
            for j in range(nq):
                qf = q[i, up, j] + sgn * 0.5 * (1.0 - c) * sqz[i, up, j]
                dq[i, k - 1, j] -= F * qf
                dq[i, k, j] += F * qf


@nb.njit(cache=True)
def _update(i0, i1, m, q, dm, dq, m_empty):
    """New masses and mass-weighted fields of rows i0:i1; returns their smallest mass."""
    ncz = m.shape[1]
    nq = q.shape[2]
    lowest = np.inf
    for i in range(i0, i1):
        for k in range(ncz):
            mo = m[i, k]
            mn = mo + dm[i, k]
            if mn < lowest:
                lowest = mn
            if mn > m_empty and mo > m_empty:
                inv = 1.0 / mn
                for j in range(nq):
                    q[i, k, j] = (mo * q[i, k, j] + dq[i, k, j]) * inv
            elif mn > m_empty:
                # an empty cell filling: what it holds is what came in (its round-off mass
                # carried no properties)
                inv = 1.0 / dm[i, k]
                for j in range(nq):
                    q[i, k, j] = dq[i, k, j] * inv
            else:
                for j in range(nq):
                    q[i, k, j] = 0.0
            m[i, k] = mn
    return lowest


@nb.njit(cache=True, parallel=True)
def advect(m, q, ux, uz, h, dt, open_x, open_z, periodic, work_rho, srx, srz, sqx, sqz,
           dm, dq):
    """One transport step (module docstring), in place.  m (ncx, ncz) cell masses (kg/m);
    q (ncx, ncz, nq) intensive fields carried with the mass; ux, uz face velocities (m/s) of
    face_velocities; h cell side (m); dt (s).  work_rho, srx, srz (ncx, ncz), sqx, sqz, dq
    (ncx, ncz, nq), dm (ncx, ncz): work arrays.  Returns the smallest cell mass after the step
    (kg/m; negative means the Courant number was too large).

    Parallel over blocks of whole rows or columns (BLOCK): an x-face's flux goes to two cells
    of one column, a z-face's to two cells of one row, so each cell receives its fluxes in the
    serial order (x-faces by ascending i, then z-faces by ascending k) whatever the threads:
    the numbers are the serial loop's, bit for bit."""
    ncx, ncz = m.shape
    area = h * h
    full = 0.0
    for i in range(ncx):
        for k in range(ncz):
            work_rho[i, k] = m[i, k] / area
            if work_rho[i, k] > full:
                full = work_rho[i, k]
    rho_empty = EMPTY * full
    m_empty = rho_empty * area
    nbx = (ncx + BLOCK - 1) // BLOCK
    nbz = (ncz + BLOCK - 1) // BLOCK
    for b in nb.prange(nbx):
        i0 = b * BLOCK
        i1 = min(ncx, i0 + BLOCK)
        _slopes(i0, i1, work_rho, q, open_x, open_z, rho_empty, periodic, srx, srz, sqx, sqz)
        dm[i0:i1] = 0.0
        dq[i0:i1] = 0.0
    for b in nb.prange(nbz):
        k0 = b * BLOCK
        _x_fluxes(k0, min(ncz, k0 + BLOCK), q, ux, h, dt, periodic, work_rho, srx, sqx, dm,
                  dq)
    for b in nb.prange(nbx):
        i0 = b * BLOCK
        _z_fluxes(i0, min(ncx, i0 + BLOCK), q, uz, h, dt, work_rho, srz, sqz, dm, dq)
    low = np.empty(nbx)
    for b in nb.prange(nbx):
        i0 = b * BLOCK
        low[b] = _update(i0, min(ncx, i0 + BLOCK), m, q, dm, dq, m_empty)
    return low.min()
