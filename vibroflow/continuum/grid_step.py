"""The grid's part of a continuum step, shared by both formulations' compiled loops.

Both formulations (the material points, fused.py; the Eulerian cells, eulerian/fused.py) scatter
their material to the nodes of the same background grid (grid.py); then the grid's part of the
step is the same for both (`grid_phase`):

1. the material points are scattered in fixed chunks, each chunk into its own buffers, which
   are summed node by node in the fixed order chunk 0, 1, ... (`sum_chunk_rows`), so the grid
   sums depend on the number of chunks and never on the number of threads (as the DEM's
   run.force_chunks: vibroflow.dem.step); with them the transfer operator's per-chunk parts
   when a step makes more than one transfer (transfer_operator.py).  The Eulerian cells, which
   do not move, write the node sums and the operator whole, node row by node row (eulerian/
   column_scatter.py, operator_build.py): their GridWork has no chunks, and step 1 is theirs;
2. the grid velocity update with the frame's body forces at mid-step (grid_update.py);
3. the grid's conditions: the lowest `no_slip_rows` node rows held still (a rough floor), the
   radial velocity of the first `axis_cols` node columns held at 0 (an axisymmetric section's
   axis);
4. the step's further transfers (transfer_operator.py), each followed by the same conditions.

Records (numba named tuples, unpacked into locals at the top of each kernel):

* `GridSpec`: the grid's origin x0, z0 (m), spacing dx (m), periodic (wraps along x), and its
  conditions no_slip_rows and axis_cols (0 for none);
* `GridWork`: the per-chunk scatter buffers cm (nchunk, nx, nz), cmv, cf (nchunk, nx, nz, 2;
  nchunk 0 where the caller writes the sums whole),
  the node mass gm (nx, nz) kg/m, momentum gmv, force gf and velocity gv (nx, nz, 2), the
  transfers a step makes, the transfer operator's per-chunk parts cb (nchunk, nx, nz, HALF),
  their sum B (nx, nz, HALF) (transfer_operator.py: the stored half) and a work grid gtmp
  (nx, nz, 2) (empty for one transfer).
"""
from __future__ import annotations

from collections import namedtuple

import numba as nb
import numpy as np

from .grid_update import frame_body, grid_update
from .transfer_operator import HALF, sum_operator_rows, transfer_rows

GridSpec = namedtuple("GridSpec", ["x0", "z0", "dx", "periodic", "no_slip_rows", "axis_cols"])
GridWork = namedtuple("GridWork", ["cm", "cmv", "cf", "gm", "gmv", "gf", "gv", "transfers", "cb",
                                   "B", "gtmp"])


def grid_spec(grid, no_slip_rows: int, axis_cols: int) -> GridSpec:
    """The GridSpec of a grid.Grid with its conditions (module docstring)."""
    return GridSpec(float(grid.x0), float(grid.z0), float(grid.dx), bool(grid.periodic),
                    int(no_slip_rows), int(axis_cols))


def grid_work(grid, chunks: int, transfers: int) -> GridWork:
    """Fresh GridWork arrays of a grid.Grid for `chunks` scatter chunks (0: the caller writes
    the node sums and the operator whole) and `transfers` APIC transfers a step (the
    operator's buffers empty for one)."""
    nx, nz = grid.nx, grid.nz
    t = (nx, nz) if transfers > 1 else (0, 0)
    return GridWork(np.zeros((chunks, nx, nz)), np.zeros((chunks, nx, nz, 2)),
                    np.zeros((chunks, nx, nz, 2)), np.zeros((nx, nz)), np.zeros((nx, nz, 2)),
                    np.zeros((nx, nz, 2)), np.zeros((nx, nz, 2)), int(transfers),
                    np.zeros((chunks, *t, HALF)), np.zeros((*t, HALF)), np.zeros((*t, 2)))


def chunk_bounds(n: int, nchunk: int) -> np.ndarray:
    """Bounds (nchunk + 1,) of nchunk contiguous chunks of n points, sizes differing by <= 1."""
    return (np.arange(nchunk + 1, dtype=np.int64) * n) // nchunk


