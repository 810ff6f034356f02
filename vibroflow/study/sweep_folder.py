"""A sweep's folder: its marker DIR/sweep.json, its locks, and what each point left behind.

    DIR/sweep.json             kind "vibroflow sweep": the base, the varied keys, every point
    DIR/sweep.csv              the table (one row per point and method)
    DIR/plots/sweep_*.png
    DIR/points/<name>/         a study folder (`vibroflow run`'s layout) plus
                 point.json    the point's values and overrides
                 failed.json   the one-line error of its last failed attempt
                 .lock         held (flock) by the process running the point

Two sweeps may share a folder: DIR/.sweep.lock serialises the short read-merge-write of
sweep.json and the writing of the table, and a point's .lock makes sure one process at a time
runs it.  flock locks belong to the open file, are released when their process dies (a killed
sweep leaves no stale lock) and work across processes on one machine; for workers on other
machines DIR must be on a file system whose flock they share (NFS v4, Lustre, GPFS).
"""
from __future__ import annotations

import contextlib
import fcntl
import json
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from vibroflow.errors import InputError
from vibroflow.io.folder_lock import check_not_under_a_file
from vibroflow.io.run_folder import SWEEP_FILE
from vibroflow.study.folder import POINT_LOCK  # noqa: F401 -- the study folder's check knows it
from vibroflow.study.stages import write_json_atomic

KIND = "vibroflow sweep"
TABLE_FILE = "sweep.csv"
POINTS = "points"
PLOTS = "plots"
DIR_LOCK = ".sweep.lock"
POINT_FILE = "point.json"
FAILED_FILE = "failed.json"


def _ignorable(name: str) -> bool:
    # a lock file or a temp file of a sweep that is starting in the same new folder
    return name == DIR_LOCK or name.startswith(".tmp-")


#: what `vibroflow sweep` advises for a folder it cannot use
SWEEP_ADVICE = ("remove the folder or give another --out", "give a new or empty folder")


def read_record(out: Path, advice: tuple[str, str] = SWEEP_ADVICE) -> dict | None:
    """DIR/sweep.json, or None for a new or empty folder; an InputError (one line) for a
    file, a foreign folder or a corrupt marker, ending with the caller's advice (for a
    corrupt record, for a foreign one)."""
    out = Path(out)
    if not out.exists():
        check_not_under_a_file(out, "DIR")
        return None
    if not out.is_dir():
        raise InputError(f"DIR = {str(out)!r}: not a folder")
    marker = out / SWEEP_FILE
    if not marker.exists():
        if any(not _ignorable(p.name) for p in out.iterdir()):
            raise InputError(f"DIR = {str(out)!r}: not a vibroflow sweep folder (no "
                             f"{SWEEP_FILE}); give a new or empty folder")
        return None
    try:
        data = json.loads(marker.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"{marker}: corrupt sweep record ({type(exc).__name__}); "
                         f"{advice[0]}") from None
    if not isinstance(data, dict) or data.get("kind") != KIND:
        kind = data.get("kind") if isinstance(data, dict) else None
        raise InputError(f"{marker}: not a vibroflow sweep record (kind = {kind!r}); "
                         f"{advice[1]}")
    if not (isinstance(data.get("base"), dict) and isinstance(data.get("varied"), list)
            and isinstance(data.get("points"), dict)):
        raise InputError(f"{marker}: corrupt sweep record (no base, varied or points); "
                         f"{advice[0]}")
    return data


def _flat(data: Any, prefix: str = "") -> dict[str, Any]:
    if isinstance(data, dict):
        out: dict[str, Any] = {}
        for k, v in data.items():
            out.update(_flat(v, f"{prefix}{k}."))
        return out
    if isinstance(data, list):
        out = {}
        for i, v in enumerate(data):
            out.update(_flat(v, f"{prefix}{i}."))
        return out or {prefix[:-1]: []}
    return {prefix[:-1]: data}


def check_same_sweep(record: dict, base: dict, varied: list[str], out: Path) -> None:
    """An InputError (one line, naming the first difference) unless the folder's sweep has the
    same base scenario, fixed options and varied keys as this one."""
    if list(record["varied"]) != list(varied):
        raise InputError(f"DIR = {str(out)!r}: a sweep of {', '.join(record['varied'])}, not of "
                         f"{', '.join(varied)}; give another --out")
    old, new = _flat(record["base"]), _flat(base)
    for key in sorted(set(old) | set(new)):
        if old.get(key, "(none)") != new.get(key, "(none)"):
            raise InputError(f"DIR = {str(out)!r}: a sweep of another base ({key} = "
                             f"{old.get(key, '(none)')!r} there, {new.get(key, '(none)')!r} "
                             "now); give another --out")


@contextlib.contextmanager
def dir_lock(out: Path) -> Iterator[None]:
    """Hold DIR/.sweep.lock (blocking): for the short read-merge-write of the sweep's files."""
    out.mkdir(parents=True, exist_ok=True)
    fd = os.open(out / DIR_LOCK, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)  # closing releases the lock


def try_lock(path: Path) -> int | None:
    """Take an exclusive flock on `path` without waiting: the open descriptor (close it to
    release), or None while another process holds it."""
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        return None
    return fd


def is_locked(path: Path) -> bool:
    """Whether another process holds the flock on `path` now."""
    if not path.exists():
        return False
    fd = try_lock(path)
    if fd is None:
        return True
    os.close(fd)
    return False


def point_dir(out: Path, name: str) -> Path:
    return Path(out) / POINTS / name


def point_state(out: Path, name: str) -> tuple[str, str | None]:
    """(status, error) of a point from its folder: "done" (summary.json, no failed.json),
    "failed" (failed.json), "running" (its lock held) or "pending"."""
    folder = point_dir(out, name)
    if is_locked(folder / POINT_LOCK):
        return "running", None
    failed = folder / FAILED_FILE
    if failed.exists():
        try:
            return "failed", str(json.loads(failed.read_text())["error"])
        except (OSError, ValueError, KeyError, TypeError):
            return "failed", "failed (unreadable failed.json)"
    if (folder / "summary.json").exists():
        return "done", None
    return "pending", None


def write_record(out: Path, record: dict) -> None:
    write_json_atomic(Path(out) / SWEEP_FILE, record)
