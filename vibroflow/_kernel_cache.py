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

Processes that compile at once: numba's cache file (numba.core.caching.IndexDataCacheFile)
reads a function's index, names a data file for a new entry after the entries it read, writes
the index, then the data, with no lock.  Two processes compiling the same function (two
signatures, or the parallel and the one-thread loops of one closure) on a cold cache can both
name their entry `.1.nbc`; one's index then points at the other's machine code, and every later
run that loads it crashes (a segfault, exit -11; numba issues 4807 and 10128).  Two vibroflow
processes on a fresh install do that: `pytest -n 2`, a sweep's workers, a run beside a test.  So
each cache folder holds a lock file (LOCK_NAME): numba's save and flush of a cache file hold it
exclusively and its load shared (`lock_cache_files`, made when numba's caching module is
imported: `install`), so an index and its data are written together and read whole, and the
removal of a stale cache holds it too.  `tests/test_kernel_cache.py` shows a second save wait
for the first.

Threads of a cached kernel: numba starts its threading layer when it loads a kernel with
parallel loops from the cache (a reload hook in the kernel's library,
numba.core.typed_passes._reload_parfors).  A kernel compiled over such a kernel that was itself
loaded from the cache inlines its loops without that hook: loaded first in a process that has
run no parallel loop yet, its first loop finds no threads and the process segfaults (exit -11;
the MPM's temperature loop over fused.advance_kernel did).  So every load from the cache
starts the layer (start_threads); `tests/test_kernel_cache.py` makes such caches, a pair of
four-line kernels and the MPM's, and runs them.
"""
from __future__ import annotations

import contextlib
import hashlib
import importlib.abc
import importlib.util
import os
import sys
from pathlib import Path

try:
    import fcntl
except ImportError:  # not POSIX: numba's cache without the lock
    fcntl = None

PACKAGE = Path(__file__).resolve().parent
STAMP_NAME = "vibroflow-kernel-sources.sha256"
#: the lock file in each numba cache folder (module docstring)
LOCK_NAME = "vibroflow-numba-cache.lock"
#: numba's module that holds the cache file class
CACHING_MODULE = "numba.core.caching"


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
        with folder_lock(str(folder), exclusive=True):
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


@contextlib.contextmanager
def folder_lock(folder: str, exclusive: bool):
    """Hold the lock file of a numba cache folder, exclusive or shared, for the `with` block;
    without fcntl, or where the lock file cannot be opened, the block runs unlocked."""
    fd = None
    if fcntl is not None:
        try:
            fd = os.open(os.path.join(folder, LOCK_NAME), os.O_RDWR | os.O_CREAT, 0o666)
        except OSError:
            fd = None
    try:
        if fd is not None:
            fcntl.flock(fd, fcntl.LOCK_EX if exclusive else fcntl.LOCK_SH)
        yield
    finally:
        if fd is not None:
            os.close(fd)  # releases the lock


def start_threads() -> None:
    """Start numba's threading layer (module docstring, "Threads of a cached kernel"); once
    started it stays for the process, so every call after the first costs nothing."""
    try:
        from numba.np.ufunc.parallel import _launch_threads
    except ImportError:  # a numba without it: its own reload hook is all there is
        return
    _launch_threads()


def lock_cache_files(cache_file_class) -> None:
    """Make numba's cache file class (IndexDataCacheFile) save and flush under its folder's
    exclusive lock and load under a shared one (module docstring), and start numba's
    threading layer once an entry has loaded (start_threads); idempotent."""
    if getattr(cache_file_class, "_vibroflow_locked", False):
        return
    save, load, flush = cache_file_class.save, cache_file_class.load, cache_file_class.flush

    def locked_save(self, key, data):
        with folder_lock(self._cache_path, exclusive=True):
            save(self, key, data)

    def locked_load(self, key):
        with folder_lock(self._cache_path, exclusive=False):
            data = load(self, key)
        if data is not None:
            start_threads()
        return data

    def locked_flush(self):
        with folder_lock(self._cache_path, exclusive=True):
            flush(self)

    cache_file_class.save = locked_save
    cache_file_class.load = locked_load
    cache_file_class.flush = locked_flush
    cache_file_class._vibroflow_locked = True


class _LockOnImport(importlib.abc.MetaPathFinder):
    """Finds numba's caching module as the other finders do, and locks its cache file class
    once the module has run (`install`): `import vibroflow` itself does not import numba."""

    def find_spec(self, name, path, target=None):
        if name != CACHING_MODULE:
            return None
        sys.meta_path.remove(self)
        spec = importlib.util.find_spec(name)
        if spec is None or spec.loader is None or not hasattr(spec.loader, "exec_module"):
            return spec
        exec_module = spec.loader.exec_module

        def exec_and_lock(module):
            exec_module(module)
            lock_cache_files(module.IndexDataCacheFile)

        spec.loader.exec_module = exec_and_lock
        return spec


def install() -> None:
    """Lock numba's cache files (module docstring): now if numba's caching module is loaded,
    else when it is imported."""
    if fcntl is None:
        return
    module = sys.modules.get(CACHING_MODULE)
    if module is not None:
        lock_cache_files(module.IndexDataCacheFile)
    elif not any(isinstance(f, _LockOnImport) for f in sys.meta_path):
        sys.meta_path.insert(0, _LockOnImport())
