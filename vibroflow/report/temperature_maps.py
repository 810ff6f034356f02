"""The granular temperature and solid fraction of the DEM and of each continuum method on the
analysis cells, side by side with their difference (continuum minus DEM), as the report shows
them.

The DEM's maps are its coarse-grained fields (calibration/fields.nc) gathered onto the
analysis cells: the temperature mass-weighted (by the fields' density) over the grid points
inside a cell, the solid fraction their mean; a cell with no mass has T = 0.  Two DEM
temperatures (m^2/s^2): the phase-resolved T's cycle mean ("temperature_cycle_mean"; older
fields without it: the time-averaged "temperature"), and the thermal T's cycle mean
("thermal_temperature_cycle_mean", calibration.thermal_temperature: the velocities about each
snapshot's own coarse-grained velocity), the agitation a continuum's T models and so what its
difference is taken against when the fields hold it.  A continuum's are its temperature.csv
(continuum.temperature_outputs), which a run writes only when it carries the temperature
(ContinuumOptions.temperature); a method without it is listed in `without`.

`temperature_difference` is tub47.md's E for a scalar: the phi-weighted rms difference over the
cells with solid fraction >= 0.3 in both, over the reference's phi-weighted mean.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from vibroflow.continuum.temperature_outputs import TEMPERATURE_CSV_NAME
from vibroflow.measure.phase_shear import node_grid

T_KEY = "temperature_m2_s2"
PHI_KEY = "solid_fraction"
SE_KEY = "temperature_stderr_m2_s2"
THERMAL = "thermal_temperature_cycle_mean"
MIN_SOLID_FRACTION = 0.3


@dataclass
class TemperatureMaps:
    """x (nx,), z (nz,) the analysis cells' centres (m); dem: {T_KEY, PHI_KEY} of (nz, nx)
    arrays (the phase-resolved T's cycle mean), or None without the DEM's fields; dem_thermal:
    the same of the thermal T (with SE_KEY, its batch-means error), or None when the fields do
    not hold it; continua: method -> {T_KEY, PHI_KEY, and their differences to the DEM
    "temperature_difference_m2_s2" (to the thermal T when there is one),
    "solid_fraction_difference" (None without the DEM's fields), and E of the temperature
    against the DEM's phase-resolved and thermal T, "E_phase_resolved", "E_thermal" (None
    without)}, for the methods that carry the temperature; without: the methods that ran
    without it; E_dem_error: the thermal T's batch-means error as an E (its size against
    the thermal T), None without."""

    x: np.ndarray
    z: np.ndarray
    dem: dict | None
    continua: dict = field(default_factory=dict)
    without: list = field(default_factory=list)
    dem_thermal: dict | None = None
    E_dem_error: float | None = None


def dem_cell_maps(ds, h: float, nxh: int, nz: int, temperature: str = "temperature") -> dict:
    """The DEM's fields (an xarray Dataset with x, z coordinates m and (x, z) arrays
    `temperature`, "solid_fraction", "density") on the analysis cells of side h (m), nxh either
    side of x = 0 and nz up (module docstring): {T_KEY, PHI_KEY} of (nz, 2 nxh + 1) arrays,
    and SE_KEY (the mass-weighted mean of `temperature`_stderr) when the fields hold it."""
    x = np.asarray(ds["x"].values, dtype=float)
    z = np.asarray(ds["z"].values, dtype=float)
    X, Z = np.meshgrid(x, z, indexing="ij")
    i = np.floor(X / h + 0.5).astype(np.int64) + nxh
    k = np.floor(Z / h + 0.5).astype(np.int64)
    T = np.asarray(ds[temperature].values, dtype=float)
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
    out = {T_KEY: np.divide(E, M, out=np.zeros(size), where=M > 0).reshape(nz, -1),
           PHI_KEY: np.divide(S, n, out=np.zeros(size), where=n > 0).reshape(nz, -1)}
    if temperature + "_stderr" in ds:
        se = np.asarray(ds[temperature + "_stderr"].values, dtype=float)
        se = np.where(np.isfinite(se), se, 0.0)[ok]
        out[SE_KEY] = np.divide(np.bincount(flat, rho * se, size), M, out=np.zeros(size),
                                where=M > 0).reshape(nz, -1)
    return out


def temperature_difference(T, T_ref, phi, phi_ref,
                           min_solid_fraction: float = MIN_SOLID_FRACTION) -> float | None:
    """E of a temperature map T against T_ref (module docstring; (nz, nx) arrays m^2/s^2 and
    their solid fractions), None when no cell is compared or T_ref is 0 there."""
    on = (np.asarray(phi) >= min_solid_fraction) & (np.asarray(phi_ref) >= min_solid_fraction)
    if not on.any():
        return None
    w = np.asarray(phi_ref)[on]
    ref = np.sum(w * np.asarray(T_ref)[on]) / np.sum(w)
    if not ref > 0:
        return None
    d = np.asarray(T)[on] - np.asarray(T_ref)[on]
    return float(np.sqrt(np.sum(w * d * d) / np.sum(w)) / ref)


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
    ds = data.dem_fields
    dem = thermal = None
    if ds is not None and "temperature" in ds:
        name = "temperature_cycle_mean" if "temperature_cycle_mean" in ds else "temperature"
        dem = dem_cell_maps(ds, h, nxh, nz, name)
        if THERMAL in ds:
            thermal = dem_cell_maps(ds, h, nxh, nz, THERMAL)
    maps = TemperatureMaps(x=(np.arange(2 * nxh + 1) - nxh) * h, z=np.arange(nz) * h, dem=dem,
                           dem_thermal=thermal)
    if thermal is not None and SE_KEY in thermal:
        maps.E_dem_error = temperature_difference(thermal[T_KEY] + thermal[SE_KEY],
                                                  thermal[T_KEY], thermal[PHI_KEY],
                                                  thermal[PHI_KEY])
    target = thermal if thermal is not None else dem
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
            cont[diff] = cont[key] - target[key] if target is not None else None
        for key, ref in (("E_phase_resolved", dem), ("E_thermal", thermal)):
            cont[key] = (temperature_difference(cont[T_KEY], ref[T_KEY], cont[PHI_KEY],
                                                ref[PHI_KEY]) if ref is not None else None)
        maps.continua[name] = cont
    return maps
