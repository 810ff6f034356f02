"""parts.nc: what each part in the bed receives, the one schema the DEM, both continua and the
report share (an xarray Dataset in a NetCDF-4 file written with h5netcdf, atomically).

Dimensions: `part` (the parts' names as its coordinate, in the scenario's order), `patch`
(0 .. MAX_PATCHES - 1, the most patches a part has, vibroflow.tub.parts.patch_layout; a part's
unused entries NaN), `phase` (run.phases_per_cycle bins of the cycle), `component` ("x", "y",
"z").  Variables (VARIABLES: dims, units, long_name; every one carries its units and
long_name): the patches' names and areas, the impact rate per area, the normal impact speed's
mean, median and 95th percentile, the energy flux, each mean with its batch-means standard
error (`_stderr`), and the force on the part and its torque about the part's centre by
phase of the cycle.  Dataset attrs: `method`
("dem", "lagrangian", "eulerian"), `window_s` (the averaging window, s), `batches`, and
`inferred_from` (what the values come from; a method that infers only some variables leaves
the others NaN and says so here).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import xarray as xr

from vibroflow.errors import InputError

from .atomic import atomic_path

PARTS_NC_NAME = "parts.nc"
#: the most patches a part has (a cylinder's sectors, vibroflow.tub.parts.CYLINDER_SECTORS)
MAX_PATCHES = 36
METHODS = ("dem", "lagrangian", "eulerian")
COMPONENTS = ("x", "y", "z")

_PP = ("part", "patch")
#: name -> (dims, units, long_name)
VARIABLES = {
    "patch_name": (_PP, "1", "name of the surface patch"),
    "patch_area_m2": (_PP, "m2", "area of the surface patch in contact with the media"),
    "impact_rate_per_area": (_PP, "m-2 s-1", "ball impacts per unit area and time"),
    "impact_rate_per_area_stderr": (_PP, "m-2 s-1", "batch-means standard error of "
                                                    "impact_rate_per_area"),
    "normal_speed_mean": (_PP, "m s-1", "mean normal impact speed"),
    "normal_speed_mean_stderr": (_PP, "m s-1", "batch-means standard error of "
                                                "normal_speed_mean"),
    "normal_speed_median": (_PP, "m s-1", "median normal impact speed"),
    "normal_speed_p95": (_PP, "m s-1", "95th percentile of the normal impact speed"),
    "energy_flux": (_PP, "W m-2", "impact kinetic energy delivered per unit area and time"),
    "energy_flux_stderr": (_PP, "W m-2", "batch-means standard error of energy_flux"),
    "force": (("part", "phase", "component"), "N", "force of the media on the part by phase "
                                                    "of the cycle (tub axes for a tub-fixed "
                                                    "part)"),
    "force_stderr": (("part", "phase", "component"), "N", "batch-means standard error of "
                                                           "force"),
    "torque": (("part", "phase", "component"), "N m", "torque of the media on the part about "
                                                      "its centre by phase of the cycle (tub "
                                                      "axes for a tub-fixed part)"),
    "torque_stderr": (("part", "phase", "component"), "N m", "batch-means standard error of "
                                                             "torque"),
}


def empty_parts_dataset(names: list[str], patch_names: list[list[str]],
                        patch_areas: list[np.ndarray], n_phases: int, method: str,
                        window_s: float, batches: int, inferred_from: str) -> xr.Dataset:
    """A parts.nc Dataset with the parts' names, patches and areas (m^2) filled in and every
    measured variable NaN, for a writer to fill."""
    if method not in METHODS:
        raise ValueError(f"method = {method!r}: must be one of {', '.join(METHODS)}")
    n = len(names)
    data = {}
    for var, (dims, units, long_name) in VARIABLES.items():
        shape = tuple({"part": n, "patch": MAX_PATCHES, "phase": n_phases,
                       "component": 3}[d] for d in dims)
        if var == "patch_name":
            a = np.full(shape, "", dtype=object)
            for k, pn in enumerate(patch_names):
                a[k, :len(pn)] = pn
            a = a.astype(str)
        else:
            a = np.full(shape, np.nan)
        if var == "patch_area_m2":
            for k, area in enumerate(patch_areas):
                a[k, :len(area)] = area
        data[var] = xr.Variable(dims, a, attrs={"units": units, "long_name": long_name})
    return xr.Dataset(data, coords={"part": np.array(names, dtype=str),
                                    "patch": np.arange(MAX_PATCHES),
                                    "phase": np.arange(n_phases),
                                    "component": np.array(COMPONENTS, dtype=str)},
                      attrs={"method": method, "window_s": float(window_s),
                             "batches": int(batches), "inferred_from": inferred_from})


def write_parts(path, ds: xr.Dataset) -> Path:
    """Write a parts.nc Dataset atomically (vibroflow.io.atomic)."""
    path = Path(path)
    with atomic_path(path) as tmp:
        ds.to_netcdf(tmp, mode="w", engine="h5netcdf", invalid_netcdf=False)
    return path


def read_parts(path) -> xr.Dataset:
    """A parts.nc file back, checked against the schema (InputError, one line, naming the
    file and what is wrong)."""
    path = Path(path)
    try:
        ds = xr.load_dataset(path, engine="h5netcdf")
    except (OSError, ValueError) as e:
        raise InputError(f"{path}: not a readable parts.nc ({e})") from None
    missing = [v for v in VARIABLES if v not in ds]
    if missing:
        raise InputError(f"{path}: not a parts.nc file: no variable {', '.join(missing)}")
    if ds.attrs.get("method") not in METHODS:
        raise InputError(f"{path}: attribute method = {ds.attrs.get('method')!r}: must be one "
                         f"of {', '.join(METHODS)}")
    return ds
