"""The face velocities of the remap, and the cells' velocity gradient matched to them.

The remap (advection.py) moves the material through the fixed mesh's faces at the face-normal
velocities u_f: the nodal velocity field of the Lagrangian step interpolated at each face's
midpoint with the mesh's constant B-spline weight tables (transfer.py; `face_velocity_rows`,
its pass along z the gather's: column_gather.py).
The stress update must see the volume change that this transport makes, so each cell's
velocity gradient gets the finite-volume divergence of its faces' velocities as its trace
(`match_divergence`; Benson 1992, Comput. Methods Appl. Mech. Eng. 99, 235, section 5).
"""
from __future__ import annotations

import numba as nb
import numpy as np

from .column_gather import ZF_Z, ZU_X, gather_rows, gather_work
from .transfer import stencil_rows


@nb.njit(cache=True)
def face_velocity_rows(i0, i1, Z, tables, periodic, open_x, open_z, m, ux, uz):
    """Face-normal velocities (m/s) of rows i0:i1: ux (ncx + 1, ncz) on the x-faces
    (x = xmin + i h), uz (ncx, ncz + 1) on the z-faces, the node velocities interpolated at
    the face midpoints with the mesh's weight tables (transfer.WeightTables as a tuple (cx, cz,
    fx, fz)), on the open faces of a cell holding material (mass m (ncx, ncz) kg/m > 0); 0
    elsewhere.  The interpolation's pass along z is the gather's (column_gather.gather_rows:
    an x-face's midpoint is at its cells' height, so its sum along z is theirs; a z-face's is
    Z[:, ZF_Z]), and here only the pass along x, from the node rows' sums Z.  A face between
    two empty cells carries no flux (advection.remap takes nothing from an empty upwind cell),
    and its divergence would only reach the velocity gradient of empty cells, which carry no
    stress (density 0: disconnected) and no weight in any output: skipping it spares about
    half the faces (the tub above the bed is empty).  Each face on its own, so rows may be
    shared out among threads (fused.py)."""
    tcx, _, tfx, _ = tables
    ncx1, ncz = ux.shape
    ncx = ncx1 - 1
    nxg = Z.shape[0]
    for i in range(i0, i1):
        # the cells left and right of face i (wrapped on a periodic mesh; a closed face's
        # neighbours are never read)
        il = (i + ncx - 1) % ncx
        ir = i % ncx
        n0, n1, n2, w0, w1, w2 = stencil_rows(tfx, i, nxg, periodic)
        z0, z1, z2 = Z[n0, ZU_X], Z[n1, ZU_X], Z[n2, ZU_X]
        for k in range(ncz):
            if open_x[i, k] and (m[il, k] > 0.0 or m[ir, k] > 0.0):
                ux[i, k] = w0 * z0[k] + w1 * z1[k] + w2 * z2[k]
            else:
                ux[i, k] = 0.0
        if i == ncx:
            continue
        n0, n1, n2, w0, w1, w2 = stencil_rows(tcx, i, nxg, periodic)
        z0, z1, z2 = Z[n0, ZF_Z], Z[n1, ZF_Z], Z[n2, ZF_Z]
        for k in range(ncz + 1):
            if open_z[i, k] and (m[i, k - 1] > 0.0 or m[i, k] > 0.0):
                uz[i, k] = w0 * z0[k] + w1 * z1[k] + w2 * z2[k]
            else:
                uz[i, k] = 0.0


def face_velocities(gv, tables, dx, periodic, open_x, open_z, m, ux, uz):
    """Every face's velocity (`face_velocity_rows`) from the node velocities gv (nx, nz, 2)
    (m/s) on a grid of spacing dx (m): the gather's pass along z first (column_gather.
    gather_rows), then the faces'."""
    rows = np.flatnonzero((m > 0.0).any(axis=0))
    ktop = int(rows[-1]) + 1 if rows.size else 0
    Z = gather_work(gv.shape[0], m.shape[1])
    gather_rows(0, gv.shape[0], ktop, tables[1], tables[3], dx, gv, Z)
    face_velocity_rows(0, ux.shape[0], Z, tables, periodic, open_x, open_z, m, ux, uz)


