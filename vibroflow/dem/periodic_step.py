"""The step of the Lees-Edwards periodic box (vibroflow.dem.lees_edwards): pair forces through
the DEM's pair kernel, stress, box control and velocity Verlet.  Numba kernels over flat arrays.

Shear: plain Newton in the lab frame (no SLLOD terms), the standard DEM approach (e.g. Chialvo,
Sun & Sundaresan 2012, PRE 85 021305): velocities are lab velocities, the shear enters only
through the boundary images, and the balls are given the linear profile at the start so that no
start-up transient has to diffuse in from the boundary.  It is chosen over peculiar velocities
because then every contact, interior or across the boundary, sees the true relative velocity
of two material points (damping and friction need it) and nothing but the LE images is
artificial; in a dense granular flow the inertia of the mean flow (what SLLOD corrects for in a
thermostatted fluid) is carried by the contacts themselves.

Box dilation (the barostat, isotropic compression, elastic strain steps): an affine map of the
box and the positions, x_a -> x_a (1 + eps_dot_a dt) per axis, not put into the velocities (the
dilation rate stays small beside the velocity fluctuations).  So that contact damping and the
tangential springs see it, the relative velocity of a pair gets the affine part
eps_dot_a (r_i - r_j)_a.

Contacts: `vibroflow.dem.contact.ball_pair` (the contact law `contact_force` of the tub's step,
for one listed pair), with the scenario's ball-ball row of `vibroflow.dem.laws.pair_table`;
time integration: velocity Verlet for translation and rotation (LAMMPS nve/sphere ordering),
as `vibroflow.dem.step`.

Stress (compression positive, as vibroflow.calibration.coarse_grain): sigma = (1/V) [sum over
contacts f_ij (x) r_ij + sum_i m_i v'_i (x) v'_i], f_ij the force on i by j, r_ij = r_i - r_j(image)
its branch vector, v' = v - gamma_dot (z - L_z/2) x the velocity relative to the mean flow
(Allen & Tildesley, ch. 2; Christoffersen, Mehrabadi & Nemat-Nasser 1981).  Under the shear
v_x = gamma_dot z with gamma_dot > 0 the shear stress resisting it is tau = -sigma_xz.

Box control (barostat): the strain rate of the controlled axes follows a proportional law

    eps_dot = clip((sigma_c - p) / (K_ref t_b), -rate_max, rate_max),

sigma_c = sigma_zz (z control, the shear cell) or tr(sigma)/3 (isotropic control, preparation),
K_ref = k_eff / d a stiffness scale of the contact law and t_b a time.  For a jammed packing of
stiffness M = d sigma_c / d eps this relaxes sigma_c - p exponentially with the time constant
t_b K_ref / M; since the box size is bounded, the time average of eps_dot vanishes and
<sigma_c> = p exactly over a long window (the law has no steady-state error).
"""
from __future__ import annotations

import numba as nb
import numpy as np

from .contact import ball_pair
from .lees_edwards import B_LX, B_LY, B_LZ, B_OFFSET, le_branch, wrap

# rates array: shear rate gamma_dot (1/s) and the dilation rates of the three axes (1/s)
R_GAMMA, R_EX, R_EY, R_EZ = range(4)
# control array
C_MODE, C_PRESSURE, C_GAIN, C_RATE_MAX, C_DAMPING, C_SKIN, C_CUT, C_MAX_OVERLAP = range(8)
N_CTRL = 8
MODE_FIXED, MODE_Z, MODE_ISO = 0, 1, 2   # box rates as given / sigma_zz control / p control
# state array: time, total shear strain, strain since the last list build, samples written,
# steps in the current sampling block, the largest overlap seen (m)
S_TIME, S_STRAIN, S_BUILD_STRAIN, S_NSAMPLE, S_BLOCK, S_MAX_OVERLAP = range(6)
N_STATE = 6
# sample columns: time (s), total shear strain, then block means of the stress (Pa, compression
# positive: xx yy zz xy xz yz zx), box lengths (m), contacts per ball Z = 2C/N, Z of the balls
# with two contacts or more, kinetic energy of the translation relative to the mean flow (J),
# and the number of steps averaged
(Q_TIME, Q_STRAIN, Q_SXX, Q_SYY, Q_SZZ, Q_SXY, Q_SXZ, Q_SYZ, Q_SZX, Q_LX, Q_LY, Q_LZ, Q_Z,
 Q_ZNR, Q_KE, Q_STEPS) = range(16)
