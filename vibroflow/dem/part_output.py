"""What the parts in the bed receive in a DEM run: DIR/parts.nc (vibroflow.io.parts_file's schema)
from dem.h5's /part_impacts and /part_loads, and the summary's lines per part.

Over the averaging window [duration - average_last, duration), split into run.batches batches of
whole cycles (vibroflow.measure.stats): per part and patch, the impact rate per area (impacts /
(area x batch time)), the mean normal impact speed, the energy flux (sum of 0.5 m v_n^2 / (area x
batch time)), each with its batch-means standard error, and the median and 95th percentile of
the normal speed over the window's impacts; per part, the force of the balls on it at the
snapshots, by phase of the cycle (the snapshots sit at the phases k / phases_per_cycle), with
the standard error of its batch means, and likewise its torque about the part's centre.
"""
from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

from ..io.atomic import json_safe
from ..io.parts_file import empty_parts_dataset, write_parts as write_file
from ..measure.stats import (batch_means, batches_of_whole_cycles, cycles_in_window, phase_bins,
                             stderr_of_batches)
from ..tub.parts import patch_layout

PARTS_NC = "parts.nc"
#: m of an explicit run's cylinder (unbounded along y) over which its patches' areas are taken
EXPLICIT_LENGTH_M = 1.0


def _empty_dataset(parts, slice_length_m: float, n_phases: int, method: str, window_s: float,
                   batches: int, inferred_from: str):
    """The shared parts.nc layout (vibroflow/io/parts_file.py) for these parts' patches."""
    layouts = [patch_layout(p, slice_length_m) for p in parts]
    return empty_parts_dataset([p.name for p in parts], [n for n, _ in layouts],
                               [a for _, a in layouts], n_phases, method, window_s, batches,
                               inferred_from)

