"""The numba cache guard (vibroflow/_kernel_cache.py): numba keys a cached kernel on its own
file's stamp only, so a kernel that inlines code from another file keeps stale machine code
after that file changes; the guard drops the package's cache whenever any source changes."""
from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

from vibroflow import _kernel_cache as kc


def fake_package(tmp_path: Path) -> Path:
    pkg = tmp_path / "pkg"
    (pkg / "dem" / "__pycache__").mkdir(parents=True)
    (pkg / "dem" / "contact.py").write_text("K = 1\n")
    (pkg / "dem" / "step.py").write_text("from .contact import K\n")
    for name in ("step.advance-1.py311.nbi", "step.advance-1.py311.1.nbc"):
        (pkg / "dem" / "__pycache__" / name).write_text("machine code")
    return pkg


def test_an_edit_to_any_source_drops_the_cache_once(tmp_path):
    pkg = fake_package(tmp_path)
    cache = pkg / "dem" / "__pycache__"
    folders, stamp = kc.cache_folders(pkg, environ={"XDG_CACHE_HOME": str(tmp_path / "xdg")})
    assert cache in folders and stamp == pkg / "__pycache__" / kc.STAMP_NAME
    d0 = kc.sources_digest(pkg)
    assert kc.refresh(folders, stamp, d0) == 2   # no stamp yet: the cache's origin is unknown
    assert not list(cache.glob("*.nb?"))
    (cache / "step.advance-1.py311.nbi").write_text("recompiled")
    assert kc.refresh(folders, stamp, kc.sources_digest(pkg)) == 0  # unchanged: kept
    assert (cache / "step.advance-1.py311.nbi").exists()
    # the inlined callee changes, the caller's file does not: the caller's cache must go
    (pkg / "dem" / "contact.py").write_text("K = 2\n")
    d1 = kc.sources_digest(pkg)
    assert d1 != d0
    assert kc.refresh(folders, stamp, d1) == 1
    assert not (cache / "step.advance-1.py311.nbi").exists()
    assert stamp.read_text().strip() == d1


def test_the_cache_folders_follow_numba_cache_dir(tmp_path):
    """With NUMBA_CACHE_DIR numba keeps a source folder's cache in
    NUMBA_CACHE_DIR/<folder name>_<SHA-1 of its absolute path>: checked against numba's own
    locator."""
    from numba.core.caching import _CacheLocator

    pkg = fake_package(tmp_path)
    user = tmp_path / "nbcache"
    folders, stamp = kc.cache_folders(pkg, environ={"NUMBA_CACHE_DIR": str(user)})
    expected = user / _CacheLocator.get_suitable_cache_subpath(str(pkg / "dem" / "step.py"))
    assert expected in folders
    assert stamp.parent == user
    expected.mkdir(parents=True)
    (expected / "step.advance-1.py311.nbi").write_text("machine code")
    assert kc.refresh(folders, stamp, kc.sources_digest(pkg)) == 1
    assert not list(expected.glob("*.nbi"))


def test_a_second_process_saving_a_cache_entry_waits_for_the_first(tmp_path):
    """numba's cache file names a new entry's data file after the index it read, unlocked: two
    writers that both read the empty index both write `.1.nbc`, and the index of one points at
    the other's machine code (a segfault when loaded).  Locked, a second save waits until the
    first has written its index and data, and each entry loads its own data."""
    import threading

    import numba.core.caching as caching

    assert caching.IndexDataCacheFile._vibroflow_locked  # vibroflow's import locked it
    folder = str(tmp_path)
    a = caching.IndexDataCacheFile(folder, "f-1.py311", source_stamp=("stamp", 1))
    b = caching.IndexDataCacheFile(folder, "f-1.py311", source_stamp=("stamp", 1))
    inside, go_on = threading.Event(), threading.Event()
    read_index = a._load_index

    def paused_load_index():  # a has read the index and not yet written it
        index = read_index()
        inside.set()
        assert go_on.wait(10)
        return index

    a._load_index = paused_load_index
    ta = threading.Thread(target=a.save, args=("key a", "data a"))
    tb = threading.Thread(target=b.save, args=("key b", "data b"))
    ta.start()
    assert inside.wait(10)
    tb.start()
    tb.join(0.5)
    assert tb.is_alive()  # b waits on a's lock (unlocked, b would write `.1.nbc` here)
    go_on.set()
    ta.join(10)
    tb.join(10)
    assert not ta.is_alive() and not tb.is_alive()
    reader = caching.IndexDataCacheFile(folder, "f-1.py311", source_stamp=("stamp", 1))
    assert reader.load("key a") == "data a"
    assert reader.load("key b") == "data b"
    assert sorted(p.name for p in tmp_path.glob("*.nbc")) == ["f-1.py311.1.nbc",
                                                              "f-1.py311.2.nbc"]