N_Q = 16
_BLOCK = (Q_SXX, Q_SYY, Q_SZZ, Q_SXY, Q_SXZ, Q_SYZ, Q_SZX, Q_LX, Q_LY, Q_LZ, Q_Z, Q_ZNR, Q_KE)
# status of `advance`
DONE, REBUILD, BLOWUP = 0, 1, 2


@nb.njit(cache=True)
def pair_forces(balls, pairs, cell, dt_hist):
    """Contact forces and torques of every listed pair (N, N m; force/torque overwritten), the
    contact virial sum f_ij (x) r_ij (N m, cell.virial[a, b] = sum f_a r_b) and the contacts of
    each ball (records of vibroflow.dem.records).  Pairs are seen at their nearest LE image:
    the image of j moves k gamma_dot L_z faster in x, and the box's affine dilation adds
    eps_dot_a (r_i - r_j)_a to the relative velocity.
    `cell.table` (1, 1, N_PARAMS) holds the ball-ball row of the contact law.  `dt_hist` = 0
    evaluates without advancing the contact histories.

    Returns (number of contacts, largest overlap (m))."""
    pos, force, torque, degree = balls.pos, balls.force, balls.torque, balls.degree
    start, nbr = pairs.start, pairs.nbr
    par, box, rates, virial = cell.table[0, 0], cell.box, cell.rates, cell.virial
    n = pos.shape[0]
    for i in range(n):
        degree[i] = 0
        for a in range(3):
            force[i, a] = 0.0
            torque[i, a] = 0.0
    for a in range(3):
        for b in range(3):
            virial[a, b] = 0.0
    # the pair kernel's per-chunk buffers: one chunk, the force arrays themselves
    fbuf = force.reshape((1, n, 3))
    tbuf = torque.reshape((1, n, 3))
    jump = rates[R_GAMMA] * box[B_LZ]
    ncontact = 0
    max_overlap = 0.0
    for i in range(n):
        for q in range(start[i], start[i + 1]):
            j = nbr[q]
            dx, dy, dz, k = le_branch(pos, i, j, box)
            touching, _first, delta, _nx, _ny, _nz, _vn, fx, fy, fz = ball_pair(
                i, j, q, dx, dy, dz, rates[R_EX] * dx - k * jump, rates[R_EY] * dy,
                rates[R_EZ] * dz, balls, pairs, par, dt_hist, fbuf, tbuf, 0)
            if not touching:
                continue
            virial[0, 0] += fx * dx
            virial[0, 1] += fx * dy
            virial[0, 2] += fx * dz
            virial[1, 0] += fy * dx
            virial[1, 1] += fy * dy
            virial[1, 2] += fy * dz
            virial[2, 0] += fz * dx
            virial[2, 1] += fz * dy
            virial[2, 2] += fz * dz
            degree[i] += 1
            degree[j] += 1
            ncontact += 1
            if delta > max_overlap:
                max_overlap = delta
    return ncontact, max_overlap


@nb.njit(cache=True)
def _damp(balls, box, rates, c):
    """Background viscous damping -c m v' (v' relative to the mean flow) and -c I w, used only to
    bring a packing to rest (preparation, elastic tests); c in 1/s."""
    pos, vel, omg, mass, inertia = balls.pos, balls.vel, balls.omg, balls.mass, balls.inertia
    force, torque = balls.force, balls.torque
    n = pos.shape[0]
    half = 0.5 * box[B_LZ]
    for i in range(n):
        force[i, 0] -= c * mass[i] * (vel[i, 0] - rates[R_GAMMA] * (pos[i, 2] - half))
        force[i, 1] -= c * mass[i] * vel[i, 1]
        force[i, 2] -= c * mass[i] * vel[i, 2]
        for a in range(3):
            torque[i, a] -= c * inertia[i] * omg[i, a]


