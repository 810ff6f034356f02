"""Reading a finished study back: `vibroflow.load(DIR)`."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import xarray as xr

from vibroflow.errors import InputError
from vibroflow.measure.bulk import read_csv
from vibroflow.study.folder import check_study_dir


def read_summary(out) -> dict:
    """DIR/summary.json of a finished study (an InputError, one line, for anything else)."""
    out = Path(out)
    check_study_dir(out, must_exist=True)
    path = out / "summary.json"
    if not path.exists():
        raise InputError(f"DIR = {str(out)!r}: the study has not finished (no summary.json); "
                         f"run `vibroflow run ... --out {out}`")
    try:
        summary = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"{path}: corrupt summary ({type(exc).__name__})") from None
    if not isinstance(summary, dict) or not isinstance(summary.get("methods"), dict):
        raise InputError(f"{path}: not a vibroflow study summary (no methods table)")
    return summary


def field_dataset(csv_path, cell_size: float | None = None, method: str = ""):
    """A bulk_velocity.csv as an xarray Dataset on its (z, x) cell grid (cells without a ball:
    NaN velocities, 0 solid fraction and samples).  Units: m, m/s."""
    try:
        t = read_csv(csv_path, cell_size=cell_size)
    except ValueError as e:
        raise InputError(f"{csv_path}: {e}") from None
    h = t.cell_size
    ix, iz = t.ix, t.iz
    xs = np.arange(ix.min(), ix.max() + 1) if len(t) else np.zeros(0, np.int64)
    zs = np.arange(iz.min(), iz.max() + 1) if len(t) else np.zeros(0, np.int64)
    shape = (zs.size, xs.size)
    j, i = (iz - (zs[0] if zs.size else 0)), (ix - (xs[0] if xs.size else 0))

    def grid(values, fill):
        a = np.full(shape, fill, dtype=float)
        a[j, i] = values
        return a

    dims = ("z", "x")
    ds = xr.Dataset(
        {"vx": (dims, grid(t.vx, np.nan), {"units": "m/s", "long_name": "bulk velocity "
                                           "relative to the tub, x"}),
         "vz": (dims, grid(t.vz, np.nan), {"units": "m/s", "long_name": "bulk velocity "
                                           "relative to the tub, z"}),
         "solid_fraction": (dims, grid(t.solid_fraction, 0.0), {"units": "1"}),
         "samples": (dims, grid(t.samples, 0.0), {"units": "1"})},
        coords={"x": ("x", xs * h, {"units": "m"}), "z": ("z", zs * h, {"units": "m"})},
        attrs={"method": method, "cell_size_m": h, "source": str(csv_path)})
    return ds


def load(out) -> dict:
    """A finished study of `vibroflow run --out DIR`: the summary (summary.json: per method
    probes, circulation, impacts, wall_time_s; continuum methods' against_dem block with E)
    plus "fields": method -> its bulk velocity field as an xarray Dataset (dims z, x; vx, vz,
    solid_fraction, samples).  A missing, foreign or corrupt DIR is an InputError."""
    out = Path(out)
    summary = read_summary(out)
    fields = {}
    for name, entry in summary["methods"].items():
        rel = entry.get("bulk_velocity_csv") if isinstance(entry, dict) else None
        if not rel or not (out / rel).is_file():
            raise InputError(f"{out / (rel or name)}: missing bulk velocity table of method "
                             f"{name!r}")
        try:
            fields[name] = field_dataset(out / rel, method=name)
        except ValueError as exc:
            raise InputError(f"{out / rel}: corrupt bulk velocity table ({exc})") from None
    return {**summary, "fields": fields}
