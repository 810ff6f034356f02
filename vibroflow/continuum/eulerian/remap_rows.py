"""The remap over the rows that can hold material: the cells up to one row above the bed's top,
on a compact layout of their own.

The remap (advection.py) runs over flat arrays of the mesh's cells, p = i * ncz + k, and a
third of tub47's rows lie above the bed (room for its flight).  A cell above the highest row
holding material, ktop - 1 (`bed_top`: a cell is empty at EMPTY of the fullest one, and gives
nothing, advection._faces), holds none, and in one step only row ktop can receive some: a
face's flux comes from its upwind cell, which must hold material, and the Courant number is
below 1.  So the transport over the rows 0:kc, kc = min(ktop + 1, ncz), laid out as
p = i * kc + k, gives every cell the whole mesh's numbers, bit for bit:

* the mass's reconstruction, the slopes' masks and the fluxes of rows 0:kc read no cell
  above them (row kc - 1 is empty, so its slopes are never used and its upper neighbour, shut
  here, is masked off there as empty);
* a cell above row kc - 1 receives nothing and is renewed as advection._modes' mode 0 makes it:
  its fields 0 and its round-off mass given a zero inflow (`renew_columns`).

`fit_rows` lays the mesh's open faces and weights out for kc (once a change of kc),
`pack_faces` and `pack_cells` the x-faces' velocities, the carried fields and the masses; the
fused loop (fused.py) runs advection.remap_fluxes on that layout, and `renew_columns` renews the
fields and unpacks them into the cells' arrays.
"""
from __future__ import annotations

from collections import namedtuple

import numba as nb
import numpy as np

from .advection import EMPTY, remap_work, renew_masses, renewed

#: the compact remap's arrays: work, advection.remap_work's arrays (their open faces and
#: weights laid out for `rows` by `fit_rows`); masks (left, right, down, up open faces) and
#: weights (cells, x-faces, z-faces) on the whole mesh's layout; the compact masses mass (N,)
#: (kg/m, or kg per radian), the x-faces' velocities ux ((ncx + 1) ncz,) (m/s), the carried
#: fields q (nq N,), and rows (1,) the row count the work is laid out for (-1: none yet)
RowsWork = namedtuple("RowsWork", ["work", "masks", "weights", "mass", "ux", "q", "rows"])


def rows_work(open_x, open_z, nq: int, radius=None) -> RowsWork:
    """The compact remap's arrays for a mesh with open faces open_x (ncx + 1, ncz), open_z
    (ncx, ncz + 1) carrying nq fields (advection.remap_work's arguments)."""
    work = remap_work(open_x, open_z, nq, radius)
    ncx, ncz = open_z.shape[0], open_x.shape[1]
    n = ncx * ncz
    return RowsWork(work, tuple(m.copy() for m in work[1][:4]),
                    tuple(w.copy() for w in work[10]), np.zeros(n),
                    np.zeros((ncx + 1) * ncz), np.zeros(nq * n), np.full(1, -1, np.int64))


@nb.njit(cache=True)
def bed_top(mass, ncx, ncz, h, wc):
    """ktop: one above the highest row with a cell that is not empty (advection.py: more than
    EMPTY of the fullest cell's mass per volume, or than that times h^2 in mass, the renewal's
    test), from the masses (N,) (kg/m, or kg per radian) and the cells' weights wc (N,) (1, or
    an axisymmetric section's radii, m) with advection._prepare's arithmetic."""
    area = h * h
    full = 0.0
    for p in range(ncx * ncz):
        r = mass[p] / (area * wc[p])
        if r > full:
            full = r
    rho_empty = EMPTY * full
    m_empty = rho_empty * area
    ktop = 0
    for i in range(ncx):
        for k in range(ncz - 1, ktop - 1, -1):
            p = i * ncz + k
            if mass[p] / (area * wc[p]) > rho_empty or mass[p] > m_empty:
                ktop = k + 1
                break
    return ktop