@nb.njit(cache=True)
def stress(balls, cell, gamma_dot, out):
    """Stress of the box (Pa, compression positive) into out[9] (row-major xx xy xz yx ...):
    (contact virial + sum m v' (x) v') / V, v' = v - gamma_dot (z - L_z/2) x."""
    pos, vel, mass = balls.pos, balls.vel, balls.mass
    box, virial = cell.box, cell.virial
    vol = box[B_LX] * box[B_LY] * box[B_LZ]
    half = 0.5 * box[B_LZ]
    for a in range(3):
        for b in range(3):
            out[3 * a + b] = virial[a, b]
    for i in range(pos.shape[0]):
        ux = vel[i, 0] - gamma_dot * (pos[i, 2] - half)
        uy = vel[i, 1]
        uz = vel[i, 2]
        m = mass[i]
        out[0] += m * ux * ux
        out[1] += m * ux * uy
        out[2] += m * ux * uz
        out[3] += m * uy * ux
        out[4] += m * uy * uy
        out[5] += m * uy * uz
        out[6] += m * uz * ux
        out[7] += m * uz * uy
        out[8] += m * uz * uz
    for a in range(9):
        out[a] /= vol


@nb.njit(cache=True, inline="always")
def _kick(balls, i, half_dt):
    """Half kick of ball i: v += dt/2 F/m, w += dt/2 T/I."""
    vel, omg, force, torque = balls.vel, balls.omg, balls.force, balls.torque
    im = half_dt / balls.mass[i]
    ii = half_dt / balls.inertia[i]
    for a in range(3):
        vel[i, a] += im * force[i, a]
        omg[i, a] += ii * torque[i, a]


