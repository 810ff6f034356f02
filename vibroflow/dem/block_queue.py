"""The blocks of balls of the DEM step's parallel loops shared out as the threads come free,
each thread on its own blocks first.

numba's OpenMP layer gives thread t of T the contiguous blocks t NBLOCK/T to (t + 1) NBLOCK/T
- 1 of a `prange` over the blocks (its scheduler cuts the range into T equal parts, `omp for`
hands them out statically), so a loop lasts as long as its slowest thread's share.  The blocks
are cut to equal list work (vibroflow.dem.neighbours.NeighbourList.chunk_bounds), but the work
of a block moves with the bed: its touching contacts (the law) gather where the bed lands and
thin where it flies, and its balls along the U wall carry the wall pass.  Measured block by
block on tub47 over a cycle (benchmarks/dem_block_balance.py), the static share bounds the pair
loop's parallel efficiency at 0.92 on 2 threads and 0.81 on 16, the ball pass's at 0.93 and
0.79; the lanes below bound them at 0.99 and 0.88, 0.99 and 0.87.

Handed out from one shared counter, a block goes to another thread at each step, and its
balls' arrays with it from one core's cache to another's: on tub47-quick, whose arrays the
two cores' caches hold, that made the step 1.5 - 2 times slower on two threads.  So each
thread has a lane, the blocks of its static share, and takes them first, in order, from its
lane's counter; a thread whose lane is empty takes from the next lanes in turn (work stealing
over the lanes, OpenMP's `schedule(static)` with stealing).  A lane's counter is one atomic
fetch-and-add a block, on a cache line of its own.  A loop over the blocks:

    lanes = open_lanes(work.queue, nblock)
    for lane in nb.prange(lanes):          # one lane a thread: OpenMP's static share of T
        c, s = take(work.queue, lane, lanes, 0)
        while c >= 0:
            ...block c...
            c, s = take(work.queue, lane, lanes, s)

The lane count is the thread count, set from Python before each call (`set_lanes`: numba's
`get_num_threads()` inside a compiled function reads a pointer of the threading layer, which
numba cannot cache).  Any lane count gives every block once (tests/test_block_queue.py), and a
block's work is the same whichever thread takes it (each block writes only its own rows of the
step's scratch, vibroflow.dem.step), so the numbers do not depend on the schedule.
"""
from __future__ import annotations

import numba as nb
import numpy as np
from numba.core import cgutils, types
from numba.extending import intrinsic


#: int64 slots from one lane's counter to the next: a 64-byte cache line each
PAD = 8


def queue_array(nblock: int) -> np.ndarray:
    """The queue of `nblock` blocks: each lane's counter and end, then the lane count."""
    return np.zeros((nblock + 1) * PAD, np.int64)


def set_lanes(queue: np.ndarray, threads: int) -> None:
    """The lane count of the loops that use `queue`: the threads they run on."""
    queue[queue.shape[0] - PAD] = max(int(threads), 1)


@intrinsic
def _fetch_add(typingctx, counter, index, value):
    """The value of counter[index] before an atomic counter[index] += value (int64;
    monotonic ordering: the counter orders nothing else, each block's data is its own)."""
    if not (isinstance(counter, types.Array) and counter.dtype == types.int64
            and counter.ndim == 1):
        return None
    sig = types.int64(counter, types.intp, types.int64)

    def codegen(context, builder, signature, args):
        arr, idx, val = args
        aryty = signature.args[0]
        ary = context.make_array(aryty)(context, builder, value=arr)
        ptr = cgutils.get_item_pointer(context, builder, aryty, ary, [idx])
        return builder.atomic_rmw("add", ptr, val, "monotonic")

    return sig, codegen


@nb.njit(cache=True, inline="always")
def open_lanes(queue, nblock):
    """Share blocks 0 to nblock - 1 into the queue's lanes (its lane count, at most nblock),
    contiguous and in order as OpenMP's static share; returns the lane count.  Called before
    the parallel loop."""
    lanes = min(max(queue[queue.shape[0] - PAD], 1), nblock)
    for t in range(lanes):
        queue[t * PAD] = (t * nblock) // lanes
        queue[t * PAD + 1] = ((t + 1) * nblock) // lanes
    return lanes


@nb.njit(cache=True, inline="always")
def take(queue, lane, lanes, s):
    """(the next block for `lane`'s thread, the lane offset to go on from): from lane
    (lane + s) mod lanes on, its own first; -1 when every lane is empty."""
    while s < lanes:
        r = lane + s
        if r >= lanes:
            r -= lanes
        c = _fetch_add(queue, r * PAD, 1)
        if c < queue[r * PAD + 1]:
            return c, s
        s += 1
    return -1, s