def test_numba_imported_after_vibroflow_has_its_cache_files_locked():
    import subprocess
    import sys

    code = ("import sys, vibroflow; assert 'numba' not in sys.modules; "
            "import numba.core.caching as c; print(c.IndexDataCacheFile._vibroflow_locked)")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "True"


_NESTED = """
import numba as nb
import numpy as np


@nb.njit(parallel=True, cache=True)
def inner(a):
    s = np.zeros(a.size)
    for i in nb.prange(a.size):
        s[i] = 2.0 * a[i]
    return s.sum()


@nb.njit(cache=True)
def outer(a):
    return inner(a) + 1.0
"""


def test_a_kernel_compiled_over_a_cached_parallel_kernel_loads_with_threads(tmp_path):
    """numba's reload hook starts the threading layer when a parallel kernel loads from the
    cache, but a kernel compiled over that loaded copy carries its loops without the hook:
    called first in a fresh process it segfaults (exit -11 on numba 0.68).  vibroflow's cache
    guard starts the layer on every load (_kernel_cache.start_threads).  Four processes on a
    cache of their own: `inner` compiled; `outer` compiled over the cached `inner` with the
    threads running; `outer` first, without and with vibroflow imported: the guarded one
    returns 2 n + 1."""
    import subprocess

    (tmp_path / "nested.py").write_text(_NESTED)
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba"),
           "PYTHONPATH": os.pathsep.join([str(tmp_path), os.environ.get("PYTHONPATH", "")])}
    call = "import numpy as np, nested; print(nested.{}(np.ones(1000)))"

    def run(code):
        return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                              env=env, timeout=300)

    assert run(call.format("inner")).stdout.split() == ["2000.0"]
    assert run("import numba; numba.get_num_threads(); " + call.format("outer")
               ).stdout.split() == ["2001.0"]
    bare = run(call.format("outer"))
    guarded = run("import vibroflow; " + call.format("outer"))
    assert guarded.returncode == 0, guarded.stderr[-2000:]
    assert guarded.stdout.split() == ["2001.0"]
    # what the guard is for: without it numba's own load crashes (a later numba that starts
    # the layer itself makes the guard a no-op, not wrong)
    print(f"outer loaded first without vibroflow: exit {bare.returncode}")


@pytest.mark.slow
def test_a_cached_temperature_kernel_runs_in_a_process_that_starts_with_it(tmp_path):
    """The MPM's temperature kernel (mpm/temperature_loop.advance_temperature_kernel) calls the
    parallel fused.advance_kernel.  Compiled in a process whose threads run and which loaded
    advance_kernel from the cache, it is saved without what starts numba's threading layer;
    a later run that calls it first, loaded from the cache, must still start the layer
    (_kernel_cache.start_threads) instead of crashing (exit -11).  Three processes on a cache of
    their own: a run without T (advance_kernel compiled), one with T after starting the
    threads (the kernel compiled over the cached advance_kernel), one with T from the start."""
    import subprocess

    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba")}
    short = ["--set", "run.duration=0.0639", "--set", "run.average_last=0.0426",
             "--set", "run.batches=2"]
    hot = ["--temperature", "--initial-temperature", "0.001"]
    run = ("import sys; {pre}from vibroflow.cli import main; "
           "sys.argv = ['vibroflow'] + sys.argv[1:]; main()")
    steps = [(run.format(pre=""), []),
             (run.format(pre="import numba; numba.get_num_threads(); "), hot),
             (run.format(pre=""), hot)]
    for k, (code, extra) in enumerate(steps):
        r = subprocess.run([sys.executable, "-c", code, "continuum", "tub47-quick", "--out",
                            str(tmp_path / f"run{k}"), "--method", "lagrangian", *extra,
                            *short], capture_output=True, text=True, env=env, timeout=600)
        assert r.returncode == 0, (k, r.returncode, r.stderr[-2000:])
