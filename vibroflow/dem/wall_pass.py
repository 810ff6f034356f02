"""The tub step's wall pass (vibroflow.dem.step): each ball's contacts with the tub's U wall,
its partitions, the plane walls and the parts, added to its force one after the other.

Without parts, the wall contacts go in tiles of up to W_TILE, as the pair pass's
(step._pair_block): (1) each ball's slots in order, the geometry and contact velocity of each
touching one written into the tile's columns (an ended contact forgotten at once); (2) the law
over the tile (`_wall_law_tile`: contact.contact_law in a loop LLVM vectorises across contacts,
packed vsqrtpd and vdivpd, no FMA: the scalar law's IEEE operations for each contact, so the
same bits, tests/test_wall_tile.py); (3) the tile's contacts in ball and slot order: flags,
impact rows, slots, histories, each ball's force and torque (its sum, term by term, as the
scalar pass makes it), the largest overlap.  With parts, each ball's contacts are evaluated one
after the other (`contact.contact_force`), the parts' after the walls'.
"""
from __future__ import annotations

import numba as nb
import numpy as np

from .block_record import D_LOST, D_WALL_OVERLAP, keep_largest, record_impact
from .contact import (add_force_torque, contact_force, contact_law, normal_constants,
                      put3)
from .laws import (MODEL_HERTZ, MODEL_LINEAR, P_KT, P_MODEL, P_MU, P_MUR, P_ROLL, ROLL_CDT,
                   ROLL_CDT_LIGGGHTS, ROLL_EPSD, ROLL_NONE)
from .parts import ball_parts
from .walls import (KIND_BALL_PARTITION, KIND_BALL_PLANE, KIND_BALL_TUB, TUB_LENGTH,
                    TUB_PERIODIC, TUB_PRESENT, TUB_RADIUS, TUB_RIM, WALL_PLANE0, WALL_U,
                    plane_wall, u_wall)

# a ball whose centre is this fraction of (R - r) nearer the U's axis than R - r is clear of
# it: far above the rounding of u_wall's gap (a few ulp of R), so `clear_of_walls` never
# drops a contact
CLEAR_MARGIN = 1e-9

# A wall tile: up to W_TILE touching wall contacts of a block, one column of W_TILE numbers a
# quantity (W_* * W_TILE + m) in the block's row of work.tile, and their ball and slot in
# work.tile_idx (WI_* * W_TILE + m); constant offsets into one array let LLVM prove that the
# law's loop writes no column it reads, and vectorise it without run-time alias checks
W_TILE = 128
(W_DELTA, W_NX, W_NY, W_NZ, W_VX, W_VY, W_VZ, W_WX, W_WY, W_WZ, W_R, W_KN, W_DAMP, W_KT, W_MU,
 W_MUR, W_MODEL, W_ROLL, W_H0, W_H1, W_H2, W_H3, W_H4, W_H5,
 W_FX, W_FY, W_FZ, W_TIX, W_TIY, W_TIZ, W_FN, W_FT, W_SL) = range(33)
N_WALL_TILE = 33
WI_I, WI_W = range(2)
N_WALL_TILE_IDX = 2


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


@nb.njit(cache=True, inline="always", error_model="numpy")
def _wall_law_one(b, m, model, roll, dt):
    """Wall contact m of tile b: contact.contact_force's law (the wall as ball j of radius 0,
    R_eff the ball's radius), read from and written to the columns."""
    T = W_TILE
    r = b[W_R * T + m]
    (fx, fy, fz, tix, tiy, tiz, _tjx, _tjy, _tjz, fn, ft, sl,
     hx, hy, hz, mx, my, mz) = contact_law(
        b[W_DELTA * T + m], b[W_NX * T + m], b[W_NY * T + m], b[W_NZ * T + m],
        b[W_VX * T + m], b[W_VY * T + m], b[W_VZ * T + m],
        b[W_WX * T + m], b[W_WY * T + m], b[W_WZ * T + m], r, 0.0, r, model, roll,
        b[W_KT * T + m], b[W_MU * T + m], b[W_MUR * T + m], b[W_KN * T + m],
        b[W_DAMP * T + m], b[W_H0 * T + m], b[W_H1 * T + m], b[W_H2 * T + m],
        b[W_H3 * T + m], b[W_H4 * T + m], b[W_H5 * T + m], dt)
    b[W_FX * T + m] = fx
    b[W_FY * T + m] = fy
    b[W_FZ * T + m] = fz
    b[W_TIX * T + m] = tix
    b[W_TIY * T + m] = tiy
    b[W_TIZ * T + m] = tiz
    b[W_FN * T + m] = fn
    b[W_FT * T + m] = ft
    b[W_SL * T + m] = sl
    b[W_H0 * T + m] = hx
    b[W_H1 * T + m] = hy
    b[W_H2 * T + m] = hz
    b[W_H3 * T + m] = mx
    b[W_H4 * T + m] = my
    b[W_H5 * T + m] = mz


