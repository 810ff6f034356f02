"""A fully periodic box of spheres with Lees-Edwards boundaries: the DEM of the shear cell and of
the elastic tests.  Numba kernels over flat arrays; `PeriodicBox` below is
the plain-Python orchestration (neighbour-list rebuilds, history transfer, samples).

Kinematics
----------
Box [0, L_x) x [0, L_y) x [0, L_z), periodic in x and y.  Across z the boundaries are those of
Lees & Edwards (1972) for the simple shear v_x = gamma_dot z: the image of ball j one box above
(k = +1) or below (k = -1) sits at r_j + k (Delta, 0, L_z) and moves at v_j + k gamma_dot L_z x,
with the accumulated offset Delta = int gamma_dot L_z dt (mod L_x).  A ball leaving through the
top re-enters at the bottom shifted by -Delta in x and with v_x - gamma_dot L_z (and the reverse
through the bottom); `image` counts these crossings, so sum m (v_x + image_z gamma_dot L_z) (the
momentum of the unwrapped balls) is conserved by the pair forces.

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

Neighbours: cell list -> half Verlet list with a skin; each pair's minimum image (including the
LE shift) is found again at every step, so the list holds only j > i.  It is rebuilt when
2 max |non-affine displacement| + (accumulated shear + dilation strain) x cut-off could exceed
the skin (the displacement measured relative to the streaming profile, so the shear flow itself
does not force rebuilds).  Each list entry carries its contact's history (tangential spring and
rolling torque) keyed by the pair (i, j): `vibroflow.dem.neighbours.transfer_history` carries it
over rebuilds, and a contact that crosses the LE boundary keeps it.

Contacts: `vibroflow.dem.contact.contact_force` with the scenario's ball-ball row of
`vibroflow.dem.laws.pair_table`; time integration: velocity Verlet for translation and rotation
(LAMMPS nve/sphere ordering), as `vibroflow.dem.step`.

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

import math

import numba as nb
import numpy as np

from vibroflow.dem.contact import contact_force, pair_contact_velocity
from vibroflow.dem.neighbours import transfer_history

# box array: lengths (m) and the Lees-Edwards offset (m)
B_LX, B_LY, B_LZ, B_OFFSET = range(4)
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


@nb.njit(cache=True, inline="always")
def le_branch(pos, i, j, box):
    """Branch vector r_i - r_j(image) (m) to the nearest Lees-Edwards image of j, and the image
    index k: the image sits at r_j + k (Delta, 0, L_z).  Positions must lie in the box and
    0 <= Delta < L_x (comparisons rather than rint: this is the innermost loop)."""
    lx = box[B_LX]
    ly = box[B_LY]
    lz = box[B_LZ]
    dz = pos[i, 2] - pos[j, 2]
    k = 0.0
    if dz > 0.5 * lz:
        k = 1.0
        dz -= lz
    elif dz < -0.5 * lz:
        k = -1.0
        dz += lz
    dx = pos[i, 0] - pos[j, 0] - k * box[B_OFFSET]
    # |dx| < 2 L_x here
    if dx > 0.5 * lx:
        dx -= lx
        if dx > 0.5 * lx:
            dx -= lx
    elif dx < -0.5 * lx:
        dx += lx
        if dx < -0.5 * lx:
            dx += lx
    dy = pos[i, 1] - pos[j, 1]
    if dy > 0.5 * ly:
        dy -= ly
    elif dy < -0.5 * ly:
        dy += ly
    return dx, dy, dz, k


@nb.njit(cache=True)
def _cell_index(x, length, n):
    c = int(x / length * n)
    if c < 0:
        c = 0
    elif c >= n:
        c = n - 1
    return c


@nb.njit(cache=True)
def build_le_list(pos, radius, box, skin, dims):
    """Half Verlet list (CSR: start (N+1,), nbr (M,), j > i) of the pairs whose surfaces are
    closer than `skin` at their nearest Lees-Edwards image.  `dims` = cells per axis, each at
    least 3 (so the 27 cells scanned are distinct) and each cell at least the cut-off wide.

    Cells across the z boundary are scanned around x_i - k Delta, where the images of that
    layer sit; positions must be wrapped into the box."""
    n = pos.shape[0]
    nx, ny, nz = dims[0], dims[1], dims[2]
    lx, ly, lz, off = box[B_LX], box[B_LY], box[B_LZ], box[B_OFFSET]
    ncell = nx * ny * nz
    counts = np.zeros(ncell + 1, np.int64)
    flat = np.empty(n, np.int64)
    for i in range(n):
        f = ((_cell_index(pos[i, 0], lx, nx) * ny + _cell_index(pos[i, 1], ly, ny)) * nz
             + _cell_index(pos[i, 2], lz, nz))
        flat[i] = f
        counts[f + 1] += 1
    for c in range(ncell):
        counts[c + 1] += counts[c]
    fill = counts[:-1].copy()
    members = np.empty(n, np.int64)
    for i in range(n):  # members of a cell in index order: the list is reproducible
        members[fill[flat[i]]] = i
        fill[flat[i]] += 1
    start = np.zeros(n + 1, np.int64)
    cap = 16 * n + 64
    nbr = np.empty(cap, np.int64)
    m = 0
    for i in range(n):
        cy = _cell_index(pos[i, 1], ly, ny)
        cz = _cell_index(pos[i, 2], lz, nz)
        for dzc in range(-1, 2):
            az = cz + dzc
            k = 0
            if az < 0:
                az += nz
                k = -1
            elif az >= nz:
                az -= nz
                k = 1
            xs = pos[i, 0] - k * off
            xs -= lx * np.floor(xs / lx)
            cx = _cell_index(xs, lx, nx)
            for dxc in range(-1, 2):
                ax = (cx + dxc) % nx
                for dyc in range(-1, 2):
                    ay = (cy + dyc) % ny
                    f = (ax * ny + ay) * nz + az
                    for q in range(counts[f], counts[f + 1]):
                        j = members[q]
                        if j <= i:
                            continue
                        dx, dy, dz, _k = le_branch(pos, i, j, box)
                        cut = radius[i] + radius[j] + skin
                        if dx * dx + dy * dy + dz * dz < cut * cut:
                            if m == cap:
                                grown = np.empty(2 * cap, np.int64)
                                grown[:m] = nbr[:m]
                                nbr = grown
                                cap *= 2
                            nbr[m] = j
                            m += 1
        start[i + 1] = m
    # the scan visits cells in a fixed order but not by j: sort each i's entries so the list
    # (and the order of force summation) depends on the configuration alone
    for i in range(n):
        nbr[start[i]:start[i + 1]] = np.sort(nbr[start[i]:start[i + 1]])
    return start, nbr[:m].copy()


@nb.njit(cache=True)
def pair_forces(pos, vel, omg, radius, mass, par, start, nbr, hist, flag, box, rates, dt_hist,
                force, torque, virial, degree):
    """Contact forces and torques of every listed pair (N, N m; force/torque overwritten), the
    contact virial sum f_ij (x) r_ij (N m, virial[a, b] = sum f_a r_b) and the contacts of each
    ball.  Pairs are seen at their nearest LE image: the image of j moves k gamma_dot L_z faster
    in x, and the box's affine dilation adds eps_dot_a (r_i - r_j)_a to the relative velocity.
    `dt_hist` = 0 evaluates without advancing the contact histories.

    Returns (number of contacts, largest overlap (m))."""
    n = pos.shape[0]
    for i in range(n):
        degree[i] = 0
        for a in range(3):
            force[i, a] = 0.0
            torque[i, a] = 0.0
    for a in range(3):
        for b in range(3):
            virial[a, b] = 0.0
    jump = rates[R_GAMMA] * box[B_LZ]
    ncontact = 0
    max_overlap = 0.0
    for i in range(n):
        ri = radius[i]
        mi = mass[i]
        for q in range(start[i], start[i + 1]):
            j = nbr[q]
            dx, dy, dz, k = le_branch(pos, i, j, box)
            rj = radius[j]
            rsum = ri + rj
            d2 = dx * dx + dy * dy + dz * dz
            if d2 >= rsum * rsum:
                if flag[q]:
                    flag[q] = 0
                    for c in range(hist.shape[1]):
                        hist[q, c] = 0.0
                continue
            flag[q] = 1
            d = np.sqrt(d2)
            delta = rsum - d
            inv = 1.0 / d
            nx = dx * inv
            ny = dy * inv
            nz = dz * inv
            vx, vy, vz = pair_contact_velocity(vel, omg, i, j, ri, rj, nx, ny, nz)
            vx += rates[R_EX] * dx - k * jump
            vy += rates[R_EY] * dy
            vz += rates[R_EZ] * dz
            mj = mass[j]
            fx, fy, fz, tix, tiy, tiz, tjx, tjy, tjz, fn, ft, sl = contact_force(
                delta, nx, ny, nz, vx, vy, vz,
                omg[i, 0] - omg[j, 0], omg[i, 1] - omg[j, 1], omg[i, 2] - omg[j, 2],
                ri, rj, ri * rj / rsum, mi * mj / (mi + mj), par, hist[q], dt_hist)
            force[i, 0] += fx
            force[i, 1] += fy
            force[i, 2] += fz
            force[j, 0] -= fx
            force[j, 1] -= fy
            force[j, 2] -= fz
            torque[i, 0] += tix
            torque[i, 1] += tiy
            torque[i, 2] += tiz
            torque[j, 0] += tjx
            torque[j, 1] += tjy
            torque[j, 2] += tjz
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
def _damp(vel, omg, pos, mass, inertia, box, rates, c, force, torque):
    """Background viscous damping -c m v' (v' relative to the mean flow) and -c I w, used only to
    bring a packing to rest (preparation, elastic tests); c in 1/s."""
    n = pos.shape[0]
    half = 0.5 * box[B_LZ]
    for i in range(n):
        force[i, 0] -= c * mass[i] * (vel[i, 0] - rates[R_GAMMA] * (pos[i, 2] - half))
        force[i, 1] -= c * mass[i] * vel[i, 1]
        force[i, 2] -= c * mass[i] * vel[i, 2]
        for a in range(3):
            torque[i, a] -= c * inertia[i] * omg[i, a]


@nb.njit(cache=True)
def wrap(pos, vel, image, box, gamma_dot):
    """Put every ball back in the box: across z with the Lees-Edwards shift -k Delta in x and
    velocity jump -k gamma_dot L_z (k = +1 leaving through the top), then x and y periodic."""
    lx, ly, lz, off = box[B_LX], box[B_LY], box[B_LZ], box[B_OFFSET]
    for i in range(pos.shape[0]):
        k = np.floor(pos[i, 2] / lz)
        if k != 0.0:
            pos[i, 2] -= k * lz
            pos[i, 0] -= k * off
            vel[i, 0] -= k * gamma_dot * lz
            image[i, 2] += int(k)
            if pos[i, 2] >= lz:  # round-off of a ball a hair below the top
                pos[i, 2] -= lz
        kx = np.floor(pos[i, 0] / lx)
        if kx != 0.0:
            pos[i, 0] -= kx * lx
            image[i, 0] += int(kx)
            if pos[i, 0] >= lx:
                pos[i, 0] -= lx
        ky = np.floor(pos[i, 1] / ly)
        if ky != 0.0:
            pos[i, 1] -= ky * ly
            image[i, 1] += int(ky)
            if pos[i, 1] >= ly:
                pos[i, 1] -= ly


@nb.njit(cache=True)
def stress(pos, vel, mass, box, gamma_dot, virial, out):
    """Stress of the box (Pa, compression positive) into out[9] (row-major xx xy xz yx ...):
    (contact virial + sum m v' (x) v') / V, v' = v - gamma_dot (z - L_z/2) x."""
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


