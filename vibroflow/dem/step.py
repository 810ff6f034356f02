"""The DEM time step: velocity Verlet over flat arrays (LAMMPS' nve/sphere ordering).

    v += dt/2 F/m,  w += dt/2 T/I,  x += dt v          (kick, drift)
    F, T = contact forces at the new positions, with the half-step velocities
    v += dt/2 F/m,  w += dt/2 T/I                     (kick)

`advance` runs steps until it is asked to stop, the neighbour list needs a rebuild (some ball
moved more than half the skin in the tub frame), the impact buffer fills, or the run blows up;
the caller (dem/simulate.py) rebuilds and calls again.  All loops over balls are parallel.
The kernels take the records of vibroflow.dem.records and read their fields into local
variables first.

A step is two parallel loops over the blocks of balls: the pairs, then the ball pass (gather,
walls, the second half kick and, when another step of the call follows, that step's first half
kick and drift: the same operations in the same order as a loop of their own).  Each loop is a
wake-up and a barrier of numba's threads, 20 - 85 us on the 2-core machine: a loop of their own
for the first half kick and drift would cost more in its wake-up than in its work.  A step
after which `advance` stops (rebuild, impacts, blow-up) has drifted its balls already;
`_kick_block` saves each ball's position, velocity and spin before that in work.save, and
`_undo_drift` gives them back, so that the caller sees the step's state bit for bit.  The wall
pass skips a ball clear of the tub's walls (vibroflow.dem.wall_pass).  Measured on tub47-quick
under load (docs/validation.md section 6): the step costs 0.67 x the CPU time of the three-loop
step with every ball through the wall pass on one thread, 0.77 x on two.

Force assembly whose numbers do not depend on the thread count (DEVELOPERS.md, "Threads"):

1. pairs (`_pair_block`): every entry k of the half neighbour list (i, j > i) is evaluated
   once, by the thread that has ball i, its contact history advanced once; the force and the
   torque on i are summed into i's force and torque (from its weight) as the entries come, and
   the force and torque on j are written to the contact's own row (vibroflow.dem.contact_rows:
   a block's contacts in consecutive rows, packed at the start of each call of `advance`; no
   two contacts share a row, no races, no atomics).  The block's entries go in tiles of up to
   TILE touching ones: (1a) the distance tests, each entry written at the tile's next place
   and that place kept when it touches (no branch on the test); (1b) the touching entries'
   velocities, spins, pair constants (m_eff, R_eff and the law's constants reused from the
   contact before when its balls are of the same kind: the same inputs, the same bits) and
   histories gathered into the tile's columns; (2) the unit normal, contact velocity and law
   over the tile (`_law_tile`), a loop LLVM vectorises across contacts (4 doubles a ymm
   register on AVX-512 machines: packed vsqrtpd, vdivpd, vmulpd, no FMA), which makes the
   scalar law's IEEE operations in the scalar law's order for each contact, so the same bits
   (tests/test_contact_tile.py); (3) the tile's contacts in entry order: flags, impact rows,
   contact rows, each ball's sums, the largest overlap;
2. gather (`_gather_block`): each ball j adds the rows of the touching entries where it is
   the second ball, in ascending entry order (the list's reverse order);
3. walls (`wall_pass.ball_walls`): each ball's wall contacts, added one after the other;
4. kick (`_kick_block`): the step's second half kick (and the next step's first, and drift),
   one straight line of arithmetic a ball (`_kick_loop`).

Each sum is over the same terms in the same order whatever the threads.  The balls are cut into
NBLOCK contiguous blocks of about equal work (a function of the list alone); each thread takes
the blocks of its own lane, then the others' as it comes free (vibroflow.dem.block_queue: the
bed's work moves between the blocks over a cycle), and each block keeps its own impact buffer
and diagnostics.  An impact row also holds the stored place of its ball (IMP_COLUMNS on), from
which vibroflow.dem.impact_order puts the rows in an order that does not depend on the threads
or on the storage order.
"""
from __future__ import annotations

import numba as nb
import numpy as np

