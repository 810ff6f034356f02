"""The DEM time step: velocity Verlet over flat arrays (LAMMPS' nve/sphere ordering).

    v += dt/2 F/m,  w += dt/2 T/I,  x += dt v          (kick, drift)
    F, T = contact forces at the new positions, with the half-step velocities
    v += dt/2 F/m,  w += dt/2 T/I                     (kick)

`advance` runs steps until it is asked to stop, the neighbour list needs a rebuild (some ball
moved more than half the skin in the tub frame), the impact buffer fills, or the run blows up;
the caller (dem/simulate.py) rebuilds and calls again.  All loops over balls are parallel.
The kernels take the records of vibroflow.dem.records and read their fields into local
variables first.

Parallel force assembly without races or atomics: balls are split into `nchunk` contiguous
chunks; the pair forces of chunk c go to its own buffer fbuf[c], then the buffers are summed in
a fixed order.  The result is reproducible bit for bit for a given chunk count (the checkpoint
records it), whatever the number of threads: the chunk count is a constant
(the scenario's run.force_chunks), not the thread count.
"""
from __future__ import annotations

import numba as nb
import numpy as np

from ..tub.motion import pose as tub_pose
from .contact import (add_pair, branch_vector, contact_force, forget, pair_contact_velocity,
                      put3, unit_normal)
from .parts import ball_parts, clear_loads
from .walls import (KIND_BALL_BALL, KIND_BALL_PARTITION, KIND_BALL_PLANE, KIND_BALL_TUB,
                    TUB_LENGTH, TUB_PERIODIC, TUB_PRESENT, WALL_PLANE0, WALL_U, plane_wall,
                    u_wall)

# columns of the per-chunk diagnostics
D_BALL_OVERLAP, D_BALL_I, D_BALL_J, D_WALL_OVERLAP, D_WALL_I, D_WALL_W, D_NAN, D_LOST = range(8)
N_DIAG = 8
# status codes returned by advance
DONE, REBUILD, IMPACTS_FULL, BLOWUP = 0, 1, 2, 3


@nb.njit(cache=True, inline="always")
def _record_impact(imp_buf, imp_count, c, t, kind, x, y, z, speed):
    k = imp_count[c]
    if k < imp_buf.shape[1]:
        imp_buf[c, k, 0] = t
        imp_buf[c, k, 1] = kind
        imp_buf[c, k, 2] = x
        imp_buf[c, k, 3] = y
        imp_buf[c, k, 4] = z
        imp_buf[c, k, 5] = speed
    imp_count[c] = k + 1


@nb.njit(cache=True)
def _pair_chunk(c, t, dt_hist, periodic_length, record_impacts, balls, pairs, table, work):
    pos, vel, omg = balls.pos, balls.vel, balls.omg
    radius, mass, mat = balls.radius, balls.mass, balls.mat
    nbr_start, nbr, hist, flag = pairs.start, pairs.nbr, pairs.hist, pairs.flag
    bounds = pairs.bounds
    fbuf, tbuf, imp_buf, imp_count, diag = (work.fbuf, work.tbuf, work.imp_buf, work.imp_count,
                                            work.diag)
    lo, hi = bounds[c], bounds[c + 1]
    for i in range(lo, hi):
        ri = radius[i]
        mi = mass[i]
        for k in range(nbr_start[i], nbr_start[i + 1]):
            j = nbr[k]
            dx, dy, dz = branch_vector(pos, i, j, periodic_length)
            rsum = ri + radius[j]
            d2 = dx * dx + dy * dy + dz * dz
            if d2 >= rsum * rsum:
                forget(hist, flag, k)
                continue
            delta, nx, ny, nz = unit_normal(dx, dy, dz, d2, rsum)
            rj = radius[j]
            vx, vy, vz = pair_contact_velocity(vel, omg, i, j, ri, rj, nx, ny, nz)
            if not flag[k]:
                flag[k] = 1
                if record_impacts:
                    vn = vx * nx + vy * ny + vz * nz
                    _record_impact(imp_buf, imp_count, c, t, KIND_BALL_BALL,
                                   pos[i, 0] - ri * nx, pos[i, 1] - ri * ny,
                                   pos[i, 2] - ri * nz, -vn)
            mj = mass[j]
            m_eff = mi * mj / (mi + mj)
            r_eff = ri * rj / (ri + rj)
            par = table[mat[i], mat[j]]
            fx, fy, fz, tix, tiy, tiz, tjx, tjy, tjz, fn, ft, sl = contact_force(
                delta, nx, ny, nz, vx, vy, vz,
                omg[i, 0] - omg[j, 0], omg[i, 1] - omg[j, 1], omg[i, 2] - omg[j, 2],
                ri, rj, r_eff, m_eff, par, hist[k], dt_hist)
            add_pair(fbuf, tbuf, c, i, j, fx, fy, fz, tix, tiy, tiz, tjx, tjy, tjz)
            if delta > diag[c, D_BALL_OVERLAP]:
                diag[c, D_BALL_OVERLAP] = delta
                diag[c, D_BALL_I] = i
                diag[c, D_BALL_J] = j