@nb.njit(cache=True)
def advance(n_steps, dt, pos, vel, omg, force, torque, radius, mass, inertia, par, start, nbr,
            hist, flag, box, rates, ctrl, state, disp, image, degree, virial, acc, samples,
            sample_every):
    """Velocity-Verlet steps of the periodic box (see the module notes).

    Per step: half kick; drift, with the non-affine displacement `disp` accumulated; affine
    dilation of the box by the rates; LE offset += gamma_dot L_z dt; wrap; forces at the new
    positions (half-step velocities; with background damping ctrl[C_DAMPING] > 0); half kick;
    stress; the box control sets the dilation rates of the next step (ctrl[C_MODE]); block
    sums, written as a row of `samples` every `sample_every` steps.

    Stops after n_steps (DONE), when the neighbour list must be rebuilt before the next step
    (REBUILD), or when an overlap exceeds ctrl[C_MAX_OVERLAP] or a value is not finite
    (BLOWUP).  Returns (status, steps done)."""
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
            im = half_dt / mass[i]
            ii = half_dt / inertia[i]
            for a in range(3):
                vel[i, a] += im * force[i, a]
                omg[i, a] += ii * torque[i, a]
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
        nc, ov = pair_forces(pos, vel, omg, radius, mass, par, start, nbr, hist, flag, box,
                             rates, dt, force, torque, virial, degree)
        if damping > 0.0:
            _damp(vel, omg, pos, mass, inertia, box, rates, damping, force, torque)
        # second half kick, largest displacement and speed
        d2max = 0.0
        v2max = 0.0
        ke = 0.0
        half = 0.5 * box[B_LZ]
        for i in range(n):
            im = half_dt / mass[i]
            ii = half_dt / inertia[i]
            for a in range(3):
                vel[i, a] += im * force[i, a]
                omg[i, a] += ii * torque[i, a]
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
        stress(pos, vel, mass, box, gd, virial, sig)
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