from ..tub.motion import pose as tub_pose
# the blocks' records' columns, read by the callers as step.D_*, step.IMP_COLUMNS, ...
from .block_record import (D_BALL_I, D_BALL_J, D_BALL_OVERLAP, D_LOST, D_NAN,  # noqa: F401
                           D_WALL_I, D_WALL_OVERLAP, D_WALL_W, IMP_COLUMNS, N_DIAG, N_IMP_BUF,
                           ROW_BALL, keep_largest, record_impact)
from .block_queue import open_lanes, take
from .contact_rows import pack, unpack
from .contact import (add_force_torque, contact_law, contact_velocity,
                      normal_constants, put3, unit_normal)
from .laws import (MODEL_HERTZ, MODEL_LINEAR, P_KT, P_MODEL, P_MU, P_MUR, P_ROLL, ROLL_CDT,
                   ROLL_CDT_LIGGGHTS, ROLL_EPSD, ROLL_NONE)
from .wall_pass import ball_walls
from .walls import KIND_BALL_BALL, TUB_LENGTH, TUB_PERIODIC, TUB_PRESENT

# status codes returned by advance
DONE, REBUILD, IMPACTS_FULL, BLOWUP, IMPACTS_LOST = 0, 1, 2, 3, 4
# blocks of balls of the parallel loops: a constant, so that the impacts' order and the
# diagnostics are the same on any number of threads (up to NBLOCK of them share the work; on
# tub47-quick's 4 200 balls 256 blocks cost about a quarter more a step on one thread than 64:
# each block pass pays for unpacking its records)
NBLOCK = 64
# what fixes a run's numbers beyond its scenario (checkpoints and the fill cache record it)
ASSEMBLY = f"pair slots, gathered per ball; {NBLOCK} blocks"


@nb.njit(cache=True)
def _part(flag, rflag, rpos, k):
    """Entry k's balls have just parted: its flags cleared (a call of its own, out of the pair
    loop's hot path); its contact row is forgotten (contact_rows.unpack zeroes its history)."""
    flag[k] = 0
    rflag[rpos[k]] = 0


# A tile: up to TILE touching entries of a block, one column of TILE numbers a quantity in
# the block's row of work.tile (T_* * TILE + m) and work.tile_idx (I_* * TILE + m).  Offsets
# that are constants of one array let LLVM prove that the law's loop (_law_loop) reads and
# writes no column twice, and vectorise it without run-time alias checks.
TILE = 128
(T_DX, T_DY, T_DZ, T_D2, T_RSUM, T_RI, T_RJ, T_DVX, T_DVY, T_DVZ, T_WIX, T_WIY, T_WIZ,
 T_WJX, T_WJY, T_WJZ, T_REFF, T_KN, T_DAMP, T_H0, T_H1, T_H2, T_H3, T_H4, T_H5,
 T_FX, T_FY, T_FZ, T_TIX, T_TIY, T_TIZ, T_TJX, T_TJY, T_TJZ,
 T_DELTA, T_NX, T_NY, T_NZ, T_VN) = range(39)
N_TILE = 39
I_K, I_I, I_J = range(3)
N_TILE_IDX = 3