@nb.njit(cache=True, inline="always", error_model="numpy")
def _wall_law_loop(n, b, model, roll, dt):
    """The first n contacts of wall tile b, of one kind of law (model and roll constants at
    each call site: straight-line code LLVM vectorises across contacts)."""
    for m in range(n):
        _wall_law_one(b, m, model, roll, dt)


@nb.njit(cache=True, error_model="numpy")
def _wall_law_tile(n, b, model, roll, mixed, dt):
    """The law of the first n contacts of wall tile b: one loop a kind of law when all are of
    the kind (model, roll); with `mixed`, each contact's kind from its columns (not
    vectorised).  The same bits as contact.contact_force contact by contact."""
    if mixed:
        for m in range(n):
            _wall_law_one(b, m, b[W_MODEL * W_TILE + m], b[W_ROLL * W_TILE + m], dt)
    elif model == MODEL_LINEAR:
        if roll == ROLL_NONE:
            _wall_law_loop(n, b, MODEL_LINEAR, ROLL_NONE, dt)
        elif roll == ROLL_CDT:
            _wall_law_loop(n, b, MODEL_LINEAR, ROLL_CDT, dt)
        elif roll == ROLL_EPSD:
            _wall_law_loop(n, b, MODEL_LINEAR, ROLL_EPSD, dt)
        else:
            _wall_law_loop(n, b, MODEL_LINEAR, ROLL_CDT_LIGGGHTS, dt)
    else:
        if roll == ROLL_NONE:
            _wall_law_loop(n, b, MODEL_HERTZ, ROLL_NONE, dt)
        elif roll == ROLL_CDT:
            _wall_law_loop(n, b, MODEL_HERTZ, ROLL_CDT, dt)
        elif roll == ROLL_EPSD:
            _wall_law_loop(n, b, MODEL_HERTZ, ROLL_EPSD, dt)
        else:
            _wall_law_loop(n, b, MODEL_HERTZ, ROLL_CDT_LIGGGHTS, dt)


@nb.njit(cache=True, inline="always")
def _wall_tile(n, b, bi, model, roll, mixed, c, t, dt_hist, record_impacts, pos, force, torque,
               wall_hist, wall_flag, wall_fn, wall_ft, wall_slide, wall_force, imp_buf,
               imp_count, diag):
    """Steps (2) and (3) of the module docstring for the first n contacts of wall tile b."""
    _wall_law_tile(n, b, model, roll, mixed, dt_hist)
    T = W_TILE
    for m in range(n):
        i = bi[WI_I * T + m]
        w = bi[WI_W * T + m]
        nx = b[W_NX * T + m]
        ny = b[W_NY * T + m]
        nz = b[W_NZ * T + m]
        if not wall_flag[i, w]:
            wall_flag[i, w] = 1
            if record_impacts:
                r = b[W_R * T + m]
                vn = b[W_VX * T + m] * nx + b[W_VY * T + m] * ny + b[W_VZ * T + m] * nz
                kind = (KIND_BALL_TUB if w == WALL_U else
                        KIND_BALL_PARTITION if w < WALL_PLANE0 else KIND_BALL_PLANE)
                record_impact(imp_buf, imp_count, c, t, kind, pos[i, 0] - r * nx,
                              pos[i, 1] - r * ny, pos[i, 2] - r * nz, -vn, i)
        for a in range(6):
            wall_hist[i, w, a] = b[(W_H0 + a) * T + m]
        wfx = b[W_FX * T + m]
        wfy = b[W_FY * T + m]
        wfz = b[W_FZ * T + m]
        fx, fy, fz, tx, ty, tz = add_force_torque(
            force[i, 0], force[i, 1], force[i, 2], torque[i, 0], torque[i, 1], torque[i, 2],
            wfx, wfy, wfz, b[W_TIX * T + m], b[W_TIY * T + m], b[W_TIZ * T + m])
        put3(force, i, fx, fy, fz)
        put3(torque, i, tx, ty, tz)
        wall_fn[i, w] = b[W_FN * T + m]
        wall_ft[i, w] = b[W_FT * T + m]
        wall_slide[i, w] = int(b[W_SL * T + m])
        wall_force[i, w, 0] = wfx
        wall_force[i, w, 1] = wfy
        wall_force[i, w, 2] = wfz
        keep_largest(diag, c, D_WALL_OVERLAP, b[W_DELTA * T + m], i, w)


