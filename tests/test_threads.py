"""numba's thread count (vibroflow/threads.py): every core the process may use by default, the
environment's NUMBA_NUM_THREADS when it names one."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time

import pytest

PROBE = "import vibroflow, numba; print(numba.config.NUMBA_NUM_THREADS)"


def _threads(env_threads: str | None, cpus: str | None = None) -> int:
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_NUM_THREADS"}
    if env_threads is not None:
        env["NUMBA_NUM_THREADS"] = env_threads
    cmd = [sys.executable, "-c", PROBE]
    if cpus is not None:
        cmd = ["taskset", "-c", cpus, *cmd]
    out = subprocess.run(cmd, env=env, capture_output=True, text=True, check=True)
    return int(out.stdout.strip())


def test_default_is_the_cores_of_the_affinity():
    assert _threads(None) == len(os.sched_getaffinity(0))


@pytest.mark.skipif(shutil.which("taskset") is None, reason="no taskset here")
def test_a_process_pinned_to_one_core_gets_one_thread():
    assert _threads(None, cpus="0") == 1


def test_the_environment_wins():
    assert _threads("3") == 3


# libgomp's spin (vibroflow/threads.py, spin_count): long while the threads fit on the free
# cores, short when other processes need them

SPIN_PROBE = "import os, vibroflow; print(os.environ['GOMP_SPINCOUNT'])"
BUSY = "import time\nt = time.time() + 30\nwhile time.time() < t: pass"


def test_the_spin_is_long_only_while_the_threads_fit_on_the_cores():
    from vibroflow.threads import SPIN_BUSY, SPIN_FREE, spin_count

    assert spin_count(0, 2, 2) == SPIN_FREE
    assert spin_count(1, 2, 2) == SPIN_BUSY
    assert spin_count(1, 2, 1) == SPIN_FREE
    assert spin_count(10, 16, 8) == SPIN_BUSY
    assert spin_count(8, 16, 8) == SPIN_FREE


def _spin(env_extra: dict[str, str]) -> str:
    env = {k: v for k, v in os.environ.items() if k not in ("GOMP_SPINCOUNT", "OMP_WAIT_POLICY")}
    env.update(env_extra)
    out = subprocess.run([sys.executable, "-c", SPIN_PROBE], env=env, capture_output=True,
                         text=True, check=True)
    return out.stdout.strip()


@pytest.mark.skipif(not os.path.exists("/proc/stat"), reason="no /proc/stat here")
def test_other_processes_on_every_core_get_the_short_spin():
    from vibroflow.threads import SPIN_BUSY, others_running

    cores = os.cpu_count() or 1
    busy = [subprocess.Popen([sys.executable, "-c", BUSY]) for _ in range(cores)]
    try:
        time.sleep(0.3)  # the loops running
        assert others_running() >= 1
        assert _spin({}) == str(SPIN_BUSY)
    finally:
        for p in busy:
            p.kill()
            p.wait()


def test_the_environments_spin_wins():
    assert _spin({"GOMP_SPINCOUNT": "77"}) == "77"


# The Eulerian loop's choice (continuum/eulerian/solver.py, parallel_loop): numba's parallel
# loops on a large mesh always, on a small one only while the threads fit on the free cores

def _reading(monkeypatch, others):
    import vibroflow.threads as T

    monkeypatch.setattr(T, "_free_read", None)
    monkeypatch.setattr(T, "others_running", lambda: others)
    monkeypatch.setattr(T.os, "cpu_count", lambda: 4)


def test_the_free_cores_are_those_other_processes_leave(monkeypatch):
    from vibroflow import threads as T

    _reading(monkeypatch, 1)
    assert T.cores_free(3)
    assert not T.cores_free(4)
    _reading(monkeypatch, None)  # the load unknown: not free
    assert not T.cores_free(1)


def test_a_reading_of_the_load_serves_its_age_then_is_read_again(monkeypatch):
    from vibroflow import threads as T

    _reading(monkeypatch, 0)
    assert T.cores_free(4)
    monkeypatch.setattr(T, "others_running", lambda: 3)
    assert T.cores_free(4)  # the first reading still serves
    assert not T.cores_free(4, max_age_s=0.0)


def test_the_eulerian_loop_is_parallel_on_a_small_mesh_only_on_free_cores(monkeypatch):
    from vibroflow.continuum.eulerian.solver import (FREE_PARALLEL_FROM, SERIAL_BELOW,
                                                     parallel_loop)

    _reading(monkeypatch, 0)
    assert parallel_loop(FREE_PARALLEL_FROM, 2)
    assert not parallel_loop(FREE_PARALLEL_FROM - 1, 2)
    assert not parallel_loop(SERIAL_BELOW, 1)  # one thread: the serial loop always
    _reading(monkeypatch, 3)  # another process on three of the four cores
    assert not parallel_loop(FREE_PARALLEL_FROM, 2)
    assert parallel_loop(SERIAL_BELOW, 2)
    assert parallel_loop(10, 2, serial_below=0)  # forced, as the tests of the loops do


# numba's threading layer: OpenMP first (vibroflow/__init__.py); where numba's threads already
# run on TBB when vibroflow is imported, a one-line warning (threads.warn_if_tbb_launched)

def test_a_launched_tbb_layer_is_warned_of_and_no_other():
    from types import SimpleNamespace

    import vibroflow.threads as T

    def layer(name):
        def threading_layer():
            if name is None:
                raise ValueError("not initialized")  # numba's answer before any launch
            return name
        return SimpleNamespace(threading_layer=threading_layer)

    with pytest.warns(RuntimeWarning, match="NUMBA_THREADING_LAYER=omp"):
        assert T.warn_if_tbb_launched(layer("tbb"))
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for name in ("omp", "workqueue", None):
            assert not T.warn_if_tbb_launched(layer(name))


LAYER_PROBE = ("import warnings, numba; numba.set_num_threads(1)\n"
               "with warnings.catch_warnings(record=True) as w:\n"
               "    warnings.simplefilter('always'); import vibroflow\n"
               "print(numba.threading_layer(), any('TBB' in str(x.message) for x in w))")


CLEAN_PROBE = ("import vibroflow, numba, numpy as np\n"
               "@numba.njit(parallel=True)\n"
               "def f(a):\n"
               "    for i in numba.prange(a.size):\n"
               "        a[i] += 1.0\n"
               "f(np.zeros(4)); print(numba.threading_layer())")


def test_numba_threads_started_before_the_import_warn_exactly_when_they_run_on_tbb():
    """numba's threads started before `import vibroflow` keep the layer numba chose (TBB where
    a libtbb is installed): the import warns then, and only then; imported first, vibroflow
    puts OpenMP (or numba's workqueue) first, with no warning."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_THREADING_LAYER")}
    out = subprocess.run([sys.executable, "-c", LAYER_PROBE], env=env, capture_output=True,
                         text=True, check=True).stdout.split()
    assert out[1] == str(out[0] == "tbb")
    clean = subprocess.run([sys.executable, "-c", CLEAN_PROBE], env=env, capture_output=True,
                           text=True, check=True)
    assert clean.stdout.strip() in ("omp", "workqueue")
    assert "TBB" not in clean.stderr
