"""The report's sections on the parts in the bed, one per part: what each method's parts.nc
(vibroflow.io.parts_file's schema, in the method's folder of the study) says the part receives.

Per part: the impact map around it (mean normal impact speed by surface patch, with the DEM's
impact rate per area: a polar plot around a cylinder, bars by face or band for a box, a sphere
or an STL), each method with its batch-means error bars; a table by patch with the DEM's speed
beside each continuum's and their difference (continuum - DEM, its error the two errors in
quadrature), the DEM's rate and energy flux per area; the DEM's normal-speed distribution by
patch (mean with its error, median, 95th percentile); the force on the part by phase of the
cycle for each method; each continuum judged against the DEM as a whole (analysis.impact_maps:
the speed map's E beside the E of the DEM's own errors, and every method's cycle-mean force and
torque).
A method whose folder has no parts.nc is left out and said so; a study
with no parts.nc at all has no part section.  Figures are PNG bytes (matplotlib, Agg); part
and patch names are the page's text, escaped by the template.  Units: SI.
"""
from __future__ import annotations

import math

import numpy as np

from vibroflow.analysis.impact_maps import cycle_mean, map_of, speed_difference, speed_noise
from vibroflow.errors import InputError
from vibroflow.io.parts_file import PARTS_NC_NAME, read_parts
from vibroflow.io.pictures import pyplot
from vibroflow.report.data import DEM, StudyData
from vibroflow.report.figures import png_bytes

#: a method's colour in the part figures
COLOURS = {DEM: "k", "lagrangian": "C0", "eulerian": "C3"}


def read_part_files(data: StudyData) -> tuple[dict, list[str]]:
    """(method -> its parts.nc Dataset, notes on the methods without one or with an unreadable
    one), the methods in the study's order."""
    found, notes = {}, []
    for name in data.methods:
        path = data.out / name / PARTS_NC_NAME
        if not path.is_file():
            notes.append(f"{name}: no {PARTS_NC_NAME}")
            continue
        try:
            found[name] = read_parts(path)
        except InputError as e:
            notes.append(str(e))
    return found, notes


def _values(ds, part: str, var: str, n: int) -> np.ndarray:
    """The first n patches of `var` of `part` (NaN where the Dataset lacks the part)."""
    if part not in ds["part"].values:
        return np.full(n, np.nan)
    return np.asarray(ds[var].sel(part=part).values[:n], dtype=float)


def _patches(ds, part: str) -> tuple[list[str], np.ndarray]:
    names = [str(s) for s in ds["patch_name"].sel(part=part).values if str(s)]
    area = np.asarray(ds["patch_area_m2"].sel(part=part).values[:len(names)], dtype=float)
    return names, area


def _map_figure(part: str, shape: str, names: list[str], files: dict) -> bytes:
    """The impact map: mean normal speed by patch of each method (error bars) and the DEM's
    impact rate per area; polar around a cylinder, bars otherwise."""
    plt = pyplot()
    n = len(names)
    polar = shape == "cylinder"
    fig = plt.figure(figsize=(10, 4.2))
    ax = fig.add_subplot(1, 2, 1, projection="polar" if polar else None)
    ax2 = fig.add_subplot(1, 2, 2, projection="polar" if polar else None)
    where = (np.arange(n) + 0.5) * 2 * math.pi / n if polar else np.arange(n)
    width = 0.8 / max(len(files), 1)
    for j, (method, ds) in enumerate(files.items()):
        v = _values(ds, part, "normal_speed_mean", n)
        se = _values(ds, part, "normal_speed_mean_stderr", n)
        ok = np.isfinite(v)
        if not ok.any():
            continue
        c = COLOURS.get(method, f"C{j + 4}")
        if polar:
            ax.errorbar(where[ok], v[ok], yerr=np.nan_to_num(se[ok]), fmt="o-", color=c,
                        ms=3, lw=1, label=method)
        else:
            ax.bar(where + (j - 0.5 * (len(files) - 1)) * width, np.where(ok, v, 0.0), width,
                   yerr=np.nan_to_num(se), color=c, label=method)
    ax.set_title("mean normal impact speed (m/s)")
    ax.legend(loc="lower left", fontsize=8, bbox_to_anchor=(-0.1, -0.15) if polar else None)
    if DEM in files:
        r = _values(files[DEM], part, "impact_rate_per_area", n)
        rse = _values(files[DEM], part, "impact_rate_per_area_stderr", n)
        ok = np.isfinite(r)
        if polar:
            ax2.errorbar(where[ok], r[ok], yerr=np.nan_to_num(rse[ok]), fmt="o-", color="k",
                         ms=3, lw=1)
        else:
            ax2.bar(where, np.where(ok, r, 0.0), 0.6, yerr=np.nan_to_num(rse), color="0.4")
    ax2.set_title("DEM impact rate per area (1/(m^2 s))")
    if not polar:
        for a in (ax, ax2):
            a.set_xticks(np.arange(n))
            a.set_xticklabels(names, rotation=45, ha="right", fontsize=8)
    else:
        for a in (ax, ax2):
            a.set_theta_zero_location("E")
            a.set_theta_direction(1)
    fig.suptitle(f"{part}: angle in the x-z plane from +x towards +z (90 deg: the top)"
                 if polar else part, fontsize=10)
    return png_bytes(fig)


