"""numba's thread count (vibroflow/threads.py): every core the process may use by default, the
environment's NUMBA_NUM_THREADS when it names one."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys

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
