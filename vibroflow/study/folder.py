"""A study's folder: its marker DIR/study.json and the check that a folder is one.

Shared by the pipeline that writes a study and by the readers of a finished one
(vibroflow.study.results), so that neither imports the other.
"""
from __future__ import annotations

import json
from pathlib import Path

from vibroflow.errors import InputError
from vibroflow.io.atomic import TMP_PREFIX
from vibroflow.io.folder_lock import LOCK_NAME
from vibroflow.io.run_folder import STUDY_FILE

POINT_LOCK = ".lock"  # a sweep point's own lock (vibroflow.study.sweep_folder)

KIND = "vibroflow study"


def read_json(path: Path, what: str) -> dict:
    """The JSON table in `path`; a one-line InputError naming `what` when it is not one."""
    try:
        data = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"{path}: corrupt {what} ({type(exc).__name__}); remove the folder "
                         "or give another --out") from None
    if not isinstance(data, dict):
        raise InputError(f"{path}: corrupt {what} (not a JSON table); remove the folder or "
                         "give another --out")
    return data


def check_study_dir(out: Path, must_exist: bool = False) -> None:
    """Raise an InputError (one line) unless `out` is new, empty, or a study folder; with
    must_exist (a reader of a study), unless it is a study folder."""
    out = Path(out)
    remedy = ("give the --out folder of a `vibroflow run`" if must_exist
              else "give a new or empty folder")
    if not out.exists():
        if must_exist:
            raise InputError(f"DIR = {str(out)!r}: no such folder")
        return
    if not out.is_dir():
        raise InputError(f"DIR = {str(out)!r}: not a folder")
    marker = out / STUDY_FILE
    if not marker.exists():
        # a lock file or an atomic writer's temporary left by a command that stopped early
        # does not make a folder a result
        own = (LOCK_NAME, POINT_LOCK)
        if any(p.name not in own and not p.name.startswith(TMP_PREFIX)
               for p in out.iterdir()) or must_exist:
            raise InputError(f"DIR = {str(out)!r}: not a vibroflow study folder (no "
                             f"{STUDY_FILE}); {remedy}")
        return
    data = read_json(marker, "study record")
    if data.get("kind") != KIND:
        raise InputError(f"{marker}: not a vibroflow study record (kind = "
                         f"{data.get('kind')!r}); {remedy}")


def calibration_of_run(run_dir: Path) -> Path | None:
    """The calibration.toml that belongs to the DEM run in run_dir: its own (`vibroflow
    calibrate RUN_DIR` writes it there), else, for a study's DEM (DIR/dem of `vibroflow run`),
    the study's DIR/calibration/calibration.toml; None when there is neither."""
    run_dir = Path(run_dir)
    own = run_dir / "calibration.toml"
    if own.is_file():
        return own
    study = run_dir.resolve().parent
    theirs = study / "calibration" / "calibration.toml"
    if run_dir.resolve().name == "dem" and (study / STUDY_FILE).is_file() and theirs.is_file():
        return theirs
    return None
