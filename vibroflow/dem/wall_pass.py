"""The tub step's wall pass (vibroflow.dem.step): each ball's contacts with the tub's U wall,
its partitions, the plane walls and the parts, added to its force one after the other.
"""
from __future__ import annotations

import numba as nb
import numpy as np

from .block_record import D_LOST, D_WALL_OVERLAP, keep_largest, record_impact
from .contact import add_force_torque, contact_force, put3
from .parts import ball_parts
from .walls import (KIND_BALL_PARTITION, KIND_BALL_PLANE, KIND_BALL_TUB, TUB_LENGTH,
                    TUB_PERIODIC, TUB_PRESENT, TUB_RADIUS, TUB_RIM, WALL_PLANE0, WALL_U,
                    plane_wall, u_wall)

# a ball whose centre is this fraction of (R - r) nearer the U's axis than R - r is clear of
# it: far above the rounding of u_wall's gap (a few ulp of R), so `clear_of_walls` never
# drops a contact
CLEAR_MARGIN = 1e-9


@nb.njit(cache=True, inline="always")
def clear_of_walls(px, py, pz, r, tub, pose, cth, sth, partitions):
    """Whether a ball provably touches neither the U wall nor a partition and is inside the
    tub: then u_wall and the partitions' tests (ball_walls) would find no overlap and no lost
    ball.  The U's test is u_wall's gap, squared, with CLEAR_MARGIN; the partitions' is theirs."""
    if partitions:
        if not (r - py <= 0.0 and r - (tub[TUB_LENGTH] - py) <= 0.0):  # NaN: not clear
            return False
    rx = px - pose[0] - pose[6]
    rz = pz - pose[1] - pose[7]
    tx = pose[6] + cth * rx + sth * rz
    tz = pose[7] - sth * rx + cth * rz
    R = tub[TUB_RADIUS]
    if tz > tub[TUB_RIM]:
        return False
    room = (R - r) * (1.0 - CLEAR_MARGIN)
    if room <= 0.0:
        return False
    if tz <= R:
        return tx * tx + (tz - R) * (tz - R) < room * room
    return abs(tx) < room