@nb.njit(cache=True)
def _pose_array(motion, pivot_x, pivot_z, t, out):
    X, Z, th, Xd, Zd, thd, _ax, _az, _al = tub_pose(motion, t)
    out[0] = X
    out[1] = Z
    out[2] = th
    out[3] = Xd
    out[4] = Zd
    out[5] = thd
    out[6] = pivot_x
    out[7] = pivot_z


@nb.njit(cache=True)
def _finish_chunk(c, t, kick, record_impacts, balls, walls, bounds, params, work, prt):
    """For the balls of chunk c: gather the pair forces from every chunk's buffer (and clear
    it), add gravity, the walls and the parts (vibroflow.dem.parts, record prt), and with `kick` finish the step (second half kick) and
    measure the largest move since the last list build (tub frame) into moved[c].

    Everything is in this one loop on purpose: a numba call that passes arrays costs a
    reference-count update per array, which per ball and wall slot cost more than the
    contact itself.  Without `kick` (the set-up force evaluation) contact histories are not
    advanced, as in LAMMPS' setup."""
    pos, vel, omg, force, torque = balls.pos, balls.vel, balls.omg, balls.force, balls.torque
    radius, mass, mat, ref_tub = balls.radius, balls.mass, balls.mat, balls.ref_tub
    wall_hist, wall_flag, wall_fn, wall_ft = walls.hist, walls.flag, walls.fn, walls.ft
    wall_slide, wall_point, wall_force, wall_arc = walls.slide, walls.point, walls.force, walls.arc
    dt, gravity, table, tub = params.dt, params.gravity, params.table, params.tub
    wall_mat, planes = params.wall_mat, params.planes
    fbuf, tbuf, imp_buf, imp_count, diag = (work.fbuf, work.tbuf, work.imp_buf, work.imp_count,
                                            work.diag)
    pose, moved = work.pose, work.moved
    nchunk = fbuf.shape[0]
    lo, hi = bounds[c], bounds[c + 1]
    cth = np.cos(pose[2])
    sth = np.sin(pose[2])
    half_dt = 0.5 * dt
    dt_hist = dt if kick else 0.0
    has_tub = tub[TUB_PRESENT] > 0.0
    partitions = has_tub and tub[TUB_PERIODIC] == 0.0
    length = tub[TUB_LENGTH]
    n_walls = WALL_PLANE0 + planes.shape[0]
    n_parts = prt.shape.shape[0]
    if n_parts > 0:
        clear_loads(prt, c)
    periodic_length = length if has_tub and tub[TUB_PERIODIC] > 0.0 else 0.0
    m2 = 0.0
    for i in range(lo, hi):
        fx = mass[i] * gravity[0]
        fy = mass[i] * gravity[1]
        fz = mass[i] * gravity[2]
        tx = 0.0
        ty = 0.0
        tz = 0.0
        for b in range(nchunk):
            fx += fbuf[b, i, 0]
            fy += fbuf[b, i, 1]
            fz += fbuf[b, i, 2]
            tx += tbuf[b, i, 0]
            ty += tbuf[b, i, 1]
            tz += tbuf[b, i, 2]
            for a in range(3):
                fbuf[b, i, a] = 0.0
                tbuf[b, i, a] = 0.0
        r = radius[i]
        # ball-tub frame quantities used by the tub's walls
        rx = pos[i, 0] - pose[0] - pose[6]
        rz = pos[i, 2] - pose[1] - pose[7]
        for w in range(n_walls):
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
                    _record_impact(imp_buf, imp_count, c, t, kind, pos[i, 0] - r * nx,
                                   pos[i, 1] - r * ny, pos[i, 2] - r * nz, -vn)
            wfx, wfy, wfz, tix, tiy, tiz, _tjx, _tjy, _tjz, fn, ft, sl = contact_force(
                delta, nx, ny, nz, vx, vy, vz, omg[i, 0], omg[i, 1] - wwy, omg[i, 2],
                r, 0.0, r, mass[i], table[mat[i], wall_mat[w]], wall_hist[i, w], dt_hist)
            fx += wfx
            fy += wfy
            fz += wfz
            tx += tix
            ty += tiy
            tz += tiz
            wall_fn[i, w] = fn
            wall_ft[i, w] = ft
            wall_slide[i, w] = sl
            wall_point[i, w, 0] = cx
            wall_point[i, w, 1] = cy
            wall_point[i, w, 2] = cz
            wall_force[i, w, 0] = wfx
            wall_force[i, w, 1] = wfy
            wall_force[i, w, 2] = wfz
            if delta > diag[c, D_WALL_OVERLAP]:
                diag[c, D_WALL_OVERLAP] = delta
                diag[c, D_WALL_I] = i
                diag[c, D_WALL_W] = w
        if n_parts > 0:
            pfx, pfy, pfz, ptx, pty, ptz, pdelta, pk = ball_parts(
                i, c, t, dt_hist, record_impacts, pos[i, 0], pos[i, 1], pos[i, 2], r, mass[i],
                vel, omg, mat[i], table, pose, cth, sth, periodic_length, prt)
            fx += pfx
            fy += pfy
            fz += pfz
            tx += ptx
            ty += pty
            tz += ptz
            if pdelta > diag[c, D_WALL_OVERLAP]:
                diag[c, D_WALL_OVERLAP] = pdelta
                diag[c, D_WALL_I] = i
                diag[c, D_WALL_W] = n_walls + pk  # a part: after the wall slots
        put3(force, i, fx, fy, fz)
        put3(torque, i, tx, ty, tz)
        if kick:
            im = 1.0 / mass[i]
            ii = 1.0 / (0.4 * mass[i] * r * r)
            for a in range(3):
                vel[i, a] += half_dt * force[i, a] * im
                omg[i, a] += half_dt * torque[i, a] * ii
            rx = pos[i, 0] - pose[0] - pose[6]
            rz = pos[i, 2] - pose[1] - pose[7]
            dx = pose[6] + cth * rx + sth * rz - ref_tub[i, 0]
            dy = pos[i, 1] - ref_tub[i, 1]
            dz = pose[7] - sth * rx + cth * rz - ref_tub[i, 2]
            d2 = dx * dx + dy * dy + dz * dz
            if not (d2 < 1e300):  # NaN or infinite
                if diag[c, D_NAN] < 0.0:
                    diag[c, D_NAN] = i
            elif d2 > m2:
                m2 = d2
    moved[c] = m2


