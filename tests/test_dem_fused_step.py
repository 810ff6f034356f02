"""The tub step's two parallel loops a step (vibroflow.dem.step.advance) against the plain
velocity-Verlet step:

- one `advance` call of many steps (each later step's first half kick and drift made in the
  ball pass of the step before, undone where the call stops at a rebuild) ends on the state of
  the same steps made one call a step (no step made in the pass before: the plain order of
  kick, drift, forces, kick), bit for bit, with the same impact rows and contact histories
  (each call packs the touching entries into contact rows and gives their histories back to
  the list when it ends: vibroflow.dem.contact_rows; a contact that parts and touches again
  within the long call keeps its row);
- the wall pass's cull (`wall_pass.clear_of_walls`) passes over no ball that the U wall or a
  partition touches or that has left the tub: on points on both sides of the surfaces, at
  distances of a few ulp to millimetres, the cleared ones have no overlap by u_wall's and the
  partitions' own tests;
- no block of balls records more impact rows in one step than the bound of
  vibroflow.dem.impact_order (its list entries plus its balls x wall slots; its balls x parts),
  on a bed thrown into itself; the bound of a hand-made list is its hand value;
- buffers of one row a block grow to the flush threshold plus that bound and give the rows of
  the large buffers, flush by flush, in the same order: no row is lost, and a run whose
  default buffers hold one row gives the dem.h5 impacts of the default run.  (A one-row
  buffer does not make ImpactsLost fire: the buffers are sized from the bound, so
  that guard cannot fire.)
"""
from __future__ import annotations

import numba
import numpy as np
import pytest

from vibroflow.dem import fill as F
from vibroflow.dem import simulate as S
from vibroflow.dem import step as K
from vibroflow.dem import parts as P
from vibroflow.dem.impact_order import impact_bound
from vibroflow.dem.run import run_dem
from vibroflow.dem.wall_pass import clear_of_walls
from vibroflow.dem.walls import TUB_LENGTH, TUB_RADIUS, TUB_RIM, WALL_PLANE0, u_wall
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


def test_the_bound_of_a_hand_made_list():
    # 6 balls owning 3, 0, 4, 1, 0, 2 entries in blocks {0, 1}, {2, 3, 4}, {5}; 4 wall slots,
    # 2 parts: B = entries + balls x 4, Q = balls x 2
    start = np.array([0, 3, 3, 7, 8, 8, 10])
    bounds = np.array([0, 2, 5, 6])
    rows, part_rows = impact_bound(start, bounds, 4, 2)
    assert rows.tolist() == [3 + 2 * 4, 5 + 3 * 4, 2 + 1 * 4]
    assert part_rows.tolist() == [4, 6, 2]


def test_no_block_records_more_rows_a_step_than_its_bound(one_thread, monkeypatch):
    # one step a call, each block's new rows against the bound of the step's list
    advance = K.advance
    seen = []

    def one_step(step0, nsteps, origin, motion, record, balls, pairs, slots, walls, params,
                 work, prt):
        before = work.imp_count.copy(), prt.imp_count.copy()
        out = advance(step0, 1, origin, motion, record, balls, pairs, slots, walls, params,
                      work, prt)
        bound = impact_bound(pairs.start, pairs.bounds, WALL_PLANE0 + params.planes.shape[0],
                             prt.shape.shape[0])
        for new, old, most in zip((work.imp_count, prt.imp_count), before, bound):
            assert np.all(new - old <= most), (new - old, most)
        seen.append(np.max(work.imp_count - before[0]))
        return out

    monkeypatch.setattr(K, "advance", one_step)
    # the fill lattice (gaps of 0.1 mm) squeezed towards its centre, then every contact
    # forgotten: all of them start again at the next step
    system, state = _bed(count=600)
    state.vel[:] = -200.0 * (state.pos - state.pos.mean(axis=0))
    S.run_steps(system, state, 60, record_impacts=True, on_impacts=lambda rows: None)
    touching = int(state.nl.flag.sum() + state.wall_flag.sum())
    for flags in (state.nl.flag, state.nl.rflag, state.wall_flag):
        flags[:] = 0
    S.run_steps(system, state, 1, record_impacts=True, on_impacts=lambda rows: None)
    assert len(seen) == 61 and touching > 600 and max(seen) >= 20


def _flushes(capacity: int, monkeypatch) -> tuple[list, int]:
    """The thrown bed's impact flushes over 3 000 steps with flushes past 4 rows of a block,
    buffers of `capacity` rows a block at first; and the buffers' rows at the end."""
    monkeypatch.setattr(S, "IMPACT_FLUSH", 4)
    monkeypatch.setattr(S, "IMPACT_CAPACITY", capacity)
    system, state = _bed(speed=1.0)
    out = []
    for _ in range(3):
        S.run_steps(system, state, 1000, record_impacts=True, on_impacts=out.append)
    b = state.scratch
    bound = impact_bound(state.nl.start, state.nl.chunk_bounds(K.NBLOCK), system.n_walls, 0)[0]
    assert b.work.imp_buf.shape[1] >= 4 + bound.max()
    return out, b.work.imp_buf.shape[1]


def test_buffers_of_one_row_grow_and_give_the_rows_of_large_ones(one_thread, monkeypatch):
    large, rows = _flushes(1 << 11, monkeypatch)
    small, grown = _flushes(1, monkeypatch)
    assert rows == 1 << 11 and 4 < grown < 100  # grown to the bound, not to the default
    assert len(large) > 10  # flushes within the calls
    assert len(small) == len(large)
    for a, b in zip(large, small):
        assert np.array_equal(a, b)


@pytest.mark.slow
def test_a_run_with_one_row_buffers_gives_the_impacts_of_the_default_run(tmp_path,
                                                                         monkeypatch):
    # a 400-ball tub recording its impacts from 10 ms into the vibration
    import h5py
    from tests.test_calibrate import SMALL

    monkeypatch.setenv("VIBROFLOW_CACHE", str(tmp_path / "cache"))
    sc = load_scenario("tub47-quick", SMALL + ["run.duration=0.1", "run.average_last=0.09"])
    run_dem(sc, tmp_path / "default", progress=False)
    monkeypatch.setattr(S, "IMPACT_CAPACITY", 1)
    monkeypatch.setattr(P, "IMPACT_CAPACITY", 1)
    run_dem(sc, tmp_path / "one", progress=False)
    assert (tmp_path / "one" / "summary.json").exists()
    with h5py.File(tmp_path / "default" / "dem.h5") as a, h5py.File(tmp_path / "one" /
                                                                   "dem.h5") as b:
        names = [n for n in ("impacts", "part_impacts") if n in a]
        assert "impacts" in names
        for name in names:
            for key in a[name]:
                assert np.array_equal(a[name][key][()], b[name][key][()]), (name, key)
        assert a["impacts"][next(iter(a["impacts"]))].shape[0] > 100
