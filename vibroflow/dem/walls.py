"""Walls: what a ball touches besides other balls.

Wall slots (index w into the per-ball wall arrays):
    0        the tub's U-shaped inner surface (exact analytic surface, tub frame)
    1, 2     the partitions y = 0 and y = L (flat, glass), absent when the length is periodic
    3 + k    plane wall k of an explicit scenario

For each slot the kernel returns the overlap, the unit normal (from the wall to the ball, lab
axes), the wall's material velocity at the contact point and its angular velocity (lab).
The tub's walls move with the tub (vibroflow.tub.motion); a plane wall translates with a
constant velocity plus a harmonic displacement a [sin(omega t + phase) - sin(phase)].
"""
from __future__ import annotations

import numba as nb
import numpy as np

from ..tub.geometry import u_wall_nearest
from ..tub.motion import rigid_velocity, tub_to_lab_cs

# tub parameters packed for the kernels: [radius, rim_height, length, periodic, has_tub]
TUB_RADIUS, TUB_RIM, TUB_LENGTH, TUB_PERIODIC, TUB_PRESENT = range(5)
# plane parameters: point(3), normal(3), velocity(3), amplitude(3), omega, phase
N_PLANE = 14
WALL_U, WALL_PARTITION_LO, WALL_PARTITION_HI, WALL_PLANE0 = 0, 1, 2, 3
# impact kinds (kept in dem.h5 /impacts/kind)
KIND_BALL_BALL, KIND_BALL_TUB, KIND_BALL_PARTITION, KIND_BALL_PLANE = 0, 1, 2, 3


def wall_kind(w: int) -> int:
    if w == WALL_U:
        return KIND_BALL_TUB
    if w in (WALL_PARTITION_LO, WALL_PARTITION_HI):
        return KIND_BALL_PARTITION
    return KIND_BALL_PLANE


@nb.njit(cache=True, inline="always")
def u_wall(px, pz, r, tub, pose, cos_th, sin_th):
    """Contact of a ball (lab x, z) with the U surface; cos_th, sin_th of the tub's angle.

    Returns (delta, nx, nz, vwx, vwz, cxt, czt, s, outside): overlap (m, <= 0 when apart, and
    then the rest is not computed), lab normal (x, z), wall velocity at the contact point (lab),
    the contact point in the tub frame, its arc coordinate, and whether the ball's centre is
    outside the tub.
    """
    X, Z, Xd, Zd, thd = pose[0], pose[1], pose[3], pose[4], pose[5]
    pvx, pvz = pose[6], pose[7]
    # lab -> tub frame (tub/motion.py lab_to_tub, with the angle's cos and sin given)
    rx = px - X - pvx
    rz = pz - Z - pvz
    tx = pvx + cos_th * rx + sin_th * rz
    tz = pvz - sin_th * rx + cos_th * rz
    R = tub[TUB_RADIUS]
    if tz > tub[TUB_RIM]:
        # above the rim: no wall; outside if beside the tub or flown far away
        outside = abs(tx) > R or tz > tub[TUB_RIM] + 1.0
        return -1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, outside
    # cheap gap first: most balls are not touching the wall
    if tz <= R:
        gap = R - np.sqrt(tx * tx + (tz - R) * (tz - R))
    else:
        gap = R - abs(tx)
    if gap >= r:
        return r - gap, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, False
    gap, ntx, ntz, cxt, czt, s = u_wall_nearest(tx, tz, R)
    nx = cos_th * ntx - sin_th * ntz
    nz = sin_th * ntx + cos_th * ntz
    clx, clz = tub_to_lab_cs(cxt, czt, X, Z, cos_th, sin_th, pvx, pvz)
    vwx, vwz = rigid_velocity(clx, clz, X, Z, Xd, Zd, thd, pvx, pvz)
    return r - gap, nx, nz, vwx, vwz, cxt, czt, s, gap < 0.0


@nb.njit(cache=True, inline="always")
def plane_wall(px, py, pz, r, plane, t):
    """Contact with a moving infinite plane: (delta, wall velocity vx, vy, vz)."""
    om = plane[12]
    ph = plane[13]
    sdisp = np.sin(om * t + ph) - np.sin(ph)
    cvel = om * np.cos(om * t + ph)
    gap = 0.0
    for a in range(3):
        p = plane[a] + plane[6 + a] * t + plane[9 + a] * sdisp
        q = px if a == 0 else (py if a == 1 else pz)
        gap += (q - p) * plane[3 + a]
    return (r - gap, plane[6] + plane[9] * cvel, plane[7] + plane[10] * cvel,
            plane[8] + plane[11] * cvel)
