"""The impact rows of a run in the order of the balls stored by id, whatever the storage.

The kernels record each new contact into the buffer of its block of stored balls
(vibroflow.dem.step, vibroflow.dem.parts), with the stored place of its ball.  `run_steps`
(vibroflow.dem.simulate) gives the rows to its callers in flushes, as the buffers of the
blocks of the balls stored by id (`NeighbourList.id_blocks`) would give them, so that a run
whose balls are stored in space order (vibroflow.dem.memory_order) writes the rows of the run
stored by id, in the same order and the same flushes:

- within a flush, block (of the balls by id, at the row's step) by block, then step by step,
  the ball-ball rows before the wall rows (the pair pass comes first), ball by id, each
  ball's rows in the order recorded (its list entries, its wall slots, its parts): the order
  in which the blocks' buffers fill;
- a flush after each step at which some block's rows since the last flush pass the flush
  threshold (1 024 ball-ball and wall rows, or 512 ball-part rows), or, when the list is
  rebuilt at that step, after the next step that is not a rebuild; and at the end of a run_steps call (the
  ball-ball and wall rows only when the call has a callback for them, else they wait).

After each `advance` call the new rows are tagged (`ImpactOrder.tag`): their ball's id, its
block and the step written into the columns after the row's own.  The rows wait in the
buffers, then in a pool (`settle`), until their flush is known; the flush threshold of
`advance` (simulate.IMPACT_FLUSH, 1 024 ball-ball and wall rows; parts.IMPACT_FLUSH, 512
ball-part rows: `Work.imp_flush`, `ImpactOrder.half`) only makes `settle` drain them sooner.  The
thresholds fix the flushes, so they do not depend on the buffers' capacity.

No buffer overflows, by construction.  In one step block c of stored balls (`Pairs.bounds`)
records at most

    B_c = E_c + n_c W  ball-ball and wall rows,   Q_c = n_c P  ball-part rows,

with n_c its balls, E_c = start[bounds[c + 1]] - start[bounds[c]] the list entries they own,
W the wall slots a ball has (system.n_walls) and P the parts (`impact_bound`).  Proof, from
the kernels' calls of the recorders: the pair pass (step._pair_block) runs once a step and
visits each entry k of block c's balls once, and records a row for k only where flag[k] goes
from 0 to 1, which it does at most once in the pass; the wall pass (wall_pass.ball_walls)
runs once a step, visits each wall slot w of each of block c's balls once, and records only
where wall_flag[i, w] goes from 0 to 1; the parts' kernel (parts.ball_parts) records, for
each ball and part, only the first contact it gives a slot while the ball had no slot of the
part at the step's start (`first` is cleared after that row): at most one row a ball and
part, below the SLOTS rows a ball and part that its slots would allow.  `advance` stops after
the first step at which some block's rows pass the threshold F, and every call starts with
each block at most F (`run_steps` drains a block past it before the next call), so a block
holds at most F + B_c (F + Q_c) rows, B_c of the list of that call.  `run_steps` grows the
buffers to F + max_c B_c (F + max_c Q_c) rows at the start of each call and after each list
rebuild (`simulate._Buffers.fit`; never below their IMPACT_CAPACITY).  step.IMPACTS_LOST, and ImpactsLost
here, remain only as a guard that cannot fire.
"""
from __future__ import annotations

import numba as nb
import numpy as np

from .parts import IMP_BALL, N_IMP
from .step import IMP_COLUMNS, ROW_BALL
from .walls import KIND_BALL_BALL

#: the ball's column in a buffered row (its stored place, its id once tagged); its block and
#: the step follow: ball-ball and wall rows (step), ball-part rows (parts)
BALL_COLUMN = (ROW_BALL, IMP_BALL)
#: the columns of a row the callers receive
OUT_COLUMNS = (IMP_COLUMNS, N_IMP)


@nb.njit(cache=True)
def _tag(buf, count, tagged, col, ids, block, origin, dt, per_block):
    """The rows of buf[c] from tagged[c] on: column col (stored place) set to the ball's id,
    col + 1 to its block of the balls by id, col + 2 to the step of the row's time (column 0,
    s; t = (step - origin) dt); per_block counts them by that block."""
    cap = buf.shape[1]
    for c in range(buf.shape[0]):
        end = min(count[c], cap)
        for r in range(tagged[c], end):
            p = int(buf[c, r, col])
            b = block[p]
            buf[c, r, col] = ids[p]
            buf[c, r, col + 1] = b
            buf[c, r, col + 2] = origin + np.rint(buf[c, r, 0] / dt)
            per_block[b] += 1
        tagged[c] = end


class ImpactsLost(RuntimeError):
    """A block of balls recorded more impact rows than its buffer holds: a guard that the
    buffers' bound (module docstring) keeps from firing."""


def impact_bound(start: np.ndarray, bounds: np.ndarray, n_walls: int,
                 n_parts: int) -> tuple[np.ndarray, np.ndarray]:
    """(B, Q) (nblock,): the most ball-ball and wall rows, and ball-part rows, that each block
    of stored balls (ids bounds[c] to bounds[c + 1] of the list's `start`) records in one
    step: B_c = its list entries + its balls x n_walls, Q_c = its balls x n_parts (module
    docstring)."""
    start = np.asarray(start, np.int64)
    bounds = np.asarray(bounds, np.int64)
    balls = np.diff(bounds)
    entries = start[bounds[1:]] - start[bounds[:-1]]
    return entries + balls * int(n_walls), balls * int(n_parts)


