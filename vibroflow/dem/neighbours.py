"""Neighbour search: cell lists and a half Verlet list with a skin (Allen & Tildesley, ch. 5;
the LAMMPS/LIGGGHTS "bin" neighbour style).

The list is built every time some ball has moved more than half the skin since the last build
(measured in the tub frame: pair distances do not care about the tub's rigid motion, so the
vibration itself does not force rebuilds).  It holds, for each ball i, the balls j > i whose
surfaces are closer than the skin, in CSR form (start[i] .. start[i+1] into `nbr`).

Each list entry carries its contact's history (tangential spring, and the EPSD law's rolling
torque where a pair has it: laws.history_width) and a flag saying whether the pair was
touching at the last step; on a rebuild, `transfer_history` copies them from the old list to
the new one, so a contact keeps its history for its whole life.

For the tub step's force assembly (vibroflow.dem.step) the list also carries, made at each
build (`index_pairs`), its reverse order: for each ball j, the entries (i, j) where it is the
second ball, in ascending order (rstart, and rpos: each entry's place in that order), with a
copy of the contact flags in that order (rflag), so that each ball gathers its pairs' forces
in a fixed order; and the arrays of the touching entries' contact rows (row, rrow, chist and
`rout`, the force and torque on j: vibroflow.dem.contact_rows).

The balls may be stored in any order (vibroflow.dem.memory_order keeps them in space order
during a run): `ids` gives each stored ball's id and the list is the same as that of the balls
stored by id.  A pair's entry belongs to the ball of the lower id, each cell's members are
visited in id order, and the reverse order runs over the first balls by id, so that every
ball's entries, their orientation and its sums are those of the balls stored by id.

Periodic length in y: positions are wrapped into [0, L) at each build and distances use the
minimum image.
"""
from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np


#: the dtype of the list's ball indices (nbr) and reverse places (rpos): 32 bits, half the
#: bytes a step streams of them on a bed whose list outgrows the caches (docs/decisions/
#: threads.md); `build_half_list` refuses a bed of more balls or entries than it numbers
#: (2^31 - 1 entries are over 100 GB of list)
INDEX = np.int32
INDEX_MAX = 2**31 - 1


class Cells(NamedTuple):
    """The balls sorted into a grid of cells (`bin_particles`), and the search's settings."""

    start: np.ndarray          # (ncell + 1,) first entry of each cell in `members`
    members: np.ndarray        # (N,) balls, cell by cell, each cell's in index order
    cell_of: np.ndarray        # (N, 3) integer cell coordinates of each ball
    dims: np.ndarray           # (3,) cells along x, y, z
    skin: float                # m
    periodic_length: float     # m along y; 0 when not periodic
    ids: np.ndarray            # (N,) the id of each stored ball


#: the chunks of the rebuild's parallel passes over the balls (`bounding_box`) and the list
#: (`reverse_arrays`): a fixed count, so that the work of a chunk is the same on any machine
REBUILD_CHUNKS = 64


