"""What one Dask task does: run (or find kept) the study of one sweep point.

`run_point(out, job)` runs on a worker.  It holds the point's lock for the whole run, so a
second sweep on the same folder never runs the same point at the same time (it gets "busy"
back at once and waits, see sweep.py); it leaves the point as `run_study` leaves a study (kept
stages, resumable), and it never raises: a failure is written to failed.json and returned, so
one bad point does not cost the others.

Threads: one worker per core runs one point at a time on one numba thread.  The local cluster
sets NUMBA_NUM_THREADS=1 in its workers' environment before anything imports numba; on a
cluster started by hand (`dask worker`) the task sets it itself when numba is not loaded yet,
and otherwise limits the running thread with numba.set_num_threads(1).  The DEM's numbers do
not depend on the thread count (vibroflow.dem.step), so a point gives the numbers of the same
scenario run alone on any number of threads.
"""
from __future__ import annotations

import os
import socket
import sys
import time
import traceback
from pathlib import Path
from typing import Any

from vibroflow import __version__
from vibroflow.io.atomic import write_json_atomic
from vibroflow.scenario.model import Scenario
from vibroflow.study.folder import KIND as STUDY_KIND
from vibroflow.study.folder import STUDY_FILE
from vibroflow.study.pipeline import run_study
from vibroflow.study.sweep_folder import FAILED_FILE, POINT_FILE, POINT_LOCK, point_dir, try_lock

THREAD_ENV = {"NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
              "OPENBLAS_NUM_THREADS": "1"}


def limit_threads() -> dict[str, Any]:
    """One thread per point (see the module notes); returns what the worker has, to record."""
    numba_loaded = "numba" in sys.modules
    if not numba_loaded:
        for k, v in THREAD_ENV.items():
            os.environ.setdefault(k, v)
    import numba  # noqa: PLC0415  (after the environment: numba reads NUMBA_NUM_THREADS once)

    if numba.get_num_threads() != 1:
        numba.set_num_threads(1)  # numba loaded earlier with more threads: this thread's share
    return {"pid": os.getpid(), "host": socket.gethostname(),
            "numba_threads": int(numba.get_num_threads()),
            "numba_num_threads_config": int(numba.config.NUMBA_NUM_THREADS),
            "NUMBA_NUM_THREADS": os.environ.get("NUMBA_NUM_THREADS"),
            "numba_loaded_before": numba_loaded}


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def _stage_mtimes(folder: Path) -> dict[str, int]:
    return {p.parent.name: p.stat().st_mtime_ns for p in folder.glob("*/stage.json")}


def run_point(out: str, job: dict) -> dict:
    """Run the study of one point (job: name, values, scenario, settings, overrides,
    shear_cell) in DIR/points/<name>; returns its result record (status "done", "kept",
    "failed" or "busy": another sweep holds the point's lock)."""
    worker = limit_threads()
    name = job["name"]
    folder = point_dir(Path(out), name)
    folder.mkdir(parents=True, exist_ok=True)
    base = {"name": name, "worker": worker}
    # the study marker before the lock file: the folder is a study folder from the start
    if not (folder / STUDY_FILE).exists():
        write_json_atomic(folder / STUDY_FILE, {"kind": STUDY_KIND,
                                                "vibroflow_version": __version__,
                                                "case": job["scenario"].get("case")})
    fd = try_lock(folder / POINT_LOCK)
    if fd is None:
        return {**base, "status": "busy", "error": None, "wall_time_s": 0.0, "ran": []}
    t0 = time.perf_counter()
    try:
        write_json_atomic(folder / POINT_FILE, {
            "name": name, "values": job["values"], "overrides": list(job["overrides"]),
            "settings": job["settings"], "shear_cell": job["shear_cell"]})
        (folder / FAILED_FILE).unlink(missing_ok=True)
        before = _stage_mtimes(folder)
        try:
            scenario = Scenario.model_validate(job["scenario"])
            with open(folder / "sweep.log", "a") as log:
                run_study(scenario, folder, job["settings"], shear_cell=job["shear_cell"],
                          extra_stages=[make() for make in job.get("finishing", ())],
                          progress=False, echo=lambda line: print(line, file=log, flush=True))
        except Exception as exc:  # any failure of this point: recorded, the others go on
            error = _one_line(exc)
            write_json_atomic(folder / FAILED_FILE, {
                "name": name, "error": error, "worker": worker,
                "traceback": traceback.format_exc(),
                "time": time.strftime("%Y-%m-%dT%H:%M:%S%z")})
            return {**base, "status": "failed", "error": error,
                    "wall_time_s": time.perf_counter() - t0, "ran": []}
        after = _stage_mtimes(folder)
        ran = sorted(k for k, v in after.items() if before.get(k) != v)
        return {**base, "status": "done" if ran else "kept", "error": None,
                "wall_time_s": time.perf_counter() - t0, "ran": ran}
    finally:
        os.close(fd)


def record_lost(out: str, name: str, error: str) -> None:
    """Write failed.json for a point whose worker died (the task's own handler never ran);
    skipped when another process holds the point now."""
    folder = point_dir(Path(out), name)
    if not folder.is_dir():
        folder.mkdir(parents=True, exist_ok=True)
    fd = try_lock(folder / POINT_LOCK)
    if fd is None:
        return
    try:
        write_json_atomic(folder / FAILED_FILE, {"name": name, "error": error,
                                                 "time": time.strftime("%Y-%m-%dT%H:%M:%S%z")})
    finally:
        os.close(fd)