def lost_message(buffers, counts, step: int) -> str:
    """The ImpactsLost message: the first block whose rows overflowed, at `step`."""
    for name, buf, count in zip(("ball-ball and wall", "ball-part"), buffers, counts):
        over = np.nonzero(count > buf.shape[1])[0]
        if over.size:
            c = int(over[0])
            return (f"impact rows lost at step {step}: block {c} of stored balls recorded "
                    f"{int(count[c])} {name} rows, its buffer holds {buf.shape[1]}")
    return f"impact rows lost at step {step}"


class ImpactOrder:
    """The flushes of a run's impact rows (module docstring): kind 0 the ball-ball and wall
    rows (`work.imp_buf`, vibroflow.dem.records.Work), kind 1 the ball-part rows (`prt.imp`,
    vibroflow.dem.parts.PartsRec)."""

    def __init__(self, nblock: int, buffers: tuple[np.ndarray, np.ndarray],
                 flush: np.ndarray):
        self.nblock = nblock
        #: the flush thresholds (Work.imp_flush): more rows of one block since the last
        #: flush flush them
        self.half = np.array(flush, np.int64)
        #: rows of each buffer block already tagged
        self.tagged = np.zeros((2, nblock), np.int64)
        #: rows since the last flush, by block of the balls by id
        self.count = np.zeros((2, nblock), np.int64)
        #: tagged rows drained from the buffers, not yet flushed
        self.pool = [np.zeros((0, b.shape[2])) for b in buffers]
        #: steps since the last flush at which the list was rebuilt
        self.rebuilds: list[int] = []
        #: the ids of balls stored by id
        self._identity = np.zeros(0, np.int64)

    def tag(self, buffers, counts, nl, origin: int, dt: float) -> None:
        """Tag the rows recorded since the last call, with the list of their step `nl`."""
        ids = nl.ids
        if ids is None:
            n = nl.start.shape[0] - 1
            if self._identity.shape[0] != n:
                self._identity = np.arange(n, dtype=np.int64)
            ids = self._identity
        block = nl.id_blocks(self.nblock)[1]
        for kind in range(2):
            _tag(buffers[kind], counts[kind], self.tagged[kind], BALL_COLUMN[kind], ids,
                 block, origin, dt, self.count[kind])

    def exceeded(self) -> bool:
        """Whether some block's rows since the last flush pass the flush threshold."""
        return bool(np.any(self.count > self.half[:, None]))

    def settle(self, buffers, counts, step: int, on_rows) -> None:
        """Drain the (tagged) buffers into the pool and give each flush up to `step` to
        on_rows = (ball-ball and wall rows' callback or None, ball-part rows' or None)."""
        for kind in range(2):
            n = np.minimum(counts[kind], buffers[kind].shape[1])
            if n.any():
                self.pool[kind] = np.concatenate(
                    [self.pool[kind]] + [buffers[kind][c, :n[c]] for c in range(self.nblock)
                                         if n[c]])
            counts[kind][:] = 0
            self.tagged[kind] = 0
        if not self.exceeded():
            return
        steps = [p[:, BALL_COLUMN[k] + 2].astype(np.int64) for k, p in enumerate(self.pool)]
        blocks = [p[:, BALL_COLUMN[k] + 1].astype(np.int64) for k, p in enumerate(self.pool)]
        by_step = [np.argsort(s, kind="stable") for s in steps]
        sorted_steps = [s[o] for s, o in zip(steps, by_step)]
        rebuilt = set(self.rebuilds)
        # a flush can only come at a step with rows, or the step after a rebuild
        candidates = np.unique(np.concatenate(steps + [np.array(self.rebuilds, np.int64) + 1]))
        count = np.zeros_like(self.count)
        at = [0, 0]
        last = None
        for s in candidates[candidates <= step]:
            for kind in range(2):
                end = int(np.searchsorted(sorted_steps[kind], s, side="right"))
                count[kind] += np.bincount(blocks[kind][by_step[kind][at[kind]:end]],
                                           minlength=self.nblock)
                at[kind] = end
            if np.any(count > self.half[:, None]) and int(s) not in rebuilt:
                self._flush(int(s), on_rows, (True, True))
                count[:] = 0
                last = int(s)
        self.count = count
        if last is not None:
            self.rebuilds = [r for r in self.rebuilds if r > last]

    def finish(self, on_rows, take_balls: bool) -> None:
        """The end of a run_steps call: flush the pool's ball-part rows, and its ball-ball and
        wall rows with `take_balls` (else they wait for the next flush)."""
        self._flush(None, on_rows, (take_balls, True))
        if not any(p.shape[0] for p in self.pool):
            self.rebuilds = []

    def _flush(self, upto: int | None, on_rows, take: tuple[bool, bool]) -> None:
        """Give the pool's rows of the steps up to `upto` (None: all) of each kind taken, in
        the module's order, to their callback (rows are dropped without one)."""
        for kind in range(2):
            if not take[kind]:
                continue
            pool, col = self.pool[kind], BALL_COLUMN[kind]
            if upto is None:
                out, keep = pool, pool[:0]
                self.count[kind] = 0
            else:
                mine = pool[:, col + 2] <= upto
                out, keep = pool[mine], pool[~mine]
            self.pool[kind] = keep
            if not out.shape[0] or on_rows[kind] is None:
                continue
            # np.lexsort is stable: a ball's rows of one step stay in the order recorded
            keys = [out[:, col], out[:, col + 2], out[:, col + 1]]
            if kind == 0:
                keys.insert(1, out[:, 1] != KIND_BALL_BALL)
            out = out[np.lexsort(keys)]
            on_rows[kind](np.ascontiguousarray(out[:, :OUT_COLUMNS[kind]]))

