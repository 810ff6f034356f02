"""The DEM time step: velocity Verlet over flat arrays (LAMMPS' nve/sphere ordering).

    v += dt/2 F/m,  w += dt/2 T/I,  x += dt v          (kick, drift)
    F, T = contact forces at the new positions, with the half-step velocities
    v += dt/2 F/m,  w += dt/2 T/I                     (kick)

`advance` runs steps until it is asked to stop, the neighbour list needs a rebuild (some ball
moved more than half the skin in the tub frame), the impact buffer fills, or the run blows up;
the caller (dem/simulate.py) rebuilds and calls again.  All loops over balls are parallel.
The kernels take the records of vibroflow.dem.records and read their fields into local
variables first.

Force assembly whose numbers do not depend on the thread count (DEVELOPERS.md, "Threads"):

1. pairs (`_pair_block`): every entry k of the half neighbour list (i, j > i) is evaluated
   once, by the thread that has ball i, its contact history advanced once; the force and the
   torque on i are summed into i's force and torque (from its weight) as the entries come, and
   the force and torque on j are written to the entry's own slot, kept in the list's reverse
   order (vibroflow.dem.neighbours: no two entries share a slot, no races, no atomics);
2. gather (`_gather_block`): each ball j adds the slots of the entries where it is the second
   ball, in ascending entry order, reading them in sequence;
3. walls (`ball_walls`): each ball's wall contacts, added one after the other;
4. kick (`_kick_block`): the step's second half kick.

Each sum is over the same terms in the same order whatever the threads.  The balls are cut into
NBLOCK contiguous blocks of about equal work (a function of the list alone); the threads share
the blocks, and each block keeps its own impact buffer and diagnostics.  An impact row also
holds the stored place of its ball (IMP_COLUMNS on), from which vibroflow.dem.impact_order
puts the rows in an order that does not depend on the threads or on the storage order.
"""
from __future__ import annotations

import numba as nb
import numpy as np

from ..tub.motion import pose as tub_pose
from .contact import (branch_vector, contact_force, forget, pair_contact_velocity, put3,
                      unit_normal)
from .parts import ball_parts
from .walls import (KIND_BALL_BALL, KIND_BALL_PARTITION, KIND_BALL_PLANE, KIND_BALL_TUB,
                    TUB_LENGTH, TUB_PERIODIC, TUB_PRESENT, TUB_RADIUS, TUB_RIM, WALL_PLANE0,
                    WALL_U, plane_wall, u_wall)

# columns of the per-block diagnostics
D_BALL_OVERLAP, D_BALL_I, D_BALL_J, D_WALL_OVERLAP, D_WALL_I, D_WALL_W, D_NAN, D_LOST = range(8)
N_DIAG = 8
# status codes returned by advance
DONE, REBUILD, IMPACTS_FULL, BLOWUP, IMPACTS_LOST = 0, 1, 2, 3, 4
# blocks of balls of the parallel loops: a constant, so that the impacts' order and the
# diagnostics are the same on any number of threads (up to NBLOCK of them share the work; on
# tub47-quick's 4 200 balls 256 blocks cost about a quarter more a step on one thread than 64:
# each block pass pays for unpacking its records)
NBLOCK = 64
# what fixes a run's numbers beyond its scenario (checkpoints and the fill cache record it)
ASSEMBLY = f"pair slots, gathered per ball; {NBLOCK} blocks"
# an impact row: time (s), kind (walls.KIND_*), contact point x, y, z (m, lab), normal speed
# (m/s); then the ball (its stored place, then its id), its block and the step
# (vibroflow.dem.impact_order)
IMP_COLUMNS = 6
ROW_BALL = 6
N_IMP_BUF = 9


@nb.njit(cache=True, inline="always")
def _record_impact(imp_buf, imp_count, c, t, kind, x, y, z, speed, i):
    k = imp_count[c]
    if k < imp_buf.shape[1]:
        imp_buf[c, k, 0] = t
        imp_buf[c, k, 1] = kind
        imp_buf[c, k, 2] = x
        imp_buf[c, k, 3] = y
        imp_buf[c, k, 4] = z
        imp_buf[c, k, 5] = speed
        imp_buf[c, k, ROW_BALL] = i
    imp_count[c] = k + 1


