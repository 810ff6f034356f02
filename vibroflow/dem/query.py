"""Read-only queries of a DEM state: the contact forces now, for stresses and statistics.

The force kernels do not keep per-contact forces (they would cost memory traffic every step);
these functions recompute them from the state and the contact histories, on copies of the
histories, so the state is left exactly as it was (a query never changes a run's results).
The damping term uses the end-of-step velocities, where the step used the half-step ones; the
difference is O(dt) of the damping force.
"""
from __future__ import annotations

import numba as nb
import numpy as np

from .contact import branch_vector, contact_force, pair_contact_velocity, put3
from .records import balls_of, pairs_of


@nb.njit(cache=True)
def _ball_ball(balls, pairs, table, periodic_length):
    pos, vel, omg, radius, mass, mat = (balls.pos, balls.vel, balls.omg, balls.radius,
                                        balls.mass, balls.mat)
    nbr_start, nbr, hist, flag = pairs.start, pairs.nbr, pairs.hist, pairs.flag
    n = pos.shape[0]
    count = 0
    for i in range(n):
        for k in range(nbr_start[i], nbr_start[i + 1]):
            if flag[k]:
                count += 1
    ii = np.empty(count, np.int64)
    jj = np.empty(count, np.int64)
    force = np.empty((count, 3))
    branch = np.empty((count, 3))
    h = np.zeros(6)
    m = 0
    for i in range(n):
        for k in range(nbr_start[i], nbr_start[i + 1]):
            if not flag[k]:
                continue
            j = nbr[k]
            dx, dy, dz = branch_vector(pos, i, j, periodic_length)
            d = np.sqrt(dx * dx + dy * dy + dz * dz)
            ri = radius[i]
            rj = radius[j]
            delta = ri + rj - d
            nx = dx / d
            ny = dy / d
            nz = dz / d
            vx, vy, vz = pair_contact_velocity(vel, omg, i, j, ri, rj, nx, ny, nz)
            for q in range(hist.shape[1]):
                h[q] = hist[k, q]
            mi = mass[i]
            mj = mass[j]
            fx, fy, fz, _a, _b, _c, _d, _e, _f, _fn, _ft, _sl = contact_force(
                delta, nx, ny, nz, vx, vy, vz, omg[i, 0] - omg[j, 0], omg[i, 1] - omg[j, 1],
                omg[i, 2] - omg[j, 2], ri, rj, ri * rj / (ri + rj), mi * mj / (mi + mj),
                table[mat[i], mat[j]], h, 0.0)
            ii[m] = i
            jj[m] = j
            put3(force, m, fx, fy, fz)
            put3(branch, m, dx, dy, dz)
            m += 1
    return ii, jj, force, branch


def ball_contacts_now(system, state) -> dict[str, np.ndarray]:
    """Every touching ball pair now: `i`, `j` (i < j), `force` (N, on i by j, lab axes) and
    `branch` = r_i - r_j (m, minimum image in a periodic length)."""
    i, j, force, branch = _ball_ball(balls_of(state), pairs_of(state.nl), system.table,
                                     system.periodic_length)
    return {"i": i, "j": j, "force": force, "branch": branch}