@nb.njit(cache=True, parallel=True)
def bounding_box(pos):
    """(lo (3,), hi (3,)): the least and the largest coordinate of the positions pos (N, 3)
    along each axis (m), in fixed chunks of balls on the threads.  A minimum is exact in any
    order, so the box is numpy's pos.min(axis=0), pos.max(axis=0) bit for bit, in one pass
    over the rows: numpy's reduction along the short axis takes 0.8 ms on tub47's 14 000 balls
    and 7 ms on 140 000 (one thread of the 2-core machine), a serial part of every rebuild."""
    n = pos.shape[0]
    nc = min(REBUILD_CHUNKS, max(n, 1))
    lows = np.full((nc, 3), np.inf)
    highs = np.full((nc, 3), -np.inf)
    for c in nb.prange(nc):
        for i in range((c * n) // nc, ((c + 1) * n) // nc):
            for a in range(3):
                v = pos[i, a]
                if v < lows[c, a]:
                    lows[c, a] = v
                if v > highs[c, a]:
                    highs[c, a] = v
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    for c in range(nc):
        for a in range(3):
            lo[a] = min(lo[a], lows[c, a])
            hi[a] = max(hi[a], highs[c, a])
    return lo, hi


@nb.njit(cache=True)
def bin_particles(pos, lo, cell_size, dims, periodic_length, rows):
    """Counting sort of particles into cells, each cell's members in id order (`rows`: the
    stored place of each id).

    Returns (cell_start (ncell+1,), cell_members (N,), cell_of (N, 3) integer cell coordinates).
    """
    n = pos.shape[0]
    nx, ny, nz = dims[0], dims[1], dims[2]
    cell_of = np.empty((n, 3), np.int64)
    flat = np.empty(n, np.int64)
    counts = np.zeros(nx * ny * nz + 1, np.int64)
    for i in range(n):
        cx = int((pos[i, 0] - lo[0]) / cell_size)
        if periodic_length > 0.0:
            cy = int(pos[i, 1] / periodic_length * ny)
            if cy >= ny:
                cy = ny - 1
        else:
            cy = int((pos[i, 1] - lo[1]) / cell_size)
        cz = int((pos[i, 2] - lo[2]) / cell_size)
        cx = min(max(cx, 0), nx - 1)
        cy = min(max(cy, 0), ny - 1)
        cz = min(max(cz, 0), nz - 1)
        cell_of[i, 0] = cx
        cell_of[i, 1] = cy
        cell_of[i, 2] = cz
        f = (cx * ny + cy) * nz + cz
        flat[i] = f
        counts[f + 1] += 1
    for c in range(nx * ny * nz):
        counts[c + 1] += counts[c]
    start = counts.copy()
    fill = counts[:-1].copy()
    members = np.empty(n, np.int64)
    for d in range(n):
        i = rows[d]
        f = flat[i]
        members[fill[f]] = i
        fill[f] += 1
    return start, members, cell_of


@nb.njit(cache=True, inline="always")
def _scan(i, pos, radius, cells, out, offset, cap, write):
    """Visit the neighbour cells of i; count (write=False) or store (write=True; `cap` of
    them, the count) its partners of higher id.  The distance test is no branch: a candidate
    passes it in no order a predictor learns, so the count adds the test's outcome and the
    write pass stores every candidate at the next place, kept when it passes (the place
    `cap` and beyond is the next ball's, never written)."""
    cell_start, cell_members, cell_of, dims = cells.start, cells.members, cells.cell_of, cells.dims
    skin, periodic_length, ids = cells.skin, cells.periodic_length, cells.ids
    nx, ny, nz = dims[0], dims[1], dims[2]
    cx, cy, cz = cell_of[i, 0], cell_of[i, 1], cell_of[i, 2]
    xi, yi, zi, ri, id_i = pos[i, 0], pos[i, 1], pos[i, 2], radius[i], ids[i]
    count = 0
    if periodic_length > 0.0 and ny < 3:
        ylo, yhi = 0, 0  # one cell across the periodic length: it holds every y
    else:
        ylo, yhi = -1, 1
    for dx in range(-1, 2):
        ax = cx + dx
        if ax < 0 or ax >= nx:
            continue
        for dy in range(ylo, yhi + 1):
            ay = cy + dy
            if periodic_length > 0.0:
                ay = ay % ny
            elif ay < 0 or ay >= ny:
                continue
            for dz in range(-1, 2):
                az = cz + dz
                if az < 0 or az >= nz:
                    continue
                f = (ax * ny + ay) * nz + az
                for m in range(cell_start[f], cell_start[f + 1]):
                    # unsigned indices: numba wraps no unsigned index around (no sign test a
                    # load); i's position, radius and id held in locals (the same operations)
                    j = np.uint64(cell_members[np.uint64(m)])
                    if ids[j] <= id_i:
                        continue
                    ddx = xi - pos[j, 0]
                    ddy = yi - pos[j, 1]
                    ddz = zi - pos[j, 2]
                    if periodic_length > 0.0:
                        ddy -= periodic_length * np.rint(ddy / periodic_length)
                    cut = ri + radius[j] + skin
                    near = np.int64(ddx * ddx + ddy * ddy + ddz * ddz < cut * cut)
                    if write and count < cap:
                        out[offset + count] = np.int32(j)
                    count += near
    return count


@nb.njit(cache=True, parallel=True)
def build_half_list(pos, radius, cells):
    """Half neighbour list in CSR form: (start (N+1,), nbr (M,) INDEX)."""
    n = pos.shape[0]
    counts = np.zeros(n + 1, np.int64)
    dummy = np.empty(0, np.int64)
    for i in nb.prange(n):
        counts[i + 1] = _scan(i, pos, radius, cells, dummy, 0, 0, False)
    for i in range(n):
        counts[i + 1] += counts[i]
    if n > INDEX_MAX or counts[n] > INDEX_MAX:
        raise ValueError("neighbour list: more than 2^31 - 1 balls or entries, beyond its "
                         "32-bit indices")
    nbr = np.empty(counts[n], INDEX)
    for i in nb.prange(n):
        # within a cell, members are in id order, so each i's list is reproducible
        _scan(i, pos, radius, cells, nbr, counts[i], counts[i + 1] - counts[i], True)
    return counts, nbr


def transfer_history(old_start, old_nbr, old_hist, old_flag, new_start, new_nbr):
    """Carry each pair's contact history from the old list to the new one (the balls stored
    in the same order)."""
    return transfer_history_moved(old_start, old_nbr, old_hist, old_flag, new_start, new_nbr,
                                  np.arange(new_start.shape[0] - 1, dtype=np.int64))


@nb.njit(cache=True, parallel=True)
def transfer_history_moved(old_start, old_nbr, old_hist, old_flag, new_start, new_nbr, old_of):
    """Carry each pair's contact history from the old list to the new one (`old_of`: each
    stored ball's place in the old list's storage)."""
    n = new_start.shape[0] - 1
    m = new_nbr.shape[0]
    hist = np.zeros((m, old_hist.shape[1]))
    flag = np.zeros(m, np.uint8)
    for i in nb.prange(n):
        oi = old_of[i]
        for k in range(new_start[i], new_start[i + 1]):
            j = old_of[new_nbr[k]]
            for q in range(old_start[oi], old_start[oi + 1]):
                if old_nbr[q] == j:
                    if old_flag[q]:
                        for c in range(old_hist.shape[1]):
                            hist[k, c] = old_hist[q, c]
                        flag[k] = 1
                    break
    return hist, flag


@nb.njit(cache=True)
def reverse_index(start, nbr, rows):
    """(rstart (n + 1,), rslot (M,)): for each ball j, the list entries k with nbr[k] == j,
    their first balls by ascending id (`rows`: the stored place of each id), each one's in
    list order (a counting sort: the same on any machine)."""
    n = start.shape[0] - 1
    m = nbr.shape[0]
    rstart = np.zeros(n + 1, np.int64)
    for k in range(m):
        rstart[nbr[k] + 1] += 1
    for j in range(n):
        rstart[j + 1] += rstart[j]
    fill = rstart[:-1].copy()
    rslot = np.empty(m, INDEX)
    for d in range(n):
        i = rows[d]
        for k in range(start[i], start[i + 1]):
            j = nbr[k]
            rslot[fill[j]] = k
            fill[j] += 1
    return rstart, rslot


@nb.njit(cache=True, parallel=True)
def reverse_arrays(rslot, flag):
    """(rpos (M,) INDEX, rflag (M,) uint8, row (M,) INDEX): each list entry's place in the
    reverse order `rslot` (a permutation of the entries, `reverse_index`), the contact flags
    in that order, and the contact rows' index with no entry given a row yet (-1; vibroflow.
    dem.contact_rows), in fixed chunks of the list on the threads (each place written once,
    so any schedule gives the same arrays)."""
    m = rslot.shape[0]
    rpos = np.empty(m, INDEX)
    rflag = np.empty(m, np.uint8)
    row = np.empty(m, INDEX)
    nc = REBUILD_CHUNKS
    for c in nb.prange(nc):
        for r in range((c * m) // nc, ((c + 1) * m) // nc):
            k = rslot[r]
            rpos[k] = r
            rflag[r] = flag[k]
            row[k] = -1
    return rpos, rflag, row


@nb.njit(cache=True)
def regroup(start, nbr, hist, flag, order, place):
    """The list of the balls stored anew (place r holds the ball of old place order[r];
    `place`: the new place of each old one): each ball's entries in their order, their
    second balls renumbered."""
    n = start.shape[0] - 1
    new_start = np.zeros(n + 1, np.int64)
    for r in range(n):
        o = order[r]
        new_start[r + 1] = new_start[r] + start[o + 1] - start[o]
    new_nbr = np.empty_like(nbr)
    new_hist = np.empty_like(hist)
    new_flag = np.empty_like(flag)
    for r in range(n):
        o = order[r]
        k = new_start[r]
        for q in range(start[o], start[o + 1]):
            new_nbr[k] = place[nbr[q]]
            for c in range(hist.shape[1]):
                new_hist[k, c] = hist[q, c]
            new_flag[k] = flag[q]
            k += 1
    return new_start, new_nbr, new_hist, new_flag


class NeighbourList:
    """Cell grid and half Verlet list of one configuration (arrays only; see module doc)."""

    def __init__(self, skin: float, periodic_length: float = 0.0, hist_width: int = 6):
        self.skin = float(skin)
        self.periodic_length = float(periodic_length)
        self.start = np.zeros(1, np.int64)
        self.nbr = np.zeros(0, INDEX)
        self.hist = np.zeros((0, hist_width))
        self.flag = np.zeros(0, np.uint8)
        self.builds = 0
        #: the id of each stored ball; None: the balls are stored by id
        self.ids: np.ndarray | None = None
        self._bounds = None
        self._id_blocks = None
        self.rout = None
        self.rstart = None
        self.rpos = None
        self.rflag = None
        self.row = None
        self.rrow = None
        self.chist = None

    def id_arrays(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """(ids, rows): the id of each stored ball and the stored place of each id."""
        if self.ids is None:
            ids = np.arange(n, dtype=np.int64)
            return ids, ids
        rows = np.empty(n, np.int64)
        rows[self.ids] = np.arange(n, dtype=np.int64)
        return self.ids, rows

    def build(self, pos: np.ndarray, radius: np.ndarray,
              old_of: np.ndarray | None = None) -> None:
        """Rebuild from the positions `pos` (wrapped in y in place when periodic); `old_of`:
        each stored ball's place at the last build when the balls were stored anew since
        (vibroflow.dem.memory_order), None when they were not."""
        if self.periodic_length > 0.0:
            pos[:, 1] %= self.periodic_length
        cell = 2.0 * float(radius.max()) + self.skin
        lo, hi = bounding_box(pos)
        lo -= 1e-9
        hi += 1e-9
        dims = np.maximum(((hi - lo) / cell).astype(np.int64), 1)
        if self.periodic_length > 0.0:
            dims[1] = max(int(self.periodic_length / cell), 1)
            if dims[1] < 3:
                dims[1] = 1
        ids, rows = self.id_arrays(pos.shape[0])
        cells = Cells(*bin_particles(pos, lo, cell, dims, self.periodic_length, rows), dims,
                      self.skin, self.periodic_length, ids)
        start, nbr = build_half_list(pos, radius, cells)
        if self.nbr.shape[0] and self.start.shape[0] == start.shape[0]:
            if old_of is None:
                old_of = np.arange(pos.shape[0], dtype=np.int64)
            hist, flag = transfer_history_moved(self.start, self.nbr, self.hist, self.flag,
                                                start, nbr, old_of)
        else:
            hist = np.zeros((nbr.shape[0], self.hist.shape[1]))
            flag = np.zeros(nbr.shape[0], np.uint8)
        self.start, self.nbr, self.hist, self.flag = start, nbr, hist, flag
        self._bounds = None
        self._id_blocks = None
        self.rout = None
        self.index_pairs()
        self.builds += 1

    def widen_history(self, width: int) -> None:
        """Histories of at least `width` columns (laws.history_width): a state whose laws
        kept fewer (a file written by a run of other laws) gains zero columns, an untouched
        spring's value."""
        if self.hist.shape[1] < width:
            hist = np.zeros((self.hist.shape[0], width))
            hist[:, :self.hist.shape[1]] = self.hist
            self.hist = hist
            self.rout = None  # the contact rows made anew, as wide

    def store(self, order: np.ndarray, place: np.ndarray) -> None:
        """The list of the balls stored anew: place r holds the ball of old place order[r]
        (`place`: the new place of each old one); the same pairs, histories and sums."""
        self.start, self.nbr, self.hist, self.flag = regroup(self.start, self.nbr, self.hist,
                                                             self.flag, order, place)
        ids = order if self.ids is None else self.ids[order]
        self.ids = None if np.array_equal(ids, np.arange(ids.shape[0])) else ids
        self._bounds = None
        self._id_blocks = None
        self.rout = None
        self.index_pairs()

    def index_pairs(self) -> None:
        """The reverse order of the current list (see the module doc), made when missing
        (after a build, or a list read from a file); its flags are the list's."""
        if self.rout is not None and self.rout.shape[0] == self.nbr.shape[0]:
            return
        self.rstart, rslot = reverse_index(self.start, self.nbr,
                                           self.id_arrays(self.start.shape[0] - 1)[1])
        self.rpos, self.rflag, self.row = reverse_arrays(rslot, self.flag)
        # the contact rows of the tub step (vibroflow.dem.contact_rows; pages that no
        # contact touches are never given memory)
        m = self.nbr.shape[0]
        self.rout = np.zeros((m, 6))
        self.rrow = np.zeros(m, INDEX)
        self.chist = np.zeros((m, self.hist.shape[1]))

    def chunk_bounds(self, nchunk: int) -> np.ndarray:
        """Split the balls into `nchunk` contiguous chunks of about equal work (list entries,
        plus a few units a ball for its walls and its integration), so the threads finish
        together however the contacts are spread (the balls are stored by height, and the
        bed is denser at the bottom).  A function of the list alone: reproducible."""
        cached = getattr(self, "_bounds", None)
        if cached is not None and cached.shape[0] == nchunk + 1:
            return cached
        self._bounds = _equal_work(self.start, nchunk)
        return self._bounds

    def id_blocks(self, nchunk: int) -> tuple[np.ndarray, np.ndarray]:
        """(bounds (nchunk + 1,), block (N,)): the chunks of chunk_bounds for the balls stored
        by id (first id of each), and the chunk of each stored ball among them: the same
        whatever the storage (the impacts' order and the part loads' sums,
        vibroflow.dem.impact_order)."""
        cached = getattr(self, "_id_blocks", None)
        if cached is not None and cached[0].shape[0] == nchunk + 1:
            return cached
        n = self.start.shape[0] - 1
        if self.ids is None:
            bounds = self.chunk_bounds(nchunk)
            block = np.repeat(np.arange(nchunk, dtype=np.int64), np.diff(bounds))
        else:
            rows = self.id_arrays(n)[1]
            start = np.zeros(n + 1, np.int64)
            np.cumsum(np.diff(self.start)[rows], out=start[1:])
            bounds = _equal_work(start, nchunk)
            block = (np.searchsorted(bounds, self.ids, side="right") - 1).astype(np.int64)
        self._id_blocks = (bounds, block)
        return self._id_blocks


def _equal_work(start: np.ndarray, nchunk: int) -> np.ndarray:
    """The first ball of each of `nchunk` contiguous chunks of about equal work (list entries
    `start`, CSR, plus 4 units a ball) and the ball count: (nchunk + 1,)."""
    n = start.shape[0] - 1
    work = start.astype(np.float64) + 4.0 * np.arange(n + 1)
    targets = work[-1] * np.arange(1, nchunk) / nchunk
    inner = np.searchsorted(work, targets)
    return np.concatenate([[0], inner, [n]]).astype(np.int64)
