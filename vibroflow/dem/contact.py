"""The contact law: one kernel for ball-ball and ball-wall contacts (models.md).

Convention: the unit normal n points from j (the other ball, or the wall) to i; delta > 0 is the
overlap; (vx, vy, vz) is the velocity of i's material relative to j's at the contact point and
(wx, wy, wz) = omega_i - omega_j the relative angular velocity.  The kernel returns the force on
i (j receives its opposite), the torque on i and the torque on j, and updates the contact's
history in place:

    hist[0:3]  accumulated tangential spring displacement xi_t (m)
    hist[3:6]  elastic rolling torque of the EPSD model (N m); the ball-pair list has these
               columns only where some pair's law is EPSD (laws.history_width)

Tangential: xi_t is first turned into the current tangent plane keeping its length (the contact
plane rotates with the balls), then incremented by v_t dt; F_t = -k_t xi_t truncated at the
Coulomb limit mu |F_n|, where xi_t is rescaled so that k_t |xi_t| = mu |F_n| (Cundall & Strack
1979; the LAMMPS/LIGGGHTS "history" model).  No tangential damping (tub47.md).

Rolling: CDT, M_r = -mu_r R_eff |F_n| w_r / |w_r|; or EPSD (Ai, Chen, Rotter, Ooi 2011, without
its viscous part, as LIGGGHTS' epsd2): M_r += -k_r w_r dt, |M_r| <= mu_r R_eff |F_n|,
k_r = 2.25 k_n mu_r^2 R_eff^2 (Iwashita & Oda 1998).  w_r is the relative angular velocity with
its twisting (normal) part removed.

Two conventions shared with LAMMPS' gran/hooke/history and LIGGGHTS, kept so the codes compare:
* the Coulomb limit is mu |F_n|, so friction still acts while the damping makes the contact pull
  at its end; the gross-sliding tangential impulse is then mu * integral |F_n| dt, 0.5% above
  mu (1 + e) m v_n at e = 0.85 and 4% above at e = 0.6 (tests/test_dem_collisions.py);
* the friction torques use the radii as lever arms, which add up to delta more than the
  distance between centres, so angular momentum is conserved only to O(delta / d).
"""
from __future__ import annotations

import numba as nb
import numpy as np

from .laws import (MODEL_LINEAR, P_DAMP, P_KN, P_KT, P_MODEL, P_MU, P_MUR, P_ROLL, ROLL_CDT,
                   ROLL_CDT_LIGGGHTS, ROLL_EPSD)


@nb.njit(cache=True, inline="always")
def into_plane(x, y, z, nx, ny, nz, len2):
    """(x, y, z) with its part along the unit normal n removed, then scaled back to the squared
    length len2 (left as it is when nothing of it is tangential)."""
    xn = x * nx + y * ny + z * nz
    x -= xn * nx
    y -= xn * ny
    z -= xn * nz
    p2 = x * x + y * y + z * z
    if p2 > 0.0:
        scale = np.sqrt(len2 / p2)
        x *= scale
        y *= scale
        z *= scale
    return x, y, z


@nb.njit(cache=True, inline="always")
def forget(hist, flag, q):
    """Entry q of a neighbour list is apart: its contact flag and history are cleared."""
    if flag[q]:
        flag[q] = 0
        for a in range(hist.shape[1]):
            hist[q, a] = 0.0


@nb.njit(cache=True, inline="always")
def unit_normal(dx, dy, dz, d2, rsum):
    """Overlap rsum - d (m) and unit normal (dx, dy, dz) / d of two touching balls, d2 = d^2."""
    d = np.sqrt(d2)
    inv = 1.0 / d
    return rsum - d, dx * inv, dy * inv, dz * inv


@nb.njit(cache=True, inline="always")
def add_pair(fbuf, tbuf, c, i, j, fx, fy, fz, tix, tiy, tiz, tjx, tjy, tjz):
    """A pair's force on i (j receives its opposite) and torques on i and j into chunk c's
    buffers."""
    fbuf[c, i, 0] += fx
    fbuf[c, i, 1] += fy
    fbuf[c, i, 2] += fz
    fbuf[c, j, 0] -= fx
    fbuf[c, j, 1] -= fy
    fbuf[c, j, 2] -= fz
    tbuf[c, i, 0] += tix
    tbuf[c, i, 1] += tiy
    tbuf[c, i, 2] += tiz
    tbuf[c, j, 0] += tjx
    tbuf[c, j, 1] += tjy
    tbuf[c, j, 2] += tjz


