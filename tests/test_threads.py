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