@nb.njit(cache=True)
def advance(n_steps, dt, sample_every, balls, pairs, cell, samples):
    """Velocity-Verlet steps of the periodic box (see the module notes; the records of
    vibroflow.dem.records).

    Per step: half kick; drift, with the non-affine displacement `disp` accumulated; affine
    dilation of the box by the rates; LE offset += gamma_dot L_z dt; wrap; forces at the new
    positions (half-step velocities; with background damping ctrl[C_DAMPING] > 0); half kick;
    stress; the box control sets the dilation rates of the next step (ctrl[C_MODE]); block
    sums, written as a row of `samples` every `sample_every` steps.

    Stops after n_steps (DONE), when the neighbour list must be rebuilt before the next step
    (REBUILD), or when an overlap exceeds ctrl[C_MAX_OVERLAP] or a value is not finite
    (BLOWUP).  Returns (status, steps done)."""
    pos, vel, mass, disp = balls.pos, balls.vel, balls.mass, balls.disp
    image, degree = balls.image, balls.degree
    box, rates, ctrl, state, acc = cell.box, cell.rates, cell.ctrl, cell.state, cell.acc
    n = pos.shape[0]
    half_dt = 0.5 * dt
    mode = int(ctrl[C_MODE])
    p_target = ctrl[C_PRESSURE]
    gain = ctrl[C_GAIN]
    rate_max = ctrl[C_RATE_MAX]
    damping = ctrl[C_DAMPING]
    skin = ctrl[C_SKIN]
    cut = ctrl[C_CUT]
    sig = np.zeros(9)
    for s in range(n_steps):
        gd = rates[R_GAMMA]
        # kick and drift
        half = 0.5 * box[B_LZ]
        for i in range(n):
            _kick(balls, i, half_dt)
            disp[i, 0] += (vel[i, 0] - gd * (pos[i, 2] - half)) * dt
            disp[i, 1] += vel[i, 1] * dt
            disp[i, 2] += vel[i, 2] * dt
            for a in range(3):
                pos[i, a] += vel[i, a] * dt
        # affine dilation of the box and the positions
        for a in range(3):
            e = rates[R_EX + a]
            if e != 0.0:
                f = 1.0 + e * dt
                box[a] *= f
                for i in range(n):
                    pos[i, a] *= f
        box[B_OFFSET] += gd * box[B_LZ] * dt
        box[B_OFFSET] -= box[B_LX] * np.floor(box[B_OFFSET] / box[B_LX])
        wrap(pos, vel, image, box, gd)
        state[S_TIME] += dt
        state[S_STRAIN] += gd * dt
        state[S_BUILD_STRAIN] += (abs(gd) + max(abs(rates[R_EX]), abs(rates[R_EY]),
                                                abs(rates[R_EZ]))) * dt
        # forces at the new positions
        nc, ov = pair_forces(balls, pairs, cell, dt)
        if damping > 0.0:
            _damp(balls, box, rates, damping)
        # second half kick, largest displacement and speed
        d2max = 0.0
        v2max = 0.0
        ke = 0.0
        half = 0.5 * box[B_LZ]
        for i in range(n):
            _kick(balls, i, half_dt)
            d2 = disp[i, 0] ** 2 + disp[i, 1] ** 2 + disp[i, 2] ** 2
            if d2 > d2max:
                d2max = d2
            ux = vel[i, 0] - gd * (pos[i, 2] - half)
            u2 = ux * ux + vel[i, 1] ** 2 + vel[i, 2] ** 2
            if u2 > v2max:
                v2max = u2
            ke += 0.5 * mass[i] * u2
        if ov > state[S_MAX_OVERLAP]:
            state[S_MAX_OVERLAP] = ov
        if ov > ctrl[C_MAX_OVERLAP] or not np.isfinite(ke):
            return BLOWUP, s + 1
        stress(balls, cell, gd, sig)
        # box control for the next step
        if mode == MODE_Z:
            e = (sig[8] - p_target) * gain
            rates[R_EZ] = min(max(e, -rate_max), rate_max)
        elif mode == MODE_ISO:
            e = ((sig[0] + sig[4] + sig[8]) / 3.0 - p_target) * gain
            e = min(max(e, -rate_max), rate_max)
            rates[R_EX] = e
            rates[R_EY] = e
            rates[R_EZ] = e
        # block sums
        nr = 0
        dnr = 0
        for i in range(n):
            if degree[i] >= 2:
                nr += 1
                dnr += degree[i]
        acc[Q_SXX] += sig[0]
        acc[Q_SYY] += sig[4]
        acc[Q_SZZ] += sig[8]
        acc[Q_SXY] += sig[1]
        acc[Q_SXZ] += sig[2]
        acc[Q_SYZ] += sig[5]
        acc[Q_SZX] += sig[6]
        acc[Q_LX] += box[B_LX]
        acc[Q_LY] += box[B_LY]
        acc[Q_LZ] += box[B_LZ]
        acc[Q_Z] += 2.0 * nc / n
        acc[Q_ZNR] += dnr / nr if nr > 0 else 0.0
        acc[Q_KE] += ke
        state[S_BLOCK] += 1.0
        if state[S_BLOCK] >= sample_every:
            k = int(state[S_NSAMPLE])
            if k < samples.shape[0]:
                nb_ = state[S_BLOCK]
                for c in range(N_Q):
                    samples[k, c] = acc[c] / nb_
                samples[k, Q_TIME] = state[S_TIME]
                samples[k, Q_STRAIN] = state[S_STRAIN]
                samples[k, Q_STEPS] = nb_
            state[S_NSAMPLE] += 1.0
            state[S_BLOCK] = 0.0
            for c in range(N_Q):
                acc[c] = 0.0
        # will the list still hold after the next drift?  (Verlet criterion, conservative)
        vmax = np.sqrt(v2max)
        grow = (state[S_BUILD_STRAIN] + (abs(gd) + abs(rates[R_EX]) + abs(rates[R_EY])
                                         + abs(rates[R_EZ])) * dt) * cut
        if 2.0 * (np.sqrt(d2max) + vmax * dt) + grow >= skin:
            return REBUILD, s + 1
    return DONE, n_steps