@nb.njit(cache=True, inline="always", error_model="numpy")
def _law_one(b, m, model, roll, kt_ratio, mu, mu_r, dt):
    """Contact m of tile b: its unit normal, contact velocity and law (contact.unit_normal,
    contact.contact_velocity, contact.contact_law), read from and written to the columns."""
    T = TILE
    delta, nx, ny, nz = unit_normal(b[T_DX * T + m], b[T_DY * T + m], b[T_DZ * T + m],
                                    b[T_D2 * T + m], b[T_RSUM * T + m])
    ri = b[T_RI * T + m]
    rj = b[T_RJ * T + m]
    wix = b[T_WIX * T + m]
    wiy = b[T_WIY * T + m]
    wiz = b[T_WIZ * T + m]
    wjx = b[T_WJX * T + m]
    wjy = b[T_WJY * T + m]
    wjz = b[T_WJZ * T + m]
    vx, vy, vz = contact_velocity(b[T_DVX * T + m], b[T_DVY * T + m], b[T_DVZ * T + m],
                                  wix, wiy, wiz, wjx, wjy, wjz, ri, rj, nx, ny, nz)
    (fx, fy, fz, tix, tiy, tiz, tjx, tjy, tjz, _fn, _ft, _sl,
     hx, hy, hz, mx, my, mz) = contact_law(
        delta, nx, ny, nz, vx, vy, vz, wix - wjx, wiy - wjy, wiz - wjz, ri, rj,
        b[T_REFF * T + m], model, roll, kt_ratio, mu, mu_r, b[T_KN * T + m],
        b[T_DAMP * T + m], b[T_H0 * T + m], b[T_H1 * T + m], b[T_H2 * T + m],
        b[T_H3 * T + m], b[T_H4 * T + m], b[T_H5 * T + m], dt)
    b[T_FX * T + m] = fx
    b[T_FY * T + m] = fy
    b[T_FZ * T + m] = fz
    b[T_TIX * T + m] = tix
    b[T_TIY * T + m] = tiy
    b[T_TIZ * T + m] = tiz
    b[T_TJX * T + m] = tjx
    b[T_TJY * T + m] = tjy
    b[T_TJZ * T + m] = tjz
    b[T_H0 * T + m] = hx
    b[T_H1 * T + m] = hy
    b[T_H2 * T + m] = hz
    b[T_H3 * T + m] = mx
    b[T_H4 * T + m] = my
    b[T_H5 * T + m] = mz
    b[T_DELTA * T + m] = delta
    b[T_NX * T + m] = nx
    b[T_NY * T + m] = ny
    b[T_NZ * T + m] = nz
    b[T_VN * T + m] = vx * nx + vy * ny + vz * nz


@nb.njit(cache=True, inline="always", error_model="numpy")
def _law_loop(n, b, model, roll, kt_ratio, mu, mu_r, dt):
    """The first n contacts of tile b, of one law (model and roll constants at each call
    site, so that the loop is straight-line code LLVM vectorises across contacts)."""
    for m in range(n):
        _law_one(b, m, model, roll, kt_ratio, mu, mu_r, dt)


@nb.njit(cache=True, error_model="numpy")
def _law_tile(n, b, par, dt):
    """The law of the first n contacts of tile b, all of the parameter row `par`: one loop a
    kind of law (the same bits as `contact.contact_force_with` contact by contact)."""
    model = int(par[P_MODEL])
    roll = int(par[P_ROLL])
    ktr, mu, mur = par[P_KT], par[P_MU], par[P_MUR]
    if model == MODEL_LINEAR:
        if roll == ROLL_NONE:
            _law_loop(n, b, MODEL_LINEAR, ROLL_NONE, ktr, mu, mur, dt)
        elif roll == ROLL_CDT:
            _law_loop(n, b, MODEL_LINEAR, ROLL_CDT, ktr, mu, mur, dt)
        elif roll == ROLL_EPSD:
            _law_loop(n, b, MODEL_LINEAR, ROLL_EPSD, ktr, mu, mur, dt)
        else:
            _law_loop(n, b, MODEL_LINEAR, ROLL_CDT_LIGGGHTS, ktr, mu, mur, dt)
    else:
        if roll == ROLL_NONE:
            _law_loop(n, b, MODEL_HERTZ, ROLL_NONE, ktr, mu, mur, dt)
        elif roll == ROLL_CDT:
            _law_loop(n, b, MODEL_HERTZ, ROLL_CDT, ktr, mu, mur, dt)
        elif roll == ROLL_EPSD:
            _law_loop(n, b, MODEL_HERTZ, ROLL_EPSD, ktr, mu, mur, dt)
        else:
            _law_loop(n, b, MODEL_HERTZ, ROLL_CDT_LIGGGHTS, ktr, mu, mur, dt)