@nb.njit(cache=True)
def ball_walls(c, t, dt_hist, record_impacts, balls, pairs, walls, params, work, prt):
    """The wall-contact pass of the balls of block c: each ball's contacts with the tub's U
    wall, its partitions and the plane walls, at time t (s) with the tub's pose in work.pose,
    their forces and torques added to the ball's force and torque, one contact after the
    other; the wall slots' histories advanced by dt_hist, their forces and contact points
    stored, new contacts recorded as impacts into block c's buffer and the largest overlap into
    its diagnostics.  Without parts, in tiles (module docstring); with them, contact by
    contact, each ball's parts after its walls."""
    if prt.shape.shape[0] == 0:
        _ball_walls(c, t, dt_hist, record_impacts, balls, pairs, walls, params, work, prt, True)
    else:
        _ball_walls(c, t, dt_hist, record_impacts, balls, pairs, walls, params, work, prt,
                    False)


@nb.njit(cache=True, inline="always")
def _ball_walls(c, t, dt_hist, record_impacts, balls, pairs, walls, params, work, prt, tiled):
    """`ball_walls`, with `tiled` a constant at each call site: its contacts in wall tiles
    (no parts), or one after the other."""
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
    b = work.tile[c]
    bi = work.tile_idx[c]
    T = W_TILE
    n = 0
    # the kind of law of the tile's first contact, and whether another kind follows
    model0 = roll0 = -1.0
    mixed = False
    # the normal constants of the last contact (its radius, mass and parameter row): the same
    # inputs give the same bits
    key_r = key_m = np.nan
    key_mat_i = key_mat_w = -1
    kn = damp = 0.0
    for i in range(pairs.bounds[c], pairs.bounds[c + 1]):
        if tiled and n + n_walls > T:
            _wall_tile(n, b, bi, model0, roll0, mixed, c, t, dt_hist, record_impacts, pos,
                       force, torque, wall_hist, wall_flag, wall_fn, wall_ft, wall_slide,
                       wall_force, imp_buf, imp_count, diag)
            n = 0
            mixed = False
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
            if tiled:
                par = table[mat_i, wall_mat[w]]
                if not (r == key_r and m == key_m and mat_i == key_mat_i
                        and wall_mat[w] == key_mat_w):
                    kn, damp = normal_constants(par, r, m)
                    key_r, key_m, key_mat_i, key_mat_w = r, m, mat_i, wall_mat[w]
                if n == 0:
                    model0 = par[P_MODEL]
                    roll0 = par[P_ROLL]
                elif par[P_MODEL] != model0 or par[P_ROLL] != roll0:
                    mixed = True
                bi[WI_I * T + n] = i
                bi[WI_W * T + n] = w
                b[W_DELTA * T + n] = delta
                b[W_NX * T + n] = nx
                b[W_NY * T + n] = ny
                b[W_NZ * T + n] = nz
                b[W_VX * T + n] = vx
                b[W_VY * T + n] = vy
                b[W_VZ * T + n] = vz
                b[W_WX * T + n] = omg[i, 0]
                b[W_WY * T + n] = omg[i, 1] - wwy
                b[W_WZ * T + n] = omg[i, 2]
                b[W_R * T + n] = r
                b[W_KN * T + n] = kn
                b[W_DAMP * T + n] = damp
                b[W_KT * T + n] = par[P_KT]
                b[W_MU * T + n] = par[P_MU]
                b[W_MUR * T + n] = par[P_MUR]
                b[W_MODEL * T + n] = par[P_MODEL]
                b[W_ROLL * T + n] = par[P_ROLL]
                for a in range(6):
                    b[(W_H0 + a) * T + n] = wall_hist[i, w, a]
                wall_point[i, w, 0] = cx
                wall_point[i, w, 1] = cy
                wall_point[i, w, 2] = cz
                n += 1
                continue
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
        if not tiled and n_parts > 0:
            pfx, pfy, pfz, ptx, pty, ptz, pdelta, pk = ball_parts(
                i, c, t, dt_hist, record_impacts, pos[i, 0], pos[i, 1], pos[i, 2], r, mass[i],
                vel, omg, mat[i], table, pose, cth, sth, periodic_length, prt)
            fx, fy, fz, tx, ty, tz = add_force_torque(fx, fy, fz, tx, ty, tz,
                                                      pfx, pfy, pfz, ptx, pty, ptz)
            # a part's slot: after the wall slots
            keep_largest(diag, c, D_WALL_OVERLAP, pdelta, i, n_walls + pk)
        if not tiled:
            put3(force, i, fx, fy, fz)
            put3(torque, i, tx, ty, tz)
    if tiled and n > 0:
        _wall_tile(n, b, bi, model0, roll0, mixed, c, t, dt_hist, record_impacts, pos, force,
                   torque, wall_hist, wall_flag, wall_fn, wall_ft, wall_slide, wall_force,
                   imp_buf, imp_count, diag)
