"""calibration.toml: the continuum's parameters measured on a DEM run, written and read here
only (`vibroflow calibrate` writes it; the continuum, the study and the report read it).

Every value carries its standard error (`*_stderr`); the tables the continuum needs are checked
when the file is read (REQUIRED), so a file that lacks one is a one-line error, not a solver
that runs on a default.
"""
from __future__ import annotations

import math
import tomllib
from pathlib import Path

import numpy as np
import tomli_w

from vibroflow.errors import InputError
from vibroflow.io.atomic import write_text_atomic

CALIBRATION_FILE = "calibration.toml"


def write_calibration(path, cal: dict) -> Path:
    """calibration.toml, atomically, with a header saying what it is."""
    path = Path(path)
    head = ("# vibroflow calibration: continuum parameters measured on a DEM run (SI units).\n"
            "# Read with vibroflow.calibration.read_calibration; every value has its standard\n"
            "# error (*_stderr, NaN where none could be estimated) and [source] says where it\n"
            "# came from.\n\n")
    return write_text_atomic(path, head + tomli_w.dumps(_plain(cal)))


def _plain(obj):
    if isinstance(obj, dict):
        return {str(k): _plain(v) for k, v in obj.items() if v is not None}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if isinstance(obj, (np.floating, float)):
        return float(obj)
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    return obj


REQUIRED = {"rheology": ("mu_s", "mu_2", "I_0", "phi_max", "phi_min"),
            "elastic": ("bulk_modulus_Pa", "shear_modulus_Pa"),
            "wall": ("friction",), "media": ("diameter_m", "solid_density_kg_m3")}


def read_calibration(path) -> dict:
    """Read calibration.toml (a file, or a run directory holding one); InputError when it is
    missing, malformed or lacks a parameter the continuum needs."""
    p = Path(path)
    if p.is_dir():
        p = p / CALIBRATION_FILE
    if not p.is_file():
        raise InputError(f"calibration = {str(path)!r}: no such file (run `vibroflow calibrate`)")
    try:
        cal = tomllib.loads(p.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as e:
        raise InputError(f"{p}: malformed TOML ({e})") from None
    except (OSError, UnicodeDecodeError) as e:
        raise InputError(f"{p}: cannot be read ({type(e).__name__}: {e})") from None
    for table, keys in REQUIRED.items():
        for k in keys:
            v = cal.get(table, {}).get(k)
            if not isinstance(v, (int, float)) or not math.isfinite(v):
                why = cal.get(table, {}).get("status", "")
                raise InputError(f"{p}: {table}.{k} = {v!r}: must be a finite number"
                                 + (f" ({why})" if why and why != "measured" else ""))
    return cal
