"""The balls stored in space order during a run, so that a step walks memory in sequence.

A bed that has mixed holds neighbours far apart in memory: every pair's read of its second
ball, and each ball's gather of its reverse slots, misses the cache.  At neighbour-list
rebuilds (every SORT_EVERY-th) `run_steps` (vibroflow.dem.simulate) stores the balls anew in
slab order (`space_order`), each cell's balls by id; it keeps the id
of each stored ball in the list (`NeighbourList.ids`) and stores them back by id before it
returns, so that everything outside a `run_steps` call (dem.h5, checkpoints, sampling,
ParaView files, blow-up messages) sees the balls by id, as always.

Nothing a run writes depends on the storage order.  A pair belongs to its ball of lower id,
each ball's entries and reverse slots come in id order (vibroflow.dem.neighbours), so a stored
run gives the same positions, velocities, forces and contact histories bit for bit; the
impact rows come in the order and the flushes of the balls stored by id
(vibroflow.dem.impact_order); the part loads are summed by block of the balls by id, each
block's balls by id (vibroflow.dem.parts.sum_loads).  So dem.h5 and parts.nc are the same
bytes of data with the sort and without it, on any thread count.

Slab order: the neighbour cells slab by slab along the bed's longest axis, each slab's cells
row by row, so that a ball's partners lie within the three slabs about it in memory (on the
140 000-ball tub about 5 000 balls, 160 kB of positions and radii, which the core's L2 holds
through the pair pass); a Morton (Z-order) curve of the cells sends the partners across its
large blocks a fraction of the time, and its step on that tub is 1.03 - 1.05 times as long
(docs/decisions/threads.md, "Slab order").

MEMORY_ORDER_FROM and SORT_EVERY are chosen by benchmarks/dem_memory_order.py on the 2-core
development machine (docs/decisions/threads.md).
"""
from __future__ import annotations

import numba as nb
import numpy as np

from . import step as K
from .neighbours import bounding_box

#: ball count from which run_steps stores the balls in space order, a matter of speed alone
#: (the output is the same either way): the sort every 8th rebuild took 1.04 x the unsorted CPU
#: time on tub47-quick (4 200 balls) as filled and 1.08 x mixed, 1.12 - 1.27 x on tub47
#: (14 000) as filled and 0.77 - 0.83 x mixed, on the 140 000-ball tub 0.85 and 1.35 x as
#: filled and 0.70 - 0.80 x mixed (docs/decisions/threads.md); a run's bed starts in its fill's
#: order (stored layer by layer) and mixes
MEMORY_ORDER_FROM = 20_000
#: neighbour-list rebuilds between two space sorts: on the 140 000-ball tub every 8th rebuild
#: took 0.85 x the unsorted CPU time as filled and 0.80 x on a mixed bed, every rebuild 1.21 x
#: and 0.84 x (the bed moves a fraction of a cell between rebuilds; docs/decisions/threads.md)
SORT_EVERY = 8
#: the state's arrays with one row a ball (vibroflow.dem.simulate.DEMState)
PER_BALL = ("pos", "vel", "omg", "force", "torque", "radius", "mass", "mat", "ref_tub",
            "wall_hist", "wall_flag", "wall_fn", "wall_ft", "wall_slide", "wall_point",
            "wall_force", "wall_arc", "part_hist", "part_key")
#: the diagnostics' columns that hold a stored ball's place (vibroflow.dem.step)
BALL_COLUMNS = (K.D_BALL_I, K.D_BALL_J, K.D_WALL_I, K.D_NAN, K.D_LOST)
#: bits of a cell coordinate in the sort key (three in 63 bits)
_BITS = 21


def space_order(pos: np.ndarray, radius: np.ndarray, skin: float,
                ids: np.ndarray) -> np.ndarray:
    """The stored places in slab order (module docstring) of the neighbour cells (2 r_max +
    skin, m): by cell along the bed's longest axis (the most cells; the first of z, x, y on a
    tie), then along the first of the other two in the order z, x, y, then the last, each
    cell's balls by id.  Place r of the new storage holds the ball of place order[r]."""
    cell = 2.0 * float(radius.max()) + skin
    lo, hi = bounding_box(pos)
    top = (1 << _BITS) - 1
    c = np.floor((pos - lo) / cell).astype(np.int64)
    np.clip(c, 0, top, out=c)
    c = c.astype(np.uint64)
    # the largest cell index along each axis is the box's top corner's: a difference, a
    # quotient by a positive cell and floor are each monotone in rounding, so no second
    # reduction over the balls is needed
    extent = np.minimum(np.floor((hi - lo) / cell).astype(np.int64), top)
    axes = sorted((2, 0, 1), key=lambda a: -int(extent[a]))
    slab = axes[0]
    row, col = [a for a in (2, 0, 1) if a != slab]
    b = np.uint64(_BITS)
    key = (c[:, slab] << (b + b)) | (c[:, row] << b) | c[:, col]
    return np.lexsort((ids, key)).astype(np.int64)


@nb.njit(cache=True, parallel=True)
def _permute_rows(a, order):
    """a[:] = a[order] for a 2-d array, row by row in parallel."""
    tmp = np.empty_like(a)
    m = a.shape[1]
    for r in nb.prange(a.shape[0]):
        o = order[r]
        for c in range(m):
            tmp[r, c] = a[o, c]
    for r in nb.prange(a.shape[0]):
        for c in range(m):
            a[r, c] = tmp[r, c]


def store(state, diag: np.ndarray, order: np.ndarray, keep_list: bool = True) -> None:
    """Store the balls of `state` anew, in place: place r holds the ball of old place
    order[r].  The per-ball arrays and the places in the diagnostics `diag` follow (the
    buffered impact rows hold ball ids, vibroflow.dem.impact_order); the neighbour list is
    regrouped (keep_list) or only told the new ids (a rebuild follows, vibroflow.dem.simulate)."""
    n = order.shape[0]
    place = np.empty(n, np.int64)
    place[order] = np.arange(n, dtype=np.int64)
    for name in PER_BALL:
        a = getattr(state, name)
        if a is not None and a.shape[0] == n and a.size:
            _permute_rows(a.reshape(n, -1), order)
    for col in BALL_COLUMNS:
        x = diag[:, col]
        held = x >= 0.0
        x[held] = place[x[held].astype(np.int64)]
    nl = state.nl
    if keep_list:
        nl.store(order, place)
    else:
        ids = order if nl.ids is None else nl.ids[order]
        nl.ids = None if np.array_equal(ids, np.arange(n)) else ids


def by_id(state) -> np.ndarray | None:
    """The order that stores the balls of `state` back by id (None: they are)."""
    ids = state.nl.ids
    if ids is None:
        return None
    rows = np.empty(ids.shape[0], np.int64)
    rows[ids] = np.arange(ids.shape[0], dtype=np.int64)
    return rows