@nb.njit(cache=True)
def _pair_block(c, t, dt_hist, periodic_length, record_impacts, balls, pairs, slots, params,
                work):
    """The list entries of the balls of block c (step 1 of the module docstring): each
    touching pair's force and torques into its slot, and each ball's force set to its weight
    plus its own entries' forces (torque: their torques on it)."""
    pos, vel, omg = balls.pos, balls.vel, balls.omg
    radius, mass, mat = balls.radius, balls.mass, balls.mat
    nbr_start, nbr, hist, flag = pairs.start, pairs.nbr, pairs.hist, pairs.flag
    bounds = pairs.bounds
    rout, rpos, rflag = slots.out, slots.rpos, slots.rflag
    table = params.table
    imp_buf, imp_count, diag = work.imp_buf, work.imp_count, work.diag
    force, torque, gravity = balls.force, balls.torque, params.gravity
    lo, hi = bounds[c], bounds[c + 1]
    for i in range(lo, hi):
        ri = radius[i]
        mi = mass[i]
        # ball i's weight and its own entries' forces, summed as they come
        sfx = mi * gravity[0]
        sfy = mi * gravity[1]
        sfz = mi * gravity[2]
        stx = 0.0
        sty = 0.0
        stz = 0.0
        for k in range(nbr_start[i], nbr_start[i + 1]):
            j = nbr[k]
            dx, dy, dz = branch_vector(pos, i, j, periodic_length)
            rsum = ri + radius[j]
            d2 = dx * dx + dy * dy + dz * dz
            if d2 >= rsum * rsum:
                if flag[k]:
                    forget(hist, flag, k)
                    rflag[rpos[k]] = 0
                continue
            delta, nx, ny, nz = unit_normal(dx, dy, dz, d2, rsum)
            rj = radius[j]
            vx, vy, vz = pair_contact_velocity(vel, omg, i, j, ri, rj, nx, ny, nz)
            q = rpos[k]
            if not flag[k]:
                flag[k] = 1
                rflag[q] = 1
                if record_impacts:
                    vn = vx * nx + vy * ny + vz * nz
                    _record_impact(imp_buf, imp_count, c, t, KIND_BALL_BALL,
                                   pos[i, 0] - ri * nx, pos[i, 1] - ri * ny,
                                   pos[i, 2] - ri * nz, -vn, i)
            mj = mass[j]
            m_eff = mi * mj / (mi + mj)
            r_eff = ri * rj / (ri + rj)
            par = table[mat[i], mat[j]]
            fx, fy, fz, tix, tiy, tiz, tjx, tjy, tjz, fn, ft, sl = contact_force(
                delta, nx, ny, nz, vx, vy, vz,
                omg[i, 0] - omg[j, 0], omg[i, 1] - omg[j, 1], omg[i, 2] - omg[j, 2],
                ri, rj, r_eff, m_eff, par, hist[k], dt_hist)
            rout[q, 0] = -fx
            rout[q, 1] = -fy
            rout[q, 2] = -fz
            rout[q, 3] = tjx
            rout[q, 4] = tjy
            rout[q, 5] = tjz
            sfx += fx
            sfy += fy
            sfz += fz
            stx += tix
            sty += tiy
            stz += tiz
            if delta > diag[c, D_BALL_OVERLAP]:
                diag[c, D_BALL_OVERLAP] = delta
                diag[c, D_BALL_I] = i
                diag[c, D_BALL_J] = j
        put3(force, i, sfx, sfy, sfz)
        put3(torque, i, stx, sty, stz)


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
def _gather_block(c, balls, pairs, slots):
    """Step 2 of the module docstring for the balls of block c: to each ball's force and
    torque (weight and own entries, from _pair_block) add the slots where it is the second
    ball, force reversed and the torque on j, in ascending entry order."""
    force, torque = balls.force, balls.torque
    bounds = pairs.bounds
    rout, rstart, rflag = slots.out, slots.rstart, slots.rflag
    for i in range(bounds[c], bounds[c + 1]):
        r0, r1 = rstart[i], rstart[i + 1]
        if r0 == r1:
            continue
        fx, fy, fz = force[i, 0], force[i, 1], force[i, 2]
        tx, ty, tz = torque[i, 0], torque[i, 1], torque[i, 2]
        for r in range(r0, r1):
            if rflag[r]:
                fx += rout[r, 0]
                fy += rout[r, 1]
                fz += rout[r, 2]
                tx += rout[r, 3]
                ty += rout[r, 4]
                tz += rout[r, 5]
        put3(force, i, fx, fy, fz)
        put3(torque, i, tx, ty, tz)


