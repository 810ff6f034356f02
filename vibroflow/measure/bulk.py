"""The bulk (circulation) velocity cell table of tub47.md ("What is measured").

What is measured (tub47.md): each ball's velocity relative to the tub -- its lab velocity minus
the tub's rigid-body velocity at its centre -- in tub axes, averaged over the sampled instants
and over y, on square cells of side h = 15 mm in the tub frame's x-z plane, centred on multiples
of h.  A cell's solid fraction is the volume of the ball centres it holds (one ball volume per
centre) over the cell volume h x h x L_y, averaged over the samples.  The table (x, z, solid
fraction, vx, vz, samples) is written to ``bulk_velocity.csv`` by every method (our DEM, imported
LIGGGHTS runs, the continuum solvers) so that any two can be compared cell by cell.

Conventions chosen here:

* Cell (i, k) is centred at (i h, k h) and holds the centres with round(x/h) = i,
  round(z/h) = k (computed as floor(x/h + 1/2), so a centre exactly on an edge goes to the cell
  above / to the right).
* The grid covers the tub cross-section x in [-R, R], z in [0, rim]: every cell that overlaps it.
  Ball centres outside the grid (balls thrown above the rim) are not counted.
* The cell's velocity is the mean over every ball in the cell over every used sample
  (ball-weighted: each ball-sample counts once).  With equal balls this makes
  solid_fraction x velocity exactly the time-averaged solid-volume flux through the cell, which is
  what the stream function (circulation.py) needs.
* Only cells that held at least one ball-sample are kept in the table (no NaN rows).
* For standard errors by batch means (stats.py), the same sums are kept per batch: batch_phi,
  batch_vx, batch_vz (n_batches, n_cells); a cell empty in a batch has NaN velocity there.

The kinematics come from vibroflow.tub.motion (lab_to_tub_np, relative_velocity_tub_axes_np);
nothing here re-derives the tub's motion.

Memory: snapshots are read in chunks, so a (752, 14000, 3) float32 h5py dataset is never loaded
whole; the per-chunk temporaries stay well under 1 GB.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from vibroflow.measure.stats import stderr_of_batches
from vibroflow.io.atomic import write_text_atomic
from vibroflow.tub.geometry import TubGeometry
from vibroflow.tub.motion import lab_to_tub_np, relative_velocity_tub_axes_np

CSV_COLUMNS = ("x", "z", "solid_fraction", "vx", "vz", "samples")


@dataclass
class CellTable:
    """Cell-averaged bulk velocity and solid fraction (tub frame, SI).

    x, z : (n,) cell centres (m), multiples of cell_size.
    solid_fraction : (n,) mean solid fraction over the samples (-).
    vx, vz : (n,) ball-weighted mean velocity relative to the tub, in tub axes (m/s).
    samples : (n,) number of ball-samples that went into the cell (-).
    cell_size : cell side h (m).
    batch_phi, batch_vx, batch_vz : (n_batches, n) the same per batch of whole cycles, for
        batch-means standard errors; None when unknown (e.g. a table read back from CSV).
    batch_samples : (n_batches, n) ball-samples per batch, or None.
    n_snapshots : number of snapshots averaged (0 if unknown).
    """

    x: np.ndarray
    z: np.ndarray
    solid_fraction: np.ndarray
    vx: np.ndarray
    vz: np.ndarray
    samples: np.ndarray
    cell_size: float
    batch_phi: np.ndarray | None = None
    batch_vx: np.ndarray | None = None
    batch_vz: np.ndarray | None = None
    batch_samples: np.ndarray | None = None
    n_snapshots: int = 0
    meta: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return int(np.asarray(self.x).size)

    @property
    def n_batches(self) -> int:
        return 0 if self.batch_vx is None else int(self.batch_vx.shape[0])

    @property
    def ix(self) -> np.ndarray:
        """Integer cell index along x: x = ix * cell_size."""
        return np.rint(np.asarray(self.x) / self.cell_size).astype(np.int64)

    @property
    def iz(self) -> np.ndarray:
        """Integer cell index along z: z = iz * cell_size."""
        return np.rint(np.asarray(self.z) / self.cell_size).astype(np.int64)

    def _se(self, a):
        if a is None or a.shape[0] < 2:
            return np.full(len(self), np.nan)
        return stderr_of_batches(a, axis=0)

    @property
    def vx_stderr(self) -> np.ndarray:
        """Batch-means standard error of vx (m/s); NaN without batches."""
        return self._se(self.batch_vx)

    @property
    def vz_stderr(self) -> np.ndarray:
        """Batch-means standard error of vz (m/s); NaN without batches."""
        return self._se(self.batch_vz)

    @property
    def solid_fraction_stderr(self) -> np.ndarray:
        """Batch-means standard error of the solid fraction (-); NaN without batches."""
        return self._se(self.batch_phi)

    def batch(self, b: int) -> "CellTable":
        """The table of batch b alone (cells empty in that batch get phi 0, v 0, samples 0)."""
        if self.batch_vx is None:
            raise ValueError("this cell table has no per-batch data")
        n = self.batch_samples[b] if self.batch_samples is not None else self.samples
        return CellTable(self.x, self.z, self.batch_phi[b], np.nan_to_num(self.batch_vx[b]),
                         np.nan_to_num(self.batch_vz[b]), n, self.cell_size)


def grid_extent(geometry: TubGeometry, cell_size: float):
    """Cell index ranges (i_min, i_max, k_min, k_max), inclusive, of the cells that overlap the
    tub cross-section x in [-R, R], z in [0, rim] (m)."""
    h = float(cell_size)
    R = geometry.radius
    i_min = int(np.ceil(-R / h - 0.5))
    i_max = int(np.floor(R / h + 0.5))
    k_min = int(np.ceil(0.0 / h - 0.5))
    k_max = int(np.floor(geometry.rim_height / h + 0.5))
    return i_min, i_max, k_min, k_max


class CellAccumulator:
    """Streaming accumulator of the cell table: feed snapshot chunks with `add`, then `table()`.

    Use this directly when the snapshots come from an iterator (e.g. a solver in flight or a
    reader of LIGGGHTS dump files); `cell_table` wraps it for arrays and h5py datasets.

    Parameters
    ----------
    geometry : the tub (its radius and rim set the grid; its length is L_y, m).
    cell_size : h (m).
    pivot : (x, z) of the tub's rotation pivot in the tub frame (m).
    n_batches : number of batches of whole cycles (1 = no standard errors).
    """

    def __init__(self, geometry: TubGeometry, cell_size: float = 0.015,
                 pivot=(0.0, -0.10), n_batches: int = 1):
        if cell_size <= 0:
            raise ValueError(f"cell_size = {cell_size}: must be > 0 m")
        if n_batches < 1:
            raise ValueError(f"n_batches = {n_batches}: must be at least 1")
        self.geometry = geometry
        self.h = float(cell_size)
        self.length = float(geometry.length)
        self.pivot = (float(pivot[0]), float(pivot[1]))
        self.n_batches = int(n_batches)
        self.i_min, self.i_max, self.k_min, self.k_max = grid_extent(geometry, cell_size)
        self.nx = self.i_max - self.i_min + 1
        self.nz = self.k_max - self.k_min + 1
        self.ncell = self.nx * self.nz
        size = self.n_batches * self.ncell
        self.count = np.zeros(size)
        self.volume = np.zeros(size)
        self.sum_vx = np.zeros(size)
        self.sum_vz = np.zeros(size)
        self.snapshots = np.zeros(self.n_batches, dtype=np.int64)

    def add(self, positions, velocities, tub_pose, radius, batch) -> None:
        """Add a chunk of c snapshots.

        positions, velocities : (c, N, 3) lab frame (m, m/s), any float dtype.
        tub_pose : (c, 6) X, Z, theta, Xdot, Zdot, thetadot (m, rad, m/s, rad/s).
        radius : (N,) ball radii (m).
        batch : (c,) batch index of each snapshot; negative = skip the snapshot.
        """
        batch = np.asarray(batch, dtype=np.int64).reshape(-1)
        keep = (batch >= 0) & (batch < self.n_batches)
        if not np.any(keep):
            return
        pos = np.asarray(positions)[keep]
        vel = np.asarray(velocities)[keep]
        pose = np.asarray(tub_pose, dtype=float)[keep]
        batch = batch[keep]
        X, Z, th, Xd, Zd, thd = (pose[:, j, None] for j in range(6))  # (c, 1) broadcasts over N
        # tub47.md "Bulk velocity": position in the tub frame, velocity relative to the tub's
        # rigid motion at the ball centre, in tub axes -- the shared kinematics of tub/motion.py.
        p_tub = lab_to_tub_np(pos, X, Z, th, self.pivot)
        v_rel = relative_velocity_tub_axes_np(pos, vel, X, Z, th, Xd, Zd, thd, self.pivot)
        i = np.floor(p_tub[..., 0] / self.h + 0.5).astype(np.int64)
        k = np.floor(p_tub[..., 2] / self.h + 0.5).astype(np.int64)
        inside = (i >= self.i_min) & (i <= self.i_max) & (k >= self.k_min) & (k <= self.k_max)
        flat = (batch[:, None] * self.ncell + (k - self.k_min) * self.nx + (i - self.i_min))
        flat = flat[inside]
        r = np.asarray(radius, dtype=float)
        vol = np.broadcast_to(4.0 / 3.0 * np.pi * r**3, inside.shape)[inside]
        n = self.count.size
        self.count += np.bincount(flat, minlength=n)
        self.volume += np.bincount(flat, weights=vol, minlength=n)
        self.sum_vx += np.bincount(flat, weights=v_rel[..., 0][inside], minlength=n)
        self.sum_vz += np.bincount(flat, weights=v_rel[..., 2][inside], minlength=n)
        self.snapshots += np.bincount(batch, minlength=self.n_batches)

    def table(self) -> CellTable:
        """The cell table of what has been added (cells with at least one ball-sample)."""
        nb, nc = self.n_batches, self.ncell
        count = self.count.reshape(nb, nc)
        volume = self.volume.reshape(nb, nc)
        svx = self.sum_vx.reshape(nb, nc)
        svz = self.sum_vz.reshape(nb, nc)
        total = count.sum(axis=0)
        cells = np.nonzero(total > 0)[0]
        kk, ii = np.divmod(cells, self.nx)
        x = (ii + self.i_min) * self.h
        z = (kk + self.k_min) * self.h
        cell_volume = self.h * self.h * self.length
        n_snap = int(self.snapshots.sum())
        phi = volume.sum(axis=0)[cells] / (max(n_snap, 1) * cell_volume)
        vx = svx.sum(axis=0)[cells] / total[cells]
        vz = svz.sum(axis=0)[cells] / total[cells]
        with np.errstate(invalid="ignore", divide="ignore"):
            bphi = volume[:, cells] / (np.maximum(self.snapshots, 1)[:, None] * cell_volume)
            bvx = svx[:, cells] / count[:, cells]
            bvz = svz[:, cells] / count[:, cells]
        bphi[self.snapshots == 0] = np.nan
        return CellTable(x=x, z=z, solid_fraction=phi, vx=vx, vz=vz,
                         samples=total[cells].astype(np.int64), cell_size=self.h,
                         batch_phi=bphi, batch_vx=bvx, batch_vz=bvz,
                         batch_samples=count[:, cells].astype(np.int64), n_snapshots=n_snap,
                         meta={"batch_snapshots": self.snapshots.copy()})


def cell_table(positions, velocities, tub_pose, radius, geometry: TubGeometry,
               cell_size: float = 0.015, pivot=(0.0, -0.10), batch_of_sample=None,
               n_batches: int | None = None, chunk_snapshots: int | None = None) -> CellTable:
    """Cell table from snapshot arrays (numpy arrays, memmaps or h5py datasets).

    Parameters
    ----------
    positions, velocities : (S, N, 3) lab positions (m) and velocities (m/s); read in chunks of
        snapshots, so h5py datasets are streamed.
    tub_pose : (S, 6) X, Z, theta, Xdot, Zdot, thetadot per snapshot (m, rad, m/s, rad/s).
    radius : (N,) ball radii (m).
    geometry : the tub (grid extent and L_y = geometry.length, m).
    cell_size : h (m), tub47: 0.015.
    pivot : rotation pivot (x, z) in the tub frame (m).
    batch_of_sample : (S,) batch index per snapshot (stats.batches_of_whole_cycles), negative =
        not used; default: every snapshot in one batch.
    n_batches : number of batches (default: max(batch_of_sample) + 1).
    chunk_snapshots : snapshots read at a time (default: about 16 MB of float64 per array).
    """
    S = positions.shape[0]
    N = positions.shape[1]
    if batch_of_sample is None:
        batch_of_sample = np.zeros(S, dtype=np.int64)
    batch_of_sample = np.asarray(batch_of_sample, dtype=np.int64)
    if batch_of_sample.shape != (S,):
        raise ValueError(f"batch_of_sample has shape {batch_of_sample.shape}: must be ({S},)")
    if n_batches is None:
        n_batches = max(int(batch_of_sample.max(initial=-1)) + 1, 1)
    acc = CellAccumulator(geometry, cell_size, pivot, n_batches)
    pose = np.asarray(tub_pose, dtype=float)
    r = np.asarray(radius, dtype=float)
    if chunk_snapshots is None:
        chunk_snapshots = max(1, int(16e6 // (max(N, 1) * 3 * 8)))
    used = np.nonzero(batch_of_sample >= 0)[0]
    if used.size == 0:
        return acc.table()
    for s0 in range(int(used[0]), int(used[-1]) + 1, chunk_snapshots):
        s1 = min(s0 + chunk_snapshots, int(used[-1]) + 1)
        b = batch_of_sample[s0:s1]
        if not np.any(b >= 0):
            continue
        acc.add(positions[s0:s1], velocities[s0:s1], pose[s0:s1], r, b)
    return acc.table()


def write_csv(table: CellTable, path) -> None:
    """Write bulk_velocity.csv atomically (vibroflow.io.atomic).

    Columns: x, z (m, cell centre, tub frame), solid_fraction (-), vx, vz (m/s, relative to the
    tub, tub axes), samples (ball-samples); one header line, then one row per cell, sorted by z
    then x.
    """
    order = np.lexsort((table.x, table.z))
    lines = [",".join(CSV_COLUMNS)]
    for j in order:
        lines.append(f"{table.x[j]:.10g},{table.z[j]:.10g},{table.solid_fraction[j]:.10g},"
                     f"{table.vx[j]:.10g},{table.vz[j]:.10g},{int(table.samples[j])}")
    write_text_atomic(path, "\n".join(lines) + "\n")


def _infer_cell_size(x, z) -> float:
    """Largest h of which every cell centre coordinate is a multiple (a float GCD, to 1e-9 m)."""
    tol = 1e-9
    vals = np.unique(np.round(np.abs(np.concatenate([x, z])), 12))
    vals = vals[vals > tol]
    if vals.size == 0:
        return float("nan")
    g = float(vals[0])
    for v in vals[1:]:
        a, b = float(v), g
        while b > tol:
            r = math.fmod(a, b)
            if b - r < tol:
                r = 0.0
            a, b = b, r
        g = a
    return float(np.round(g, 12))


def read_csv(path, cell_size: float | None = None) -> CellTable:
    """Read a bulk_velocity.csv (any method's) back into a CellTable (no per-batch data).
    ValueError (one line, without the path: the caller names the file) on a table that is not
    one: another header, text, NaN or inf in a number, a negative count.

    cell_size (m) defaults to the largest length of which every centre coordinate is a multiple
    (right for any table with two neighbouring cells along some row or column; pass it when
    known).
    """
    with open(path) as f:
        header = f.readline().strip().split(",")
    if tuple(h.strip() for h in header[:len(CSV_COLUMNS)]) != CSV_COLUMNS:
        raise ValueError(f"header {','.join(header)}: must start with {','.join(CSV_COLUMNS)}")
    data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2, usecols=range(len(CSV_COLUMNS)))
    bad = np.argwhere(~np.isfinite(data))
    if bad.size:  # every row is a cell that held samples: a NaN or inf is no measurement
        i, j = bad[0]
        raise ValueError(f"row {i + 1}, column {CSV_COLUMNS[j]} = {data[i, j]}: must "
                         "be a finite number")
    x, z, phi, vx, vz, n = (data[:, j] for j in range(len(CSV_COLUMNS)))
    if (n < 0).any() or (phi < 0).any():
        i = int(np.flatnonzero((n < 0) | (phi < 0))[0])
        raise ValueError(f"row {i + 1}: solid_fraction = {phi[i]}, samples = {n[i]}: "
                         "must be >= 0")
    h = _infer_cell_size(x, z) if cell_size is None else float(cell_size)
    return CellTable(x=x, z=z, solid_fraction=phi, vx=vx, vz=vz,
                     samples=np.rint(n).astype(np.int64), cell_size=h)


def probe_values(table: CellTable, probes) -> dict:
    """Bulk velocity at probe points: the cell holding each probe (tub47.md "Probe points").

    probes : mapping name -> (x, z) in m, or an object with .x and .z (scenario Probe).
    Returns name -> {x, z (the probe point, m), cell_x, cell_z (its cell's centre, m),
    vx, vz (m/s), vx_stderr, vz_stderr (m/s, batch means; NaN without batches), solid_fraction,
    solid_fraction_stderr (-, batch means; NaN without batches), samples}.  A probe in a cell
    that held no ball gets NaN velocities, 0 samples and a "note" saying why (the probe lies
    above the bed's surface, or outside the tub).
    """
    h = table.cell_size
    lookup = {(int(a), int(b)): j for j, (a, b) in enumerate(zip(table.ix, table.iz))}
    se_x, se_z, se_phi = table.vx_stderr, table.vz_stderr, table.solid_fraction_stderr
    out = {}
    for name, p in probes.items():
        px, pz = (p.x, p.z) if hasattr(p, "x") else (float(p[0]), float(p[1]))
        key = (int(np.floor(px / h + 0.5)), int(np.floor(pz / h + 0.5)))
        j = lookup.get(key)
        rec = {"x": float(px), "z": float(pz), "cell_x": key[0] * h, "cell_z": key[1] * h}
        if j is None:
            rec.update(vx=float("nan"), vz=float("nan"), vx_stderr=float("nan"),
                       vz_stderr=float("nan"), solid_fraction=0.0,
                       solid_fraction_stderr=float("nan"), samples=0)
        else:
            rec.update(vx=float(table.vx[j]), vz=float(table.vz[j]),
                       vx_stderr=float(se_x[j]), vz_stderr=float(se_z[j]),
                       solid_fraction=float(table.solid_fraction[j]),
                       solid_fraction_stderr=float(se_phi[j]),
                       samples=int(table.samples[j]))
        if rec["samples"] == 0:
            rec["note"] = (f"no ball entered its {h * 1e3:.0f} mm cell in the averaging window: "
                           "the probe lies above the bed's surface (a shallow bed, or a probe "
                           "placed high), or outside the tub; its velocity is n/a")
        out[name] = rec
    return out
