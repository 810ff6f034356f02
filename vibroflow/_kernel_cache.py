"""Keep numba's on-disk cache of vibroflow's kernels consistent with their sources.

Why: numba's `cache=True` keys a compiled function on the modification stamp of the file that
defines it, and on nothing else.  vibroflow's kernels inline small functions from other files
(the contact law of dem/contact.py into the step loops of dem/step.py, the constitutive update
into the continuum's fused loops, the tub's kinematics into both), so after an edit of such a
file -- a `git pull` in an editable install -- the callers' cached machine code would silently
keep the old law (a changed rolling model, say, would give the step loops no torque until the
caches were removed).

What it does: a digest of every .py file of the package is kept beside the cache; when the
sources' digest differs from it, every numba index and data file (*.nbi, *.nbc) of the package's
cache is removed before anything compiles, and the new digest is written.  Called once when the
package is imported (vibroflow/__init__.py); it reads the sources (well under 10 ms) and imports
nothing heavy.  Where the cache lives follows numba's locators (numba.core.caching): each source
folder's __pycache__, or, when NUMBA_CACHE_DIR is set, NUMBA_CACHE_DIR/<folder name>_<SHA-1 of
the folder's absolute path> (and the same under the user-wide cache, ~/.cache/numba, where numba
goes when a __pycache__ is not writable).  Any file-system error leaves the cache as it is.
"""
from __future__ import annotations

import hashlib
import os
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent
STAMP_NAME = "vibroflow-kernel-sources.sha256"


def sources_digest(package: Path = PACKAGE) -> str:
    """SHA-256 over the package's .py files (their paths relative to the package and bytes)."""
    h = hashlib.sha256()
    for path in sorted(package.rglob("*.py")):
        h.update(str(path.relative_to(package)).encode())
        h.update(b"\0")
        h.update(path.read_bytes())
    return h.hexdigest()


def _source_folders(package: Path) -> list[Path]:
    return sorted({p.parent for p in package.rglob("*.py")})


def _numba_subpath(folder: Path) -> str:
    """numba's name for a source folder's cache under a cache directory
    (_CacheLocator.get_suitable_cache_subpath)."""
    path = os.path.abspath(str(folder))
    return f"{os.path.split(path)[-1]}_{hashlib.sha1(path.encode()).hexdigest()}"


def cache_folders(package: Path = PACKAGE, environ=os.environ) -> tuple[list[Path], Path]:
    """(the folders numba may keep this package's cache files in, the stamp file's path)."""
    folders = _source_folders(package)
    user = environ.get("NUMBA_CACHE_DIR")
    if user:
        tag = hashlib.sha1(os.path.abspath(str(package)).encode()).hexdigest()
        return ([Path(user) / _numba_subpath(f) for f in folders],
                Path(user) / f"{STAMP_NAME}-{tag}")
    wide = Path(environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "numba"
    return ([f / "__pycache__" for f in folders] + [wide / _numba_subpath(f) for f in folders],
            package / "__pycache__" / STAMP_NAME)


def refresh(folders: list[Path], stamp: Path, digest: str) -> int:
    """Remove the numba cache files (*.nbi, *.nbc) in `folders` unless `stamp` holds `digest`,
    then write the stamp; returns how many files were removed (0 when fresh)."""
    try:
        if stamp.read_text().strip() == digest:
            return 0
    except OSError:
        pass
    removed = 0
    for folder in folders:
        if not folder.is_dir():
            continue
        for path in list(folder.glob("*.nbi")) + list(folder.glob("*.nbc")):
            try:
                path.unlink()
                removed += 1
            except FileNotFoundError:
                pass
    from vibroflow.io.atomic import write_text_atomic  # only when stale: the import stays light

    write_text_atomic(stamp, digest + "\n")
    return removed


def ensure_fresh() -> None:
    """refresh() for this package's cache; silent on any file-system error."""
    try:
        folders, stamp = cache_folders()
        refresh(folders, stamp, sources_digest())
    except OSError:
        pass
