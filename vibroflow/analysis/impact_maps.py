"""A part's impact map from two results compared as tub47.md compares flow fields: per patch of
the part's surface (vibroflow.tub.parts.patch_layout), the impact rate per area and the mean
normal impact speed, and one number for the difference of two maps.

Map difference of a against the reference b (dimensionless), the analogue of tub47.md's E:

    E_rate(a, b) = sqrt( mean_p (r_a,p - r_b,p)^2 ) / mean_p r_b,p

over the part's patches p (impact rates r, m^-2 s^-1; a patch without impacts has rate 0), and

    E_speed(a, b) = sqrt( sum_p w_p (v_a,p - v_b,p)^2 / sum_p w_p ) / (sum_p w_p v_b,p / sum_p w_p)

over the patches with impacts in both, weighted by b's rate w_p = r_b,p (mean normal speeds v,
m/s).  Two maps agree when E between them is no more than 1.5 times the seed-to-seed E of the
reference code (tub47.md's rule for fields).  A continuum infers speeds and no rates, so its
map is judged by E_speed against the DEM's, beside the E_speed that the DEM's own batch-means
errors give (`speed_noise`: MAP_ERRORS standard errors on every patch) when only one DEM seed
is at hand (docs/validation.md section 25).

`cycle_mean`: the mean over the phase bins of a by-phase quantity (parts.nc's force, torque),
its standard error the bins' errors combined in quadrature over the bin count (each bin
averages its own samples).
"""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from vibroflow.io.parts_file import read_parts

#: the allowance of `speed_noise`: two batch-means standard errors on every patch
MAP_ERRORS = 2.0
#: the columns of a stored map (`write_map_csv`), SI units
MAP_COLUMNS = ("patch", "patch_name", "area_m2", "impact_rate_per_area_m-2_s-1",
               "impact_rate_per_area_stderr_m-2_s-1", "normal_speed_mean_m_s",
               "normal_speed_mean_stderr_m_s")


def part_map(parts_nc, part: str) -> dict:
    """The impact map of `part` in a parts.nc file: patch areas (m^2), rates (m^-2 s^-1) and
    mean normal speeds (m/s) with their batch-means errors, over the part's patches."""
    return map_of(read_parts(parts_nc), part)


def map_of(ds, part: str) -> dict:
    """`part_map` of a parts.nc Dataset already read (a rate NaN, a continuum's, counts 0)."""
    sel = ds.sel(part=part)
    area = sel["patch_area_m2"].values
    used = np.isfinite(area)
    return {"patch": np.arange(int(used.sum())),
            "patch_name": [str(x) for x in sel["patch_name"].values[used]],
            "area_m2": area[used],
            "rate": np.nan_to_num(sel["impact_rate_per_area"].values[used]),
            "rate_stderr": sel["impact_rate_per_area_stderr"].values[used],
            "speed": sel["normal_speed_mean"].values[used],
            "speed_stderr": sel["normal_speed_mean_stderr"].values[used]}


def write_map_csv(path, m: dict) -> Path:
    """A map (part_map) as CSV with MAP_COLUMNS."""
    path = Path(path)
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(MAP_COLUMNS)
        for k in range(len(m["patch"])):
            w.writerow([int(m["patch"][k]), m["patch_name"][k], f"{m['area_m2'][k]:.9g}",
                        f"{m['rate'][k]:.9g}", f"{m['rate_stderr'][k]:.9g}",
                        f"{m['speed'][k]:.9g}", f"{m['speed_stderr'][k]:.9g}"])
    return path


def read_map_csv(path) -> dict:
    """A map written by write_map_csv."""
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    col = {name: np.array([float(r[name]) for r in rows]) for name in MAP_COLUMNS
           if name != "patch_name"}
    return {"patch": col["patch"].astype(int), "patch_name": [r["patch_name"] for r in rows],
            "area_m2": col["area_m2"], "rate": col["impact_rate_per_area_m-2_s-1"],
            "rate_stderr": col["impact_rate_per_area_stderr_m-2_s-1"],
            "speed": col["normal_speed_mean_m_s"],
            "speed_stderr": col["normal_speed_mean_stderr_m_s"]}


def rate_difference(a: dict, b: dict) -> float:
    """E_rate(a, b) (module docstring), b the reference."""
    mean_b = float(np.mean(b["rate"]))
    if mean_b <= 0:
        raise ValueError("the reference map has no impacts")
    return float(np.sqrt(np.mean((a["rate"] - b["rate"]) ** 2)) / mean_b)


def speed_difference(a: dict, b: dict) -> float:
    """E_speed(a, b) (module docstring), b the reference."""
    both = np.isfinite(a["speed"]) & np.isfinite(b["speed"]) & (b["rate"] > 0)
    if not np.any(both):
        raise ValueError("no patch has impacts in both maps")
    w = b["rate"][both]
    rms = np.sqrt(np.sum(w * (a["speed"][both] - b["speed"][both]) ** 2) / np.sum(w))
    return float(rms / (np.sum(w * b["speed"][both]) / np.sum(w)))


def speed_noise(b: dict, errors: float = MAP_ERRORS) -> float:
    """The E_speed that `errors` of b's batch-means standard errors on every patch give (the
    module docstring's weights and patches)."""
    both = np.isfinite(b["speed"]) & np.isfinite(b["speed_stderr"]) & (b["rate"] > 0)
    if not np.any(both):
        raise ValueError("the reference map has no impacts")
    w = b["rate"][both]
    rms = np.sqrt(np.sum(w * (errors * b["speed_stderr"][both]) ** 2) / np.sum(w))
    return float(rms / (np.sum(w * b["speed"][both]) / np.sum(w)))


def cycle_mean(values, stderr) -> tuple[np.ndarray, np.ndarray]:
    """(mean, standard error) over the phase bins (axis 0) of values (phase, ...) with their
    batch-means errors stderr alike (module docstring), bins with a non-finite value left
    out."""
    values, stderr = np.asarray(values, float), np.asarray(stderr, float)
    ok = np.isfinite(values) & np.isfinite(stderr)
    n = ok.sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(ok, values, 0.0).sum(axis=0) / n
        se = np.sqrt((np.where(ok, stderr, 0.0) ** 2).sum(axis=0)) / n
    return np.where(n > 0, mean, np.nan), np.where(n > 0, se, np.nan)