@nb.njit(cache=True, inline="always")
def add_force_torque(fx, fy, fz, tx, ty, tz, afx, afy, afz, atx, aty, atz):
    """A contact's force (afx, afy, afz) and torque (atx, aty, atz) added to a ball's sums."""
    return fx + afx, fy + afy, fz + afz, tx + atx, ty + aty, tz + atz


@nb.njit(cache=True, inline="always")
def put3(a, i, x, y, z):
    """Row i of an (N, 3) array set to (x, y, z)."""
    a[i, 0] = x
    a[i, 1] = y
    a[i, 2] = z


@nb.njit(cache=True, inline="always")
def normal_constants(par, r_eff, m_eff):
    """The normal law's constants of a contact (models.md): linear, (k_n, gamma_n =
    2 zeta sqrt(m_eff k_n)); Hertz, (k = k_n sqrt(R_eff), c = zeta sqrt(m_eff k)).  A
    function of the pair's materials, R_eff and m_eff alone: a pair loop reuses them from the
    entry before when those are the same (step._pair_block)."""
    if par[P_MODEL] == MODEL_LINEAR:
        kn = par[P_KN]
        return kn, 2.0 * par[P_DAMP] * np.sqrt(m_eff * kn)
    k = par[P_KN] * np.sqrt(r_eff)
    return k, par[P_DAMP] * np.sqrt(m_eff * k)


@nb.njit(cache=True, inline="always", fastmath=False)
def contact_force(delta, nx, ny, nz, vx, vy, vz, wx, wy, wz, r_i, r_j, r_eff, m_eff, par,
                  hist, dt):
    """Force and torques of one contact; see the module docstring.

    Returns (fx, fy, fz, tix, tiy, tiz, tjx, tjy, tjz, fn, ft, sliding):
    force on i (N), torque on i and on j (N m), the normal force |F_n| (N, signed: the
    damping may make it negative during the rebound), |F_t| (N), and 1 if at the Coulomb limit.
    """
    kn, damp = normal_constants(par, r_eff, m_eff)
    return contact_force_with(delta, nx, ny, nz, vx, vy, vz, wx, wy, wz, r_i, r_j, r_eff,
                              par, kn, damp, hist, dt)


@nb.njit(cache=True, inline="always", fastmath=False)
def contact_force_with(delta, nx, ny, nz, vx, vy, vz, wx, wy, wz, r_i, r_j, r_eff, par, kn,
                       damp, hist, dt):
    """`contact_force` with the normal law's constants (kn, damp) of `normal_constants`."""
    roll = par[P_ROLL]
    (fx, fy, fz, tix, tiy, tiz, tjx, tjy, tjz, fn, ft, sliding,
     hx, hy, hz, mx, my, mz) = contact_law(
        delta, nx, ny, nz, vx, vy, vz, wx, wy, wz, r_i, r_j, r_eff, par[P_MODEL], roll,
        par[P_KT], par[P_MU], par[P_MUR], kn, damp,
        hist[0], hist[1], hist[2], hist[3], hist[4], hist[5], dt)
    hist[0] = hx
    hist[1] = hy
    hist[2] = hz
    if roll == ROLL_EPSD:
        hist[3] = mx
        hist[4] = my
        hist[5] = mz
    return fx, fy, fz, tix, tiy, tiz, tjx, tjy, tjz, fn, ft, sliding


