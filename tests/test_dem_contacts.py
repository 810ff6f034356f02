"""Contacts the DEM's other checks do not reach: the tub's curved U wall, against analytic
mechanics, and a contact's tangential history across the neighbour list's rebuilds.

A ball released at rest a small angle theta0 up the half-circle bottom of the U (radius R) moves
on a circle of radius R - r about the U's centre.  Without friction it slides, a pendulum of
length R - r: T = 2 pi sqrt((R - r) / g).  With friction enough to stop slipping it rolls, its
kinetic energy (1/2) m v^2 (1 + 2/5) for a solid sphere: T = 2 pi sqrt(7 (R - r) / (5 g)).  The
finite amplitude lengthens both by (1 + theta0^2 / 16) (the pendulum's first correction); the
wall's compliance (mg / k_n ~ 0.2 um here) is nothing against R - r.  The DEM's U is an exact
analytic surface (vibroflow.dem.walls), so the periods come out within 1e-4 (measured: 1e-6).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from tests.dem_helpers import one_thread
from vibroflow.dem import simulate as S
from vibroflow.dem.laws import material_index
from vibroflow.scenario.io import load_scenario

G = 9.81
THETA0 = 0.05  # rad


def _oscillation(friction: float, seconds: float) -> tuple[float, float, float]:
    """(measured period, R - r, the largest gap to the circle) of a steel ball released at
    THETA0 on the U of tub47-quick's tub, at rest, followed for `seconds`."""
    s = load_scenario("tub47-quick", [
        "fill.count=1", "motion.amplitude_factor=0.0", "run.dt=1e-5",
        f"contacts.1.friction={friction}", "contacts.1.rolling_friction=0.0"])
    R, r = s.tub.radius, 0.5 * s.fill.diameter
    arm = R - r
    system = S.make_system(s)
    x0, z0 = arm * math.sin(THETA0), R - arm * math.cos(THETA0)
    state = S.init_state(system, [[x0, 0.5 * s.tub.length, z0]], [[0.0, 0.0, 0.0]],
                         [[0.0, 0.0, 0.0]], [r], [s.materials["steel"].density],
                         [material_index(s)["steel"]])
    every = 20
    n = int(seconds / (every * s.run.dt))
    t = np.arange(n + 1) * every * s.run.dt
    x = np.empty(n + 1)
    gap = np.empty(n + 1)
    with one_thread():
        for k in range(n + 1):
            if k:
                S.run_steps(system, state, every)
            px, _, pz = state.pos[0]
            x[k] = px
            gap[k] = abs(math.hypot(px, pz - R) - arm)
    # downward zero crossings of x, linearly interpolated: one a period
    i = np.flatnonzero((x[:-1] > 0) & (x[1:] <= 0))
    tc = t[i] + x[i] / (x[i] - x[i + 1]) * (t[i + 1] - t[i])
    assert tc.size >= 2, "fewer than two periods"
    return float(np.diff(tc).mean()), arm, float(gap.max())


@pytest.mark.parametrize("friction, factor", [
    (0.0, 1.0), pytest.param(0.4, 7.0 / 5.0, marks=pytest.mark.slow)])
def test_a_ball_in_the_u_swings_with_the_analytic_period(friction, factor):
    s = load_scenario("tub47-quick")
    arm = s.tub.radius - 0.5 * s.fill.diameter
    expected = 2.0 * math.pi * math.sqrt(factor * arm / G) * (1.0 + THETA0**2 / 16.0)
    # 1.5 periods: the first downward crossing at a quarter period and the next one; the swing
    # repeats to round-off (three periods read the same mean period to 1e-15)
    period, arm, gap = _oscillation(friction, 1.5 * expected)
    assert gap < 1e-6  # on the wall all along (its compliance mg / k_n is 0.2 um)
    assert period == pytest.approx(expected, rel=1e-4), (period, expected)


# ---------------------------------------------------------------------------------------------
# The tangential history of a contact survives the neighbour list's rebuilds

def _oblique_collision(with_passer_by: bool):
    """Ball 1 strikes ball 0 off-centre (impact parameter d/2, 1 m/s, friction 0.5: a sticking
    then sliding contact whose tangential spring carries its history through the whole
    contact).  A third ball far away, flying at 50 m/s, makes the neighbour list rebuild every
    ~20 steps during the contact; it touches nothing.  Returns the two balls' final state and
    the number of rebuilds."""
    from tests.dem_helpers import D_STEEL, Sim, ball, contact, scenario

    d = D_STEEL
    x0 = math.sqrt(d * d - (0.5 * d) ** 2) + 1e-4
    balls = [ball((0.0, 0.0, 0.0)), ball((x0, 0.0, 0.5 * d), vel=(-1.0, 0.0, 0.0))]
    if with_passer_by:
        balls.append(ball((0.5, 0.0, 0.0), vel=(50.0, 0.0, 0.0)))
    sim = Sim(scenario(balls, [contact(mu=0.5, e=0.85)], dt=1e-6, duration=1e-3))
    sim.run(1000)
    st = sim.state
    return st.pos[:2].copy(), st.vel[:2].copy(), st.omg[:2].copy(), st.nl.builds


def test_the_tangential_history_survives_neighbour_list_rebuilds():
    """The two colliding balls end bit for bit as without the rebuilds: their one contact's
    force is the only force on them, so only a lost or reset tangential history could change
    it (zeroing the history half-way through the contact changes the spins by 55 rad/s)."""
    pos0, vel0, omg0, builds0 = _oblique_collision(False)
    pos1, vel1, omg1, builds1 = _oblique_collision(True)
    assert builds1 >= builds0 + 10  # the passer-by made the list rebuild during the contact
    assert np.abs(omg0).max() > 10.0  # the contact's friction spun the balls
    np.testing.assert_array_equal(vel1, vel0)
    np.testing.assert_array_equal(omg1, omg0)
    np.testing.assert_array_equal(pos1, pos0)