def _distribution_figure(part: str, names: list[str], dem) -> bytes:
    """The DEM's normal-speed distribution by patch: mean (error bars), median, p95."""
    plt = pyplot()
    n = len(names)
    fig, ax = plt.subplots(figsize=(10, 3.4))
    x = np.arange(n)
    mean = _values(dem, part, "normal_speed_mean", n)
    ax.errorbar(x, mean, yerr=np.nan_to_num(_values(dem, part, "normal_speed_mean_stderr", n)),
                fmt="o", color="k", ms=4, label="mean")
    ax.plot(x, _values(dem, part, "normal_speed_median", n), "s", color="C2", ms=4,
            label="median")
    ax.plot(x, _values(dem, part, "normal_speed_p95", n), "^", color="C3", ms=4,
            label="95th percentile")
    ax.set_xticks(x)
    ax.set_xticklabels(names, rotation=60, ha="right", fontsize=7)
    ax.set_ylabel("normal impact speed (m/s)")
    ax.legend(fontsize=8)
    return png_bytes(fig)


def part_sections(data: StudyData) -> tuple[list[dict], list[str]]:
    """One dict per part (the parts of the first parts.nc found: the DEM's where it has one):
    name, shape, the map and distribution figures (PNG bytes or None), and the tables' raw
    rows (floats, for vibroflow.report.html to format); and the notes on missing files."""
    files, notes = read_part_files(data)
    if not files:
        return [], notes
    first = files.get(DEM) or next(iter(files.values()))
    shapes = str(first.attrs.get("shapes", "")).split(", ")
    out = []
    for k, part in enumerate(str(p) for p in first["part"].values):
        shape = _shape_of(data, part) or (shapes[k] if k < len(shapes) else "")
        names, area = _patches(first, part)
        n = len(names)
        continua = [m for m in files if m != DEM]
        dem = files.get(DEM)
        rows = []
        for j, name in enumerate(names):
            row = {"patch": name, "area": area[j]}
            if dem is not None:
                row["dem"] = (_values(dem, part, "normal_speed_mean", n)[j],
                              _values(dem, part, "normal_speed_mean_stderr", n)[j])
                row["rate"] = (_values(dem, part, "impact_rate_per_area", n)[j],
                               _values(dem, part, "impact_rate_per_area_stderr", n)[j])
                row["flux"] = (_values(dem, part, "energy_flux", n)[j],
                               _values(dem, part, "energy_flux_stderr", n)[j])
                row["median"] = _values(dem, part, "normal_speed_median", n)[j]
                row["p95"] = _values(dem, part, "normal_speed_p95", n)[j]
            for m in continua:
                v = _values(files[m], part, "normal_speed_mean", n)[j]
                se = _values(files[m], part, "normal_speed_mean_stderr", n)[j]
                row[m] = (v, se)
                if dem is not None:
                    d, dse = row["dem"]
                    row[m + "_diff"] = (v - d, math.hypot(se, dse))
            rows.append(row)
        forces, whole = {}, {}
        for m, ds in files.items():
            if part in ds["part"].values:
                forces[m] = tuple(np.asarray(ds[v].sel(part=part).values, float)
                                  for v in ("force", "force_stderr", "torque", "torque_stderr"))
                whole[m] = {"force": cycle_mean(forces[m][0], forces[m][1]),
                            "torque": cycle_mean(forces[m][2], forces[m][3])}
                if dem is not None and m != DEM:
                    whole[m]["map"] = _speed_e(ds, dem, part)
        out.append({"name": part, "shape": shape, "continua": continua,
                    "has_dem": dem is not None, "rows": rows, "forces": forces, "whole": whole,
                    "inferred_from": {m: str(ds.attrs.get("inferred_from", ""))
                                      for m, ds in files.items()},
                    "map": _map_figure(part, shape, names, files),
                    "distribution": (_distribution_figure(part, names, dem)
                                     if dem is not None else None)})
    return out, notes


def _speed_e(ds, dem, part: str) -> tuple[float, float]:
    """(E_speed of the method's map against the DEM's, the E of the DEM's own errors);
    NaNs where the DEM's map has no impacts or the two share no patch."""
    try:
        ref = map_of(dem, part)
        return speed_difference(map_of(ds, part), ref), speed_noise(ref)
    except ValueError:
        return float("nan"), float("nan")


def _shape_of(data: StudyData, part: str) -> str:
    """The shape of the scenario's part `part` ("" when the scenario has none of that name)."""
    for p in data.scenario.parts or []:
        if p.name == part:
            return p.shape
    return ""