@nb.njit(cache=True, inline="always", fastmath=False)
def contact_law(delta, nx, ny, nz, vx, vy, vz, wx, wy, wz, r_i, r_j, r_eff, model, roll,
                kt_ratio, mu, mu_r, kn, damp, h0, h1, h2_, h3, h4, h5, dt):
    """The contact law's arithmetic, on numbers alone: the one source of `contact_force_with`
    (which reads the parameters from a table row and the history from its array) and of the
    tub step's law over a tile of contacts (step._law_loop, vectorised across contacts: each
    branch below is free of side effects, so LLVM turns it into a select of both sides, the
    same IEEE operations a contact).

    model, roll: the row's P_MODEL and P_ROLL; kt_ratio, mu, mu_r its P_KT, P_MU, P_MUR;
    (h0, h1, h2_) the tangential history and (h3, h4, h5) the EPSD rolling torque.  Returns
    `contact_force`'s 12 numbers, then the tangential history and the rolling history after
    the step (the latter as given unless roll is EPSD)."""
    vn = vx * nx + vy * ny + vz * nz  # > 0 separating
    if model == MODEL_LINEAR:
        gamma = damp
        f_elastic = kn * delta
        fn = f_elastic - gamma * vn
        kt = kt_ratio * kn
        kn_tangent = kn
    else:
        k = kn
        sd = np.sqrt(delta)
        c = damp
        f_elastic = k * delta * sd
        fn = f_elastic - c * np.sqrt(sd) * vn
        kt = kt_ratio * np.sqrt(r_eff * delta)
        kn_tangent = 1.5 * k * sd

    # tangential relative velocity
    vtx = vx - vn * nx
    vty = vy - vn * ny
    vtz = vz - vn * nz

    # turn the history into the current tangent plane, keeping its length
    hx = h0
    hy = h1
    hz = h2_
    h2 = hx * hx + hy * hy + hz * hz
    if h2 > 0.0:
        hx, hy, hz = into_plane(hx, hy, hz, nx, ny, nz, h2)
    hx += vtx * dt
    hy += vty * dt
    hz += vtz * dt
    ftx = -kt * hx
    fty = -kt * hy
    ftz = -kt * hz
    ft = np.sqrt(ftx * ftx + fty * fty + ftz * ftz)
    limit = mu * abs(fn)
    sliding = 0
    if ft > limit:
        sliding = 1
        if ft > 0.0:
            s = limit / ft
            ftx *= s
            fty *= s
            ftz *= s
            ft = limit
        if kt > 0.0:
            hx = -ftx / kt
            hy = -fty / kt
            hz = -ftz / kt

    fx = fn * nx + ftx
    fy = fn * ny + fty
    fz = fn * nz + ftz

    # torque of F_t about each centre: lever -r_i n for i, +r_j n for j with force -F_t
    cx = ny * ftz - nz * fty
    cy = nz * ftx - nx * ftz
    cz = nx * fty - ny * ftx
    tix = -r_i * cx
    tiy = -r_i * cy
    tiz = -r_i * cz
    tjx = -r_j * cx
    tjy = -r_j * cy
    tjz = -r_j * cz

    hmx = h3
    hmy = h4
    hmz = h5
    if roll != 0.0:
        wn = wx * nx + wy * ny + wz * nz
        wrx = wx - wn * nx
        wry = wy - wn * ny
        wrz = wz - wn * nz
        mlimit = mu_r * r_eff * abs(fn)
        mx = 0.0
        my = 0.0
        mz = 0.0
        if roll == ROLL_CDT:
            wr = np.sqrt(wrx * wrx + wry * wry + wrz * wrz)
            if wr > 1e-12:
                mx = -mlimit * wrx / wr
                my = -mlimit * wry / wr
                mz = -mlimit * wrz / wr
        elif roll == ROLL_CDT_LIGGGHTS:
            # LIGGGHTS 3.8's CDT (src/rolling_model_cdt.h), for comparisons with it: the
            # elastic normal force, along the whole relative spin omega_i - omega_j, then its
            # normal (twisting) part removed, so the magnitude is mu_r R_eff k_n delta times
            # |omega_rolling| / |omega| (docs/liggghts.md "Differences that remain")
            w = np.sqrt(wx * wx + wy * wy + wz * wz)
            if w > 1e-12:
                m = mu_r * r_eff * f_elastic / w
                mx = -m * wrx
                my = -m * wry
                mz = -m * wrz
        elif roll == ROLL_EPSD:
            kr = 2.25 * kn_tangent * mu_r * mu_r * r_eff * r_eff
            mx = h3
            my = h4
            mz = h5
            mx, my, mz = into_plane(mx, my, mz, nx, ny, nz, mx * mx + my * my + mz * mz)
            mx -= kr * wrx * dt
            my -= kr * wry * dt
            mz -= kr * wrz * dt
            mm = np.sqrt(mx * mx + my * my + mz * mz)
            if mm > mlimit and mm > 0.0:
                s = mlimit / mm
                mx *= s
                my *= s
                mz *= s
            hmx = mx
            hmy = my
            hmz = mz
        tix += mx
        tiy += my
        tiz += mz
        tjx -= mx
        tjy -= my
        tjz -= mz
    return (fx, fy, fz, tix, tiy, tiz, tjx, tjy, tjz, fn, ft, sliding,
            hx, hy, hz, hmx, hmy, hmz)


@nb.njit(cache=True, inline="always")
def branch_vector(pos, i, j, periodic_length):
    """r_i - r_j (m), with the minimum image along y when the length is periodic."""
    dx = pos[i, 0] - pos[j, 0]
    dy = pos[i, 1] - pos[j, 1]
    dz = pos[i, 2] - pos[j, 2]
    if periodic_length > 0.0:
        dy -= periodic_length * np.rint(dy / periodic_length)
    return dx, dy, dz