# ----------------------------------------------------------------------------------------------
# orchestration

def random_fill(n: int, radius: np.ndarray, lengths, rng: np.random.Generator,
                max_tries: int = 100_000) -> np.ndarray:
    """Random sequential addition of n non-overlapping spheres in a periodic box (positions, m).

    Each ball is drawn uniformly until it overlaps none already placed (minimum image); fine up
    to solid fractions of about 0.3 (the random sequential addition limit is 0.38)."""
    lengths = np.asarray(lengths, float)
    pos = np.empty((n, 3))
    for i in range(n):
        for _ in range(max_tries):
            x = rng.random(3) * lengths
            d = pos[:i] - x
            d -= lengths * np.rint(d / lengths)
            if i == 0 or np.all((d * d).sum(axis=1) >= (radius[:i] + radius[i]) ** 2):
                pos[i] = x
                break
        else:
            raise RuntimeError(f"random fill: no room for ball {i} of {n} after {max_tries} "
                               f"tries")
    return pos


class PeriodicBox:
    """State of a Lees-Edwards periodic box of spheres and its stepping (see module notes).

    pos (m), radius (m), mass (kg) per ball; `par` the contact-law row (laws.pair_table) of the
    ball-ball pair; `lengths` the box (m); `dt` (s); `skin` (m).  Positions are wrapped in."""

    def __init__(self, pos, radius, mass, par, lengths, dt: float, skin: float,
                 max_overlap: float):
        n = len(pos)
        self.pos = np.array(pos, float)
        self.radius = np.asarray(radius, float).copy()
        self.mass = np.asarray(mass, float).copy()
        self.inertia = 0.4 * self.mass * self.radius**2
        self.par = np.asarray(par, float).copy()
        self.vel = np.zeros((n, 3))
        self.omg = np.zeros((n, 3))
        self.force = np.zeros((n, 3))
        self.torque = np.zeros((n, 3))
        self.box = np.array([*map(float, lengths), 0.0])
        self.rates = np.zeros(4)
        self.state = np.zeros(N_STATE)
        self.disp = np.zeros((n, 3))
        self.image = np.zeros((n, 3), np.int64)
        self.degree = np.zeros(n, np.int64)
        self.virial = np.zeros((3, 3))
        self.acc = np.zeros(N_Q)
        self.dt = float(dt)
        self.skin = float(skin)
        self.cut = 2.0 * float(self.radius.max()) + self.skin
        self.max_overlap = float(max_overlap)
        self.start = np.zeros(n + 1, np.int64)
        self.nbr = np.zeros(0, np.int64)
        self.hist = np.zeros((0, 6))
        self.flag = np.zeros(0, np.uint8)
        self.builds = 0
        wrap(self.pos, self.vel, self.image, self.box, 0.0)
        self.rebuild()
        self.evaluate()

    # -- geometry ------------------------------------------------------------------------------
    @property
    def n(self) -> int:
        return self.pos.shape[0]

    @property
    def volume(self) -> float:
        return float(self.box[0] * self.box[1] * self.box[2])

    @property
    def solid_fraction(self) -> float:
        return float((4.0 / 3.0 * np.pi * self.radius**3).sum() / self.volume)

    def rebuild(self) -> None:
        """New neighbour list (history carried over) from the current positions."""
        dims = np.floor(self.box[:3] / self.cut).astype(np.int64)
        if dims.min() < 3:
            raise ValueError(f"periodic box {self.box[:3]} m is less than three cut-offs "
                             f"({self.cut:.4g} m) across: too few balls")
        wrap(self.pos, self.vel, self.image, self.box, self.rates[R_GAMMA])
        start, nbr = build_le_list(self.pos, self.radius, self.box, self.skin, dims)
        if self.nbr.shape[0]:
            hist, flag = transfer_history(self.start, self.nbr, self.hist, self.flag, start,
                                          nbr)
        else:
            hist = np.zeros((nbr.shape[0], 6))
            flag = np.zeros(nbr.shape[0], np.uint8)
        self.start, self.nbr, self.hist, self.flag = start, nbr, hist, flag
        self.disp[:] = 0.0
        self.state[S_BUILD_STRAIN] = 0.0
        self.builds += 1

    def evaluate(self) -> tuple[int, float]:
        """Forces, torques and virial at the current state without advancing contact histories
        (LAMMPS' setup).  Returns (contacts, largest overlap)."""
        return pair_forces(self.pos, self.vel, self.omg, self.radius, self.mass, self.par,
                           self.start, self.nbr, self.hist, self.flag, self.box, self.rates,
                           0.0, self.force, self.torque, self.virial, self.degree)

    def stress_tensor(self) -> np.ndarray:
        """Instantaneous stress (3x3, Pa, compression positive) from the last evaluation."""
        out = np.zeros(9)
        stress(self.pos, self.vel, self.mass, self.box, self.rates[R_GAMMA], self.virial, out)
        return out.reshape(3, 3)

    # -- velocities of the mean flow -------------------------------------------------------------
    def set_shear_rate(self, gamma_dot: float) -> None:
        """Change the imposed shear rate (1/s), re-profiling the balls' velocities: v_x keeps its
        fluctuation about the mean flow, which becomes gamma_dot (z - L_z/2), and the spin w_y
        keeps its fluctuation about the flow's half vorticity gamma_dot / 2."""
        old = self.rates[R_GAMMA]
        self.vel[:, 0] += (gamma_dot - old) * (self.pos[:, 2] - 0.5 * self.box[B_LZ])
        self.omg[:, 1] += 0.5 * (gamma_dot - old)
        self.rates[R_GAMMA] = float(gamma_dot)

    def unwrapped_momentum(self) -> np.ndarray:
        """Momentum of the unwrapped balls (kg m/s): sum m (v + image_z gamma_dot L_z x); the pair
        forces conserve it (at constant L_z and gamma_dot)."""
        v = self.vel.copy()
        v[:, 0] += self.image[:, 2] * self.rates[R_GAMMA] * self.box[B_LZ]
        return (self.mass[:, None] * v).sum(axis=0)

    # -- stepping --------------------------------------------------------------------------------
    def run(self, n_steps: int, mode: int = MODE_FIXED, pressure: float = 0.0,
            gain: float = 0.0, rate_max: float = math.inf, damping: float = 0.0,
            dilation=(0.0, 0.0, 0.0), sample_every: int = 100, stop=None) -> np.ndarray:
        """Advance n_steps; returns the samples (rows of Q_* columns, one per `sample_every`
        steps).  mode: MODE_FIXED (box rates as set in `self.rates`), MODE_Z (sigma_zz = pressure)
        or MODE_ISO (tr sigma / 3 = pressure), with the control law of the module notes:
        eps_dot = clip((sigma_c - p) gain, +-rate_max), gain = 1 / (K_ref t_b) (1/(Pa s)).
        `stop(samples_so_far)`, checked every ten samples, may end the run early.
        Raises FloatingPointError when the box blows up."""
        ctrl = np.zeros(N_CTRL)
        ctrl[C_MODE] = mode
        ctrl[C_PRESSURE] = pressure
        ctrl[C_GAIN] = gain
        ctrl[C_RATE_MAX] = rate_max
        ctrl[C_DAMPING] = damping
        ctrl[C_SKIN] = self.skin
        ctrl[C_CUT] = self.cut
        ctrl[C_MAX_OVERLAP] = self.max_overlap
        if mode == MODE_FIXED:
            self.rates[R_EX:R_EZ + 1] = np.asarray(dilation, float)
        elif mode == MODE_Z:
            self.rates[R_EX] = self.rates[R_EY] = 0.0
        samples = np.zeros((n_steps // sample_every + 1, N_Q))
        self.state[S_NSAMPLE] = 0.0
        self.state[S_BLOCK] = 0.0
        self.acc[:] = 0.0
        done = 0
        chunk = 20_000 if stop is None else 10 * sample_every
        while done < n_steps:
            todo = min(n_steps - done, chunk)
            status, steps = advance(todo, self.dt, self.pos, self.vel, self.omg, self.force,
                                    self.torque, self.radius, self.mass, self.inertia,
                                    self.par, self.start, self.nbr, self.hist, self.flag,
                                    self.box, self.rates, ctrl, self.state, self.disp,
                                    self.image, self.degree, self.virial, self.acc, samples,
                                    sample_every)
            done += steps
            if status == BLOWUP:
                raise FloatingPointError(
                    f"periodic box blew up at t = {self.state[S_TIME]:.4g} s (largest overlap "
                    f"{self.state[S_MAX_OVERLAP]:.3g} m)")
            if status == REBUILD:
                self.rebuild()
            k = min(int(self.state[S_NSAMPLE]), samples.shape[0])
            if stop is not None and stop(samples[:k]):
                break
        return samples[:min(int(self.state[S_NSAMPLE]), samples.shape[0])]

    def copy(self) -> "PeriodicBox":
        """An independent copy of the whole state (to branch experiments from one packing)."""
        new = object.__new__(PeriodicBox)
        for k, v in self.__dict__.items():
            setattr(new, k, v.copy() if isinstance(v, np.ndarray) else v)
        return new