@nb.njit(cache=True, parallel=True)
def compute_forces(t, kick, record_impacts, balls, pairs, walls, params, work, prt):
    """Forces and torques at the current positions (gravity, pairs, walls) at time t (s), with
    the tub's pose in work.pose; with `kick`, also the step's second half kick.  Two parallel
    loops: pairs into the chunk buffers, then each chunk's balls."""
    nchunk = work.fbuf.shape[0]
    tub = params.tub
    periodic_length = tub[TUB_LENGTH] if (tub[TUB_PRESENT] > 0.0 and
                                          tub[TUB_PERIODIC] > 0.0) else 0.0
    dt_hist = params.dt if kick else 0.0  # the set-up evaluation does not advance histories
    for c in nb.prange(nchunk):
        _pair_chunk(c, t, dt_hist, periodic_length, record_impacts, balls, pairs, params.table,
                    work)
    for c in nb.prange(nchunk):
        _finish_chunk(c, t, kick, record_impacts, balls, walls, pairs.bounds, params, work, prt)


@nb.njit(cache=True, parallel=True)
def advance(step0, nsteps, time_origin_step, motion, record_impacts, balls, pairs, walls, params,
            work, prt):
    """Run up to `nsteps` velocity-Verlet steps from step `step0`.

    Time is t = (step - time_origin_step) dt, so that the vibration's phase comes from an
    integer step count (exact on resume).  work.pose receives the tub pose of the last step.
    Returns (steps done, status) with status DONE, REBUILD, IMPACTS_FULL or BLOWUP.
    """
    pos, vel, omg, force, torque = balls.pos, balls.vel, balls.omg, balls.force, balls.torque
    radius, mass = balls.radius, balls.mass
    dt, half_skin, max_overlap = params.dt, params.half_skin, params.max_overlap
    imp_buf, imp_count, diag, pose, moved = (work.imp_buf, work.imp_count, work.diag, work.pose,
                                             work.moved)
    n = pos.shape[0]
    nchunk = work.fbuf.shape[0]
    half_dt = 0.5 * dt
    hs2 = half_skin * half_skin
    cap = imp_buf.shape[1]
    for k in range(nsteps):
        # kick and drift
        for i in nb.prange(n):
            im = 1.0 / mass[i]
            ii = 1.0 / (0.4 * mass[i] * radius[i] * radius[i])
            for a in range(3):
                vel[i, a] += half_dt * force[i, a] * im
                omg[i, a] += half_dt * torque[i, a] * ii
                pos[i, a] += dt * vel[i, a]
        step = step0 + k + 1
        t = (step - time_origin_step) * dt
        _pose_array(motion, pose[6], pose[7], t, pose)
        compute_forces(t, True, record_impacts, balls, pairs, walls, params, work, prt)
        blown = False
        rebuild = False
        full = False
        for c in range(nchunk):
            if diag[c, D_NAN] >= 0.0 or diag[c, D_LOST] >= 0.0:
                blown = True
            if diag[c, D_BALL_OVERLAP] > max_overlap or diag[c, D_WALL_OVERLAP] > max_overlap:
                blown = True
            if moved[c] > hs2:
                rebuild = True
            if imp_count[c] > cap // 2 or prt.imp_count[c] > prt.imp.shape[1] // 2:
                full = True
        if blown:
            return k + 1, BLOWUP
        if rebuild:
            return k + 1, REBUILD
        if full:
            return k + 1, IMPACTS_FULL
    return nsteps, DONE
