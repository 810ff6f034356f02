"""The granular temperature and solid fraction of the DEM and of each continuum method on the
analysis cells, side by side with their difference (continuum minus DEM), as the report shows
them.

The DEM's maps are its time-averaged coarse-grained fields (calibration/fields.nc,
"temperature" m^2/s^2 and "solid_fraction") gathered onto the analysis cells: the temperature mass-weighted (by the
fields' density) over the grid points inside a cell, the solid fraction their mean; a cell with
no mass has T = 0.  A continuum's are its temperature.csv (continuum.temperature_outputs), which
a run writes only when it carries the temperature (ContinuumOptions.temperature); a method
without it is listed in `without`.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from vibroflow.continuum.temperature_outputs import TEMPERATURE_CSV_NAME
from vibroflow.measure.phase_shear import node_grid

T_KEY = "temperature_m2_s2"
PHI_KEY = "solid_fraction"


@dataclass
class TemperatureMaps:
    """x (nx,), z (nz,) the analysis cells' centres (m); dem: {T_KEY, PHI_KEY} of (nz, nx)
    arrays, or None without the DEM's fields; continua: method -> {T_KEY, PHI_KEY, and their
    differences to the DEM "temperature_difference_m2_s2", "solid_fraction_difference" (None
    without the DEM's fields)}, for the methods that carry the temperature; without: the
    methods that ran without it."""

    x: np.ndarray
    z: np.ndarray
    dem: dict | None
    continua: dict = field(default_factory=dict)
    without: list = field(default_factory=list)


def dem_cell_maps(ds, h: float, nxh: int, nz: int) -> dict:
    """The DEM's fields (an xarray Dataset with x, z coordinates m and (x, z) arrays
    "temperature", "solid_fraction", "density") on the analysis cells of side h (m), nxh either
    side of x = 0 and nz up (module docstring): {T_KEY, PHI_KEY} of (nz, 2 nxh + 1) arrays."""
    x = np.asarray(ds["x"].values, dtype=float)
    z = np.asarray(ds["z"].values, dtype=float)
    X, Z = np.meshgrid(x, z, indexing="ij")
    i = np.floor(X / h + 0.5).astype(np.int64) + nxh
    k = np.floor(Z / h + 0.5).astype(np.int64)
    T = np.asarray(ds["temperature"].values, dtype=float)
    phi = np.asarray(ds["solid_fraction"].values, dtype=float)
    rho = np.asarray(ds["density"].values, dtype=float)
    ok = (i >= 0) & (i <= 2 * nxh) & (k >= 0) & (k < nz)
    flat = (k * (2 * nxh + 1) + i)[ok]
    size = nz * (2 * nxh + 1)
    T, phi, rho = (np.where(np.isfinite(a), a, 0.0)[ok] for a in (T, phi, rho))
    M = np.bincount(flat, rho, size)
    E = np.bincount(flat, rho * T, size)
    n = np.bincount(flat, minlength=size)
    S = np.bincount(flat, phi, size)
    return {T_KEY: np.divide(E, M, out=np.zeros(size), where=M > 0).reshape(nz, -1),
            PHI_KEY: np.divide(S, n, out=np.zeros(size), where=n > 0).reshape(nz, -1)}


def read_temperature_csv(path: Path, h: float, nxh: int, nz: int) -> dict | None:
    """A continuum run's temperature.csv on the analysis cells: {T_KEY, PHI_KEY} of
    (nz, 2 nxh + 1) arrays (0 in a cell it does not list), or None when the file is missing or
    unreadable."""
    try:
        lines = Path(path).read_text().splitlines()
    except (OSError, UnicodeDecodeError):
        return None
    if len(lines) < 2:
        return None
    head = lines[0].split(",")
    cols = ("x", "z", "granular_temperature_m2_s2", "solid_fraction")
    if not all(c in head for c in cols):
        return None
    idx = [head.index(c) for c in cols]
    out = {T_KEY: np.zeros((nz, 2 * nxh + 1)), PHI_KEY: np.zeros((nz, 2 * nxh + 1))}
    for line in lines[1:]:
        parts = line.split(",")
        try:
            x, z, T, phi = (float(parts[j]) for j in idx)
        except (ValueError, IndexError):
            return None
        i, k = int(round(x / h)) + nxh, int(round(z / h))
        if 0 <= i <= 2 * nxh and 0 <= k < nz:
            out[T_KEY][k, i], out[PHI_KEY][k, i] = T, phi
    return out


def temperature_maps(data) -> TemperatureMaps:
    """The maps of a study (report.data.StudyData) on its analysis cells (module docstring)."""
    h, nxh, nz = node_grid(data.geometry, float(data.scenario.analysis.cell_size))
    dem = dem_cell_maps(data.dem_fields, h, nxh, nz) if (
        data.dem_fields is not None and "temperature" in data.dem_fields) else None
    maps = TemperatureMaps(x=(np.arange(2 * nxh + 1) - nxh) * h, z=np.arange(nz) * h, dem=dem)
    for name in data.continuum_methods:
        entry = data.summary["methods"].get(name, {})
        rel = entry.get("bulk_velocity_csv", f"{name}/bulk_velocity.csv")
        cont = read_temperature_csv(data.out / Path(rel).parent / TEMPERATURE_CSV_NAME,
                                    h, nxh, nz)
        if cont is None:
            maps.without.append(name)
            continue
        for key, diff in ((T_KEY, "temperature_difference_m2_s2"),
                          (PHI_KEY, "solid_fraction_difference")):
            cont[diff] = cont[key] - dem[key] if dem is not None else None
        maps.continua[name] = cont
    return maps
