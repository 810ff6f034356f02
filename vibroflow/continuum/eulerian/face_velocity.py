"""The face velocities of the remap, and the cells' velocity gradient matched to them.

The remap (advection.py) moves the material through the fixed mesh's faces at the face-normal
velocities u_f: the nodal velocity field of the Lagrangian step interpolated at each face's
midpoint with the mesh's constant B-spline weight tables (transfer.py; `face_velocity_rows`).
The stress update must see the volume change that this transport makes, so each cell's
velocity gradient gets the finite-volume divergence of its faces' velocities as its trace
(`match_divergence`; Benson 1992, Comput. Methods Appl. Mech. Eng. 99, 235, section 5).
"""
from __future__ import annotations

import numba as nb

from ..stencil import axis_node
from .transfer import table_row


@nb.njit(cache=True, inline="always")
def _interp(gv, tx, ix, tz, kz, periodic, comp):
    """Component comp of the node velocities gv (nx, nz, 2) at the point whose B-spline
    weights are rows tx[ix] and tz[kz] of transfer.weight_table tables."""
    nxg = gv.shape[0]
    wx = table_row(tx, ix)
    wz = table_row(tz, kz)
    s = 0.0
    for a in range(3):
        i, _, wa, _ = axis_node(wx, a, 0.0, periodic, nxg)
        for b in range(3):
            k, _, wb, _ = axis_node(wz, b, 0.0, False, 0)
            s += wa * wb * gv[i, k, comp]
    return s


@nb.njit(cache=True)
def face_velocity_rows(i0, i1, gv, tables, periodic, open_x, open_z, m, ux, uz):
    """Face-normal velocities (m/s) of rows i0:i1: ux (ncx + 1, ncz) on the x-faces
    (x = xmin + i h), uz (ncx, ncz + 1) on the z-faces, the node velocities gv (nx, nz, 2)
    interpolated at the face midpoints with the mesh's weight tables (transfer.WeightTables as
    a tuple (cx, cz, fx, fz)), on the open faces of a cell holding material (mass m (ncx, ncz)
    kg/m > 0); 0 elsewhere.  A face between two empty cells carries no flux (advection.remap
    takes nothing from an empty upwind cell), and its divergence would only reach the velocity
    gradient of empty cells, which carry no stress (density 0: disconnected) and no weight in
    any output: skipping it spares about half the interpolations (the tub above the bed is
    empty).  Each face on its own, so rows may be shared out among threads (fused.py)."""
    tcx, tcz, tfx, tfz = tables
    ncx1, ncz = ux.shape
    ncx = ncx1 - 1
    for i in range(i0, i1):
        # the cells left and right of face i (wrapped on a periodic mesh; a closed face's
        # neighbours are never read)
        il = (i + ncx - 1) % ncx
        ir = i % ncx
        for k in range(ncz):
            if open_x[i, k] and (m[il, k] > 0.0 or m[ir, k] > 0.0):
                ux[i, k] = _interp(gv, tfx, i, tcz, k, periodic, 0)
            else:
                ux[i, k] = 0.0
        if i == ncx:
            continue
        for k in range(ncz + 1):
            if open_z[i, k] and (m[i, k - 1] > 0.0 or m[i, k] > 0.0):
                uz[i, k] = _interp(gv, tcx, i, tfz, k, periodic, 1)
            else:
                uz[i, k] = 0.0


@nb.njit(cache=True)
def face_velocities(gv, tables, periodic, open_x, open_z, m, ux, uz):
    """Every face's velocity (`face_velocity_rows`, the same arguments)."""
    face_velocity_rows(0, ux.shape[0], gv, tables, periodic, open_x, open_z, m, ux, uz)


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
    for p in range(a, b):
        i = p // ncz
        k = p - i * ncz
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
