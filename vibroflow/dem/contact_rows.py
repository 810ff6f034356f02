"""The touching entries' histories and pair slots packed in contact rows, block by block, for
the steps of one call of the tub step (vibroflow.dem.step.advance, compute_forces).

Why: about one list entry in six touches.  Kept at its entry's place (the list's `hist`) and
at its reverse place (the slots' force and torque on j), a contact's rows are scattered one
in six over arrays that, on a bed larger than the caches (the 140 000-ball tub's list is
about 80 MB), live in main memory: each contact costs the pair pass a few cache lines of its
own, read and written back.  Packed, the contacts of a block of balls sit in consecutive rows
in entry order, and the pair pass reads and writes them as a stream.

The rows: block c of the list's blocks (pairs.bounds) owns the rows of its own entries' range,
[start[bounds[c]], start[bounds[c + 1]]).  `pack` gives the touching entries of the block the
first rows of that range, in entry order (slots.row: the entry's row, -1 without one;
slots.rrow: the row of each reverse place), and copies their histories into slots.chist.
During the call, an entry whose contact begins takes the block's next free row
(work.row_next), or its own row again when it had one in this call (a contact that parted and
touches again): an entry has at most one row a call, so a block never runs out of its range.
The pair pass writes each contact's force and torque on j to slots.out at the contact's row;
the gather reads them through rrow.  `unpack` copies the histories back to the list's entries,
zero for the contacts that parted during the call, so that between calls (files, rebuilds,
queries) the list holds them as always.  The same operations on the same numbers: the same
bits (tests/test_dem_fused_step.py, one call against one step a call; tests/test_contact_rows.py,
a contact that parts and touches again within one call).
"""
from __future__ import annotations

import numba as nb


@nb.njit(cache=True)
def _pack_block(c, pairs, slots, work):
    start, bounds, hist, flag = pairs.start, pairs.bounds, pairs.hist, pairs.flag
    row, rrow, chist, rpos = slots.row, slots.rrow, slots.chist, slots.rpos
    width = hist.shape[1]
    r = start[bounds[c]]
    for k in range(start[bounds[c]], start[bounds[c + 1]]):
        if flag[k]:
            row[k] = r
            rrow[rpos[k]] = r
            for a in range(width):
                chist[r, a] = hist[k, a]
            r += 1
        else:
            row[k] = -1
    work.row_next[c] = r


@nb.njit(cache=True)
def _unpack_block(c, pairs, slots):
    start, bounds, hist, flag = pairs.start, pairs.bounds, pairs.hist, pairs.flag
    row, chist = slots.row, slots.chist
    width = hist.shape[1]
    for k in range(start[bounds[c]], start[bounds[c + 1]]):
        r = row[k]
        if r < 0:
            continue
        if flag[k]:
            for a in range(width):
                hist[k, a] = chist[r, a]
        else:
            for a in range(width):
                hist[k, a] = 0.0


# Each block's loop is a function of its own: inlined in the parallel loop's body, numba takes
# the row counter for a reduction over the blocks.
@nb.njit(cache=True, parallel=True)
def pack(pairs, slots, work):
    """Each block's touching entries into its first rows, in entry order."""
    for c in nb.prange(pairs.bounds.shape[0] - 1):
        _pack_block(c, pairs, slots, work)


@nb.njit(cache=True, parallel=True)
def unpack(pairs, slots):
    """The contacts' histories back at their entries; zero where a contact parted."""
    for c in nb.prange(pairs.bounds.shape[0] - 1):
        _unpack_block(c, pairs, slots)