@nb.njit(cache=True, inline="always")
def pair_contact_velocity(vel, omg, i, j, ri, rj, nx, ny, nz):
    """Velocity of i's material relative to j's at their contact point (normal n from j to i):
    v_i - v_j - (r_i w_i + r_j w_j) x n."""
    return contact_velocity(vel[i, 0] - vel[j, 0], vel[i, 1] - vel[j, 1], vel[i, 2] - vel[j, 2],
                            omg[i, 0], omg[i, 1], omg[i, 2], omg[j, 0], omg[j, 1], omg[j, 2],
                            ri, rj, nx, ny, nz)


@nb.njit(cache=True, inline="always")
def contact_velocity(dvx, dvy, dvz, wix, wiy, wiz, wjx, wjy, wjz, ri, rj, nx, ny, nz):
    """`pair_contact_velocity` on numbers: (dvx, dvy, dvz) = v_i - v_j (m/s), w_i and w_j the
    spins (rad/s)."""
    wsx = ri * wix + rj * wjx
    wsy = ri * wiy + rj * wjy
    wsz = ri * wiz + rj * wjz
    return (dvx - (wsy * nz - wsz * ny),
            dvy - (wsz * nx - wsx * nz),
            dvz - (wsx * ny - wsy * nx))


@nb.njit(cache=True, inline="always")
def ball_pair(i, j, q, dx, dy, dz, dvx, dvy, dvz, balls, pairs, par, dt_hist, fbuf, tbuf, c):
    """One listed pair of balls (i, j), entry q of a neighbour list: the pair kernel of the
    Lees-Edwards box (vibroflow.dem.periodic_step).  The tub's step (vibroflow.dem.step) makes
    the same operations over tiles of contacts (`contact_law` in a loop vectorised across
    them), with the same bits.

    (dx, dy, dz) = r_i - r_j (m) is the branch vector to the image of j the caller chose;
    (dvx, dvy, dvz) (m/s) is added to the material relative velocity: the velocity of i's frame
    relative to that image's (Lees-Edwards images and the box's affine dilation; -0.0 where the
    image moves with j, which leaves the velocity bit for bit and costs no addition).  `balls`
    holds vel, omg, radius and mass, `pairs` the list's hist and flag (vibroflow.dem.records).
    Apart, the contact's history is forgotten.  In contact, the force and torques of
    `contact_force` with the parameters `par` (a row of vibroflow.dem.laws.pair_table) are added
    to fbuf[c, i], -fbuf[c, j], tbuf[c, i], tbuf[c, j] and the history advances by dt_hist.

    Returns (touching, first, delta, nx, ny, nz, vn, fx, fy, fz): whether they touch, whether
    the contact is new (its flag was clear), the overlap (m), the unit normal from j to i, the
    normal relative velocity (m/s, > 0 separating) and the force on i (N).
    """
    vel, omg, radius, mass = balls.vel, balls.omg, balls.radius, balls.mass
    hist, flag = pairs.hist, pairs.flag
    ri = radius[i]
    rj = radius[j]
    rsum = ri + rj
    d2 = dx * dx + dy * dy + dz * dz
    if d2 >= rsum * rsum:
        forget(hist, flag, q)
        return False, False, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    delta, nx, ny, nz = unit_normal(dx, dy, dz, d2, rsum)
    vx, vy, vz = pair_contact_velocity(vel, omg, i, j, ri, rj, nx, ny, nz)
    vx += dvx
    vy += dvy
    vz += dvz
    vn = vx * nx + vy * ny + vz * nz
    first = flag[q] == 0
    flag[q] = 1
    mi = mass[i]
    mj = mass[j]
    fx, fy, fz, tix, tiy, tiz, tjx, tjy, tjz, fn, ft, sl = contact_force(
        delta, nx, ny, nz, vx, vy, vz,
        omg[i, 0] - omg[j, 0], omg[i, 1] - omg[j, 1], omg[i, 2] - omg[j, 2],
        ri, rj, ri * rj / rsum, mi * mj / (mi + mj), par, hist[q], dt_hist)
    add_pair(fbuf, tbuf, c, i, j, fx, fy, fz, tix, tiy, tiz, tjx, tjy, tjz)
    return True, first, delta, nx, ny, nz, vn, fx, fy, fz