@nb.njit(cache=True)
def sum_chunk_rows(i0, i1, cm, cmv, cf, gm, gmv, gf):
    """Grid rows i0:i1 of mass gm, momentum gmv and force gf: the sums of the per-chunk
    buffers cm, cmv, cf in the fixed order chunk 0, 1, ... (module docstring)."""
    nchunk = cm.shape[0]
    nz = gm.shape[1]
    for i in range(i0, i1):
        for k in range(nz):
            sm = cm[0, i, k]
            s0 = cmv[0, i, k, 0]
            s1 = cmv[0, i, k, 1]
            f0 = cf[0, i, k, 0]
            f1 = cf[0, i, k, 1]
            for c in range(1, nchunk):
                sm += cm[c, i, k]
                s0 += cmv[c, i, k, 0]
                s1 += cmv[c, i, k, 1]
                f0 += cf[c, i, k, 0]
                f1 += cf[c, i, k, 1]
            gm[i, k] = sm
            gmv[i, k, 0] = s0
            gmv[i, k, 1] = s1
            gf[i, k, 0] = f0
            gf[i, k, 1] = f1


def _make_grid_phase(parallel: bool):
    """`grid_phase` with numba's parallel loops over the node rows, or the same loops run
    serially (the Eulerian one-thread loop, eulerian/fused.py); `parallel` is a closure
    constant, so the two are cached apart."""

    @nb.njit(cache=True, parallel=parallel)
    def grid_phase(grid, work, frame, t, dt):
        """The grid's part of a step of dt (s) from time t (s) (module docstring, 1-4): from
        the chunks' scatter in `work` (GridWork) to the grid velocity work.gv (m/s), on the
        grid `grid` (GridSpec) in the frame `frame` (grid_update.FRAME_FIELDS).  Returns
        work.gv: a caller's parallel loop that gathers from the returned array depends on
        this call, so numba's parfor fusion cannot move the gather before it."""
        _ = parallel
        x0, z0, dx, periodic, no_slip_rows, axis_cols = grid
        cm, cmv, cf, gm, gmv, gf, gv, transfers, cb, B, gtmp = work
        nx = gm.shape[0]
        chunked = cm.shape[0] > 0
        summed = transfers > 1 and chunked
        # (the serial loop makes each pass in one call over all rows, not one call a row)
        if parallel:
            for i in nb.prange(nx if chunked else 0):
                sum_chunk_rows(i, i + 1, cm, cmv, cf, gm, gmv, gf)
                if summed:
                    sum_operator_rows(i, i + 1, cb, B)
        elif chunked:
            sum_chunk_rows(0, nx, cm, cmv, cf, gm, gmv, gf)
            if summed:
                sum_operator_rows(0, nx, cb, B)
        a0x, a0z, om, al, pvx, pvz = frame_body(frame, t + 0.5 * dt)
        grid_update(gm, gmv, gf, gv, x0, z0, dx, dt, a0x, a0z, om, al, pvx, pvz, periodic)
        if no_slip_rows > 0:
            gv[:, :no_slip_rows, :] = 0.0
        if axis_cols > 0:
            gv[:axis_cols, :, 0] = 0.0
        # the further transfers: from gv to gtmp and back, one parallel loop a transfer, the
        # last copied back; the conditions inside transfer_rows (numba's parallel build
        # dropped slice assignments to the alternating buffer)
        for j in range(transfers - 1):
            if not parallel:
                src, dst = (gv, gtmp) if j % 2 == 0 else (gtmp, gv)
                transfer_rows(0, nx, B, gm, src, dst, periodic, no_slip_rows, axis_cols)
            elif j % 2 == 0:
                for i in nb.prange(nx):
                    transfer_rows(i, i + 1, B, gm, gv, gtmp, periodic, no_slip_rows,
                                  axis_cols)
            else:
                for i in nb.prange(nx):
                    transfer_rows(i, i + 1, B, gm, gtmp, gv, periodic, no_slip_rows,
                                  axis_cols)
        if transfers % 2 == 0:
            # a copy of a few thousand numbers: serial, a parallel loop's launch costs more
            nz = gv.shape[1]
            for i in range(nx):
                for k in range(nz):
                    gv[i, k, 0] = gtmp[i, k, 0]
                    gv[i, k, 1] = gtmp[i, k, 1]
        return gv

    return grid_phase


grid_phase = _make_grid_phase(True)
grid_phase_serial = _make_grid_phase(False)
