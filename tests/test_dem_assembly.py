"""The DEM's force assembly (vibroflow.dem.step): per-pair slots gathered per ball.

- every touching pair enters both of its balls with opposite forces, exactly once: the pair
  forces of all balls sum to zero (Newton's third law) to rounding;
- the numbers do not depend on the thread count: a falling bed, whose contacts and impacts
  start and end at every step, comes out bit for bit the same on one thread and on two.
"""
from __future__ import annotations

import numba
import numpy as np
import pytest

from vibroflow.dem import fill as F
from vibroflow.dem import simulate as S
from vibroflow.scenario.io import load_scenario


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