# a ball whose centre is this fraction of (R - r) nearer the U's axis than R - r is clear of
# it: far above the rounding of u_wall's gap (a few ulp of R), so `_clear` never drops a contact
CLEAR_MARGIN = 1e-9


@nb.njit(cache=True, inline="always")
def _clear(px, py, pz, r, tub, pose, cth, sth, partitions):
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
        if cull and _clear(pos[i, 0], pos[i, 1], pos[i, 2], r, tub, pose, cth, sth, partitions):
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
                    _record_impact(imp_buf, imp_count, c, t, kind, pos[i, 0] - r * nx,
                                   pos[i, 1] - r * ny, pos[i, 2] - r * nz, -vn, i)
            wfx, wfy, wfz, tix, tiy, tiz, _tjx, _tjy, _tjz, fn, ft, sl = contact_force(
                delta, nx, ny, nz, vx, vy, vz, omg[i, 0], omg[i, 1] - wwy, omg[i, 2],
                r, 0.0, r, m, table[mat_i, wall_mat[w]], wall_hist[i, w], dt_hist)
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


@nb.njit(cache=True)
def _kick_block(c, balls, pairs, params, work, drift):
    """The step's second half kick of the balls of block c, and the largest squared move of
    one of them since the last list build (tub frame) into moved[c]; with `drift`, then each
    ball's state saved into work.save and the next step's first half kick and drift (the
    same operations, in the same order, as `_kick_drift`)."""
    pos, vel, omg, force, torque = balls.pos, balls.vel, balls.omg, balls.force, balls.torque
    radius, mass, ref_tub = balls.radius, balls.mass, balls.ref_tub
    diag, pose, moved, save = work.diag, work.pose, work.moved, work.save
    dt = params.dt
    half_dt = 0.5 * dt
    cth = np.cos(pose[2])
    sth = np.sin(pose[2])
    m2 = 0.0
    for i in range(pairs.bounds[c], pairs.bounds[c + 1]):
        r = radius[i]
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
        if drift:
            for a in range(3):
                save[i, a] = pos[i, a]
                save[i, 3 + a] = vel[i, a]
                save[i, 6 + a] = omg[i, a]
                vel[i, a] += half_dt * force[i, a] * im
                omg[i, a] += half_dt * torque[i, a] * ii
                pos[i, a] += dt * vel[i, a]
    moved[c] = m2


@nb.njit(cache=True, parallel=True)
def _kick_drift(balls, params):
    """A step's first half kick and drift of every ball, in parallel."""
    pos, vel, omg, force, torque = balls.pos, balls.vel, balls.omg, balls.force, balls.torque
    radius, mass = balls.radius, balls.mass
    dt = params.dt
    half_dt = 0.5 * dt
    for i in nb.prange(pos.shape[0]):
        im = 1.0 / mass[i]
        ii = 1.0 / (0.4 * mass[i] * radius[i] * radius[i])
        for a in range(3):
            vel[i, a] += half_dt * force[i, a] * im
            omg[i, a] += half_dt * torque[i, a] * ii
            pos[i, a] += dt * vel[i, a]


@nb.njit(cache=True)
def _undo_drift(balls, save):
    """Every ball's position, velocity and spin back from `save` (_kick_block's)."""
    pos, vel, omg = balls.pos, balls.vel, balls.omg
    for i in range(pos.shape[0]):
        for a in range(3):
            pos[i, a] = save[i, a]
            vel[i, a] = save[i, 3 + a]
            omg[i, a] = save[i, 6 + a]


@nb.njit(cache=True, parallel=True)
def _pair_pass(t, dt_hist, periodic_length, record_impacts, balls, pairs, slots, params, work):
    """Step 1 for every block, in parallel."""
    for c in nb.prange(work.diag.shape[0]):
        _pair_block(c, t, dt_hist, periodic_length, record_impacts, balls, pairs, slots,
                    params, work)


