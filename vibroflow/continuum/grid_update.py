"""Grid momentum update: internal and external forces, gravity and the frame's inertial forces.

Choice of frame.  The solver works on a grid fixed to the tub (the tub frame of tub47.md), not on
a lab-frame grid with moving walls, because (1) the U wall is then still on the grid, so the
wall contact needs no moving geometry and the grid never has to be larger than the tub; (2) the
velocity the solver carries is already the velocity relative to the tub in tub axes, the
quantity every output is about (bulk_velocity.csv, probes, circulation); (3) it is how the
Eulerian formulation must work too (models.md), so both share the frame.  The price is the
inertial body force of the accelerating, rotating frame, exact for the rigid motion of
vibroflow.tub.motion (nothing about the motion is re-derived here: `pose` gives it):

    with the lab position r = P + Rot(theta) (p - P) + (X, Z) (tub.motion), q = p - P and
    J = [[0, -1], [1, 0]] (a quarter turn x -> z), the tub-frame acceleration of a point is
    p'' = Rot(theta)^T (g + f/m - (X'', Z'')) - theta'' J q + theta'^2 q - 2 theta' J p'

(translation, Euler, centrifugal and Coriolis terms; models.md "Eulerian").  A lab frame is the
special case theta = 0, (X'', Z'') = 0 and is what the verification tests use (`LabFrame`).

The update (explicit, symplectic Euler on the grid): v_i = (m v)_i / m_i, then
v_i += dt (f_i / m_i + a_body(x_i, v_i)).  Nodes within one node of the grid's edge are held
still (a safety rim: points are kept GUARD nodes inside, grid.py), except along x on a grid
periodic in x (the steady inclined layer of the tests).  Nodes with no mass get no
velocity.
"""
from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

from vibroflow.tub.motion import TubMotion, pose

#: a node with less mass than this (kg/m) is empty
MASS_EPS = 1.0e-14

#: a frame packed for the kernels (`frame_body`): kind (FRAME_LAB or FRAME_TUB), lab gravity
#: (gx, gz) m/s^2, then the tub's motion (TubMotion.as_array(): omega, amplitudes and phases,
#: pivot) for FRAME_TUB
F_KIND, F_GX, F_GZ, F_MOTION = 0, 1, 2, 3
FRAME_FIELDS = 12
FRAME_LAB, FRAME_TUB = 0, 1


@nb.njit(cache=True)
def frame_body(frame, t):
    """(a0x, a0z, thetadot, thetaddot, pivot_x, pivot_z) of a packed frame at time t (s)
    (LabFrame.body, TubFrame.body): a0 = Rot^T (g - X'') (m/s^2) in the frame's axes."""
    if frame[F_KIND] == FRAME_LAB:
        return frame[F_GX], frame[F_GZ], 0.0, 0.0, 0.0, 0.0
    X, Z, th, Xd, Zd, thd, Xdd, Zdd, thdd = pose(frame[F_MOTION:], t)
    gx = frame[F_GX] - Xdd
    gz = frame[F_GZ] - Zdd
    c = np.cos(th)
    s = np.sin(th)
    return (c * gx + s * gz, -s * gx + c * gz, thd, thdd, frame[F_MOTION + 7],
            frame[F_MOTION + 8])


@dataclass(frozen=True)
class LabFrame:
    """An inertial frame with gravity (gx, gz) (m/s^2)."""

    gravity: tuple[float, float] = (0.0, -9.81)

    def body(self, t: float):
        """(a0x, a0z, thetadot, thetaddot, pivot_x, pivot_z) at time t (s)."""
        return float(self.gravity[0]), float(self.gravity[1]), 0.0, 0.0, 0.0, 0.0

    def as_array(self) -> np.ndarray:
        """Packed for `frame_body` (FRAME_FIELDS)."""
        a = np.zeros(FRAME_FIELDS)
        a[F_KIND] = FRAME_LAB
        a[F_GX], a[F_GZ] = self.gravity
        return a

    def pose(self, t: float):
        """(X, Z, theta, Xdot, Zdot, thetadot) of this frame in the lab: the identity."""
        return 0.0, 0.0, 0.0, 0.0, 0.0, 0.0


@dataclass(frozen=True)
class TubFrame:
    """The frame of the vibrating tub: `motion` (vibroflow.tub.motion.TubMotion) with lab
    gravity (gx, gz) (m/s^2)."""

    motion: TubMotion
    gravity: tuple[float, float] = (0.0, -9.81)

    def body(self, t: float):
        """(a0x, a0z, thetadot, thetaddot, pivot_x, pivot_z) at time t (s): a0 = Rot^T (g - X'')
        (m/s^2) in tub axes, the rotation rate and acceleration (rad/s, rad/s^2), the pivot (m)."""
        return frame_body(self.as_array(), float(t))

    def as_array(self) -> np.ndarray:
        """Packed for `frame_body` (FRAME_FIELDS)."""
        a = np.zeros(FRAME_FIELDS)
        a[F_KIND] = FRAME_TUB
        a[F_GX], a[F_GZ] = self.gravity
        a[F_MOTION:] = self.motion.as_array()
        return a

    def pose(self, t: float):
        """(X, Z, theta, Xdot, Zdot, thetadot) of the tub at time t (s) (tub.motion.pose)."""
        X, Z, th, Xd, Zd, thd, _, _, _ = pose(self.motion.as_array(), t)
        return float(X), float(Z), float(th), float(Xd), float(Zd), float(thd)


@nb.njit(cache=True, inline="always")
def idle_node(gm, i, k, periodic, out):
    """Whether node (i, k) of the grid of masses gm (nx, nz) (kg/m) gets no velocity: it holds
    no mass (<= MASS_EPS) or lies on the grid's edge (no edge along x when periodic); then its
    velocity out[i, k] (nx, nz, 2) (m/s) is set to 0."""
    nx, nz = gm.shape
    edge = k < 1 or k >= nz - 1 or (not periodic and (i < 1 or i >= nx - 1))
    if gm[i, k] <= MASS_EPS or edge:
        out[i, k, 0] = 0.0
        out[i, k, 1] = 0.0
        return True
    return False


@nb.njit(cache=True)
def grid_update(gm, gmv, gf, gv, x0, z0, dx, dt, a0x, a0z, w, alpha, pivx, pivz, periodic):
    """New grid velocities gv (nx, nz, 2) (m/s) from masses gm (kg/m), momenta gmv (kg/s) and
    forces gf (N/m) over dt (s), with the frame's body acceleration (module docstring):
    a0 (m/s^2), rotation rate w = theta' (rad/s) and acceleration alpha = theta'' (rad/s^2)
    about the pivot (pivx, pivz) (m).  periodic: the grid wraps along x (no edge nodes in x)."""
    nx, nz = gm.shape
    for i in range(nx):
        for k in range(nz):
            if idle_node(gm, i, k, periodic, gv):
                continue
            m = gm[i, k]
            vx = gmv[i, k, 0] / m
            vz = gmv[i, k, 1] / m
            qx = x0 + i * dx - pivx
            qz = z0 + k * dx - pivz
            # -alpha J q + w^2 q - 2 w J v, with J (a, b) = (-b, a)
            ax = gf[i, k, 0] / m + a0x + alpha * qz + w * w * qx + 2.0 * w * vz
            az = gf[i, k, 1] / m + a0z - alpha * qx + w * w * qz - 2.0 * w * vx
            gv[i, k, 0] = vx + dt * ax
            gv[i, k, 1] = vz + dt * az