@nb.njit(cache=True, error_model="numpy")
def _law_tile_mixed(n, b, bi, mat, table, dt):
    """`_law_tile` for a tile whose contacts are of several material pairs: each contact's
    row of the table, its law's kind resolved contact by contact (not vectorised)."""
    for m in range(n):
        par = table[mat[bi[I_I * TILE + m]], mat[bi[I_J * TILE + m]]]
        _law_one(b, m, par[P_MODEL], par[P_ROLL], par[P_KT], par[P_MU], par[P_MUR], dt)


@nb.njit(cache=True)
def _pair_block(c, t, dt_hist, periodic_length, record_impacts, balls, pairs, slots, params,
                work):
    """The list entries of the balls of block c (step 1 of the module docstring): each
    touching pair's force and torques into its contact row, and each ball's force set to its
    weight plus its own entries' forces (torque: their torques on it).

    Tile by tile of up to TILE touching entries: (1a) the entries in order, each apart one
    rejected (its flags cleared when it has just parted), each touching one's entry and ball
    listed; (1b) their geometry (recomputed: the same bits), velocities, spins, pair constants
    and histories (their contact rows', read in sequence: contact_rows.py) copied into the
    tile's columns; (2) the law over the tile (_law_tile, vectorised); (3) the tile's contacts
    in entry order: flags and a row for each contact that begins, impact rows, histories and
    forces on j into the contact rows, each ball's sums, the largest overlap.  The walk and
    the copy index with unsigned integers: numba wraps a signed index around (a sign test and
    an add a load), an unsigned one not (docs/decisions/threads.md)."""
    pos, vel, omg = balls.pos, balls.vel, balls.omg
    radius, mass, mat = balls.radius, balls.mass, balls.mat
    nbr_start, nbr, flag = pairs.start, pairs.nbr, pairs.flag
    bounds = pairs.bounds
    out, rpos, rflag = slots.out, slots.rpos, slots.rflag
    row, rrow, chist = slots.row, slots.rrow, slots.chist
    width = chist.shape[1]
    table = params.table
    imp_buf, imp_count, diag = work.imp_buf, work.imp_count, work.diag
    b = work.tile[c]
    bi = work.tile_idx[c]
    force, torque, gravity = balls.force, balls.torque, params.gravity
    lo, hi = bounds[c], bounds[c + 1]
    if lo >= hi:
        return
    # the block's next free contact row, in a local: the blocks' counters share cache lines
    nxt = work.row_next[c]
    T = TILE
    # the rolling histories travel through the tiles only where a law keeps them (EPSD)
    nh = 3
    for a in range(table.shape[0]):
        for bb in range(table.shape[1]):
            if table[a, bb, P_ROLL] == ROLL_EPSD:
                nh = 6
    # beyond a quarter of the length apart along y, the minimum image may differ from the
    # stored branch; nearer, np.rint(dy / L) is 0 and the image is the branch itself
    wrap = 0.25 * periodic_length if periodic_length > 0.0 else np.inf
    # the pair constants of the last contact (materials, radii, masses -> m_eff, R_eff, the
    # law's normal constants): the same inputs give the same bits, so a contact of the same
    # kind of balls reuses them (a monodisperse bed: two divisions and one or two square
    # roots fewer a contact)
    key_ri = key_mi = key_rj = key_mj = np.nan
    key_mat_i = key_mat_j = -1
    m_eff = r_eff = kn = damp = 0.0
    # the ball whose sums are open (its weight, then its entries' forces as they come)
    cur = lo
    sfx = mass[lo] * gravity[0]
    sfy = mass[lo] * gravity[1]
    sfz = mass[lo] * gravity[2]
    stx = 0.0
    sty = 0.0
    stz = 0.0
    i = lo
    k = nbr_start[lo]
    while i < hi:
        # (1a) the next tile's touching entries, listed without a branch on the test (a
        # third of the entries touch, in no order a branch predictor learns): each entry is
        # written at place n, and n moves on when it touches
        n = 0
        while i < hi and n < T:
            xi = pos[i, 0]
            yi = pos[i, 1]
            zi = pos[i, 2]
            ri = radius[i]
            kend = nbr_start[i + 1]
            while k < kend and n < T:
                # the untouched entry's rejection first: three loads of j, no call, no division;
                # unsigned indices, which numba does not wrap around (no sign test an index)
                ku = np.uint64(k)
                j = np.uint64(nbr[ku])
                dx = xi - pos[j, 0]
                dy = yi - pos[j, 1]
                dz = zi - pos[j, 2]
                if abs(dy) > wrap:
                    dy -= periodic_length * np.rint(dy / periodic_length)
                rsum = ri + radius[j]
                d2 = dx * dx + dy * dy + dz * dz
                touch = np.int64(d2 < rsum * rsum)
                if flag[ku] > touch:  # parted since the last step
                    _part(flag, rflag, rpos, k)
                nu = np.uint64(n)
                bi[np.uint64(I_K * T) + nu] = k
                bi[np.uint64(I_I * T) + nu] = i
                n += touch
                k += 1
            if k == kend:
                i += 1
        # (1b) the tile's geometry again (the same operations, the same bits: two stores an
        # entry in (1a) instead of eight), balls' velocities, spins, pair constants and
        # histories (the contact rows', contact_rows.py; zero for a contact that begins)
        mat0_i = mat0_j = -1
        mixed = False
        for m in range(n):
            ku = np.uint64(bi[I_K * T + m])
            iu = np.uint64(bi[I_I * T + m])
            ju = np.uint64(nbr[ku])
            bi[I_J * T + m] = np.int64(ju)
            dx = pos[iu, 0] - pos[ju, 0]
            dy = pos[iu, 1] - pos[ju, 1]
            dz = pos[iu, 2] - pos[ju, 2]
            if abs(dy) > wrap:
                dy -= periodic_length * np.rint(dy / periodic_length)
            rsum = radius[iu] + radius[ju]
            b[T_DX * T + m] = dx
            b[T_DY * T + m] = dy
            b[T_DZ * T + m] = dz
            b[T_D2 * T + m] = dx * dx + dy * dy + dz * dz
            b[T_RSUM * T + m] = rsum
            ri = radius[iu]
            mi = mass[iu]
            mat_i = mat[iu]
            rj = radius[ju]
            mj = mass[ju]
            mat_j = mat[ju]
            if not (ri == key_ri and mi == key_mi and mat_i == key_mat_i and rj == key_rj
                    and mj == key_mj and mat_j == key_mat_j):
                m_eff = mi * mj / (mi + mj)
                r_eff = ri * rj / (ri + rj)
                kn, damp = normal_constants(table[mat_i, mat_j], r_eff, m_eff)
                key_ri, key_mi, key_mat_i = ri, mi, mat_i
                key_rj, key_mj, key_mat_j = rj, mj, mat_j
            if m == 0:
                mat0_i, mat0_j = mat_i, mat_j
            elif mat_i != mat0_i or mat_j != mat0_j:
                mixed = True
            b[T_RI * T + m] = ri
            b[T_RJ * T + m] = rj
            b[T_DVX * T + m] = vel[iu, 0] - vel[ju, 0]
            b[T_DVY * T + m] = vel[iu, 1] - vel[ju, 1]
            b[T_DVZ * T + m] = vel[iu, 2] - vel[ju, 2]
            b[T_WIX * T + m] = omg[iu, 0]
            b[T_WIY * T + m] = omg[iu, 1]
            b[T_WIZ * T + m] = omg[iu, 2]
            b[T_WJX * T + m] = omg[ju, 0]
            b[T_WJY * T + m] = omg[ju, 1]
            b[T_WJZ * T + m] = omg[ju, 2]
            b[T_REFF * T + m] = r_eff
            b[T_KN * T + m] = kn
            b[T_DAMP * T + m] = damp
            if flag[ku]:
                ru = np.uint64(row[ku])
                b[T_H0 * T + m] = chist[ru, 0]
                b[T_H1 * T + m] = chist[ru, 1]
                b[T_H2 * T + m] = chist[ru, 2]
                if nh == 6:
                    b[T_H3 * T + m] = chist[ru, 3]
                    b[T_H4 * T + m] = chist[ru, 4]
                    b[T_H5 * T + m] = chist[ru, 5]
            else:
                for a in range(nh):
                    b[(T_H0 + a) * T + m] = 0.0
        # (2) the law over the tile
        if n == 0:
            continue
        if mixed:
            _law_tile_mixed(n, b, bi, mat, table, dt_hist)
        else:
            _law_tile(n, b, table[mat0_i, mat0_j], dt_hist)
        # (3) the tile's contacts in entry order
        for m in range(n):
            ku = np.uint64(bi[I_K * T + m])
            ii = bi[I_I * T + m]
            jj = bi[I_J * T + m]
            while cur < ii:
                put3(force, cur, sfx, sfy, sfz)
                put3(torque, cur, stx, sty, stz)
                cur += 1
                sfx = mass[cur] * gravity[0]
                sfy = mass[cur] * gravity[1]
                sfz = mass[cur] * gravity[2]
                stx = 0.0
                sty = 0.0
                stz = 0.0
            delta = b[T_DELTA * T + m]
            if not flag[ku]:
                # a contact begins: its entry's row of this call, or the block's next one
                if row[ku] < 0:
                    row[ku] = nxt
                    nxt += 1
                q = np.uint64(rpos[ku])
                flag[ku] = 1
                rflag[q] = 1
                rrow[q] = row[ku]
                # the columns no law of the bed keeps (a wider file's): zero in a row that an
                # earlier call may have left (a kept contact's are zero already)
                for a in range(nh, width):
                    chist[np.uint64(row[ku]), a] = 0.0
                if record_impacts:
                    ri = radius[ii]
                    record_impact(imp_buf, imp_count, c, t, KIND_BALL_BALL,
                                  pos[ii, 0] - ri * b[T_NX * T + m],
                                  pos[ii, 1] - ri * b[T_NY * T + m],
                                  pos[ii, 2] - ri * b[T_NZ * T + m], -b[T_VN * T + m], ii)
            ru = np.uint64(row[ku])
            for a in range(nh):
                chist[ru, a] = b[(T_H0 + a) * T + m]
            fx = b[T_FX * T + m]
            fy = b[T_FY * T + m]
            fz = b[T_FZ * T + m]
            out[ru, 0] = -fx
            out[ru, 1] = -fy
            out[ru, 2] = -fz
            out[ru, 3] = b[T_TJX * T + m]
            out[ru, 4] = b[T_TJY * T + m]
            out[ru, 5] = b[T_TJZ * T + m]
            sfx, sfy, sfz, stx, sty, stz = add_force_torque(
                sfx, sfy, sfz, stx, sty, stz, fx, fy, fz,
                b[T_TIX * T + m], b[T_TIY * T + m], b[T_TIZ * T + m])
            keep_largest(diag, c, D_BALL_OVERLAP, delta, ii, jj)
    work.row_next[c] = nxt
    # the balls after the last contact
    while True:
        put3(force, cur, sfx, sfy, sfz)
        put3(torque, cur, stx, sty, stz)
        cur += 1
        if cur >= hi:
            break
        sfx = mass[cur] * gravity[0]
        sfy = mass[cur] * gravity[1]
        sfz = mass[cur] * gravity[2]
        stx = 0.0
        sty = 0.0
        stz = 0.0


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
    torque (weight and own entries, from _pair_block) add the contact rows where it is the
    second ball, force reversed and the torque on j, in ascending entry order."""
    force, torque = balls.force, balls.torque
    bounds = pairs.bounds
    out, rstart, rflag, rrow = slots.out, slots.rstart, slots.rflag, slots.rrow
    for i in range(bounds[c], bounds[c + 1]):
        r0, r1 = rstart[i], rstart[i + 1]
        # most balls are no pair's touching second ball: only their flags are read
        while r0 < r1 and not rflag[r0]:
            r0 += 1
        if r0 == r1:
            continue
        fx, fy, fz = force[i, 0], force[i, 1], force[i, 2]
        tx, ty, tz = torque[i, 0], torque[i, 1], torque[i, 2]
        for r in range(r0, r1):
            if rflag[r]:
                q = np.uint64(rrow[r])
                fx += out[q, 0]
                fy += out[q, 1]
                fz += out[q, 2]
                tx += out[q, 3]
                ty += out[q, 4]
                tz += out[q, 5]
        put3(force, i, fx, fy, fz)
        put3(torque, i, tx, ty, tz)


@nb.njit(cache=True, inline="always")
def _kick_loop(lo, hi, pos, vel, omg, force, torque, radius, mass, ref_tub, save, pose, dt,
               drift):
    """`_kick_block`'s balls lo to hi - 1, each one straight line of arithmetic (no branch:
    `drift` is a constant at each call site, the tests are selects), so that LLVM pipelines
    or vectorises it across balls.  Returns the largest squared move (m^2) of a finite one and
    the first ball whose move is NaN or infinite (-1 when none)."""
    half_dt = 0.5 * dt
    cth = np.cos(pose[2])
    sth = np.sin(pose[2])
    m2 = 0.0
    bad = -1
    for i in range(lo, hi):
        r = radius[i]
        im = 1.0 / mass[i]
        ii = 1.0 / (0.4 * mass[i] * r * r)
        fx = force[i, 0]
        fy = force[i, 1]
        fz = force[i, 2]
        tx = torque[i, 0]
        ty = torque[i, 1]
        tz = torque[i, 2]
        vx = vel[i, 0] + half_dt * fx * im
        vy = vel[i, 1] + half_dt * fy * im
        vz = vel[i, 2] + half_dt * fz * im
        wx = omg[i, 0] + half_dt * tx * ii
        wy = omg[i, 1] + half_dt * ty * ii
        wz = omg[i, 2] + half_dt * tz * ii
        px = pos[i, 0]
        py = pos[i, 1]
        pz = pos[i, 2]
        rx = px - pose[0] - pose[6]
        rz = pz - pose[1] - pose[7]
        dx = pose[6] + cth * rx + sth * rz - ref_tub[i, 0]
        dy = py - ref_tub[i, 1]
        dz = pose[7] - sth * rx + cth * rz - ref_tub[i, 2]
        d2 = dx * dx + dy * dy + dz * dz
        finite = d2 < 1e300  # False: NaN or infinite
        m2 = d2 if finite & (d2 > m2) else m2
        bad = i if (not finite) & (bad < 0) else bad
        if drift:
            save[i, 0] = px
            save[i, 1] = py
            save[i, 2] = pz
            save[i, 3] = vx
            save[i, 4] = vy
            save[i, 5] = vz
            save[i, 6] = wx
            save[i, 7] = wy
            save[i, 8] = wz
            vx = vx + half_dt * fx * im
            vy = vy + half_dt * fy * im
            vz = vz + half_dt * fz * im
            wx = wx + half_dt * tx * ii
            wy = wy + half_dt * ty * ii
            wz = wz + half_dt * tz * ii
            put3(pos, i, px + dt * vx, py + dt * vy, pz + dt * vz)
        put3(vel, i, vx, vy, vz)
        put3(omg, i, wx, wy, wz)
    return m2, bad


@nb.njit(cache=True)
def _kick_block(c, balls, pairs, params, work, drift):
    """The step's second half kick of the balls of block c, and the largest squared move of
    one of them since the last list build (tub frame) into moved[c]; with `drift`, then each
    ball's state saved into work.save and the next step's first half kick and drift (the
    same operations, in the same order, as `_kick_drift`), one straight line a ball
    (`_kick_loop`)."""
    lo, hi = pairs.bounds[c], pairs.bounds[c + 1]
    pos, vel, omg, force, torque = balls.pos, balls.vel, balls.omg, balls.force, balls.torque
    radius, mass, ref_tub = balls.radius, balls.mass, balls.ref_tub
    save, pose = work.save, work.pose
    if drift:
        m2, bad = _kick_loop(lo, hi, pos, vel, omg, force, torque, radius, mass, ref_tub, save,
                             pose, params.dt, True)
    else:
        m2, bad = _kick_loop(lo, hi, pos, vel, omg, force, torque, radius, mass, ref_tub, save,
                             pose, params.dt, False)
    if bad >= 0 and work.diag[c, D_NAN] < 0.0:
        work.diag[c, D_NAN] = bad
    work.moved[c] = m2


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
    """Step 1 for every block, in parallel: each thread its own lane of blocks first, then
    the others' as it comes free (vibroflow.dem.block_queue)."""
    queue = work.queue
    lanes = open_lanes(queue, work.diag.shape[0])
    for lane in nb.prange(lanes):
        c, s = take(queue, lane, lanes, 0)
        while c >= 0:
            _pair_block(c, t, dt_hist, periodic_length, record_impacts, balls, pairs, slots,
                        params, work)
            c, s = take(queue, lane, lanes, s)


