"""Rigid motion of the tub in the lab's x-z plane (tub47.md, "Tub motion").

Every displacement is s(a, phi, t) = a [sin(omega t + phi) - sin(phi)], zero at t = 0:

    X(t) = s(A_x, phi_x, t),  Z(t) = s(A_z, phi_z, t),  theta(t) = s(Theta, phi_theta, t)

theta turns the tub about the pivot P (tub frame) counterclockwise seen with x to the right and
z up, so a tub-frame point p sits at  P + Rot(theta) (p - P) + (X, Z)  in the lab, with
Rot(theta) = [[cos, -sin], [sin, cos]] acting on (x, z).  As a 3D angular velocity this is
omega_tub = (0, -theta_dot, 0): turning x towards z is a negative turn about +y.

The DEM, the continuum solvers and the analysis all call these functions: nobody re-derives the
tub's kinematics.  The scalar kernels are numba-compiled so the DEM step can call them.
"""
from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np


@dataclass(frozen=True)
class TubMotion:
    """Harmonic rigid-body motion of the tub (SI: m, rad, Hz).

    The amplitudes are the scenario's amplitudes already multiplied by its amplitude factor.
    """

    frequency: float = 47.0
    amplitude_x: float = 1.0e-3
    phase_x: float = 0.0
    amplitude_z: float = 1.5e-3
    phase_z: float = 0.5 * np.pi
    amplitude_theta: float = 4.0e-3
    phase_theta: float = 0.0
    pivot_x: float = 0.0
    pivot_z: float = -0.10

    @property
    def omega(self) -> float:
        return 2.0 * np.pi * self.frequency

    def as_array(self) -> np.ndarray:
        """Packed parameters for the numba kernels (see `pose`)."""
        return np.array(
            [self.omega, self.amplitude_x, self.phase_x, self.amplitude_z, self.phase_z,
             self.amplitude_theta, self.phase_theta, self.pivot_x, self.pivot_z],
            dtype=np.float64,
        )

    @staticmethod
    def of_scenario(scenario) -> "TubMotion":
        """The scenario's rigid tub motion, every amplitude times motion.amplitude_factor
        (tub47.md "Tub motion"); the one mapping the DEM, the continuum and the LIGGGHTS deck
        use."""
        m = scenario.motion
        f = m.amplitude_factor
        return TubMotion(frequency=m.frequency, amplitude_x=f * m.amplitude_x,
                         phase_x=m.phase_x, amplitude_z=f * m.amplitude_z, phase_z=m.phase_z,
                         amplitude_theta=f * m.amplitude_theta, phase_theta=m.phase_theta,
                         pivot_x=m.pivot[0], pivot_z=m.pivot[1])

    @staticmethod
    def still() -> "TubMotion":
        return TubMotion(amplitude_x=0.0, amplitude_z=0.0, amplitude_theta=0.0)


@nb.njit(cache=True, inline="always")
def _harmonic(a, phase, omega, t):
    """s, s', s'' of s(a, phi, t) = a [sin(omega t + phi) - sin(phi)]."""
    arg = omega * t + phase
    s = a * (np.sin(arg) - np.sin(phase))
    ds = a * omega * np.cos(arg)
    dds = -a * omega * omega * np.sin(arg)
    return s, ds, dds


@nb.njit(cache=True)
def pose(params, t):
    """Tub pose at time t (s).

    Returns (X, Z, theta, Xdot, Zdot, thetadot, Xddot, Zddot, thetaddot) in m, rad and their
    time derivatives.  `params` is `TubMotion.as_array()`.
    """
    omega = params[0]
    x, vx, ax = _harmonic(params[1], params[2], omega, t)
    z, vz, az = _harmonic(params[3], params[4], omega, t)
    th, w, al = _harmonic(params[5], params[6], omega, t)
    return x, z, th, vx, vz, w, ax, az, al


@nb.njit(cache=True, inline="always")
def tub_to_lab(px, pz, X, Z, theta, pivot_x, pivot_z):
    """Lab (x, z) of a tub-frame point (px, pz) at pose (X, Z, theta)."""
    return tub_to_lab_cs(px, pz, X, Z, np.cos(theta), np.sin(theta), pivot_x, pivot_z)