def _batch_seconds(n_cycles: int, n_batches: int, frequency: float) -> np.ndarray:
    """Duration (s) of each batch of whole cycles (cycle k in batch k n_b // n_c)."""
    cycles = np.bincount(np.arange(n_cycles) * n_batches // n_cycles, minlength=n_batches)
    return cycles / frequency


def _even_batches(times, t_start: float, t_end: float, n_batches: int) -> np.ndarray:
    """Batch index of each time in n_batches equal spans of [t_start, t_end) (-1 outside)."""
    t = np.asarray(times, dtype=float)
    b = np.floor((t - t_start) / (t_end - t_start) * n_batches).astype(np.int64)
    return np.where((t >= t_start) & (t < t_end) & (b < n_batches), b, -1)


def part_dataset(h5path: Path, scenario, parts):
    """The parts.nc Dataset of a finished DEM run's dem.h5 (parts: vibroflow.tub.parts.Part
    records in the scenario's order).  A tub run's window and phases are its cycles' (module
    docstring); an explicit run's window is the whole run [0, duration) in run.batches equal
    spans, with one phase bin, and an (unbounded) cylinder's patches are over EXPLICIT_LENGTH_M
    of its axis."""
    run = scenario.run
    nb = run.batches
    if scenario.explicit:
        t0, t1, n_phases, length = 0.0, run.duration, 1, EXPLICIT_LENGTH_M
        window = t1 - t0
        tb = np.full(nb, window / nb)

        def batch_of(t):
            return _even_batches(t, t0, t1, nb)

        def phase_of(t):
            return np.zeros(np.shape(t), np.int64)
    else:
        f = scenario.motion.frequency
        t1 = run.duration
        t0 = t1 - run.average_last
        n_cycles = cycles_in_window(t0, t1, f)
        window = n_cycles / f
        n_phases, length = run.phases_per_cycle, scenario.tub.length
        tb = _batch_seconds(n_cycles, nb, f)

        def batch_of(t):
            return batches_of_whole_cycles(t, t0, t1, f, nb)

        def phase_of(t):
            return phase_bins(t, f, n_phases)
    ds = _empty_dataset(parts, length, n_phases, "dem", window, nb,
                       "every ball-part contact of the DEM (impacts: its first step) and the "
                       "contact forces and their torques at the snapshots"
                       + ("; an explicit run: the whole run in one phase bin, a cylinder's "
                          f"patches over {EXPLICIT_LENGTH_M:g} m of its axis"
                          if scenario.explicit else ""))
    with h5py.File(h5path, "r") as h5:
        imp = {k: h5["part_impacts"][k][()] for k in h5["part_impacts"]}
        load = {k: h5["part_loads"][k][()] for k in h5["part_loads"]}
        snap_time = h5["snapshots/time"][()]
    batch = batch_of(imp["time"])
    for k, part in enumerate(parts):
        _, area = patch_layout(part, length)
        for p in range(area.size):
            sel = (imp["part"] == k) & (imp["patch"] == p) & (batch >= 0)
            vn = imp["normal_speed"][sel].astype(float)
            b = batch[sel]
            counts = np.bincount(b, minlength=nb)
            energy = np.bincount(b, weights=imp["energy"][sel], minlength=nb)
            rate_b = counts / (area[p] * tb)
            flux_b = energy / (area[p] * tb)
            ds["impact_rate_per_area"][k, p] = counts.sum() / (area[p] * window)
            ds["impact_rate_per_area_stderr"][k, p] = stderr_of_batches(rate_b)
            ds["energy_flux"][k, p] = energy.sum() / (area[p] * window)
            ds["energy_flux_stderr"][k, p] = stderr_of_batches(flux_b)
            if vn.size:
                with np.errstate(invalid="ignore", divide="ignore"):
                    means = np.bincount(b, weights=vn, minlength=nb) / counts
                ds["normal_speed_mean"][k, p] = vn.mean()
                ds["normal_speed_mean_stderr"][k, p] = stderr_of_batches(means)
                ds["normal_speed_median"][k, p] = np.median(vn)
                ds["normal_speed_p95"][k, p] = np.percentile(vn, 95.0)
        rows = load["part"] == k
        t = snap_time[load["snapshot"][rows]]
        sb = batch_of(t)
        ph = phase_of(t)
        for var in ("force", "torque"):
            value = load[var][rows]
            for q in range(n_phases):
                at = ph == q
                if np.any(at & (sb >= 0)):
                    mean, se = batch_means(value[at], sb[at], nb)
                    ds[var][k, q] = mean
                    ds[var + "_stderr"][k, q] = se
    return ds


def summary_lines(ds, parts) -> list[dict]:
    """One summary entry per part: impacts per second, mean normal speed, energy per second
    and mean force, over its whole surface (the patches' areas weighting)."""
    out = []
    for k, part in enumerate(parts):
        area = ds["patch_area_m2"][k].values
        ok = np.isfinite(area)
        rate = ds["impact_rate_per_area"][k].values[ok] * area[ok]
        vmean = ds["normal_speed_mean"][k].values[ok]
        flux = ds["energy_flux"][k].values[ok] * area[ok]
        total = float(rate.sum())
        has = np.isfinite(vmean) & (rate > 0)
        out.append({
            "name": part.name, "shape": part.shape, "frame": part.frame,
            "area_m2": float(area[ok].sum()),
            "impacts_per_s": total,
            "normal_speed_mean_m_s": float((vmean[has] * rate[has]).sum() / rate[has].sum())
            if has.any() else None,
            "energy_per_s_W": float(flux.sum()),
            "force_mean_N": [float(x) for x in np.nanmean(ds["force"][k].values, axis=0)]
            if np.isfinite(ds["force"][k].values).any() else None,
        })
    return out


def write_parts_nc(h5path: Path, out_dir: Path, scenario, system) -> list[dict]:
    """Write DIR/parts.nc of a finished run (tub or explicit) and return the summary's entries per part
    (NaN as None: valid JSON)."""
    ds = part_dataset(h5path, scenario, system.parts)
    write_file(Path(out_dir) / PARTS_NC, ds)
    return json_safe(summary_lines(ds, system.parts))


def part_line(entry: dict) -> str:
    """One line of `vibroflow dem`'s output for a part's summary entry."""
    v = entry["normal_speed_mean_m_s"]
    force = entry["force_mean_N"]
    fz = f", mean force z {force[2]:.3g} N" if force else ""
    speed = f"{v:.3g} m/s" if v is not None else "n/a"
    return (f"part {entry['name']} ({entry['shape']}, {entry['frame']} frame): "
            f"{entry['impacts_per_s']:.4g} impacts/s, mean normal impact speed {speed}, "
            f"{entry['energy_per_s_W']:.3g} W delivered{fz}")