@nb.njit(cache=True, parallel=True)
def _ball_pass(t, dt_hist, kick, drift, record_impacts, balls, pairs, slots, walls, params,
               work, prt):
    """Steps 2 to 4 for every block, in parallel; with `drift`, also the next step's first
    half kick and drift (_kick_block)."""
    for c in nb.prange(work.diag.shape[0]):
        _gather_block(c, balls, pairs, slots)
        ball_walls(c, t, dt_hist, record_impacts, balls, pairs, walls, params, work, prt)
        if kick:
            _kick_block(c, balls, pairs, params, work, drift)
        else:
            work.moved[c] = 0.0


@nb.njit(cache=True)
def compute_forces(t, kick, drift, record_impacts, balls, pairs, slots, walls, params, work,
                   prt):
    """Forces and torques at the current positions (gravity, pairs, walls) at time t (s), with
    the tub's pose in work.pose; with `kick`, also the step's second half kick.  Two parallel
    loops over the blocks, each in its own function (numba fuses two parallel loops of one
    function when they run over the same range, and the gather must wait for every block's
    pairs): the pairs; then, block by block, each ball's gather, its wall contacts and its kick.
    Each pass over a block's balls is one compiled function: a numba call that passes arrays
    costs a reference-count update per array, which per ball would cost more than its contacts.
    Without `kick` (the set-up force evaluation) contact histories are not advanced, as in
    LAMMPS' setup."""
    tub = params.tub
    periodic_length = tub[TUB_LENGTH] if (tub[TUB_PRESENT] > 0.0 and
                                          tub[TUB_PERIODIC] > 0.0) else 0.0
    dt_hist = params.dt if kick else 0.0  # the set-up evaluation does not advance histories
    _pair_pass(t, dt_hist, periodic_length, record_impacts, balls, pairs, slots, params, work)
    _ball_pass(t, dt_hist, kick, drift, record_impacts, balls, pairs, slots, walls, params, work,
               prt)


@nb.njit(cache=True)
def advance(step0, nsteps, time_origin_step, motion, record_impacts, balls, pairs, slots, walls,
            params, work, prt):
    """Run up to `nsteps` velocity-Verlet steps from step `step0`.

    Time is t = (step - time_origin_step) dt, so that the vibration's phase comes from an
    integer step count (exact on resume).  work.pose receives the tub pose of the last step.
    Returns (steps done, status) with status DONE, REBUILD, IMPACTS_FULL, IMPACTS_LOST or
    BLOWUP.  Two parallel loops a step: the first step's kick and drift run alone, each later
    one's in the ball pass of the step before (_kick_block); a step after which the call
    stops gives its balls back from work.save, so that the state is the step's, bit for bit.
    """
    dt, half_skin, max_overlap = params.dt, params.half_skin, params.max_overlap
    imp_count, diag, pose, moved = work.imp_count, work.diag, work.pose, work.moved
    nblock = diag.shape[0]
    hs2 = half_skin * half_skin
    cap = work.imp_buf.shape[1]
    part_cap = prt.imp.shape[1]
    tub = params.tub
    periodic_length = tub[TUB_LENGTH] if (tub[TUB_PRESENT] > 0.0 and
                                          tub[TUB_PERIODIC] > 0.0) else 0.0
    _kick_drift(balls, params)
    for k in range(nsteps):
        step = step0 + k + 1
        t = (step - time_origin_step) * dt
        _pose_array(motion, pose[6], pose[7], t, pose)
        drift = k + 1 < nsteps
        _pair_pass(t, dt, periodic_length, record_impacts, balls, pairs, slots, params, work)
        _ball_pass(t, dt, True, drift, record_impacts, balls, pairs, slots, walls, params, work,
                   prt)
        blown = False
        rebuild = False
        full = False
        lost = False
        for c in range(nblock):
            if diag[c, D_NAN] >= 0.0 or diag[c, D_LOST] >= 0.0:
                blown = True
            if diag[c, D_BALL_OVERLAP] > max_overlap or diag[c, D_WALL_OVERLAP] > max_overlap:
                blown = True
            if moved[c] > hs2:
                rebuild = True
            if imp_count[c] > cap // 2 or prt.imp_count[c] > part_cap // 2:
                full = True
            if imp_count[c] > cap or prt.imp_count[c] > part_cap:
                lost = True
        status = (BLOWUP if blown else IMPACTS_LOST if lost else REBUILD if rebuild else
                  IMPACTS_FULL if full else DONE)
        if status != DONE:
            if drift:
                _undo_drift(balls, work.save)
            return k + 1, status
    return nsteps, DONE
