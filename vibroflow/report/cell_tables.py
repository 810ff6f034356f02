"""Every method's bulk-velocity cell table as the report's new sections use it, with one table
per batch of whole cycles (so that its profiles and turnover time carry batch-means standard
errors over the study's batches, stats.py): each method's bulk_velocity.csv with the batches its
run wrote beside it (bulk_velocity_batches.csv, measure.bulk_batches). A DEM folder without
that file (written before the DEM wrote it) has its batches rebuilt from its snapshots
(`dem_batch_table`: vibroflow.measure.bulk.cell_table over the snapshots of the averaging
window's whole cycles, batches_of_whole_cycles, the table its run wrote); a table whose batches
are missing and cannot be rebuilt (a LIGGGHTS import without them) carries no errors.
"""
from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

from vibroflow.measure.bulk import CellTable, cell_table, read_csv
from vibroflow.measure.bulk_batches import BATCHES_CSV_NAME, with_batches
from vibroflow.measure.stats import batches_of_whole_cycles

DEM = "dem"


def csv_table(data, name: str) -> CellTable:
    """A method's bulk_velocity.csv of the study as a CellTable, with the batches of the
    bulk_velocity_batches.csv beside it where there is one that fits it (no batches
    otherwise)."""
    entry = data.summary["methods"].get(name, {})
    rel = entry.get("bulk_velocity_csv", f"{name}/bulk_velocity.csv")
    path = Path(rel) if Path(rel).is_absolute() else data.out / rel
    if not path.is_file():
        path = data.out / name / "bulk_velocity.csv"
    table = read_csv(path, cell_size=float(data.scenario.analysis.cell_size))
    batches = path.parent / BATCHES_CSV_NAME
    if not batches.is_file():
        return table
    try:
        return with_batches(table, batches)
    except (OSError, ValueError) as exc:  # listed under the page's "Missing pieces"
        data.notes[batches_note(name)] = (f"{batches}: unreadable ({exc}); {name}'s profiles "
                                          "and turnover time carry no error bars")
        return table


def batches_note(name: str) -> str:
    """The key of StudyData.notes saying why a method's batches are unreadable."""
    return f"{name} batches"


def dem_batch_table(data) -> CellTable | None:
    """The DEM's cell table with its batches, rebuilt from DIR/dem/dem.h5's snapshots of the
    averaging window (module docstring): the table the DEM run wrote, with its batches; None
    without snapshots in the window."""
    h5 = data.out / DEM / "dem.h5"
    if not h5.is_file():
        return None
    sc = data.scenario
    run = sc.run
    t0, t1 = run.duration - run.average_last, run.duration
    try:
        with h5py.File(h5, "r") as f:
            if "snapshots/position" not in f or f["snapshots/time"].shape[0] == 0:
                return None
            batch = batches_of_whole_cycles(f["snapshots/time"][:], t0, t1,
                                            float(sc.motion.frequency), int(run.batches))
            if not (batch >= 0).any():
                return None
            pivot = tuple(float(p) for p in sc.motion.pivot)
            return cell_table(f["snapshots/position"], f["snapshots/velocity"],
                              f["snapshots/tub_pose"][:], f["particles/radius"][:],
                              data.geometry, float(sc.analysis.cell_size), pivot=pivot,
                              batch_of_sample=batch, n_batches=int(run.batches))
    except (OSError, KeyError, ValueError):
        return None


def method_tables(data) -> dict[str, CellTable]:
    """method -> its cell table, the DEM first (module docstring)."""
    out: dict[str, CellTable] = {}
    for name in data.methods:
        table = csv_table(data, name)
        if name == DEM and table.n_batches < 2:
            rebuilt = dem_batch_table(data)
            if rebuilt is not None:
                data.notes.pop(batches_note(name), None)
                table = rebuilt
        out[name] = table
    return out


def grid_of(table: CellTable, ix_range: tuple[int, int], iz_range: tuple[int, int],
            min_solid_fraction: float) -> dict:
    """A table's cells on the grid of cell indices ix_range[0] .. ix_range[1], iz_range[0] ..
    iz_range[1] (inclusive): arrays (nz, nx) "vx", "vz" (m/s) and their batch-means standard
    errors "vx_stderr", "vz_stderr" (NaN without batches), NaN where the cell is missing or its
    solid fraction is below min_solid_fraction; "solid_fraction" (0 where missing)."""
    nx = ix_range[1] - ix_range[0] + 1
    nz = iz_range[1] - iz_range[0] + 1
    i, k = table.ix - ix_range[0], table.iz - iz_range[0]
    ok = (i >= 0) & (i < nx) & (k >= 0) & (k < nz)
    phi = np.zeros((nz, nx))
    phi[k[ok], i[ok]] = table.solid_fraction[ok]
    bed = phi >= min_solid_fraction
    out = {"solid_fraction": phi}
    for key, values in (("vx", table.vx), ("vz", table.vz), ("vx_stderr", table.vx_stderr),
                        ("vz_stderr", table.vz_stderr)):
        a = np.full((nz, nx), np.nan)
        a[k[ok], i[ok]] = np.asarray(values, dtype=float)[ok]
        out[key] = np.where(bed, a, np.nan)
    return out


def common_range(tables) -> tuple[tuple[int, int], tuple[int, int]]:
    """The smallest (ix_range, iz_range) holding every cell of the tables."""
    ix = np.concatenate([t.ix for t in tables])
    iz = np.concatenate([t.iz for t in tables])
    return (int(ix.min()), int(ix.max())), (int(iz.min()), int(iz.max()))
