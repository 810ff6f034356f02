"""DEM verification, a ball on a vibrating plate (moving plane wall).

The plate's displacement is a [sin(w t + phase) - sin(phase)] (vibroflow.dem.walls); a steel ball
(linear law, k_n = 1e5 N/m) rests on it under gravity.  The wall's own velocity must enter the
contact's relative velocity (models.md), which is what these checks exercise.

Horizontal vibration, rolling without slipping (I = 2/5 m R^2): with friction F on the ball,
m x'' = F and I omega' = -R F; no slip at the contact, x' - R omega = X_p', differentiated:
x'' + R^2 F / I = X_p'', so x'' = (2/7) X_p''.  Started consistently (here at rest, with the
plate at rest: phase pi/2), x(t) = x(0) + (2/7) X_p(t): the centre moves 2/7 of the plate's
displacement.  The friction needed, (2/7) m A w^2, is available while A w^2 < (7/2) mu g;
above, the ball slips: its acceleration, F_t / m, is bounded by mu g, and its oscillation falls
well short of (2/7) A.

A belt (the plane sliding in its own plane at constant speed u) under a ball at rest: friction
mu m g accelerates the ball (dv/dt = mu g) and spins it backwards (R domega/dt = -(5/2) mu g)
until its contact point moves with the belt, v - R omega = u, at t = 2 u / (7 mu g), where
v = (2/7) u (angular momentum about the contact point is conserved, as for the sliding ball).

Vertical vibration: the ball stays on the plate while the plate can push it, i.e. while the
plate's acceleration -A w^2 sin(w t) is above -g.  With Gamma = A w^2 / g < 1 it never leaves;
with Gamma > 1 (phase 0, ball moving with the plate) it leaves at w t* = asin(1 / Gamma) and
flies freely, z(t) = z_p(t*) + z_p'(t*) (t - t*) - g (t - t*)^2 / 2, until it meets the plate
again (solved for below).  The contact stiffness makes the ball follow the plate with an error
of order (w / w_n)^2, here 2e-4.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import brentq

from dem_helpers import (G, M_STEEL, R_STEEL, Sim, ball, contact, fit_harmonic, linear_dt,
                         plane, plane_displacement, scenario)

K_N = 1.0e5
DT = linear_dt(K_N, M_STEEL, 50)
OVERLAP0 = M_STEEL * G / K_N  # resting overlap


def plate_run(amplitude, frequency, phase, mu, periods, every, vel=(0.0, 0.0, 0.0),
              plate_velocity=(0.0, 0.0, 0.0)):
    law = contact(model="linear", k_n=K_N, e=0.85, mu=mu)
    sim = Sim(scenario([ball((0.0, 0.0, R_STEEL - OVERLAP0), vel)], [law],
                       walls=[plane(amplitude=amplitude, frequency=frequency, phase=phase,
                                    velocity=plate_velocity)],
                       dt=DT, gravity=(0.0, 0.0, -G)))
    return sim.trace(int(periods / frequency / DT), every=every)


def test_ball_on_moving_belt_ends_rolling_at_two_sevenths():
    u, mu = 0.1, 0.3
    t_roll = 2 * u / (7 * mu * G)
    # "frequency" 1 Hz with no amplitude: just sets the run length (periods = seconds)
    tr = plate_run((0.0, 0.0, 0.0), 1.0, 0.0, mu, 1.6 * t_roll, every=10,
                   plate_velocity=(u, 0.0, 0.0))
    t, v, om = tr["t"], tr["vel"][:, 0, 0], tr["omg"][:, 0, 1]
    late = t > 1.2 * t_roll
    assert v[late].mean() == pytest.approx(2 / 7 * u, rel=0.01)
    assert -R_STEEL * om[late].mean() == pytest.approx(5 / 7 * u, rel=0.01)
    t_slip_end = t[np.nonzero(tr["slide"])[0][-1]]
    assert abs(t_slip_end - t_roll) < 0.02 * t_roll


def horizontal(mu):
    f, amp = 10.0, 0.002
    w = 2 * math.pi * f
    tr = plate_run((amp, 0.0, 0.0), f, 0.5 * math.pi, mu, periods=3, every=20)
    t, x = tr["t"], tr["pos"][:, 0, 0]
    late = t > 1.0 / f  # the fit skips the first period
    _, drift, b, c = fit_harmonic(t[late], x[late], w)
    return amp, w, tr, late, drift, b, c


def test_ball_rolls_on_horizontally_vibrating_plate():
    mu = 0.4
    amp, w, tr, late, drift, b, c = horizontal(mu)
    assert amp * w**2 < 3.5 * mu * G  # 7.9 < 13.7 m/s^2: rolls
    # plate: A (cos w t - 1); ball: (2/7) A (cos w t - 1)
    assert math.hypot(b, c) == pytest.approx(2 / 7 * amp, rel=0.03)
    assert abs(c) < 0.03 * 2 / 7 * amp and b > 0  # in phase with the plate
    assert abs(drift) < 1e-3 * amp * w
    assert not tr["slide"][late].any()
    xp = plane_displacement(tr["t"], (amp, 0, 0), 10.0, 0.5 * math.pi)[:, 0]
    assert np.abs(tr["pos"][:, 0, 0] - 2 / 7 * xp).max() < 0.03 * 2 / 7 * amp


def test_ball_slips_on_plate_above_the_friction_limit():
    mu = 0.1
    amp, w, tr, late, drift, b, c = horizontal(mu)
    assert amp * w**2 > 3.5 * mu * G  # 7.9 > 3.4 m/s^2: slips
    assert tr["slide"][late].mean() > 0.5
    assert math.hypot(b, c) < 0.7 * 2 / 7 * amp
    # Coulomb: the acceleration (averaged over each sampling interval) never exceeds mu g
    accel = np.diff(tr["vel"][:, 0, 0]) / np.diff(tr["t"])
    assert np.abs(accel).max() < 1.001 * mu * G


def vertical(gamma, periods):
    f = 20.0
    w = 2 * math.pi * f
    amp = gamma * G / w**2
    # phase 0: the plate starts at its centre moving up at A w, with zero acceleration; the
    # ball starts with it, resting at its equilibrium overlap
    tr = plate_run((0.0, 0.0, amp), f, 0.0, 0.2, periods, every=1, vel=(0.0, 0.0, amp * w))
    zp = plane_displacement(tr["t"], (0, 0, amp), f, 0.0)[:, 2]
    gap = tr["pos"][:, 0, 2] - zp - R_STEEL
    return f, w, amp, tr, gap


def test_ball_stays_on_plate_below_one_g():
    gamma = 0.8
    f, w, amp, tr, gap = vertical(gamma, periods=2)
    assert tr["touch"].all() and gap.max() < 0
    # the plate pushes with m (g + z_p''), at least (1 - Gamma) m g
    assert tr["fn"].min() == pytest.approx((1 - gamma) * M_STEEL * G, rel=0.02)


def test_ball_leaves_plate_above_one_g_at_the_analytic_phase():
    gamma = 1.2
    f, w, amp, tr, gap = vertical(gamma, periods=1)
    t, fn = tr["t"], tr["fn"]
    phase_off = math.asin(1 / gamma) / (2 * math.pi)  # 0.1568 of a period
    # the plate stops pushing: first zero of the normal force (interpolated between steps)
    i = int(np.argmax(fn <= 0))
    assert i > 0
    t_off = t[i - 1] + (t[i] - t[i - 1]) * fn[i - 1] / (fn[i - 1] - fn[i])
    assert abs(t_off * f - phase_off) < 0.01
    # and the gap opens right after (once the resting overlap has relaxed)
    j = int(np.argmax(gap > 0))
    assert j > 0 and 0 <= t[j] * f - phase_off < 0.03
    # free flight until the plate catches it up again
    t1 = phase_off / f
    z1, v1 = amp * math.sin(w * t1), amp * w * math.cos(w * t1)

    def height(tt):  # ball's lowest point above the plate in free flight
        return z1 + v1 * (tt - t1) - 0.5 * G * (tt - t1) ** 2 - amp * math.sin(w * tt)

    ts = np.linspace(t1 + 1e-3 / f, t1 + 1.0 / f, 2001)
    k = int(np.argmax(np.array([height(x) for x in ts]) < 0))
    t_land = brentq(height, ts[k - 1], ts[k])
    k2 = j + int(np.argmax(gap[j:] <= 0))
    assert k2 > j
    assert abs(t[k2] - t_land) * f < 0.01



@pytest.mark.slow
def test_a_dense_layer_takes_off_near_the_block_phase_and_the_floor_carries_its_weight():
    """A layer of tub47's balls, 8 diameters deep, on a floor at Gamma = 1.5 (the DEM strip of
    calibration.vibrated_layer): dense and inelastic, it flies and lands nearly as one block,
    which would leave the floor where the floor's deceleration reaches g, sin(psi) = 1 / Gamma
    (psi / 2 pi = 0.116; the measure's level, a twentieth of the weight, at 0.109).  The
    grains' contacts are compliant and the landing compresses the layer, so it leaves later,
    within 0.07 of a cycle after the block (0.151 - 0.157 measured, the force falling as the
    block's from 1.45 at psi = 0).  The phase is read where the force's tail falls through a
    twentieth of the weight; where the tail lingers at that level one seed's crossing comes a
    twentieth of a cycle later (seed 1: 0.231), so the check takes the median of three fill
    seeds.  Over whole cycles the floor's force carries the layer's weight (momentum balance:
    the layer's momentum is bounded), within 3 standard errors of the seeds' pooled mean."""
    from vibroflow.calibration.vibrated_layer import LayerSetup, run_seed
    from vibroflow.measure.layer_profiles import TAKE_OFF_LEVEL
    from vibroflow.scenario.io import load_scenario

    gamma = 1.5
    seeds = (1, 2, 3)
    setup = LayerSetup(layers=8.0, warm_cycles=6, cycles=8, batches=4, gamma=gamma, seeds=seeds)
    runs = [run_seed(load_scenario("tub47", []), setup, s) for s in seeds]
    block = math.asin((1.0 - TAKE_OFF_LEVEL) / gamma) / (2 * math.pi)
    assert block <= float(np.median([r["take_off_phase"] for r in runs])) < block + 0.07
    for r in runs:
        f = np.array(r["floor_force_over_weight"])
        assert f[:8].min() > 0.2 and f.max() < 5.0  # carried from the landing to psi = 0.12
    # the three seeds' cycle means pooled: their mean and its standard error
    mean = float(np.mean([r["floor_force_cycle_mean_over_weight"] for r in runs]))
    se = float(np.sqrt(np.sum([r["floor_force_cycle_mean_stderr"] ** 2 for r in runs]))) / 3
    assert abs(mean - 1.0) < 3 * se
