"""Forgetting the contact histories (vibroflow.dem.simulate.forget_histories): a ball at rest on
a plane tilted by theta, held by its loaded tangential spring and EPSD rolling spring.

Statics of the wall contact (contact.py; the lever arm is the radius r, the slip along the
downhill direction d is xi = s - r phi for a displacement s along d and a turn phi about the
axis n x d): the spring forces balance gravity's downhill pull when

    k_t xi = m g sin(theta),    k_r phi = r m g sin(theta),    k_r = 2.25 k_n mu_r^2 r^2,

so the loaded springs hold xi_t = (m g sin(theta) / k_t) d and M_r = -r m g sin(theta) (n x d).
Kept, they hold the ball where it is.  Zeroed, the ball moves down the slope until they carry
the load again, to s_eq = m g sin(theta) (1 / k_t + r^2 / k_r), about which it oscillates
without tangential damping (the linear two-degree-of-freedom system
m s'' = m g sin(theta) - k_t (s - r phi), I phi'' = r k_t (s - r phi) - k_r phi, started at
rest at s = phi = 0): its time mean over whole cycles is s_eq.
"""
from __future__ import annotations

import math

import numpy as np

from dem_helpers import G, M_STEEL, R_STEEL, Sim, ball, contact, linear_dt, plane, scenario
from vibroflow.dem.simulate import forget_histories
from vibroflow.dem.walls import WALL_PLANE0

K_N = 1.0e5
KT_RATIO = 2.0 / 7.0
MU, MU_R = 0.5, 0.5
THETA = math.radians(10.0)  # tan 0.18: twice the load stays below mu and mu_r (no slip)
DT = linear_dt(K_N, M_STEEL, 50)
N = np.array([math.sin(THETA), 0.0, math.cos(THETA)])    # the plane's normal
D = np.array([math.cos(THETA), 0.0, -math.sin(THETA)])   # downhill
LOAD = M_STEEL * G * math.sin(THETA)                      # N
K_T = KT_RATIO * K_N
K_R = 2.25 * K_N * MU_R**2 * R_STEEL**2
S_EQ = LOAD * (1.0 / K_T + R_STEEL**2 / K_R)              # 9.40e-8 m at these numbers


def _held_ball() -> Sim:
    overlap = M_STEEL * G * math.cos(THETA) / K_N
    law = contact(model="linear", k_n=K_N, e=0.85, mu=MU, mu_r=MU_R, rolling="epsd",
                  kt_ratio=KT_RATIO)
    sim = Sim(scenario([ball(N * (R_STEEL - overlap))], [law], walls=[plane(normal=tuple(N))],
                       dt=DT, gravity=(0.0, 0.0, -G)))
    hist = sim.state.wall_hist[0, WALL_PLANE0]
    hist[0:3] = LOAD / K_T * D                          # F_t = -k_t xi_t points uphill
    hist[3:6] = -R_STEEL * LOAD * np.cross(N, D)        # balances the friction's torque
    return sim


def _downhill(sim: Sim, seconds: float) -> np.ndarray:
    start = sim.state.pos[0].copy()
    tr = sim.trace(int(seconds / DT), every=1)
    return (tr["pos"][:, 0, :] - start) @ D


def test_hand_computed_equilibrium_load():
    """The hand values of the module docstring at these numbers."""
    assert math.isclose(LOAD, 1.0454e-3 * 9.81 * 0.17365, rel_tol=1e-3)
    assert math.isclose(S_EQ, 1.7813e-3 * (3.5 + 1.0 / (2.25 * 0.25)) / 1.0e5,
                        rel_tol=1e-3)


def test_with_its_histories_kept_a_held_ball_stays_put():
    """Within 2 % of s_eq: the state starts without forces, so the first step's half kick of
    gravity alone rings the springs by about 1 % of s_eq (g sin(theta) dt / omega)."""
    s = _downhill(_held_ball(), 0.02)
    assert np.max(np.abs(s)) < 0.02 * S_EQ


def test_with_its_histories_forgotten_a_held_ball_moves_until_the_springs_carry_the_load():
    sim = _held_ball()
    forget_histories(sim.state)
    assert not sim.state.wall_hist.any()
    s = _downhill(sim, 0.06)
    assert np.max(s) > 1.5 * S_EQ     # it moves, overshooting the new rest
    assert np.min(s) > -0.02 * S_EQ   # only downhill
    late = s[len(s) // 6:]            # ~40 cycles of the slowest mode
    assert math.isclose(late.mean(), S_EQ, rel_tol=0.01)  # measured 1.001
    assert not sim.state.wall_slide.any()
