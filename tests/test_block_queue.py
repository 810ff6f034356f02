"""vibroflow.dem.block_queue: every block handed out once, whatever the lanes and the threads;
each thread's own lane first, in order."""
import numba
import numpy as np
import pytest

from vibroflow.dem.block_queue import open_lanes, queue_array, set_lanes, take


@numba.njit(parallel=True)
def _take_all(nblock, queue, cost, taken, lane_of, order):
    """A loop over the blocks as the step makes it (step._pair_pass); block c costs cost[c]
    units of arithmetic, so that the threads come free at different times and steal."""
    lanes = open_lanes(queue, nblock)
    for lane in numba.prange(lanes):
        k = 0
        c, s = take(queue, lane, lanes, 0)
        while c >= 0:
            x = 0.0
            for m in range(cost[c]):
                x += np.sqrt(m + 1.0)
            taken[c] += 1
            lane_of[c] = lane if x >= 0.0 else -1
            order[c] = k
            k += 1
            c, s = take(queue, lane, lanes, s)
    return lanes


@pytest.mark.parametrize("threads", [1, 2])
@pytest.mark.parametrize("lanes", [1, 2, 3, 16, 64, 100])
def test_every_block_is_taken_exactly_once(threads, lanes):
    """Any lane count, even one that is not the thread count or exceeds the blocks, on one
    thread and on two: each block once; uneven block costs make the threads steal."""
    before = numba.get_num_threads()
    numba.set_num_threads(threads)
    try:
        nblock = 64
        rng = np.random.default_rng(lanes)
        queue = queue_array(nblock)
        set_lanes(queue, lanes)
        for _ in range(10):
            cost = rng.integers(0, 20_000, nblock)
            taken = np.zeros(nblock, np.int64)
            lane_of = np.full(nblock, -2, np.int64)
            order = np.zeros(nblock, np.int64)
            used = _take_all(nblock, queue, cost, taken, lane_of, order)
            assert used == min(lanes, nblock)
            assert (taken == 1).all()
            assert (lane_of >= 0).all() and (lane_of < used).all()
    finally:
        numba.set_num_threads(before)


def test_one_lane_takes_the_blocks_in_order():
    """One lane: blocks 0 to nblock - 1 in order, as a plain loop."""
    queue = queue_array(64)
    set_lanes(queue, 1)
    taken = np.zeros(64, np.int64)
    lane_of = np.full(64, -2, np.int64)
    order = np.zeros(64, np.int64)
    _take_all(64, queue, np.full(64, 10, np.int64), taken, lane_of, order)
    assert (taken == 1).all() and (lane_of == 0).all()
    assert (order == np.arange(64)).all()


def test_a_thread_takes_its_own_lane_first_in_order():
    """Two lanes on one thread: lane 0 takes its blocks 0 - 31 in order, then steals 32 - 63,
    which lane 1 then finds taken: the static share first, stealing after."""
    before = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        queue = queue_array(64)
        set_lanes(queue, 2)
        taken = np.zeros(64, np.int64)
        lane_of = np.full(64, -2, np.int64)
        order = np.zeros(64, np.int64)
        _take_all(64, queue, np.full(64, 10, np.int64), taken, lane_of, order)
        assert (taken == 1).all()
        assert (lane_of == 0).all() and (order == np.arange(64)).all()
    finally:
        numba.set_num_threads(before)
