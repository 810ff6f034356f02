"""Ball-part contacts in the DEM (docs/models.md, "Parts in the bed"): the kernel the tub step
calls once per ball (`ball_parts`, from vibroflow.dem.step.ball_walls), the kernels' record of
the parts (`PartsRec`) and its arrays (`parts_record`).

Geometry is vibroflow.tub.parts: a part fixed in the tub frame is met in the tub frame (the
ball's centre taken there, the normal and the force turned back to the lab, the part's material
velocity at the contact point the tub's rigid velocity there and its spin the tub's); a
lab-fixed part is still.  A periodic tub takes the minimum image along y.  The contact law is
the walls' (vibroflow.dem.contact.contact_force with R_j = 0, m_eff = m_ball) with the
scenario's pair (ball material, part material).

Contacts and their tangential histories: part k holds SLOTS contact slots per ball, each with
its own history and a key (the feature it is on; EMPTY when free).  A cylinder, a box and a
sphere are convex: a ball touches one at one point, the nearest (part_nearest), in slot 0.  An
STL is touched as LIGGGHTS touches a mesh, triangle by triangle: every triangle whose nearest
point lies within the ball's radius is a candidate; face candidates (the nearest point inside
the triangle) are contacts (a ball in a concave fold touches both faces); an edge or vertex
candidate is a contact only when the ball has no face contact with the part; and no candidate
is a contact where an earlier one sits at the same point (the triangles sharing an edge or a
vertex give it once, not once each).  A contact keeps its slot while its key (triangle) stays; a contact on a new
triangle takes over the history of a slot whose contact ended in the same step (a ball sliding
across the mesh keeps its tangential spring), else starts one afresh.

What the part receives: the force and torque of every contact on each part (the opposite of the
ball's, torque about the part's centre, tub axes for a tub-fixed part), kept per ball and part in
the order of the ball's contacts (contrib, ncontrib) and summed by `sum_loads`, block of balls
by id by block, each block's balls by id (the same sums whatever the threads and the storage
order, vibroflow.dem.memory_order); and with impacts recorded, one row per impact (a ball's
contact with a part that had none in the step before): IMP_* columns below, then the ball's
block and the step (vibroflow.dem.impact_order).  The impact energy is 0.5 m v_n^2, the
ball's kinetic energy of its normal approach: for a part that does not move under the hit it is
also 0.5 m_eff v_n^2.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

from ..tub.motion import rigid_velocity, tub_to_lab_cs
from ..tub.parts import (FRAME_TUB, P_CX, P_CY, P_CZ, P_FRAME, P_HX, P_HY, P_HZ, P_RADIUS,
                         SHAPE_BOX, SHAPE_CYLINDER, SHAPE_SPHERE, SHAPE_STL, PackedParts,
                         closest_on_triangle, part_nearest, patch_of)
from .contact import contact_force

SLOTS = 4            # contact slots per ball and part (an STL's several faces)
EMPTY = -2           # key of a free slot
ANALYTIC = -1        # key of the one contact of a convex analytic part
DONE = -3.0          # a candidate that has its slot (scratch marker)
# columns of an impact row
(IMP_TIME, IMP_PART, IMP_PATCH, IMP_X, IMP_Y, IMP_Z, IMP_VN, IMP_VT, IMP_ENERGY,
 IMP_BALL) = range(10)
N_IMP = 10
N_PART_IMP_BUF = N_IMP + 2  # a buffered row: the IMP_* columns, the ball's block, the step
IMPACT_CAPACITY = 1 << 10  # rows per block of balls (step.NBLOCK), at least
IMPACT_FLUSH = 1 << 9  # a block's rows past which they are flushed (impact_order)
# columns of a load: force (N) and torque about the part's centre (N m), part frame axes
N_LOAD = 6


class PartsRec(NamedTuple):
    """The parts for the kernels (SI): packed geometry (vibroflow.tub.parts.PackedParts), the
    material index mat (P,) and bounding reach (P,) (m, from the centre; a cylinder's in x-z),
    the per-ball contact slots hist (N, P, SLOTS, 6) and key (N, P, SLOTS), each ball's
    loads on each part at the step, one row a contact, contrib (N, P, SLOTS, N_LOAD) with
    their counts ncontrib (N, P), impact rows imp (nblock, IMPACT_CAPACITY, N_PART_IMP_BUF;
    grown by vibroflow.dem.simulate to the bound of vibroflow.dem.impact_order) with
    their counts imp_count (nblock,), and scratch (nblock, SLOTS, 9) for an STL's candidates
    (nblock: step.NBLOCK, the blocks of balls)."""

    shape: np.ndarray
    prm: np.ndarray
    tri: np.ndarray
    tri_normal: np.ndarray
    tri_group: np.ndarray
    tri_start: np.ndarray
    mat: np.ndarray
    reach: np.ndarray
    hist: np.ndarray
    key: np.ndarray
    contrib: np.ndarray
    ncontrib: np.ndarray
    imp: np.ndarray
    imp_count: np.ndarray
    scratch: np.ndarray


def reach_of(packed: PackedParts) -> np.ndarray:
    """Distance (m) from each part's centre beyond which no point of it lies (a cylinder's in
    the x-z plane)."""
    out = np.zeros(packed.n)
    for k in range(packed.n):
        p = packed.prm[k]
        s = packed.shape[k]
        if s in (SHAPE_CYLINDER, SHAPE_SPHERE):
            out[k] = p[P_RADIUS]
        elif s == SHAPE_BOX:
            out[k] = math.sqrt(p[P_HX] ** 2 + p[P_HY] ** 2 + p[P_HZ] ** 2)
        else:
            tri = packed.tri[packed.tri_start[k]:packed.tri_start[k + 1]].reshape(-1, 3)
            out[k] = float(np.linalg.norm(tri - p[P_CX:P_CZ + 1], axis=1).max())
    return out


def parts_record(packed: PackedParts, mat: np.ndarray, hist: np.ndarray, key: np.ndarray,
                 nblock: int) -> PartsRec:
    """The kernels' record of the packed parts and a state's slot arrays, for `nblock`
    blocks of balls."""
    n, p = key.shape[0], key.shape[1]
    return PartsRec(packed.shape, packed.prm, packed.tri, packed.tri_normal, packed.tri_group,
                    packed.tri_start, np.ascontiguousarray(mat, dtype=np.int64), reach_of(packed),
                    hist, key, np.zeros((n, p, SLOTS, N_LOAD)), np.zeros((n, p), np.int64),
                    np.zeros((nblock, IMPACT_CAPACITY, N_PART_IMP_BUF)),
                    np.zeros(nblock, np.int64),
                    np.zeros((nblock, SLOTS, 9)))


@nb.njit(cache=True, inline="always")
def _clear(hist, key, i, k, s):
    key[i, k, s] = EMPTY
    for q in range(6):
        hist[i, k, s, q] = 0.0


@nb.njit(cache=True, parallel=True)
def sum_loads(contrib, ncontrib, rows, bounds, load):
    """load[c, k] (N, N m): the loads on part k of the balls of block c (ids bounds[c] to
    bounds[c + 1]; `rows`: the stored place of each id), added ball by ball by id, each
    ball's contacts in their order, from zero: the same sums whatever the threads and the
    storage."""
    for c in nb.prange(load.shape[0]):
        for k in range(load.shape[1]):
            for a in range(N_LOAD):
                load[c, k, a] = 0.0
        for d in range(bounds[c], bounds[c + 1]):
            i = rows[d]
            for k in range(load.shape[1]):
                for q in range(ncontrib[i, k]):
                    for a in range(N_LOAD):
                        load[c, k, a] += contrib[i, k, q, a]


@nb.njit(cache=True)
def _stl_candidates(prt, k, qx, qy, qz, r, sc):
    """The contacts of a ball (centre q in the part's frame, radius r) with STL part k by the
    module's rule, into sc rows [key, cx, cy, cz, nx, ny, nz, delta, feature]; returns their number."""
    tri, tri_normal = prt.tri, prt.tri_normal
    n = 0
    faces = 0
    for t in range(prt.tri_start[k], prt.tri_start[k + 1]):
        cx, cy, cz, region = closest_on_triangle(qx, qy, qz, tri, t)
        dx, dy, dz = qx - cx, qy - cy, qz - cz
        d2 = dx * dx + dy * dy + dz * dz
        if d2 >= r * r:
            continue
        if region != 0 and faces > 0:
            continue
        if region == 0 and faces == 0 and n > 0:
            n = 0  # the first face contact replaces the edge and vertex candidates so far
        # one contact per point: the triangles sharing an edge or a vertex (or two coplanar
        # ones whose common edge the ball sits over) give it once
        same = False
        for j in range(n):
            ex, ey, ez = sc[j, 1] - cx, sc[j, 2] - cy, sc[j, 3] - cz
            if ex * ex + ey * ey + ez * ez < 1e-12 * r * r:
                same = True
        if same:
            continue
        if n == sc.shape[0]:
            continue
        d = math.sqrt(d2)
        side = dx * tri_normal[t, 0] + dy * tri_normal[t, 1] + dz * tri_normal[t, 2]
        if d < 1e-12 * r or (region == 0 and side < 0.0):
            # centre on or behind the face: the face's normal, the overlap past it
            nx, ny, nz = tri_normal[t, 0], tri_normal[t, 1], tri_normal[t, 2]
            delta = r + (-d if side >= 0.0 else d)
        else:
            nx, ny, nz = dx / d, dy / d, dz / d
            delta = r - d
        sc[n, 0] = t
        sc[n, 1] = cx
        sc[n, 2] = cy
        sc[n, 3] = cz
        sc[n, 4] = nx
        sc[n, 5] = ny
        sc[n, 6] = nz
        sc[n, 7] = delta
        sc[n, 8] = t
        n += 1
        if region == 0:
            faces += 1
    return n


@nb.njit(cache=True, inline="always")
def _one_contact(i, k, slot, c, t, dt_hist, first, r, m, vel, omg, mat_i, table, pose, cth, sth,
                 tub_fixed, sc, j, prt, fx, fy, fz, tx, ty, tz):
    """Contact j of the scratch rows in slot `slot`: the force and torque on the ball added to
    (fx .. tz) and returned, the opposite kept as the ball's next load on part k, the impact
    written when `first`.  Contact point and normal are in the part's frame; the force law
    works in the lab."""
    cx, cy, cz = sc[j, 1], sc[j, 2], sc[j, 3]
    nx, ny, nz, delta = sc[j, 4], sc[j, 5], sc[j, 6], sc[j, 7]
    if tub_fixed:
        lnx = cth * nx - sth * nz
        lnz = sth * nx + cth * nz
        clx, clz = tub_to_lab_cs(cx, cz, pose[0], pose[1], cth, sth, pose[6], pose[7])
        vwx, vwz = rigid_velocity(clx, clz, pose[0], pose[1], pose[3], pose[4], pose[5],
                                  pose[6], pose[7])
        wwy = -pose[5]
    else:
        lnx, lnz = nx, nz
        vwx = vwz = wwy = 0.0
    lny = ny
    vx = vel[i, 0] - r * (omg[i, 1] * lnz - omg[i, 2] * lny) - vwx
    vy = vel[i, 1] - r * (omg[i, 2] * lnx - omg[i, 0] * lnz)
    vz = vel[i, 2] - r * (omg[i, 0] * lny - omg[i, 1] * lnx) - vwz
    if first:
        vn = vx * lnx + vy * lny + vz * lnz
        ux, uy, uz = vx - vn * lnx, vy - vn * lny, vz - vn * lnz
        row = prt.imp_count[c]
        if row < prt.imp.shape[1]:
            imp = prt.imp[c, row]
            prm = prt.prm[k]
            imp[IMP_TIME] = t
            imp[IMP_PART] = k
            imp[IMP_PATCH] = patch_of(prt.shape[k], prt.tri_group, nx, ny, nz, int(sc[j, 8]))
            imp[IMP_X] = cx - prm[P_CX]
            imp[IMP_Y] = cy - prm[P_CY]
            imp[IMP_Z] = cz - prm[P_CZ]
            imp[IMP_VN] = -vn
            imp[IMP_VT] = math.sqrt(ux * ux + uy * uy + uz * uz)
            imp[IMP_ENERGY] = 0.5 * m * vn * vn
            imp[IMP_BALL] = i
        prt.imp_count[c] = row + 1
    wfx, wfy, wfz, tix, tiy, tiz, tjx, _tjy, tjz, _fn, _ft, _sl = contact_force(
        delta, lnx, lny, lnz, vx, vy, vz, omg[i, 0], omg[i, 1] - wwy, omg[i, 2], r, 0.0, r, m,
        table[mat_i, prt.mat[k]], prt.hist[i, k, slot], dt_hist)
    # the part's load: -F at the contact point, the rolling moment's reaction, part axes
    gx, gy, gz = -wfx, -wfy, -wfz
    mx, my, mz = tjx, _tjy, tjz
    if tub_fixed:
        gx, gz = cth * gx + sth * gz, -sth * gx + cth * gz
        mx, mz = cth * mx + sth * mz, -sth * mx + cth * mz
    prm = prt.prm[k]
    ax, ay, az = cx - prm[P_CX], cy - prm[P_CY], cz - prm[P_CZ]
    q = prt.ncontrib[i, k]
    load = prt.contrib[i, k, q]
    load[0] = gx
    load[1] = gy
    load[2] = gz
    load[3] = ay * gz - az * gy + mx
    load[4] = az * gx - ax * gz + my
    load[5] = ax * gy - ay * gx + mz
    prt.ncontrib[i, k] = q + 1
    return fx + wfx, fy + wfy, fz + wfz, tx + tix, ty + tiy, tz + tiz


@nb.njit(cache=True, inline="always")
def ball_parts(i, c, t, dt_hist, record, px, py, pz, r, m, vel, omg, mat_i, table, pose,
               cth, sth, periodic_length, prt):
    """The contacts of ball i (centre (px, py, pz), lab; radius r, mass m) of chunk c with every
    part at time t: their force and torque on the ball (lab axes) and the largest overlap with
    the part it is with, as (fx, fy, fz, tx, ty, tz, delta_max, k_max) (k_max -1: none).
    Updates the ball's slots, keeps the opposite as the ball's loads on the parts
    (prt.contrib) and, with `record`, writes the impacts.  pose is the tub's
    (vibroflow.dem.step._pose_array)."""
    hist, key, sc = prt.hist, prt.key, prt.scratch[c]
    fx = fy = fz = tx = ty = tz = 0.0
    dmax = 0.0
    kmax = -1
    X, Z, pvx, pvz = pose[0], pose[1], pose[6], pose[7]
    for k in range(prt.shape.shape[0]):
        prt.ncontrib[i, k] = 0
        prm = prt.prm[k]
        tub_fixed = prm[P_FRAME] == FRAME_TUB
        if tub_fixed:
            rx = px - X - pvx
            rz = pz - Z - pvz
            qx = pvx + cth * rx + sth * rz
            qz = pvz - sth * rx + cth * rz
        else:
            qx = px
            qz = pz
        qy = py
        if periodic_length > 0.0:
            dy = qy - prm[P_CY]
            qy = prm[P_CY] + dy - periodic_length * np.rint(dy / periodic_length)
        active = False
        for s in range(SLOTS):
            if key[i, k, s] != EMPTY:
                active = True
        ex, ez = qx - prm[P_CX], qz - prm[P_CZ]
        ey = 0.0 if prt.shape[k] == SHAPE_CYLINDER else qy - prm[P_CY]
        reach = prt.reach[k] + r
        if ex * ex + ey * ey + ez * ez >= reach * reach:
            if active:
                for s in range(SLOTS):
                    _clear(hist, key, i, k, s)
            continue
        if prt.shape[k] == SHAPE_STL:
            n = _stl_candidates(prt, k, qx, qy, qz, r, sc)
        else:
            gap, nx, ny, nz, cx, cy, cz, feat = part_nearest(
                prt.shape, prt.prm, prt.tri, prt.tri_normal, prt.tri_start, k, qx, qy, qz)
            n = 0
            if gap < r:
                sc[0, 0] = ANALYTIC
                sc[0, 8] = feat
                sc[0, 1] = cx
                sc[0, 2] = cy
                sc[0, 3] = cz
                sc[0, 4] = nx
                sc[0, 5] = ny
                sc[0, 6] = nz
                sc[0, 7] = r - gap
                n = 1
        # slots: the same key first, then an ended contact's slot (its history goes on), then
        # a free one; sc[j, 0] = DONE once contact j has its slot
        taken = 0
        first = record and not active
        for j in range(n):
            want = int(sc[j, 0])
            for s in range(SLOTS):
                if key[i, k, s] == want and not (taken >> s) & 1:
                    taken |= 1 << s
                    sc[j, 0] = DONE
                    fx, fy, fz, tx, ty, tz = _one_contact(
                        i, k, s, c, t, dt_hist, False, r, m, vel, omg, mat_i, table, pose,
                        cth, sth, tub_fixed, sc, j, prt, fx, fy, fz, tx, ty, tz)
                    break
        for j in range(n):
            if sc[j, 0] == DONE:
                continue
            slot = -1
            for s in range(SLOTS):
                if key[i, k, s] != EMPTY and not (taken >> s) & 1:
                    slot = s
                    break
            if slot < 0:
                for s in range(SLOTS):
                    if key[i, k, s] == EMPTY and not (taken >> s) & 1:
                        slot = s
                        break
            if slot < 0:
                continue
            key[i, k, slot] = int(sc[j, 0])
            taken |= 1 << slot
            fx, fy, fz, tx, ty, tz = _one_contact(
                i, k, slot, c, t, dt_hist, first, r, m, vel, omg, mat_i, table, pose, cth, sth,
                tub_fixed, sc, j, prt, fx, fy, fz, tx, ty, tz)
            first = False
        for s in range(SLOTS):
            if not (taken >> s) & 1 and key[i, k, s] != EMPTY:
                _clear(hist, key, i, k, s)
        for j in range(n):
            if sc[j, 7] > dmax:
                dmax = sc[j, 7]
                kmax = k
    return fx, fy, fz, tx, ty, tz, dmax, kmax
