"""The bulk velocity cell table's batches of whole cycles as files beside bulk_velocity.csv,
written by every method (a DEM run, a LIGGGHTS import, a continuum run): the batch-means
standard error of every cell (bulk_velocity_stderr.csv) and the per-batch cell means behind it
(bulk_velocity_batches.csv), from which a reader rebuilds the table's batches (`with_batches`)
and so any quantity's batch-means standard error over the same batches (stats.py; the report's
profiles and turnover time, E's error over two runs' batches).

bulk_velocity_stderr.csv, one row per cell of bulk_velocity.csv in its order (z, then x):
x, z (m, cell centre, tub frame), vx_stderr_m_s, vz_stderr_m_s (m/s),
solid_fraction_stderr (-): std(batch means, ddof=1) / sqrt(n) (stats.stderr_of_batches, as
CellTable's: a velocity over the n batches in which the cell held a ball-sample, empty when
n < 2; the solid fraction over every batch, 0 where the cell held none), batches (n).

bulk_velocity_batches.csv, one row per cell and batch in which it held a ball-sample, by batch
then as bulk_velocity.csv: batch (0-based), x, z (m), solid_fraction (-), vx_m_s, vz_m_s (m/s),
samples (ball-samples); the means as Python's repr, so they read back bit for bit.  In both
files the cell centres are written as bulk_velocity.csv writes them.  A cell
missing in a batch held no ball there: solid fraction 0, velocity undefined.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from vibroflow.io.atomic import write_text_atomic
from vibroflow.measure.bulk import CellTable

STDERR_CSV_NAME = "bulk_velocity_stderr.csv"
BATCHES_CSV_NAME = "bulk_velocity_batches.csv"

#: the files' columns and their units (SI; "1": a number)
STDERR_COLUMNS = {"x": "m", "z": "m", "vx_stderr_m_s": "m s-1", "vz_stderr_m_s": "m s-1",
                  "solid_fraction_stderr": "1", "batches": "1"}
BATCHES_COLUMNS = {"batch": "1", "x": "m", "z": "m", "solid_fraction": "1", "vx_m_s": "m s-1",
                   "vz_m_s": "m s-1", "samples": "1"}


def _held(table: CellTable) -> np.ndarray:
    """(n_batches, n) True where the cell held a ball-sample in the batch."""
    if table.batch_samples is not None:
        return np.asarray(table.batch_samples) > 0
    return np.isfinite(np.asarray(table.batch_vx, dtype=float))


def _centre(table: CellTable, j: int) -> str:
    """Cell j's x,z as bulk_velocity.csv writes them (measure.bulk.write_csv)."""
    return f"{table.x[j]:.10g},{table.z[j]:.10g}"


def _number(v: float) -> str:
    return repr(float(v)) if np.isfinite(v) else ""


def write_batch_csvs(table: CellTable, folder) -> None:
    """Write bulk_velocity_stderr.csv and bulk_velocity_batches.csv of a table with batches into
    `folder`, atomically (module docstring).  ValueError for a table without batches."""
    if table.batch_vx is None:
        raise ValueError("the cell table has no batches: nothing to write")
    folder = Path(folder)
    order = np.lexsort((table.x, table.z))
    held = _held(table)
    se = {"vx": table.vx_stderr, "vz": table.vz_stderr, "phi": table.solid_fraction_stderr}
    n = held.sum(axis=0)
    lines = [",".join(STDERR_COLUMNS)]
    for j in order:
        lines.append(f"{_centre(table, j)},{_number(se['vx'][j])},"
                     f"{_number(se['vz'][j])},{_number(se['phi'][j])},{int(n[j])}")
    write_text_atomic(folder / STDERR_CSV_NAME, "\n".join(lines) + "\n")
    samples = (np.asarray(table.batch_samples) if table.batch_samples is not None
               else held.astype(np.int64))
    lines = [",".join(BATCHES_COLUMNS)]
    for b in range(table.n_batches):
        for j in order[held[b, order]]:
            lines.append(f"{b},{_centre(table, j)},"
                         f"{float(table.batch_phi[b, j])!r},{float(table.batch_vx[b, j])!r},"
                         f"{float(table.batch_vz[b, j])!r},{int(samples[b, j])}")
    write_text_atomic(folder / BATCHES_CSV_NAME, "\n".join(lines) + "\n")


def with_batches(table: CellTable, path) -> CellTable:
    """The table (read from bulk_velocity.csv, without batches) with the batches of the
    bulk_velocity_batches.csv at `path` (module docstring): batch_phi (0 where a cell held no
    ball in a batch), batch_vx, batch_vz (NaN there), batch_samples.  ValueError (one line,
    without the path) for a file that is not one or whose cells are not the table's."""
    with open(path) as f:
        header = tuple(h.strip() for h in f.readline().strip().split(","))
    if header != tuple(BATCHES_COLUMNS):
        raise ValueError(f"header {','.join(header)}: must be {','.join(BATCHES_COLUMNS)}")
    data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    if data.shape[0] == 0 or data.shape[1] != len(BATCHES_COLUMNS):
        raise ValueError(f"{data.shape[0]} rows of {data.shape[1]} columns: must be at least "
                         f"one row of {len(BATCHES_COLUMNS)}")
    if not np.isfinite(data).all():
        i, k = np.argwhere(~np.isfinite(data))[0]
        raise ValueError(f"row {i + 1}, column {list(BATCHES_COLUMNS)[k]} = {data[i, k]}: "
                         "must be a finite number")
    b = np.rint(data[:, 0]).astype(np.int64)
    if (b < 0).any():
        raise ValueError(f"batch = {int(b.min())}: must be >= 0")
    h = table.cell_size
    key = {(int(i), int(k)): j for j, (i, k) in enumerate(zip(table.ix, table.iz))}
    ii = np.rint(data[:, 1] / h).astype(np.int64)
    kk = np.rint(data[:, 2] / h).astype(np.int64)
    cells = np.array([key.get((int(i), int(k)), -1) for i, k in zip(ii, kk)], dtype=np.int64)
    if (cells < 0).any():
        r = int(np.flatnonzero(cells < 0)[0])
        x, z = float(data[r, 1]), float(data[r, 2])
        raise ValueError(f"row {r + 1}: cell x = {x!r}, z = {z!r} m is not a cell of "
                         "bulk_velocity.csv")
    nb, n = int(b.max()) + 1, len(table)
    phi = np.zeros((nb, n))
    vx, vz = np.full((nb, n), np.nan), np.full((nb, n), np.nan)
    count = np.zeros((nb, n), np.int64)
    phi[b, cells], vx[b, cells], vz[b, cells] = data[:, 3], data[:, 4], data[:, 5]
    count[b, cells] = np.rint(data[:, 6]).astype(np.int64)
    return CellTable(x=table.x, z=table.z, solid_fraction=table.solid_fraction, vx=table.vx,
                     vz=table.vz, samples=table.samples, cell_size=h, batch_phi=phi,
                     batch_vx=vx, batch_vz=vz, batch_samples=count,
                     n_snapshots=table.n_snapshots, meta=dict(table.meta))
