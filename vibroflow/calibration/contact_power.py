"""The power each DEM contact takes out of the balls' motion (W), from what dem.h5 holds at a
snapshot: the balls' velocities and spins, every touching pair's force and every wall contact's
force and contact point.

Kinematics are the DEM's own (vibroflow.dem.contact): n the unit normal from j (or the wall) to
i, the radii as lever arms, so the relative velocity of i's surface against j's at the contact is
u = v_i - v_j - (r_i w_i + r_j w_j) x n, and the torques the DEM applies are exactly those of
these lever arms.  The mechanical power of a pair's force F (on i; j gets -F) and rolling moment
M_r on the two balls is then F . u + M_r . (w_i - w_j), so the contact takes out

    P = -F . u - M_r . (w_i - w_j)
      = -F_n (u . n)  [the dashpot, and the normal spring's storage rate]
        -F_t . u_t    [sliding, and the tangential spring's storage rate]
        + mu_r R_eff |F_n| |w_r|  [CDT rolling resistance, w_r the rolling part of w_i - w_j]

(F_n = F . n, F_t = F - F_n n).  The springs' rate of storage, d/dt (k_n delta^2 / 2 + |F_t|^2 /
(2 k_t)), averages out over a steady cycle, so the cycle mean of P is the dissipation (checked on
tub47-quick against the stored energy of `elastic_energy_J`, docs/validation.md section 29).
A wall contact is the same with the wall as j, its radius 0 and its velocity that of the rigid
tub: in the tub frame (the velocities and spins relative to the tub) the wall is at rest except
for the frame's spin Omega, which moves the contact point delta from the centre's lever end:
u = v_i - r w_i x n - delta Omega x n.

The rolling moment is not stored in dem.h5: for the CDT law it is a function of the stored
state (mu_r R_eff |F_n| along -w_r), so it is reconstructed here; for the EPSD law (an elastic
spring with a history) it is not, and its loss is left out (`rolling_reconstructable`).
Known answers (tests/test_thermal_balance.py): a head-on dashpot gives gamma v_n^2, a sliding
contact mu |F_n| |v_slip|, a rigid rotation of touching balls zero.
"""
from __future__ import annotations

import numpy as np

#: rolling laws whose moment is a function of the stored state
ROLLING_RECONSTRUCTED = ("cdt", "none")


def rolling_reconstructable(model: str) -> bool:
    """True when the rolling law's moment follows from dem.h5's state (CDT, or none)."""
    return model in ROLLING_RECONSTRUCTED


def _unit(b):
    d = np.sqrt(np.einsum("ij,ij->i", b, b))
    return b / d[:, None], d


def _rolling(F_n, w_rel, n, mu_r, r_eff):
    """CDT's loss mu_r R_eff |F_n| |w_r| (W), w_r = w_rel less its part along n."""
    w_r = w_rel - np.einsum("ij,ij->i", w_rel, n)[:, None] * n
    return mu_r * r_eff * np.abs(F_n) * np.sqrt(np.einsum("ij,ij->i", w_r, w_r))


def pair_power_loss(branch, r_i, r_j, v_i, v_j, w_i, w_j, force, mu_r: float = 0.0):
    """(normal, tangential, rolling) power taken out by each touching pair (C,) W each (module
    notes): branch (C, 3) r_i - r_j (m), radii (C,) m, velocities (C, 3) m/s, spins (C, 3)
    rad/s, force (C, 3) on i by j (N), all in one frame; mu_r the CDT rolling resistance (0:
    no rolling loss)."""
    n, _ = _unit(np.asarray(branch, float))
    r_i = np.asarray(r_i, float)[:, None]
    r_j = np.asarray(r_j, float)[:, None]
    w_i, w_j = np.asarray(w_i, float), np.asarray(w_j, float)
    u = np.asarray(v_i, float) - np.asarray(v_j, float) - np.cross(r_i * w_i + r_j * w_j, n)
    F = np.asarray(force, float)
    F_n = np.einsum("ij,ij->i", F, n)
    u_n = np.einsum("ij,ij->i", u, n)
    normal = -F_n * u_n
    tangential = -np.einsum("ij,ij->i", F, u) - normal
    r_eff = (r_i * r_j / (r_i + r_j))[:, 0]
    rolling = _rolling(F_n, w_i - w_j, n, mu_r, r_eff) if mu_r > 0 else np.zeros(F_n.size)
    return normal, tangential, rolling


def wall_power_loss(branch, radius, v, w, force, frame_spin=(0.0, 0.0, 0.0), mu_r: float = 0.0):
    """(normal, tangential, rolling) power taken out by each wall contact (W, W, W), in the
    frame of the rigid walls: branch (W, 3) the ball's centre minus the contact point (m),
    radius (W,) m, the ball's velocity v (W, 3) m/s and spin w (W, 3) rad/s relative to that
    frame, force (W, 3) the wall's on the ball (N), frame_spin the frame's angular velocity
    Omega (rad/s, the same axes), mu_r the CDT rolling resistance."""
    n, dist = _unit(np.asarray(branch, float))
    r = np.asarray(radius, float)
    delta = r - dist
    Om = np.broadcast_to(np.asarray(frame_spin, float), n.shape)
    u = (np.asarray(v, float) - np.cross(r[:, None] * np.asarray(w, float), n)
         - np.cross(delta[:, None] * Om, n))
    F = np.asarray(force, float)
    F_n = np.einsum("ij,ij->i", F, n)
    normal = -F_n * np.einsum("ij,ij->i", u, n)
    tangential = -np.einsum("ij,ij->i", F, u) - normal
    rolling = _rolling(F_n, np.asarray(w, float), n, mu_r, r) if mu_r > 0 else np.zeros(r.size)
    return normal, tangential, rolling


def elastic_energy_J(branch, r_sum, force, k_n: float, k_t: float) -> float:
    """Energy stored in linear springs (J): sum of k_n delta^2 / 2 + |F_t|^2 / (2 k_t), delta =
    r_sum - |branch| (r_i + r_j, or the ball's radius at a wall; branch as in the functions
    above), F_t the force's part across n (the tangential spring's force, k_t |xi_t|)."""
    n, dist = _unit(np.asarray(branch, float))
    F = np.asarray(force, float)
    F_t = F - np.einsum("ij,ij->i", F, n)[:, None] * n
    delta = np.maximum(np.asarray(r_sum, float) - dist, 0.0)
    return float(0.5 * k_n * np.sum(delta**2) + 0.5 * np.sum(F_t * F_t) / k_t)
