"""What a block of balls records during a tub step (vibroflow.dem.step): its diagnostics
and its impact rows, each block into its own row of the step's scratch arrays
(vibroflow.dem.records.Work), so that no two threads write the same number.
"""
from __future__ import annotations

import numba as nb

# columns of the per-block diagnostics
# (keep_largest: an overlap's ball and other ball or wall in the two columns after it)
D_BALL_OVERLAP, D_BALL_I, D_BALL_J, D_WALL_OVERLAP, D_WALL_I, D_WALL_W, D_NAN, D_LOST = range(8)
N_DIAG = 8
# an impact row: time (s), kind (walls.KIND_*), contact point x, y, z (m, lab), normal speed
# (m/s); then the ball (its stored place, then its id), its block and the step
# (vibroflow.dem.impact_order)
IMP_COLUMNS = 6
ROW_BALL = 6
N_IMP_BUF = 9


@nb.njit(cache=True, inline="always")
def record_impact(imp_buf, imp_count, c, t, kind, x, y, z, speed, i):
    """Row k of block c's impact buffer (its count, k = imp_count[c], then one more).  A row
    past the buffer would be counted, not written (step.IMPACTS_LOST); the buffers are sized
    from a proven bound so that none is (vibroflow.dem.impact_order)."""
    k = imp_count[c]
    if k < imp_buf.shape[1]:
        imp_buf[c, k, 0] = t
        imp_buf[c, k, 1] = kind
        imp_buf[c, k, 2] = x
        imp_buf[c, k, 3] = y
        imp_buf[c, k, 4] = z
        imp_buf[c, k, 5] = speed
        imp_buf[c, k, ROW_BALL] = i
    imp_count[c] = k + 1


@nb.njit(cache=True, inline="always")
def keep_largest(diag, c, col, delta, a, b):
    """Block c's largest overlap of a kind: columns col (overlap, m), col + 1 and col + 2
    (its ball and its other ball or wall: D_BALL_OVERLAP, D_BALL_I, D_BALL_J or D_WALL_*),
    replaced when `delta` is larger."""
    if delta > diag[c, col]:
        diag[c, col] = delta
        diag[c, col + 1] = a
        diag[c, col + 2] = b
