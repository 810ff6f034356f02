"""Difference maps of the bulk velocity, continuum minus DEM, on the analysis cells: the
components dvx, dvz (m/s) and the magnitude of the difference |v_c - v_DEM| (m/s), on the
cells where both methods hold bed (solid fraction >= the analysis' min_solid_fraction, the
cells tub47.md's E is taken over), one colour scale for every method."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from matplotlib.colors import Normalize

from vibroflow.io.pictures import pyplot
from vibroflow.measure.bulk import CellTable
from vibroflow.report.cell_tables import common_range, grid_of
from vibroflow.report.figures import _outline, png_bytes


@dataclass
class DifferenceMaps:
    """x (nx,), z (nz,) cell centres (m); maps: method -> {"dvx", "dvz", "dspeed"} (nz, nx)
    arrays (m/s, NaN off the shared bed)."""

    x: np.ndarray
    z: np.ndarray
    maps: dict


def velocity_difference(a: CellTable, b: CellTable, min_solid_fraction: float,
                        ix_range=None, iz_range=None) -> dict:
    """a minus b on the cells both hold with solid fraction >= min_solid_fraction: "dvx",
    "dvz" and "dspeed" = |v_a - v_b| (m/s), (nz, nx) arrays over ix_range, iz_range (default:
    the cells of both)."""
    if ix_range is None or iz_range is None:
        ix_range, iz_range = common_range([a, b])
    ga = grid_of(a, ix_range, iz_range, min_solid_fraction)
    gb = grid_of(b, ix_range, iz_range, min_solid_fraction)
    dvx, dvz = ga["vx"] - gb["vx"], ga["vz"] - gb["vz"]
    return {"dvx": dvx, "dvz": dvz, "dspeed": np.hypot(dvx, dvz)}


def difference_maps(data, tables: dict) -> DifferenceMaps:
    """Every continuum method's maps against the DEM (tables: method -> CellTable)."""
    ix_range, iz_range = common_range(list(tables.values()))
    h = float(data.scenario.analysis.cell_size)
    maps = {n: velocity_difference(tables[n], tables["dem"], data.min_solid_fraction,
                                   ix_range, iz_range) for n in data.continuum_methods}
    return DifferenceMaps(x=np.arange(ix_range[0], ix_range[1] + 1) * h,
                          z=np.arange(iz_range[0], iz_range[1] + 1) * h, maps=maps)


def figure(data, dm: DifferenceMaps) -> bytes:
    """One row per continuum method: dvx, dvz on one diverging scale, |dv| from 0, on the U."""
    names = list(dm.maps)
    plt = pyplot()
    fig, axes = plt.subplots(max(len(names), 1), 3, figsize=(13.5, 4.0 * max(len(names), 1)),
                             squeeze=False, layout="constrained")
    vals = [np.abs(m[k]) for m in dm.maps.values() for k in ("dvx", "dvz")]
    big = max([float(np.nanmax(v)) for v in vals if np.isfinite(v).any()] or [1e-3])
    sp = max([float(np.nanmax(m["dspeed"])) for m in dm.maps.values()
              if np.isfinite(m["dspeed"]).any()] or [1e-3])
    div, mag = Normalize(-big, big), Normalize(0.0, sp)
    top = float(dm.z.max()) + float(data.scenario.analysis.cell_size) if dm.z.size else None
    meshes = {}
    for row, name in zip(axes, names):
        for ax, key, norm, cmap, what in (
                (row[0], "dvx", div, "RdBu_r", "vx"), (row[1], "dvz", div, "RdBu_r", "vz"),
                (row[2], "dspeed", mag, "magma", "|v|")):
            meshes[key] = ax.pcolormesh(dm.x, dm.z, dm.maps[name][key], shading="nearest",
                                        cmap=cmap, norm=norm)
            _outline(ax, data, top)
            label = f"|v_{name} - v_dem|" if key == "dspeed" else f"{what}: {name} - dem"
            ax.set_title(f"{label} (m/s)", fontsize=9)
    if names:
        fig.colorbar(meshes["dvx"], ax=list(axes[:, :2].ravel()), shrink=0.8,
                     label="velocity difference, continuum - DEM (m/s)")
        fig.colorbar(meshes["dspeed"], ax=list(axes[:, 2]), shrink=0.8,
                     label="|v_continuum - v_DEM| (m/s)")
    fig.suptitle("bulk velocity relative to the tub, continuum minus DEM, cells where both "
                 f"hold solid fraction >= {data.min_solid_fraction:g}")
    return png_bytes(fig)
