"""vibroflow.dem.block_queue: every block handed out once, whatever the threads, and the
step's numbers the same whoever takes a block."""
import numba
import numpy as np
import pytest

from vibroflow.dem.block_queue import next_block


@numba.njit(parallel=True)
def _take_all(nblock, cost, taken, turns):
    """A loop over the blocks as the step makes it (step._pair_pass): each turn drains the
    queue; block c costs cost[c] units of arithmetic, so that the threads interleave."""
    queue = np.zeros(1, np.int64)
    for w in numba.prange(nblock):
        c = next_block(queue)
        while c < nblock:
            x = 0.0
            for k in range(cost[c]):
                x += np.sqrt(k + 1.0)
            taken[c] += 1
            turns[c] = w if x > 0.0 else -1
            c = next_block(queue)


@pytest.mark.parametrize("threads", [1, 2])
def test_every_block_is_taken_exactly_once(threads):
    before = numba.get_num_threads()
    numba.set_num_threads(threads)
    try:
        nblock = 64
        rng = np.random.default_rng(threads)
        for _ in range(20):
            cost = rng.integers(0, 20_000, nblock)
            taken = np.zeros(nblock, np.int64)
            turns = np.full(nblock, -2, np.int64)
            _take_all(nblock, cost, taken, turns)
            assert (taken == 1).all()
            assert (turns >= 0).all() and (turns < nblock).all()
    finally:
        numba.set_num_threads(before)


def test_one_thread_takes_the_blocks_in_order():
    """On one thread the first turn takes every block, 0 to nblock - 1, as a plain loop."""
    before = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        taken = np.zeros(64, np.int64)
        turns = np.full(64, -2, np.int64)
        _take_all(64, np.full(64, 10, np.int64), taken, turns)
        assert (taken == 1).all() and (turns == 0).all()
    finally:
        numba.set_num_threads(before)