@nb.njit(cache=True)
def ball_walls(c, t, dt_hist, record_impacts, balls, pairs, walls, params, work, prt):
    """The wall-contact pass of the balls of block c: each ball's contacts with the tub's U
    wall, its partitions and the plane walls, at time t (s) with the tub's pose in work.pose,
    their forces and torques added to the ball's force and torque, one contact after the
    other; the wall slots' histories advanced by dt_hist, their forces and contact points
    stored, new contacts recorded as impacts into block c's buffer and the largest overlap into
    its diagnostics."""
    pos, vel, omg, force, torque = balls.pos, balls.vel, balls.omg, balls.force, balls.torque
    radius, mass, mat = balls.radius, balls.mass, balls.mat
    wall_hist, wall_flag, wall_fn, wall_ft = walls.hist, walls.flag, walls.fn, walls.ft
    wall_slide, wall_point, wall_force, wall_arc = walls.slide, walls.point, walls.force, walls.arc
    table, tub, wall_mat, planes = params.table, params.tub, params.wall_mat, params.planes
    imp_buf, imp_count, diag, pose = work.imp_buf, work.imp_count, work.diag, work.pose
    has_tub = tub[TUB_PRESENT] > 0.0
    partitions = has_tub and tub[TUB_PERIODIC] == 0.0
    length = tub[TUB_LENGTH]
    n_walls = WALL_PLANE0 + planes.shape[0]
    n_parts = prt.shape.shape[0]
    periodic_length = length if has_tub and tub[TUB_PERIODIC] > 0.0 else 0.0
    cth = np.cos(pose[2])
    sth = np.sin(pose[2])
    # the tub's walls alone: a ball clear of them, with no wall contact to end, is skipped
    cull = has_tub and n_walls == WALL_PLANE0
    for i in range(pairs.bounds[c], pairs.bounds[c + 1]):
        r = radius[i]
        skip = False
        if cull and clear_of_walls(pos[i, 0], pos[i, 1], pos[i, 2], r, tub, pose, cth, sth,
                                   partitions):
            skip = True
            for w in range(n_walls):
                if wall_flag[i, w]:
                    skip = False
            if skip and n_parts == 0:
                continue
        fx, fy, fz = force[i, 0], force[i, 1], force[i, 2]
        tx, ty, tz = torque[i, 0], torque[i, 1], torque[i, 2]
        m = mass[i]
        mat_i = mat[i]
        # ball-tub frame quantities used by the tub's walls
        rx = pos[i, 0] - pose[0] - pose[6]
        rz = pos[i, 2] - pose[1] - pose[7]
        for w in range(0 if skip else n_walls):
            # geometry of slot w: overlap, normal (wall -> ball), wall velocity and spin (y),
            # contact point
            if w == WALL_U:
                if not has_tub:
                    continue
                delta, nx, nz, vwx, vwz, cx, cz, s, outside = u_wall(
                    pos[i, 0], pos[i, 2], r, tub, pose, cth, sth)
                if outside and diag[c, D_LOST] < 0.0:
                    diag[c, D_LOST] = i
                if delta <= 0.0 and not wall_flag[i, w]:
                    continue
                if delta > 0.0:
                    wall_arc[i] = s
                ny = 0.0
                vwy = 0.0
                wwy = -pose[5]
                cy = pos[i, 1]
                kind = KIND_BALL_TUB
            elif w < WALL_PLANE0:
                if not partitions:
                    continue
                y = pos[i, 1]
                if w == 1:
                    if (y < 0.0 or y > length) and diag[c, D_LOST] < 0.0:
                        diag[c, D_LOST] = i
                    delta = r - y
                    ny = 1.0
                    cy = 0.0
                else:
                    delta = r - (length - y)
                    ny = -1.0
                    cy = length
                if delta <= 0.0 and not wall_flag[i, w]:
                    continue
                nx = 0.0
                nz = 0.0
                vwx = pose[3] - pose[5] * rz
                vwz = pose[4] + pose[5] * rx
                vwy = 0.0
                wwy = -pose[5]
                cx = pose[6] + cth * rx + sth * rz
                cz = pose[7] - sth * rx + cth * rz
                kind = KIND_BALL_PARTITION
            else:
                k = w - WALL_PLANE0
                delta, vwx, vwy, vwz = plane_wall(pos[i, 0], pos[i, 1], pos[i, 2], r,
                                                  planes[k], t)
                if delta <= 0.0 and not wall_flag[i, w]:
                    continue
                nx = planes[k, 3]
                ny = planes[k, 4]
                nz = planes[k, 5]
                wwy = 0.0
                cx = pos[i, 0] - (r - delta) * nx
                cy = pos[i, 1] - (r - delta) * ny
                cz = pos[i, 2] - (r - delta) * nz
                kind = KIND_BALL_PLANE
            if delta <= 0.0:
                # the contact has just ended: forget its history
                wall_flag[i, w] = 0
                for q in range(6):
                    wall_hist[i, w, q] = 0.0
                wall_fn[i, w] = 0.0
                wall_ft[i, w] = 0.0
                wall_slide[i, w] = 0
                continue
            vx = vel[i, 0] - r * (omg[i, 1] * nz - omg[i, 2] * ny) - vwx
            vy = vel[i, 1] - r * (omg[i, 2] * nx - omg[i, 0] * nz) - vwy
            vz = vel[i, 2] - r * (omg[i, 0] * ny - omg[i, 1] * nx) - vwz
            if not wall_flag[i, w]:
                wall_flag[i, w] = 1
                if record_impacts:
                    vn = vx * nx + vy * ny + vz * nz
                    record_impact(imp_buf, imp_count, c, t, kind, pos[i, 0] - r * nx,
                                  pos[i, 1] - r * ny, pos[i, 2] - r * nz, -vn, i)
            wfx, wfy, wfz, tix, tiy, tiz, _tjx, _tjy, _tjz, fn, ft, sl = contact_force(
                delta, nx, ny, nz, vx, vy, vz, omg[i, 0], omg[i, 1] - wwy, omg[i, 2],
                r, 0.0, r, m, table[mat_i, wall_mat[w]], wall_hist[i, w], dt_hist)
            fx, fy, fz, tx, ty, tz = add_force_torque(fx, fy, fz, tx, ty, tz,
                                                      wfx, wfy, wfz, tix, tiy, tiz)
            wall_fn[i, w] = fn
            wall_ft[i, w] = ft
            wall_slide[i, w] = sl
            wall_point[i, w, 0] = cx
            wall_point[i, w, 1] = cy
            wall_point[i, w, 2] = cz
            wall_force[i, w, 0] = wfx
            wall_force[i, w, 1] = wfy
            wall_force[i, w, 2] = wfz
            keep_largest(diag, c, D_WALL_OVERLAP, delta, i, w)
        if n_parts > 0:
            pfx, pfy, pfz, ptx, pty, ptz, pdelta, pk = ball_parts(
                i, c, t, dt_hist, record_impacts, pos[i, 0], pos[i, 1], pos[i, 2], r, mass[i],
                vel, omg, mat[i], table, pose, cth, sth, periodic_length, prt)
            fx, fy, fz, tx, ty, tz = add_force_torque(fx, fy, fz, tx, ty, tz,
                                                      pfx, pfy, pfz, ptx, pty, ptz)
            # a part's slot: after the wall slots
            keep_largest(diag, c, D_WALL_OVERLAP, pdelta, i, n_walls + pk)
        put3(force, i, fx, fy, fz)
        put3(torque, i, tx, ty, tz)
