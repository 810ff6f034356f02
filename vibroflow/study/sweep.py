"""`vibroflow sweep`: the whole study at every point of an amplitude (and any field) sweep, the
points run as tasks on Dask distributed.

    run_sweep(plan, out)      plan = sweep_points.plan_sweep(...), checked before anything runs

The cluster is a local one, one single-threaded worker process per core (at most one per point
to compute), or the one at `scheduler` (`dask scheduler` + `dask worker`, see the README); the
workers must see DIR at the same path.  Each point is a study folder DIR/points/<name> run by
`run_study`, so a finished point is kept by its stage hashes and an interrupted one resumes.

A failed point is written to its failed.json and reported, and the others go on.  A point
whose lock another sweep holds ("running elsewhere") is waited for: this sweep polls the lock
and, once it is free, submits the point again, which then finds it kept (or runs it, if the
other sweep died); so both sweeps end with the whole table and every point runs once.
"""
from __future__ import annotations

import asyncio
import logging
import os
import socket
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from distributed import Client, LocalCluster, wait
from distributed.comm import connect, parse_address
from distributed.comm.addressing import parse_host_port
from rich.console import Console

from vibroflow import __version__
from vibroflow.errors import InputError
from vibroflow.progress import PLAIN_EVERY_S, format_duration
from vibroflow.study.sweep_folder import (KIND, PLOTS, POINT_LOCK, TABLE_FILE, check_same_sweep,
                                          dir_lock, is_locked, point_dir, read_record, write_record)
from vibroflow.study.sweep_plots import write_plots
from vibroflow.study.sweep_points import SweepPlan
from vibroflow.study.sweep_table import rich_table, sweep_rows, write_csv_atomic

#: the width of the table in a log file or a pipe: wide enough for any row whole
PLAIN_WIDTH = 10_000
from vibroflow.study.sweep_worker import THREAD_ENV, record_lost, run_point

#: seconds between two looks at the lock of a point running elsewhere
POLL_S = 1.0


def check_sweep_dir(out: Path, plan: SweepPlan) -> dict | None:
    """The folder's sweep record (None for a new or empty folder); an InputError (one line)
    for a foreign or corrupt folder or one holding a sweep of another base."""
    record = read_record(out)
    if record is not None:
        check_same_sweep(record, plan.base, plan.varied, out)
    return record


def _merge_record(out: Path, plan: SweepPlan) -> dict:
    """Create or extend DIR/sweep.json with this sweep's points (under the folder lock: two
    sweeps starting together both see one folder, one base, every point)."""
    with dir_lock(out):
        record = check_sweep_dir(out, plan)
        now = time.strftime("%Y-%m-%dT%H:%M:%S%z")
        if record is None:
            record = {"kind": KIND, "vibroflow_version": __version__, "created": now,
                      "source": plan.source, "base": plan.base, "varied": plan.varied,
                      "fixed_settings": plan.fixed, "points": {}}
        for p in plan.points:
            record["points"].setdefault(p.name, {"values": p.values,
                                                 "overrides": list(p.overrides)})
        record["updated"] = now
        record["vibroflow_version"] = __version__
        write_record(out, record)
    return record


def finish_outputs(out: Path, results: dict[str, dict] | None = None) -> dict:
    """Write sweep.csv, the plots and sweep.json from what the points' folders hold now (under
    the folder lock, so two sweeps never interleave); returns the record with the rows."""
    with dir_lock(out):
        record = read_record(out)
        assert record is not None  # written by _merge_record before any point ran
        varied = list(record["varied"])
        rows = sweep_rows(out, record["points"], varied)
        write_csv_atomic(out / TABLE_FILE, rows, varied)
        plots = write_plots(out / PLOTS, rows, varied)
        for name, p in record["points"].items():
            st = [r for r in rows if r["point"] == name]
            p["status"] = st[0]["status"] if st else "pending"
            p["error"] = st[0].get("error") or None if st else None
            p["folder"] = f"points/{name}"
            if results and name in results:
                r = results[name]
                p["last_run"] = {k: r.get(k) for k in ("status", "wall_time_s", "ran",
                                                       "worker")}
        record["table"] = TABLE_FILE
        record["plots"] = [f"{PLOTS}/{n}" for n in plots]
        record["updated"] = time.strftime("%Y-%m-%dT%H:%M:%S%z")
        write_record(out, record)
    return {**record, "rows": rows}


#: seconds a scheduler has to accept the connection and answer Dask's handshake
CONNECT_TIMEOUT_S = 10.0

#: the schemes of Dask's comms (distributed.comm.registry); tcp:// is checked in full
_SCHEMES = ("tcp", "tls", "ws", "wss", "ucx")