@nb.njit(cache=True, parallel=True)
def _ball_pass(t, dt_hist, kick, drift, record_impacts, balls, pairs, slots, walls, params,
               work, prt):
    """Steps 2 to 4 for every block, in parallel; with `drift`, also the next step's first
    half kick and drift (_kick_block).  Each thread takes its own lane of blocks first, then
    the others' as it comes free (vibroflow.dem.block_queue)."""
    queue = work.queue
    lanes = open_lanes(queue, work.diag.shape[0])
    for lane in nb.prange(lanes):
        c, s = take(queue, lane, lanes, 0)
        while c >= 0:
            _gather_block(c, balls, pairs, slots)
            ball_walls(c, t, dt_hist, record_impacts, balls, pairs, walls, params, work, prt)
            if kick:
                _kick_block(c, balls, pairs, params, work, drift)
            else:
                work.moved[c] = 0.0
            c, s = take(queue, lane, lanes, s)


@nb.njit(cache=True)
def compute_forces(t, kick, drift, record_impacts, balls, pairs, slots, walls, params, work,
                   prt):
    """Forces and torques at the current positions (gravity, pairs, walls) at time t (s), with
    the tub's pose in work.pose; with `kick`, also the step's second half kick, and with
    `drift` the next step's first half kick and drift (_kick_block).  Two parallel
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
    pack(pairs, slots, work)
    _pair_pass(t, dt_hist, periodic_length, record_impacts, balls, pairs, slots, params, work)
    _ball_pass(t, dt_hist, kick, drift, record_impacts, balls, pairs, slots, walls, params, work,
               prt)
    unpack(pairs, slots)


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
    flush, part_flush = work.imp_flush[0], work.imp_flush[1]
    tub = params.tub
    periodic_length = tub[TUB_LENGTH] if (tub[TUB_PRESENT] > 0.0 and
                                          tub[TUB_PERIODIC] > 0.0) else 0.0
    pack(pairs, slots, work)
    _kick_drift(balls, params)
    for k in range(nsteps):
        step = step0 + k + 1
        t = (step - time_origin_step) * dt
        _pose_array(motion, pose[6], pose[7], t, pose)
        drift = k + 1 < nsteps
        _pair_pass(t, dt, periodic_length, record_impacts, balls, pairs, slots, params, work)
        # np.bool_(True), not the literal: the pass compiled for compute_forces serves
        _ball_pass(t, dt, np.bool_(True), drift, record_impacts, balls, pairs, slots, walls,
                   params, work, prt)
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
            if imp_count[c] > flush or prt.imp_count[c] > part_flush:
                full = True
            if imp_count[c] > cap or prt.imp_count[c] > part_cap:
                lost = True
        status = (BLOWUP if blown else IMPACTS_LOST if lost else REBUILD if rebuild else
                  IMPACTS_FULL if full else DONE)
        if status != DONE:
            if drift:
                _undo_drift(balls, work.save)
            unpack(pairs, slots)
            return k + 1, status
    unpack(pairs, slots)
    return nsteps, DONE