@nb.njit(cache=True)
def match_divergence(L, ux, uz, h, periodic, v, normal, mass, open_x, open_z, inv_r):
    """Replace the trace of each cell's velocity gradient L (N, 4) [xx, xz, zx, zz] (1/s,
    p = i * ncz + k) by the finite-volume divergence of its face velocities (1/s), split
    equally between L_xx and L_zz, so that the volume change the stress update sees is the one
    the mass transport makes.  In the domain's interior the two are equal (the quadratic
    B-spline velocity differenced over a cell that lies within one knot span); they differ next
    to the wall, whose closed faces pass no material while the nodal field beyond them moves.

    A closed face is the wall; what moves there is the material's separation from it.  A wall
    cell (normal (N, 2) its inward unit normal, mesh.py) whose material moves away from the
    wall, s = v . n > 0 (v (N, 2) the cells' velocities, m/s), gives its closed faces the
    velocity s n: the material leaves the wall as a body and the gap it opens is the cell's
    empty part (its volume fraction falls as the remap takes its mass out through the open
    faces), as a material point of the Lagrangian method lifts off the wall leaving empty
    space behind.  With the closed faces held at 0 instead, the wall cell's material would be
    stretched between the still wall and the lifting bed at every take-off, dilated below the
    critical density (stress-free), and the next landing would close the gap without
    compacting it (lagrangian_step.void_first: that ratchet).  A cell
    pressing on the wall or sliding along it (s <= 0) keeps them at 0: the wall compresses it,
    its empty part first (lagrangian_step.void_first).  mass (N,) kg/m: only cells holding
    material; open_x (ncx + 1, ncz), open_z (ncx, ncz + 1): the open faces.

    Axisymmetric section (L (N, 5), its fifth column the hoop rate; inv_r (N,) 1 / r of the
    cells' centres): the finite-volume divergence of a cell of revolution, (u_R r_R - u_L r_L)
    / (h r) + (w_T - w_B) / h, is the plane one plus (u_L + u_R) / (2 r) exactly (r_R, r_L =
    r +- h/2), which is the hoop rate given to L[:, 4]: the volume change the stress update
    sees is again the one the mass transport (remap_work's radii) makes."""
    match_divergence_cells(0, L.shape[0], L, ux, uz, h, v, normal, mass, open_x, open_z,
                           inv_r)


@nb.njit(cache=True)
def match_divergence_cells(a, b, L, ux, uz, h, v, normal, mass, open_x, open_z, inv_r):
    """`match_divergence` on the cells a:b alone (p = i * ncz + k; the other arguments as
    there): each cell's arithmetic is that one's, so the fused step's chunks of cells give its
    numbers."""
    ncz = ux.shape[1]
    hoop = L.shape[1] > 4
    # the cell's column and row counted along, not divided out of p (remap_rows.pack_cells)
    i = a // ncz
    k = a - i * ncz - 1
    for p in range(a, b):
        k += 1
        if k == ncz:
            k = 0
            i += 1
        ir = i + 1
        uxl = ux[i, k]
        uxr = ux[ir, k]
        uzb = uz[i, k]
        uzt = uz[i, k + 1]
        if mass[p] > 0.0:
            nx = normal[p, 0]
            nz = normal[p, 1]
            s = v[p, 0] * nx + v[p, 1] * nz
            if s > 0.0:
                if not open_x[i, k]:
                    uxl = s * nx
                if not open_x[ir, k]:
                    uxr = s * nx
                if not open_z[i, k]:
                    uzb = s * nz
                if not open_z[i, k + 1]:
                    uzt = s * nz
        div = (uxr - uxl + uzt - uzb) / h
        d = 0.5 * (div - L[p, 0] - L[p, 3])
        L[p, 0] += d
        L[p, 3] += d
        if hoop:
            L[p, 4] = 0.5 * (uxl + uxr) * inv_r[p]
