"""Line profiles of the bulk velocity through the roll, every method on one plot: vx against z
in the column of cells at x = 0, and vz against x in the row of cells at mid-depth (the cell
row nearest half the DEM bed's height at x = 0, its top the highest cell there with solid
fraction >= min_solid_fraction).  Cells below min_solid_fraction are left out.  Error bars:
the batch-means standard error of each cell (stats.py) over the study's batches of whole
cycles, which the DEM's table has from its snapshots and a continuum's from its
bulk_velocity_batches.csv (cell_tables.py); a table without batches carries none."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vibroflow.io.pictures import pyplot
from vibroflow.measure.bulk import CellTable
from vibroflow.report.cell_tables import common_range, grid_of
from vibroflow.report.figures import png_bytes


@dataclass
class Profiles:
    """z_column (nz,) and x_row (nx,) cell centres (m); the row's height z_mid (m); per method
    "vx", "vx_stderr" along the column and "vz", "vz_stderr" along the row (m/s, NaN off the
    bed or without batches)."""

    z_column: np.ndarray
    x_row: np.ndarray
    z_mid: float
    lines: dict


def mid_depth(table: CellTable, min_solid_fraction: float) -> float:
    """Half the bed's height (m) at x = 0: half the centre height of the highest cell of the
    x = 0 column with solid fraction >= min_solid_fraction (the bottom of the U at z = 0)."""
    col = (table.ix == 0) & (table.solid_fraction >= min_solid_fraction)
    if not col.any():
        raise ValueError("no bed cell at x = 0")
    return 0.5 * float(np.max(np.asarray(table.z)[col]))


def profiles(tables: dict, min_solid_fraction: float) -> Profiles:
    """The profiles of every method (tables: method -> CellTable, the DEM's under "dem")."""
    ix_range, iz_range = common_range(list(tables.values()))
    h = tables["dem"].cell_size
    z_mid = mid_depth(tables["dem"], min_solid_fraction)
    k_mid = int(np.floor(z_mid / h + 0.5)) - iz_range[0]
    i0 = -ix_range[0]
    lines = {}
    for name, t in tables.items():
        g = grid_of(t, ix_range, iz_range, min_solid_fraction)
        lines[name] = {"vx": g["vx"][:, i0], "vx_stderr": g["vx_stderr"][:, i0],
                       "vz": g["vz"][k_mid, :], "vz_stderr": g["vz_stderr"][k_mid, :]}
    return Profiles(z_column=np.arange(iz_range[0], iz_range[1] + 1) * h,
                    x_row=np.arange(ix_range[0], ix_range[1] + 1) * h,
                    z_mid=(k_mid + iz_range[0]) * h, lines=lines)


def figure(p: Profiles) -> bytes:
    """Two panels: vx(z) at x = 0 and vz(x) at mid-depth, every method with its error bars."""
    plt = pyplot()
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(12, 4.6), layout="constrained")
    for k, (name, ln) in enumerate(p.lines.items()):
        style = dict(fmt="o-" if name == "dem" else "s--", ms=4, capsize=3, lw=1.2,
                     color=f"C{k}", label=name + ("" if np.isfinite(ln["vx_stderr"]).any()
                                                 else " (no error bars: no batches)"))
        a1.errorbar(ln["vx"], p.z_column, xerr=np.nan_to_num(ln["vx_stderr"]), **style)
        a2.errorbar(p.x_row, ln["vz"], yerr=np.nan_to_num(ln["vz_stderr"]), **style)
    a1.set_xlabel("vx relative to the tub (m/s)")
    a1.set_ylabel("z (m)")
    a1.set_title("vx against z at x = 0", fontsize=10)
    a2.set_xlabel("x (m)")
    a2.set_ylabel("vz relative to the tub (m/s)")
    a2.set_title(f"vz against x at mid-depth, z = {p.z_mid:.3f} m", fontsize=10)
    a1.axvline(0.0, color="0.6", lw=0.8)
    a2.axhline(0.0, color="0.6", lw=0.8)
    for ax in (a1, a2):
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle("time-averaged bulk velocity profiles, ± batch-means standard error")
    return png_bytes(fig)
