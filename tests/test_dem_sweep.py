"""The tub step's sweep (vibroflow.dem.step: a block's ball pass right after the pairs that it
waits for, in the same parallel loop; vibroflow.dem.block_reach) against the plain step:

- `block_reach` gives, for each block of balls, the lowest and the highest block with a list
  entry into it, as counted from the list entry by entry;
- the sweep ends on the state of the plain velocity-Verlet step (kick and drift, then the
  pairs of every block in one parallel loop, then every block's ball pass in another), bit for
  bit, whatever the lanes the blocks are shared into: one lane (every ball pass follows its
  pairs in one run of blocks), and two, three and seven lanes, where a lane's first blocks wait
  for the lane before (`_pending_pass`) and some blocks of a run wait for the run's later
  blocks.
"""
from __future__ import annotations

import numba
import numpy as np
import pytest

from vibroflow.dem import fill as F
from vibroflow.dem import simulate as S
from vibroflow.dem import step as K
from vibroflow.dem.block_queue import set_lanes
from vibroflow.dem.block_reach import block_reach
from vibroflow.dem.contact_rows import pack, unpack
from vibroflow.dem.records import pairs_of
from vibroflow.dem.walls import TUB_LENGTH, TUB_PERIODIC, TUB_PRESENT
from vibroflow.scenario.io import load_scenario

ARRAYS = ("pos", "vel", "omg", "force", "torque", "ref_tub", "wall_hist", "wall_flag",
          "wall_fn", "wall_ft", "wall_point", "wall_force", "wall_arc")


@numba.njit
def plain_step(step0, nsteps, time_origin_step, motion, record_impacts, balls, pairs, slots,
               walls, params, work, prt):
    """step.advance's steps as the plain velocity-Verlet step: each step's first half kick and
    drift, the pairs of every block, then every block's gather, walls and second half kick,
    each a parallel loop of its own."""
    dt, hs2 = params.dt, params.half_skin * params.half_skin
    diag, pose, moved = work.diag, work.pose, work.moved
    tub = params.tub
    periodic_length = tub[TUB_LENGTH] if (tub[TUB_PRESENT] > 0.0 and
                                          tub[TUB_PERIODIC] > 0.0) else 0.0
    pack(pairs, slots, work)
    for k in range(nsteps):
        K._kick_drift(balls, params)
        t = (step0 + k + 1 - time_origin_step) * dt
        K._pose_array(motion, pose[6], pose[7], t, pose)
        K._pair_pass(t, dt, periodic_length, record_impacts, balls, pairs, slots, params, work)
        K._ball_pass(t, dt, True, False, record_impacts, balls, pairs, slots, walls, params,
                     work, prt)
        for c in range(diag.shape[0]):
            if diag[c, K.D_NAN] >= 0.0 or diag[c, K.D_LOST] >= 0.0:
                unpack(pairs, slots)
                return k + 1, K.BLOWUP
            if moved[c] > hs2:
                unpack(pairs, slots)
                return k + 1, K.REBUILD
    unpack(pairs, slots)
    return nsteps, K.DONE


def _bed(count: int = 600, speed: float = 1.0):
    """tub47-quick's balls on their fill lattice in the vibrating tub, each thrown at up to
    `speed` (m/s), so that the bed mixes; the steps store it in space order (memory_order),
    as a large bed's run does, so that a block's entries reach blocks below and above it."""
    sc = load_scenario("tub47-quick", [f"fill.count={count}"])
    system = S.make_system(sc)
    state = F.fill_state(system, sc)
    state.vibrating = True
    state.vel[:] = np.random.default_rng(5).uniform(-speed, speed, state.vel.shape)
    return system, state


def test_block_reach_counts_the_entries_into_each_block():
    system, state = _bed()
    S.run_steps(system, state, 600, memory_order=True, keep_order=True)
    assert state.nl.ids is not None  # stored in space order: owners below and above a block
    work = S._Buffers(system, state).work
    pairs = pairs_of(state.nl, K.NBLOCK)
    block_reach(pairs, work)
    bounds = pairs.bounds
    block = np.searchsorted(bounds, np.arange(state.n), side="right") - 1
    owner = np.repeat(np.arange(state.n), np.diff(pairs.start))
    a, b = block[owner], block[pairs.nbr]
    lo, hi = np.arange(K.NBLOCK), np.arange(K.NBLOCK)
    np.minimum.at(lo, b, a)
    np.maximum.at(hi, b, a)
    assert np.array_equal(work.owner_lo, lo)
    assert np.array_equal(work.owner_hi, hi)
    reach = np.zeros((K.NBLOCK, K.NBLOCK), np.uint8)
    reach[a, b] = 1
    assert np.array_equal(work.reach, reach)
    # the mixed bed's blocks wait for blocks both below and above them
    assert (lo < np.arange(K.NBLOCK)).sum() > 10 and (hi > np.arange(K.NBLOCK)).sum() > 10


@pytest.fixture
def two_threads():
    before = numba.get_num_threads()
    numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
    yield
    numba.set_num_threads(before)


def _run(lanes, steps: int, monkeypatch, advance=None):
    """The thrown bed after `steps` steps, its blocks shared into `lanes` lanes (or the
    threads' count) and stepped by `advance` (default: step.advance, the sweep)."""
    system, state = _bed()
    with monkeypatch.context() as m:
        if lanes is not None:
            m.setattr(S, "set_lanes", lambda queue, threads: set_lanes(queue, lanes))
        if advance is not None:
            m.setattr(K, "advance", advance)
        S.run_steps(system, state, steps, memory_order=True)
    return state


def test_the_sweep_gives_the_plain_steps_numbers_on_any_lanes(two_threads, monkeypatch):
    steps = 600
    plain = _run(None, steps, monkeypatch, advance=plain_step)
    assert plain.nl.builds > 5  # the calls stopped at rebuilds: the drift undone
    for lanes in (1, 2, 3, 7):
        swept = _run(lanes, steps, monkeypatch)
        for name in ARRAYS:
            assert np.array_equal(getattr(swept, name), getattr(plain, name)), (lanes, name)
        assert np.array_equal(swept.nl.hist, plain.nl.hist), lanes
