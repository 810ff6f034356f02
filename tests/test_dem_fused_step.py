"""The tub step's two parallel loops a step (vibroflow.dem.step.advance) against the plain
velocity-Verlet step:

- one `advance` call of many steps (each later step's first half kick and drift made in the
  ball pass of the step before, undone where the call stops at a rebuild) ends on the state of
  the same steps made one call a step (no step made in the pass before: the plain order of
  kick, drift, forces, kick), bit for bit, with the same impact rows;
- the wall pass's cull (`wall_pass.clear_of_walls`) passes over no ball that the U wall or a
  partition touches or that has left the tub: on points on both sides of the surfaces, at
  distances of a few ulp to millimetres, the cleared ones have no overlap by u_wall's and the
  partitions' own tests;
- a block of balls that records more impact rows than its buffer holds stops the run with
  ImpactsLost, which names the block, instead of losing rows; run_dem leaves no result.
"""
from __future__ import annotations

import numba
import numpy as np
import pytest

from vibroflow.dem import fill as F
from vibroflow.dem import simulate as S
from vibroflow.dem import step as K
from vibroflow.dem.impact_order import ImpactsLost
from vibroflow.dem.run import run_dem
from vibroflow.dem.wall_pass import clear_of_walls
from vibroflow.dem.walls import TUB_LENGTH, TUB_RADIUS, TUB_RIM, u_wall
from vibroflow.scenario.io import load_scenario

ARRAYS = ("pos", "vel", "omg", "force", "torque", "ref_tub", "wall_hist", "wall_flag",
          "wall_fn", "wall_ft", "wall_point", "wall_force", "wall_arc")


def _bed(count: int = 300, speed: float = 0.0):
    """A bed of tub47-quick's balls on its fill lattice in the vibrating tub, each ball thrown
    at up to `speed` (m/s) in a direction of a fixed random draw."""
    sc = load_scenario("tub47-quick", [f"fill.count={count}"])
    system = S.make_system(sc)
    state = F.fill_state(system, sc)
    state.vibrating = True
    state.vel[:] = np.random.default_rng(3).uniform(-speed, speed, state.vel.shape)
    return system, state


@pytest.fixture
def one_thread():
    before = numba.get_num_threads()
    numba.set_num_threads(1)
    yield
    numba.set_num_threads(before)


def _rows(flushes: list) -> np.ndarray:
    rows = np.concatenate(flushes)
    return rows[np.lexsort(rows.T[::-1])]


def test_one_call_of_many_steps_ends_on_the_state_of_one_step_a_call(one_thread):
    steps = 300
    system, whole = _bed(speed=1.0)
    _s, single = _bed(speed=1.0)
    builds = whole.nl.builds
    a, b = [], []
    S.run_steps(system, whole, steps, record_impacts=True, on_impacts=a.append)
    for _ in range(steps):
        S.run_steps(system, single, 1, record_impacts=True, on_impacts=b.append)
    assert whole.nl.builds - builds > 3  # the long call stopped at rebuilds, drift undone
    for name in ARRAYS:
        assert np.array_equal(getattr(whole, name), getattr(single, name)), name
    assert np.array_equal(whole.nl.hist, single.nl.hist)
    assert whole.step == single.step == steps
    assert len(a) >= 1 and np.array_equal(_rows(a), _rows(b))


def test_the_wall_cull_clears_no_ball_that_touches_a_wall():
    R, rim, length, r = 0.2032, 0.305, 0.01905, 0.003175
    tub = np.array([R, rim, length, 0.0, 1.0])
    rng = np.random.default_rng(7)
    cleared = 0
    for th in (0.0, 0.05):
        pose = np.array([0.001, -0.002, th, 0.3, -0.2, 1.5, 0.0, 0.25])
        cth, sth = np.cos(th), np.sin(th)
        # tub-frame points: on rays from the U's axis, at R - r plus or minus a few ulp to a
        # few mm, on the flanks up to above the rim, and near each partition
        phi = rng.uniform(-0.5 * np.pi, 0.5 * np.pi, 400)
        gap = np.concatenate([np.array([-3e-3, -1e-6, -1e-12, -1e-16, 0.0, 1e-16, 1e-12,
                                        1e-6, 3e-3]), rng.normal(0.0, 1e-4, 391)])
        rho = (R - r) + gap
        tx = np.concatenate([rho * np.sin(phi), rng.choice([-1, 1], 200) * (R - r + gap[:200])])
        tz = np.concatenate([R - rho * np.cos(phi), rng.uniform(R, rim + 0.01, 200)])
        ty = rng.choice([r, length - r], tx.size) + rng.choice(gap, tx.size)
        ty[::3] = rng.uniform(r, length - r, ty[::3].size)
        for x, y, z in zip(tx, ty, tz):
            # tub frame -> lab (tub/motion.py tub_to_lab)
            px = pose[0] + pose[6] + cth * (x - pose[6]) - sth * (z - pose[7])
            pz = pose[1] + pose[7] + sth * (x - pose[6]) + cth * (z - pose[7])
            if not clear_of_walls(px, y, pz, r, tub, pose, cth, sth, True):
                continue
            cleared += 1
            delta, *_rest, outside = u_wall(px, pz, r, tub, pose, cth, sth)
            assert delta <= 0.0 and not outside, (x, y, z)
            assert r - y <= 0.0 and r - (tub[TUB_LENGTH] - y) <= 0.0, (x, y, z)
            assert 0.0 <= y <= length
    assert cleared > 100
    # a ball on the U's axis, mid-length, is clear; one a hair past R - r is not
    pose = np.zeros(8)
    assert clear_of_walls(0.0, 0.5 * length, tub[TUB_RADIUS], r, tub, pose, 1.0, 0.0, True)
    assert not clear_of_walls(0.0, 0.5 * length, -1e-15 + r, r, tub, pose, 1.0, 0.0, True)
    assert not clear_of_walls(0.0, 0.5 * length, tub[TUB_RIM] + 1e-9, r, tub, pose, 1.0, 0.0, True)
    assert not clear_of_walls(0.0, np.nan, tub[TUB_RADIUS], r, tub, pose, 1.0, 0.0, True)


def test_a_block_past_its_impact_buffer_stops_the_run(one_thread, monkeypatch):
    # one row a block: the thrown bed's first block to start two contacts at one step
    monkeypatch.setattr(S, "IMPACT_CAPACITY", 1)
    system, state = _bed(speed=1.0)
    with pytest.raises(ImpactsLost, match=r"impact rows lost at step \d+: block \d+ of stored "
                                          r"balls recorded [2-9]\d* ball-ball and wall rows, "
                                          r"its buffer holds 1"):
        S.run_steps(system, state, 3000, record_impacts=True, on_impacts=lambda rows: None)



@pytest.mark.slow
def test_a_run_short_of_impact_rows_stops_and_leaves_no_result(tmp_path, monkeypatch):
    # a 400-ball tub recording its impacts from 10 ms into the vibration, one row a block
    from tests.test_calibrate import SMALL

    monkeypatch.setenv("VIBROFLOW_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(S, "IMPACT_CAPACITY", 1)
    sc = load_scenario("tub47-quick", SMALL + ["run.duration=0.1", "run.average_last=0.09"])
    out = tmp_path / "out"
    with pytest.raises(ImpactsLost, match=r"^impact rows lost at step \d+: block \d+ "):
        run_dem(sc, out, progress=False)
    assert not (out / "summary.json").exists()
