"""parts.nc: what the parts in the bed receive, one schema for every method (the DEM, the
continuum's two formulations; the report reads it).  An xarray Dataset written with h5netcdf,
atomically (vibroflow.io.atomic).

Dims: part (the parts' names, scenario order), patch (0 .. MAX_PATCHES - 1; a part's unused
patches NaN), phase (the run's phases_per_cycle bins of the cycle), component ("x", "y", "z").
Variables, each with attrs `units` and `long_name` (VARIABLES): patch_name, patch_area_m2,
impact_rate_per_area (+ _stderr), normal_speed_mean (+ _stderr), normal_speed_median,
normal_speed_p95, energy_flux (+ _stderr), force (+ _stderr).  Dataset attrs: method ("dem",
"lagrangian", "eulerian"), window_s (the averaging window, s), batches, inferred_from (what the
numbers come from).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import xarray as xr

from ..tub.parts import Part, patch_layout
from .atomic import atomic_path

MAX_PATCHES = 36
COMPONENTS = ("x", "y", "z")

#: name -> (dims, units, long_name)
VARIABLES = {
    "patch_area_m2": (("part", "patch"), "m^2", "area of the surface patch"),
    "impact_rate_per_area": (("part", "patch"), "1/(m^2 s)",
                             "ball impacts per unit area and time"),
    "impact_rate_per_area_stderr": (("part", "patch"), "1/(m^2 s)",
                                    "batch-means standard error of impact_rate_per_area"),
    "normal_speed_mean": (("part", "patch"), "m/s", "mean normal impact speed"),
    "normal_speed_mean_stderr": (("part", "patch"), "m/s",
                                 "batch-means standard error of normal_speed_mean"),
    "normal_speed_median": (("part", "patch"), "m/s", "median normal impact speed"),
    "normal_speed_p95": (("part", "patch"), "m/s", "95th percentile of the normal impact speed"),
    "energy_flux": (("part", "patch"), "W/m^2", "impact energy delivered per unit area and time"),
    "energy_flux_stderr": (("part", "patch"), "W/m^2",
                           "batch-means standard error of energy_flux"),
    "force": (("part", "phase", "component"), "N",
              "contact force of the media on the part by phase of the cycle (tub axes for a "
              "tub-fixed part)"),
    "force_stderr": (("part", "phase", "component"), "N",
                     "batch-means standard error of force"),
}


def empty_dataset(parts: tuple[Part, ...], slice_length_m: float, n_phases: int, method: str,
                  window_s: float, batches: int, inferred_from: str) -> xr.Dataset:
    """A parts.nc Dataset with the patches' names and areas filled and every measure NaN."""
    n = len(parts)
    names = np.full((n, MAX_PATCHES), "", dtype=object)
    area = np.full((n, MAX_PATCHES), np.nan)
    for k, p in enumerate(parts):
        pn, pa = patch_layout(p, slice_length_m)
        names[k, :len(pn)] = pn
        area[k, :len(pa)] = pa
    data = {"patch_name": (("part", "patch"), names.astype(str),
                           {"units": "1", "long_name": "name of the surface patch"})}
    for name, (dims, units, long_name) in VARIABLES.items():
        shape = tuple({"part": n, "patch": MAX_PATCHES, "phase": n_phases,
                       "component": 3}[d] for d in dims)
        values = area if name == "patch_area_m2" else np.full(shape, np.nan)
        data[name] = (dims, values, {"units": units, "long_name": long_name})
    coords = {"part": [p.name for p in parts], "patch": np.arange(MAX_PATCHES),
              "phase": np.arange(n_phases) / max(n_phases, 1), "component": list(COMPONENTS)}
    ds = xr.Dataset(data, coords=coords,
                    attrs={"method": method, "window_s": float(window_s), "batches": int(batches),
                           "inferred_from": inferred_from})
    ds["phase"].attrs.update(units="1", long_name="phase of the vibration cycle (fraction)")
    ds["patch"].attrs.update(units="1", long_name="patch index (vibroflow.tub.parts)")
    return ds


def write_parts_nc(path: Path, ds: xr.Dataset) -> Path:
    """Write the Dataset to `path` atomically (h5netcdf)."""
    with atomic_path(Path(path), suffix=".nc") as tmp:
        ds.to_netcdf(tmp, mode="w", engine="h5netcdf", invalid_netcdf=False)
    return Path(path)


def read_parts_nc(path: Path) -> xr.Dataset:
    """The Dataset of a parts.nc (loaded into memory, the file closed)."""
    return xr.load_dataset(Path(path), engine="h5netcdf")
