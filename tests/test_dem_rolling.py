"""DEM verification, a ball on a plane under gravity: sliding, rolling, rolling resistance.

Rigid-body answers (a steel ball, I = 2/5 m R^2, on a steel plane, linear law k_n = 1e5 N/m):

* Sliding then rolling on a level plane.  Started at v0 without spin, friction -mu m g slows
  the ball (dv/dt = -mu g) and spins it up (R domega/dt = (5/2) mu g) until v = R omega, at
  t_r = 2 v0 / (7 mu g), with v = v0 - mu g t_r = (5/7) v0 (angular momentum about the contact
  point is conserved: m R v0 = m R v + I omega = (7/5) m R v).
* On a slope theta, rolling without slipping: m a = m g sin(theta) - F, I a / R = F R, so
  a = (5/7) g sin(theta) and F = (2/7) m g sin(theta); friction can supply it while
  mu > (2/7) tan(theta).  Below, the ball slides with a = g (sin(theta) - mu cos(theta)).
* Rolling resistance, constant directional torque (CDT): M_r = mu_r R F_n = mu_r R m g opposes
  the rolling.  With friction F (along the motion): m dv/dt = F and
  I domega/dt = -R F - mu_r R m g; rolling (dv/dt = R domega/dt) gives
  (I/R + m R) dv/dt = -mu_r R m g, i.e. dv/dt = -(5/7) mu_r g.  The EPSD model's spring torque
  saturates at the same mu_r R F_n once the ball rolls on, so it gives the same deceleration.

The ball starts resting at its equilibrium overlap m g cos(theta) / k_n, so no normal bounce.
Rolling models are off ("none") except in the rolling-resistance checks.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from dem_helpers import (G, M_STEEL, R_STEEL, Sim, ball, contact, fit_quadratic, linear_dt,
                         plane, rel, scenario)

K_N = 1.0e5
DT = linear_dt(K_N, M_STEEL, 50)  # 50 steps per ball-wall contact time


def resting_ball(normal=(0.0, 0.0, 1.0), vel=(0.0, 0.0, 0.0), omg=(0.0, 0.0, 0.0), mu=0.3,
                 mu_r=0.0, rolling="none") -> Sim:
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    overlap = M_STEEL * G * n[2] / K_N
    law = contact(model="linear", k_n=K_N, e=0.85, mu=mu, mu_r=mu_r, rolling=rolling)
    return Sim(scenario([ball(n * (R_STEEL - overlap), vel, omg)], [law],
                        walls=[plane(normal=tuple(n))], dt=DT, gravity=(0.0, 0.0, -G)))


def test_sliding_ball_ends_rolling_at_five_sevenths():
    mu, v0 = 0.3, 0.2
    t_roll = 2 * v0 / (7 * mu * G)
    sim = resting_ball(vel=(v0, 0.0, 0.0), mu=mu)
    tr = sim.trace(int(1.6 * t_roll / DT), every=10)
    t, v, om = tr["t"], tr["vel"][:, 0, 0], tr["omg"][:, 0, 1]
    late = t > 1.2 * t_roll
    # the contact's tangential spring (no tangential damping) rings a little after the slip
    # stops: average over the last part
    v_end = v[late].mean()
    assert rel(v_end, 5 / 7 * v0) < 0.01
    assert rel(R_STEEL * om[late].mean(), v_end) < 0.01
    # slip stops when the analysis says
    t_slip_end = t[np.nonzero(tr["slide"])[0][-1]]
    assert abs(t_slip_end - t_roll) < 0.02 * t_roll
    # during the slip the deceleration is mu g
    slip = (t > 0.1 * t_roll) & (t < 0.9 * t_roll)
    _, _, a = fit_quadratic(t[slip], tr["pos"][slip, 0, 0])
    assert rel(a, -mu * G) < 0.01


def _slope_run(theta_deg, mu, duration=0.06, skip=0.01):
    th = math.radians(theta_deg)
    # plane through the origin, normal tilted about y: downhill is +x along the plane
    sim = resting_ball(normal=(math.sin(th), 0.0, math.cos(th)), mu=mu)
    tr = sim.trace(int(duration / DT), every=10)
    downhill = np.array([math.cos(th), 0.0, -math.sin(th)])
    s = tr["pos"][:, 0, :] @ downhill
    sel = tr["t"] > skip
    _, _, a = fit_quadratic(tr["t"][sel], s[sel])
    return a, tr["slide"][sel], th


@pytest.mark.parametrize("mu", [0.3, 0.12])
def test_ball_rolls_down_slope(mu):
    theta = 20.0
    assert mu > 2 / 7 * math.tan(math.radians(theta))  # 0.104: rolls
    a, sliding, th = _slope_run(theta, mu)
    assert rel(a, 5 / 7 * G * math.sin(th)) < 0.02
    assert not sliding.any()


def test_ball_slides_down_slope():
    theta, mu = 20.0, 0.05
    assert mu < 2 / 7 * math.tan(math.radians(theta))
    a, sliding, th = _slope_run(theta, mu)
    assert rel(a, G * (math.sin(th) - mu * math.cos(th))) < 0.02
    assert sliding.mean() > 0.95


@pytest.mark.parametrize("model", ["cdt", "epsd", "cdt_liggghts"])
def test_rolling_resistance_decelerates_at_five_sevenths_mu_r_g(model):
    mu_r, v0 = 0.02, 0.1
    # start rolling: v0 and omega_y = v0 / R
    sim = resting_ball(vel=(v0, 0.0, 0.0), omg=(0.0, v0 / R_STEEL, 0.0), mu=0.3, mu_r=mu_r,
                       rolling=model)
    tr = sim.trace(int(0.3 / DT), every=20)
    t = tr["t"]
    assert tr["vel"][-1, 0, 0] > 0.3 * v0  # still rolling at the end
    sel = t > 0.02
    _, _, a = fit_quadratic(t[sel], tr["pos"][sel, 0, 0])
    assert rel(a, -5 / 7 * mu_r * G) < 0.02
    assert not tr["slide"][sel].any()


@pytest.mark.parametrize("model, share", [("cdt", 1.0), ("cdt_liggghts", 1.0 / math.sqrt(10.0))])
def test_a_twisting_ball_is_resisted_by_the_rolling_share_of_its_spin_in_liggghts_cdt(model,
                                                                                       share):
    """A ball rolling at v0 and spinning about the plane's normal at 3 v0 / R (nothing resists
    the twist: no torsional friction in either model).  tub47.md's CDT takes its rolling
    velocity alone, so the deceleration stays (5/7) mu_r g; LIGGGHTS 3.8's CDT
    (rolling_model = "cdt_liggghts", src/rolling_model_cdt.h) directs mu_r R_eff k_n delta
    along the whole spin and drops its normal part, so it is that times |omega_rolling| /
    |omega| = 1 / sqrt(1 + 3^2) at the start: the weaker torque that separates the two codes
    on tub47-quick (docs/liggghts.md)."""
    mu_r, v0 = 0.1, 0.1
    sim = resting_ball(vel=(v0, 0.0, 0.0), omg=(0.0, v0 / R_STEEL, 3.0 * v0 / R_STEEL), mu=0.3,
                       mu_r=mu_r, rolling=model)
    # a short window, over which v changes by about 2 % (the share by under 1.5 %)
    tr = sim.trace(int(0.012 / DT), every=5)
    t = tr["t"]
    sel = t > 0.002
    a = np.polyfit(t[sel], tr["vel"][sel, 0, 0], 1)[0]
    assert rel(a, -5 / 7 * mu_r * G * share) < 0.03
    assert not tr["slide"][sel].any()
    # nothing resists the twist
    assert tr["omg"][-1, 0, 2] == pytest.approx(3.0 * v0 / R_STEEL, rel=1e-6)
