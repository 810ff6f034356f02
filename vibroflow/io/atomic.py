"""Write a file atomically: a reader sees the old file or the whole new one, never a part.

Why: results are read while runs are going (a study's summary.json, a sweep's table, a report
polled by a browser, a checkpoint read after a kill), and the standards say "Results are
written atomically".  A file written in place is, for a while, empty or half written; a run
killed then (or a full disk) leaves it so for good.  Here the bytes go to a temporary file in
the target's own folder (the same file system, so the final rename is atomic), are flushed and
fsync'ed, the temporary file gets the mode a plainly created file would have (0o666 less the
umask; mkstemp's is 0o600), and os.replace moves it over the target.  On any exception --
KeyboardInterrupt included -- the temporary file is removed and the exception re-raised: the
previous file is untouched and nothing is left behind.

Every temporary name is unique (tempfile.mkstemp), so two processes or threads writing the same
file do not collide (the last os.replace wins, and each file is whole), and starts with ".tmp-"
(TMP_PREFIX), which code that lists a results folder may skip (study/sweep_folder.py does).

    write_bytes_atomic(path, data)            bytes
    write_text_atomic(path, text)             str, UTF-8, "\\n" line ends (no translation)
    write_json_atomic(path, data, indent=2)   json.dumps(...) + "\\n"
    json_safe(obj)                            numpy values as Python's, NaN/inf as null
    atomic_path(path) / replace_atomic(path, writer)
                                              for writers that want a path of their own
                                              (matplotlib savefig, PIL, h5py, NetCDF, pyevtk)
All return the final path (a Path; atomic_path yields the temporary one).
"""
from __future__ import annotations

import contextlib
import json
import math
import os
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

TMP_PREFIX = ".tmp-"


def file_mode() -> int:
    """The mode of a newly created plain file: 0o666 less the process's umask."""
    try:  # Linux: read it without changing it (os.umask's set-and-restore is not thread-safe)
        with open("/proc/self/status", encoding="ascii") as f:
            for line in f:
                if line.startswith("Umask:"):
                    return 0o666 & ~int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


def _temp(path: Path, suffix: str | None) -> tuple[int, Path]:
    path.parent.mkdir(parents=True, exist_ok=True)
    # the default suffix ends with the target's name, so its extension too (savefig and PIL
    # pick the format from it) and a stray file says whose it was
    fd, tmp = tempfile.mkstemp(prefix=TMP_PREFIX, dir=path.parent,
                               suffix=f"-{path.name}" if suffix is None else suffix)
    return fd, Path(tmp)


def write_bytes_atomic(path, data: bytes) -> Path:
    """Write data to path atomically (see the module's docstring); returns the path."""
    path = Path(path)
    fd, tmp = _temp(path, None)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
            os.fchmod(f.fileno(), file_mode())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def write_text_atomic(path, text: str) -> Path:
    """Write text (UTF-8, line ends as given: newline="\\n") to path atomically."""
    return write_bytes_atomic(path, text.encode("utf-8"))


def write_json_atomic(path, data: Any, *, indent: int | None = 2, sort_keys: bool = False,
                      allow_nan: bool = True) -> Path:
    """Write json.dumps(data, ...) and a newline to path atomically.  Nothing is written when
    data does not serialise (the exception propagates)."""
    text = json.dumps(data, indent=indent, sort_keys=sort_keys, allow_nan=allow_nan) + "\n"
    return write_text_atomic(path, text)


def json_safe(obj):
    """Recursively turn numpy scalars into Python numbers and NaN/inf into None."""
    if isinstance(obj, dict):
        return {str(k): json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return [json_safe(v) for v in obj.tolist()]
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        f = float(obj)
        return f if math.isfinite(f) else None
    return obj


def _fsync_path(tmp: Path) -> None:
    fd = os.open(tmp, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


@contextlib.contextmanager
def atomic_path(path, suffix: str | None = None) -> Iterator[Path]:
    """Yield a unique temporary path in path's folder for a writer that wants a file name;
    when the block ends without an exception the file is fsync'ed, given the umask's mode and
    moved onto path; on any exception it is removed and the exception propagates.

    The temporary file exists (empty) when yielded: open it for writing ("w", not "x").  Its
    name ends with "-<path's name>" unless `suffix` is given (a writer that appends an
    extension itself, such as pyevtk's, needs suffix=that extension)."""
    path = Path(path)
    fd, tmp = _temp(path, suffix)
    os.close(fd)
    try:
        yield tmp
        _fsync_path(tmp)
        os.chmod(tmp, file_mode())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def replace_atomic(path, writer: Callable[[Path], Any], suffix: str | None = None) -> Path:
    """writer(temporary path) in atomic_path(path, suffix); returns path."""
    with atomic_path(path, suffix) as tmp:
        writer(tmp)
    return Path(path)


__all__ = ["TMP_PREFIX", "atomic_path", "file_mode", "replace_atomic", "write_bytes_atomic",
           "write_json_atomic", "write_text_atomic"]