def check_scheduler(address: str, timeout: float = CONNECT_TIMEOUT_S) -> None:
    """Check that a Dask scheduler answers at `address` (tcp://HOST:PORT): one-line InputError
    naming the address and what is there instead (a malformed address, nothing listening, a
    service that is not Dask, a worker, silence), before any Client is made.

    Why a check of its own: distributed's Client, pointed at a service that speaks another
    protocol, reads the service's reply as a Dask frame header and fails with MemoryError
    ("Unable to allocate 3.07 EiB" for an HTTP reply), ValueError or a comm error, and it waits
    for ever on a peer that accepts the connection and stays silent."""
    def refuse(what: str) -> InputError:
        return InputError(f"--scheduler = {address!r}: no Dask scheduler answers there "
                          f"({what}); start one with `dask scheduler` or leave --scheduler out")

    def malformed(what: str) -> InputError:
        return InputError(f"--scheduler = {address!r}: not a Dask scheduler address ({what}); "
                          "give tcp://HOST:PORT as `dask scheduler` prints it, or leave "
                          "--scheduler out")

    try:
        scheme, loc = parse_address(address)
    except ValueError as e:
        raise malformed(" ".join(str(e).split())) from None
    if scheme not in _SCHEMES:
        raise malformed(f"scheme {scheme}://; Dask's are " + ", ".join(_SCHEMES))
    if scheme != "tcp":
        return  # tls, ws, ucx: Client's own connection is the check
    try:
        host, port = parse_host_port(loc)
    except ValueError as e:
        raise malformed(" ".join(str(e).split())) from None
    if not host or not 0 < int(port) < 65536:
        raise malformed("a host and a port 1 - 65535 are needed")
    try:
        with socket.create_connection((host, int(port)), timeout=timeout):
            pass
    except ConnectionRefusedError:
        raise refuse("nothing listens on that port: connection refused") from None
    except socket.gaierror:
        raise refuse(f"no such host {host!r}") from None
    except TimeoutError:
        raise refuse(f"no answer to a connection in {timeout:g} s") from None
    except OSError as e:
        raise refuse((e.strerror or str(e)).lower()) from None

    async def identity():
        comm = await connect(address, timeout=timeout)
        try:
            await comm.write({"op": "identity", "reply": True})
            return await comm.read()
        finally:
            await comm.close()

    try:
        reply = asyncio.run(asyncio.wait_for(identity(), timeout))
    except (TimeoutError, asyncio.TimeoutError):
        raise refuse(f"a service that accepts connections but gives no Dask handshake in "
                     f"{timeout:g} s") from None
    except Exception as e:  # noqa: BLE001 -- any failure of the handshake means "not Dask"
        # (MemoryError, ValueError, CommClosedError, ... as the docstring says); Ctrl-C is
        # a BaseException and passes
        kind = ("closed the connection without a Dask handshake"
                if "closed" in str(e).lower() else
                "answers in another protocol than Dask's")
        raise refuse(f"a service that {kind}") from None
    what = reply.get("type") if isinstance(reply, dict) else None
    if what != "Scheduler":
        raise refuse(f"a Dask {what.lower()}, not the scheduler" if isinstance(what, str)
                     else "a service whose answer is not a Dask scheduler's")


def make_client(scheduler: str | None, workers: int):
    """(client, cluster): the cluster at `scheduler` (checked first, check_scheduler), or a
    local one of `workers` processes with one thread each and NUMBA_NUM_THREADS=1 in their
    environment."""
    if scheduler:
        check_scheduler(scheduler)
        try:
            return Client(scheduler, timeout="15s"), None
        except (OSError, TimeoutError, ValueError) as exc:
            raise InputError(f"--scheduler = {scheduler!r}: cannot connect "
                             f"({' '.join(str(exc).split())[:160]})") from None
    # memory_limit=0: the nanny would kill a worker above its share of the memory (total /
    # workers) even with the machine's memory free; a point's memory is the OS's business
    # silence_logs: the nanny's warnings (a worker slow to stop on a busy machine) are noise
    # in the sweep's output; errors still show
    cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                           dashboard_address=None, memory_limit=0, env=dict(THREAD_ENV),
                           silence_logs=logging.ERROR)
    return Client(cluster), cluster