@nb.njit(cache=True, inline="always")
def tub_to_lab_cs(px, pz, X, Z, c, s, pivot_x, pivot_z):
    """`tub_to_lab` with the angle's cosine c and sine s given (a pass that has them)."""
    rx = px - pivot_x
    rz = pz - pivot_z
    return pivot_x + c * rx - s * rz + X, pivot_z + s * rx + c * rz + Z


@nb.njit(cache=True, inline="always")
def lab_to_tub(lx, lz, X, Z, theta, pivot_x, pivot_z):
    """Tub-frame (x, z) of a lab point (lx, lz) at pose (X, Z, theta)."""
    c = np.cos(theta)
    s = np.sin(theta)
    rx = lx - X - pivot_x
    rz = lz - Z - pivot_z
    return pivot_x + c * rx + s * rz, pivot_z - s * rx + c * rz


@nb.njit(cache=True, inline="always")
def rigid_velocity(lx, lz, X, Z, Xdot, Zdot, thetadot, pivot_x, pivot_z):
    """Lab velocity (vx, vz) of the tub's material point now at lab (lx, lz).

    v = (Xdot, Zdot) + thetadot e_theta x r, with r from the moving pivot; for a counterclockwise
    turn in x-z that is (-thetadot r_z, +thetadot r_x).
    """
    rx = lx - X - pivot_x
    rz = lz - Z - pivot_z
    return Xdot - thetadot * rz, Zdot + thetadot * rx


# ----------------------------------------------------------------------------------------------
# Vectorised (numpy) forms for the analysis of snapshots.

def pose_np(motion: TubMotion, t):
    """Vectorised pose: dict of arrays X, Z, theta and their first derivatives at times t."""
    t = np.asarray(t, dtype=float)
    w = motion.omega

    def h(a, ph):
        return a * (np.sin(w * t + ph) - np.sin(ph)), a * w * np.cos(w * t + ph)

    X, Xd = h(motion.amplitude_x, motion.phase_x)
    Z, Zd = h(motion.amplitude_z, motion.phase_z)
    th, thd = h(motion.amplitude_theta, motion.phase_theta)
    return {"X": X, "Z": Z, "theta": th, "Xdot": Xd, "Zdot": Zd, "thetadot": thd}


def lab_to_tub_np(pos_lab, X, Z, theta, pivot=(0.0, -0.10)):
    """Tub-frame positions of lab positions (..., 3) at one pose (scalars). y is unchanged."""
    pos_lab = np.asarray(pos_lab, dtype=float)
    c, s = np.cos(theta), np.sin(theta)
    rx = pos_lab[..., 0] - X - pivot[0]
    rz = pos_lab[..., 2] - Z - pivot[1]
    out = np.array(pos_lab, dtype=float, copy=True)
    out[..., 0] = pivot[0] + c * rx + s * rz
    out[..., 2] = pivot[1] - s * rx + c * rz
    return out


def relative_velocity_tub_axes_np(pos_lab, vel_lab, X, Z, theta, Xdot, Zdot, thetadot,
                                  pivot=(0.0, -0.10)):
    """Velocity relative to the tub (lab velocity minus the tub's rigid velocity at the same
    point), expressed in tub axes (tub47.md "Bulk velocity").  Arrays (..., 3); y unchanged."""
    pos_lab = np.asarray(pos_lab, dtype=float)
    vel_lab = np.asarray(vel_lab, dtype=float)
    rx = pos_lab[..., 0] - X - pivot[0]
    rz = pos_lab[..., 2] - Z - pivot[1]
    dvx = vel_lab[..., 0] - (Xdot - thetadot * rz)
    dvz = vel_lab[..., 2] - (Zdot + thetadot * rx)
    c, s = np.cos(theta), np.sin(theta)
    out = np.array(vel_lab, dtype=float, copy=True)
    out[..., 0] = c * dvx + s * dvz
    out[..., 2] = -s * dvx + c * dvz
    return out
