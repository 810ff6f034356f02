"""Which blocks of balls each block's list entries reach, so that the tub step's sweep
(vibroflow.dem.step) knows when a block's balls are no other block's business any more.

A list entry (i, j) belongs to its ball of lower id (vibroflow.dem.neighbours) and is made by
the block that stores i: it reads ball j's position, velocity and spin and writes the force on
j into a contact row.  Block b's ball pass (its gather, walls, kick and drift) may therefore
run once every block with an entry into b, and b itself (whose pairs set its balls' forces),
has made its pairs, and none of them may make its pairs after it.  `owner_lo[b]` and
`owner_hi[b]` are the lowest and the highest of those blocks; `reach[a, b]` says whether block
a has an entry into block b.  Stored by id (below MEMORY_ORDER_FROM balls) or in space order,
a block's entries reach its neighbours in space, a few blocks on either side of it.  All are
made once per call of the step: the list is the same throughout a call.
"""
from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(cache=True)
def _reach_row(c, start, nbr, bounds, row):
    """Row c of `reach`: the blocks of the partners of block c's entries."""
    row[:] = 0
    b = np.int64(c)
    for k in range(start[bounds[c]], start[bounds[c + 1]]):
        j = np.int64(nbr[k])
        while j >= bounds[b + 1]:
            b += 1
        while j < bounds[b]:
            b -= 1
        row[b] = 1


@nb.njit(cache=True, parallel=True)
def block_reach(pairs, work):
    """work.reach, work.owner_lo and work.owner_hi of the list's blocks (module docstring)."""
    bounds = pairs.bounds
    nblock = bounds.shape[0] - 1
    reach, owner_lo, owner_hi = work.reach, work.owner_lo, work.owner_hi
    for c in nb.prange(nblock):
        _reach_row(c, pairs.start, pairs.nbr, bounds, reach[c])
    for b in range(nblock):
        lo = b
        hi = b
        for a in range(nblock):
            if reach[a, b]:
                lo = min(lo, a)
                hi = max(hi, a)
        owner_lo[b] = lo
        owner_hi[b] = hi
