"""The DEM's force assembly (vibroflow.dem.step): per-pair slots gathered per ball.

- every touching pair enters both of its balls with opposite forces, exactly once: the pair
  forces of all balls sum to zero (Newton's third law) to rounding;
- the numbers do not depend on the thread count: a falling bed, whose contacts and impacts
  start and end at every step, comes out bit for bit the same on one thread and on two;
- each pair gets its own law's constants, whatever kind of partner the entry before had.
"""
from __future__ import annotations

import math

import numba
import numpy as np
import pytest

from dem_helpers import R_STEEL, RHO_STEEL, Sim, ball, contact, scenario, zeta_of
from vibroflow.dem import fill as F
from vibroflow.dem import simulate as S
from vibroflow.scenario.io import load_scenario
from vibroflow.scenario.model import Material


def _falling_bed(steps: int, threads: int):
    """300 balls of tub47-quick dropped from their fill lattice, `steps` steps on `threads`
    threads, impacts recorded; the state and the impacts."""
    sc = load_scenario("tub47-quick", ["fill.count=300"])
    system = S.make_system(sc)
    before = numba.get_num_threads()
    numba.set_num_threads(threads)
    try:
        state = F.fill_state(system, sc)
        impacts = []
        S.run_steps(system, state, steps, record_impacts=True, on_impacts=impacts.append)
    finally:
        numba.set_num_threads(before)
    return system, state, np.concatenate(impacts) if impacts else np.zeros((0, 6))


def test_pair_forces_sum_to_zero():
    """Each ball's force less its weight and its wall forces is its pair forces; over all the
    balls they cancel pair by pair, to rounding of the largest force."""
    system, state, _imp = _falling_bed(6000, 1)
    assert np.count_nonzero(state.nl.flag) > 20  # balls touch one another
    wall = (state.wall_force * state.wall_flag[:, :, None]).sum(axis=1)
    pair = state.force - state.mass[:, None] * system.gravity - wall
    scale = np.abs(pair).max()
    assert scale > 0.0
    assert np.abs(pair.sum(axis=0)).max() < 1e-12 * scale * state.n


def test_same_numbers_on_one_thread_and_on_two_in_process():
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("numba has a single thread here")
    _s1, a, imp_a = _falling_bed(6000, 1)
    _s2, b, imp_b = _falling_bed(6000, 2)
    assert imp_a.shape[0] > 100  # contacts began during the run
    for name in ("pos", "vel", "omg", "force", "torque", "wall_hist", "wall_flag"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert np.array_equal(a.nl.hist, b.nl.hist) and np.array_equal(a.nl.flag, b.nl.flag)
    assert np.array_equal(imp_a, imp_b)


def test_each_partner_of_a_ball_gets_its_own_pair_law():
    """Ball 0 touches four balls of three kinds (steel of its size, glass, steel of half its
    size, steel again), each approaching at its own speed: the pair loop reuses a contact's
    constants only for the same kind of partner, so each partner's force is its own linear
    law, F_n = k_n delta + 2 zeta sqrt(m_eff k_n) u (models.md; tangential 0 at the set-up
    evaluation), along the line of centres."""
    mats = {"steel": Material(density=RHO_STEEL), "glass": Material(density=2500.0)}
    laws = {("steel", "steel"): (1.0e5, 0.85), ("glass", "steel"): (2.0e5, 0.6),
            ("glass", "glass"): (3.0e5, 0.5)}
    r0 = R_STEEL
    # (material, radius, unit vector from ball 0, overlap, approach speed)
    partners = [("steel", r0, (1.0, 0.0, 0.0), 1.0e-5, 0.10),
                ("glass", r0, (-1.0, 0.0, 0.0), 2.0e-5, 0.20),
                ("steel", 0.5 * r0, (0.0, 1.0, 0.0), 1.5e-5, 0.30),
                ("steel", r0, (0.0, -1.0, 0.0), 0.5e-5, 0.05)]
    balls = [ball((0.0, 0.0, 0.0))]
    for mat, r, e, delta, u in partners:
        dist = r0 + r - delta
        balls.append(ball(tuple(dist * x for x in e), vel=tuple(-u * x for x in e), d=2.0 * r,
                          material=mat))
    sim = Sim(scenario(balls, [contact(a, b, k_n=k, e=ee) for (a, b), (k, ee) in laws.items()],
                       materials=mats))
    m0 = 4.0 / 3.0 * math.pi * r0**3 * RHO_STEEL
    for p, (mat, r, e, delta, u) in enumerate(partners, start=1):
        k_n, rest = laws[tuple(sorted((mat, "steel")))]
        mj = 4.0 / 3.0 * math.pi * r**3 * mats[mat].density
        m_eff = m0 * mj / (m0 + mj)
        fn = k_n * delta + 2.0 * zeta_of(rest) * math.sqrt(m_eff * k_n) * u
        np.testing.assert_allclose(sim.state.force[p], fn * np.array(e), rtol=1e-12,
                                   atol=1e-12 * fn)


def test_a_bed_keeps_the_histories_its_laws_need():
    """tub47's laws (CDT rolling) keep the tangential spring alone: a list of three history
    columns (laws.history_width).  The same bed stepped from a six-column list (a state file
    of the wider layout) takes the same steps bit for bit, its spare columns staying zero.
    With the EPSD law the list keeps six, and the rolling torque of the touching contacts is
    held in the last three."""
    sc = load_scenario("tub47-quick", ["fill.count=300"])
    runs = []
    for width in (3, 6):
        system = S.make_system(sc)
        assert system.history_width == 3
        state = F.fill_state(system, sc)
        assert state.nl.hist.shape[1] == 3
        state.nl.widen_history(width)
        with_threads = numba.get_num_threads()
        numba.set_num_threads(1)
        try:
            S.run_steps(system, state, 6000)
        finally:
            numba.set_num_threads(with_threads)
        runs.append(state)
    narrow, wide = runs
    assert np.count_nonzero(narrow.nl.flag) > 20  # balls touch one another
    for name in ("pos", "vel", "omg", "force", "torque"):
        assert np.array_equal(getattr(narrow, name), getattr(wide, name)), name
    assert np.array_equal(narrow.nl.hist, wide.nl.hist[:, :3])
    assert not wide.nl.hist[:, 3:].any()

    sets = [f"contacts.{k}.rolling_model=epsd" for k in range(len(sc.contacts))]
    epsd = load_scenario("tub47-quick", ["fill.count=300", *sets])
    system = S.make_system(epsd)
    assert system.history_width == 6
    state = F.fill_state(system, epsd)
    S.run_steps(system, state, 6000)
    touching = state.nl.flag.astype(bool)
    assert np.count_nonzero(touching) > 20
    torque = np.linalg.norm(state.nl.hist[:, 3:6], axis=1)
    assert np.count_nonzero(torque[touching]) > 0.9 * np.count_nonzero(touching)
    assert not torque[~touching].any()