def run_sweep(plan: SweepPlan, out: Path, scheduler: str | None = None,
              workers: int | None = None, client=None,
              echo: Callable[[str], None] | None = print,
              finishing: Sequence[Callable[[], Any]] = ()) -> dict:
    """Run (or bring up to date) every point of `plan` in `out`; write the table and plots.

    workers: local worker processes (default one per core, at most one per point); client: a
    dask.distributed Client to use as it is (tests); echo: where the one line per finished
    point goes; finishing: factories of the stages each point's study ends with, from the
    layers above the study (the report: vibroflow.report.stage.report_stage).  Returns the
    sweep record (sweep.json) with "rows" (the table) and "results" (this run's result per
    point)."""
    out = Path(out)
    check_sweep_dir(out, plan)  # before anything is written or started
    jobs = {p.name: {"name": p.name, "values": p.values, "scenario": p.scenario,
                     "settings": p.settings, "overrides": list(p.overrides),
                     "shear_cell": plan.shear_cell, "finishing": list(finishing)}
            for p in plan.points}
    n = len(jobs)
    own_client = client is None
    cluster = None
    if own_client:  # first: a scheduler that cannot be reached leaves DIR untouched
        nw = workers or os.cpu_count() or 1
        client, cluster = make_client(scheduler, max(1, min(nw, n)))
    results: dict[str, dict] = {}
    try:
        out.mkdir(parents=True, exist_ok=True)
        _merge_record(out, plan)
        # the table before any point runs: a point's page, written when it finishes, finds
        # the sweep it belongs to (vibroflow.report) even on the sweep's first run
        finish_outputs(out)
        concurrency = max(1, sum(client.nthreads().values()))
        pending = {client.submit(run_point, str(out), job, pure=False, retries=0): name
                   for name, job in jobs.items()}
        waiting: dict[str, float] = {}  # point running elsewhere -> since when
        finished = 0
        computed: list[float] = []
        t_start = time.perf_counter()
        said = t_start  # the last progress line: one at least every PLAIN_EVERY_S
        while pending or waiting:
            done = []
            if pending:
                try:
                    done = list(wait(list(pending), timeout=POLL_S,
                                     return_when="FIRST_COMPLETED").done)
                except TimeoutError:
                    done = []
            else:
                time.sleep(POLL_S)
            for fut in done:
                name = pending.pop(fut)
                if fut.status == "finished":
                    r = fut.result()
                else:  # the worker died or the task was lost: its handler never ran
                    exc = fut.exception() if fut.status == "error" else None
                    msg = (f"{type(exc).__name__}: {' '.join(str(exc).split())}" if exc
                           else f"task {fut.status}")
                    record_lost(str(out), name, msg)
                    r = {"name": name, "status": "failed", "error": msg, "wall_time_s": 0.0,
                         "ran": [], "worker": None}
                if r["status"] == "busy":
                    if name not in waiting and echo is not None:
                        echo(f"        {name}: running elsewhere (another sweep); waiting")
                    waiting.setdefault(name, time.perf_counter())
                    continue
                results[name] = r
                finished += 1
                if r["status"] == "done":
                    computed.append(r["wall_time_s"])
                if echo is not None:
                    what = {"done": f"done in {format_duration(r['wall_time_s'])} "
                                    f"({', '.join(r['ran'])})",
                            "kept": "up to date, kept",
                            "failed": f"FAILED: {r['error']}"}[r["status"]]
                    per = (sum(computed) / len(computed)) if computed else plan.estimate_s
                    left_n = n - finished
                    left = per * -(-left_n // concurrency) if left_n else 0.0
                    echo(f"[{finished}/{n}] {name}: {what}; time left ~ {format_duration(left)}")
                    said = time.perf_counter()
            now = time.perf_counter()
            if echo is not None and now - said >= PLAIN_EVERY_S:
                echo(f"        {finished} of {n} finished, {len(pending)} running, "
                     f"{len(waiting)} waiting; {format_duration(now - t_start)} so far")
                said = now
            for name in list(waiting):
                if not is_locked(point_dir(out, name) / POINT_LOCK):
                    del waiting[name]
                    fut = client.submit(run_point, str(out), jobs[name], pure=False,
                                        retries=0)
                    pending[fut] = name
        wall = time.perf_counter() - t_start
    finally:
        if own_client:
            client.close()
            if cluster is not None:
                cluster.close()
    record = finish_outputs(out, results)
    record["results"] = results
    record["wall_time_s"] = wall
    return record


def print_table(record: dict, file=None) -> None:
    """The sweep's table (rich): on a terminal as wide as the terminal; elsewhere (a log file, a
    pipe) as wide as the table needs, so that no column is cut."""
    console = Console(file=file or sys.stdout)
    if not console.is_terminal:
        console = Console(file=file or sys.stdout, width=PLAIN_WIDTH)
    console.print(rich_table(record["rows"], record["varied"]))


def failed_points(record: dict) -> list[str]:
    """The points of this run that failed (the folder may hold older failed points too; the
    table shows them, the exit code does not count them)."""
    return [name for name, r in record.get("results", {}).items() if r["status"] == "failed"]


def summary_of(record: dict) -> dict[str, Any]:
    """Counts of the points by status."""
    counts: dict[str, int] = {}
    for p in record["points"].values():
        counts[p.get("status", "pending")] = counts.get(p.get("status", "pending"), 0) + 1
    return counts
