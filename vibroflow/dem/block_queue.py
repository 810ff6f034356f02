"""Blocks of balls handed out to the threads as they come free: the DEM step's parallel loops
balanced whatever the bed does.

numba's OpenMP layer gives thread t of T the contiguous blocks t NBLOCK/T to (t + 1) NBLOCK/T
- 1 of a `prange` (its scheduler cuts the range into T equal parts, `omp for` hands them out
statically), so a loop lasts as long as its slowest thread's share.  The blocks are cut to
equal list work (vibroflow.dem.neighbours.NeighbourList.chunk_bounds), but the work of a block
moves with the bed: its touching contacts (the law) rise tenfold where the bed lands and fall
where it flies, and its balls along the U wall carry the wall pass.  Measured block by block
on tub47 over a cycle (benchmarks/dem_block_balance.py), that static share bounds the pair
loop's parallel efficiency at 0.92 on 2 threads and 0.81 on 16, the ball pass's at 0.93 and
0.79; blocks taken from a shared counter (`next_block`: one atomic fetch-and-add a block, the
OpenMP `schedule(dynamic, 1)` of a loop over blocks) bound them at 1.00 and 0.96, 0.99 and
0.86.

A loop over the blocks takes them so (vibroflow.dem.step._pair_pass, _ball_pass):

    queue = np.zeros(1, np.int64)
    for _w in nb.prange(nblock):      # each thread's first turn drains the queue
        c = next_block(queue)
        while c < nblock:
            ...block c...
            c = next_block(queue)

A `prange` over the thread count would be the plain form, but `nb.get_num_threads()` in a
compiled function reads a pointer of the threading layer, which numba cannot cache; over the
blocks, a thread's later turns find the queue empty and end at once (one atomic each).

A block's work is the same whichever thread takes it (each block writes only its own rows of
the step's scratch, vibroflow.dem.step), so the numbers do not depend on the schedule
(tests/test_block_queue.py, tests/test_dem_assembly.py).
"""
from __future__ import annotations

import numba as nb
from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic


@intrinsic
def _fetch_add(typingctx, counter, value):
    """The value of counter[0] before an atomic counter[0] += value (int64; monotonic
    ordering: the counter orders nothing else, each block's data is its own)."""
    if not (isinstance(counter, types.Array) and counter.dtype == types.int64
            and counter.ndim == 1):
        return None
    sig = types.int64(counter, types.int64)

    def codegen(context, builder, signature, args):
        arr, val = args
        aryty = signature.args[0]
        ary = context.make_array(aryty)(context, builder, value=arr)
        ptr = cgutils.get_item_pointer(context, builder, aryty, ary,
                                       [ir.Constant(ir.IntType(64), 0)])
        return builder.atomic_rmw("add", ptr, val, "monotonic")

    return sig, codegen


@nb.njit(cache=True, inline="always")
def next_block(counter):
    """The next block to do (0, 1, 2, ... across every thread; a thread stops when it gets
    the block count or more): counter, (1,) int64, set to 0 before the parallel loop."""
    return _fetch_add(counter, 1)