@nb.njit(cache=True)
def fit_rows(rw, kc, ncx, ncz):
    """The open faces and weights of rw.work laid out for the rows 0:kc (module docstring),
    unless they are already: the top face of a column's row kc - 1 shut (the cell above is
    outside the layout)."""
    if rw.rows[0] == kc:
        return
    ol, orr, od, ou = rw.work[1][0], rw.work[1][1], rw.work[1][2], rw.work[1][3]
    wc, wx, wz = rw.work[10]
    fl, fr, fd, fu = rw.masks
    vc, vx, vz = rw.weights
    for i in range(ncx):
        for k in range(kc):
            p = i * kc + k
            f = i * ncz + k
            ol[p] = fl[f]
            orr[p] = fr[f]
            od[p] = fd[f]
            ou[p] = fu[f] and k < kc - 1
            wc[p] = vc[f]
            wx[p] = vx[f]
            wz[p] = vz[f]
    for k in range(kc):
        wx[ncx * kc + k] = vx[ncx * ncz + k]
    wz[ncx * kc] = vz[ncx * ncz]
    rw.rows[0] = kc


@nb.njit(cache=True)
def pack_faces(i0, i1, ux, kc, out):
    """The velocities ux (ncx + 1, ncz) (m/s) of the x-faces i0:i1 on the rows 0:kc into out,
    on the compact layout (face i * kc + k)."""
    for i in range(i0, i1):
        for k in range(kc):
            out[i * kc + k] = ux[i, k]


@nb.njit(cache=True)
def pack_cells(a, b, kc, ncz, v, C, stress, rho, mass, q, mr):
    """The cells a:b's carried fields packed on the rows 0:kc (module docstring): q (NQ, ncx
    kc) the velocity v (N, 2) (m/s), the APIC matrix C (N, 4) (1/s), the stress (N, 4) (Pa)
    and the density rho (N,) (kg/m^3) (solver.NQ = 11 fields), mr (ncx kc,) the masses (kg/m)."""
    # the cell's row k counted along, not divided out of p (a division per cell costs as
    # much as the copy)
    i = a // ncz
    k = a - i * ncz
    for p in range(a, b):
        if k < kc:
            r = i * kc + k
            q[0, r] = v[p, 0]
            q[1, r] = v[p, 1]
            for j in range(4):
                q[2 + j, r] = C[p, j]
                q[6 + j, r] = stress[p, j]
            q[10, r] = rho[p]
            mr[r] = mass[p]
        k += 1
        if k == ncz:
            k = 0
            i += 1


@nb.njit(cache=True)
def renew_field(qj, dqj, mode, mass, inv):
    """One carried field qj (n,) renewed in place from its inflow dqj by the cells' modes,
    old masses and reciprocals (advection.renewed): a loop that vectorises, where renewing a
    cell's eleven fields at once, each written into its array, does not."""
    for p in range(qj.shape[0]):
        qj[p] = renewed(mode[p], mass[p], inv[p], qj[p], dqj[p])


@nb.njit(cache=True)
def renew_columns(c0, c1, kc, ncz, q, mr, dq, mode, inv, dm, v, C, stress, rho, mass):
    """The end of the transport step on the columns c0:c1 (advection.renew_cells on the rows
    0:kc, the arguments of `pack_cells` and the inflows dq, dm, modes and reciprocals of
    advection.remap_fluxes), the fields and masses unpacked into the cells' arrays; above row
    kc - 1 the fields 0 and the masses given a zero inflow, as the whole mesh's remap leaves
    those cells (module docstring).  Returns the smallest new mass (kg/m; inf for none) and
    whether every velocity is finite."""
    a = c0 * kc
    b = c1 * kc
    for j in range(q.shape[0]):
        renew_field(q[j, a:b], dq[j, a:b], mode[a:b], mr[a:b], inv[a:b])
    lowest = renew_masses(a, b, mr, dm)
    finite = True
    for i in range(c0, c1):
        for k in range(kc):
            p = i * ncz + k
            r = i * kc + k
            v[p, 0] = q[0, r]
            v[p, 1] = q[1, r]
            for j in range(4):
                C[p, j] = q[2 + j, r]
                stress[p, j] = q[6 + j, r]
            rho[p] = q[10, r]
            mass[p] = mr[r]
            if not (np.isfinite(v[p, 0]) and np.isfinite(v[p, 1])):
                finite = False
        for p in range(i * ncz + kc, (i + 1) * ncz):
            v[p, 0] = 0.0
            v[p, 1] = 0.0
            for j in range(4):
                C[p, j] = 0.0
                stress[p, j] = 0.0
            rho[p] = 0.0
            # advection.renew_masses' sum with a zero inflow (-0 becomes 0, as there)
            mn = mass[p] + 0.0
            lowest = min(lowest, mn)
            mass[p] = mn
    return lowest, finite
