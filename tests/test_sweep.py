"""`vibroflow sweep`: the study at every amplitude factor (and other values) as Dask tasks, on a
tiny tub (250 balls, 0.15 s of vibration): the table against each point's own summary, the tub
speed against the factor, kept points, a failing point among good ones, a scheduler started by
hand, foreign/corrupt folders, two sweeps on one folder."""
from __future__ import annotations

import csv
import json
import os
import shutil
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.test_calibrate import SMALL

# SMALL, shorter (0.13 s window = 6 cycles at 47 Hz >= 4 batches) and with 250 balls
GOOD = 250
FIXED = [s for s in SMALL if not s.startswith(("fill.count=", "run.duration=",
                                               "run.average_last="))]
FIXED += ["run.duration=0.15", "run.average_last=0.13", f"fill.count={GOOD}"]
# a fixed continuum option every point takes, as `vibroflow run --set` does
FIXED += ["lagrangian.cfl=0.3"]
# the ball-ball stiffness the fixture varies: tub47-quick's own (N/m), and one that passes every
# check made before a run but fails in it: at 1 N/m a ball's weight alone (0.01 N) presses its
# contacts by 10 mm, beyond the blow-up bound of a quarter diameter, while the fill settles
GOOD_KN = 100000.0
BAD_KN = 1.0
STAGES = ("dem", "calibration", "lagrangian", "comparison")


def _sets(items):
    out = []
    for s in items:
        out += ["--set", s]
    return out


def _env(tmp):
    return dict(os.environ, NO_COLOR="1", COLUMNS="200", PYTHONDONTWRITEBYTECODE="1",
                VIBROFLOW_CACHE=str(tmp / "cache"))


def _cli(*args, env, timeout=600):
    return subprocess.run([sys.executable, "-m", "vibroflow.cli", *map(str, args)],
                          capture_output=True, text=True, env=env, stdin=subprocess.DEVNULL,
                          timeout=timeout)


def _sweep_args(out, factors="0.5,1", kns=f"{GOOD_KN},{BAD_KN}", *extra):
    return ["sweep", "tub47-quick", "--factors", factors, "--vary", f"contacts.0.k_n={kns}",
            "--out", out, *_sets(FIXED), *extra]


def _rows(out):
    with open(out / "sweep.csv", newline="") as f:
        return list(csv.DictReader(f))


def _num(cell):
    """A number of sweep.csv: an empty cell is a value that could not be estimated (None in
    summary.json)."""
    return None if cell == "" else float(cell)


def _good(factor):
    return f"amplitude_factor={factor!r},contacts.0.k_n={GOOD_KN!r}"


def _bad(factor):
    return f"amplitude_factor={factor!r},contacts.0.k_n={BAD_KN!r}"


def _mtimes(out, names):
    return {(n, s): (out / "points" / n / s / "stage.json").stat().st_mtime_ns
            for n in names for s in STAGES}


@pytest.fixture(scope="module")
def swept(tmp_path_factory):
    """Four points on a local cluster of two workers: factors 0.5 and 1 with 250 balls (run)
    and with the soft contacts of BAD_KN (fail at run time)."""
    tmp = tmp_path_factory.mktemp("sweep")
    env = _env(tmp)
    out = tmp / "sweep"
    r = _cli(*_sweep_args(out, "0.5,1", f"{GOOD_KN},{BAD_KN}", "--workers", "2"), env=env)
    return tmp, out, env, r


@pytest.mark.slow
def test_sweep_table_matches_points_and_tub_speed_scales_with_factor(swept):
    import h5py
    import numpy as np

    tmp, out, env, r = swept
    assert r.returncode == 1, r.stderr  # two points fail (see the next test), two finish
    lines = [ln for ln in r.stdout.splitlines() if ln.startswith("[")]
    assert len(lines) == 4 and all("time left" in ln for ln in lines), r.stdout
    rows = _rows(out)
    for f in (0.5, 1.0):
        name = _good(f)
        mine = [row for row in rows if row["point"] == name]
        summary = json.loads((out / "points" / name / "summary.json").read_text())
        # one row per method of the study (the DEM and every registered continuum method)
        assert sorted(row["method"] for row in mine) == sorted(summary["methods"])
        assert {"dem", "lagrangian"} <= set(summary["methods"])
        assert all(row["status"] == "done" for row in mine)
        assert all(float(row["motion.amplitude_factor"]) == f
                   and float(row["contacts.0.k_n"]) == GOOD_KN for row in mine)
        for row in mine:
            m = summary["methods"][row["method"]]
            c = m["circulation"]
            assert _num(row["circulation_strength"]) == c["strength"]
            assert _num(row["circulation_strength_stderr"]) == c["strength_stderr"]
            assert row["circulation_sense"] == c["sense"]
            for p, v in m["probes"].items():
                for k in ("vx", "vz", "vx_stderr", "vz_stderr"):
                    assert _num(row[f"{p}_{k}"]) == v[k], (p, k)
            assert _num(row["wall_time_s"]) == m["wall_time_s"]
            if row["method"] != "dem":
                assert _num(row["E_against_dem"]) == m["against_dem"]["field_difference_E"]
                assert (_num(row["E_against_dem_stderr"])
                        == m["against_dem"]["field_difference_E_stderr"])

    # a point's folder is a study folder like `vibroflow run`'s: vibroflow.load reads it
    import vibroflow

    loaded = vibroflow.load(out / "points" / _good(1.0))
    assert set(loaded["fields"]) == set(loaded["methods"]) >= {"dem", "lagrangian"}

    # physics: every tub amplitude is the factor times the preset's (tub47.md "Tub motion"),
    # so the tub's velocities at the same sampled phases scale exactly with the factor
    peak = {}
    for f in (0.5, 1.0):
        with h5py.File(out / "points" / _good(f) / "dem" / "dem.h5", "r") as h:
            pose = h["snapshots/tub_pose"][()]
        peak[f] = np.abs(pose[:, 3:6]).max(axis=0)  # Xdot, Zdot, thetadot
    assert np.all(peak[0.5] > 0)
    np.testing.assert_allclose(peak[1.0] / peak[0.5], 2.0, rtol=1e-9)
    # and the balls hit the wall faster at twice the amplitude (the wall's speed doubles)
    bw = {f: float(next(row["impact_ball_wall"] for row in rows
                        if row["point"] == _good(f) and row["method"] == "dem"))
          for f in (0.5, 1.0)}
    assert 1.3 < bw[1.0] / bw[0.5] < 3.0, bw

    # the pictures, written whole (PNG signature, no temp file left)
    for name in ("sweep_probes", "sweep_circulation", "sweep_impacts", "sweep_wall_time"):
        data = (out / "plots" / f"{name}.png").read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000
    assert not list(out.rglob(".tmp-*"))
    # one numba thread per worker process: NUMBA_NUM_THREADS=1 in the local workers'
    # environment before numba loads (numba's own config reads it at import)
    record = json.loads((out / "sweep.json").read_text())
    assert record["kind"] == "vibroflow sweep"
    assert record["varied"] == ["motion.amplitude_factor", "contacts.0.k_n"]
    for name in (_good(0.5), _good(1.0), _bad(0.5), _bad(1.0)):
        w = record["points"][name]["last_run"]["worker"]
        assert w["numba_threads"] == 1 and w["numba_num_threads_config"] == 1
        assert w["pid"] != os.getpid()
    assert "vibroflow sweep" in r.stdout and "lagrangian" in r.stdout  # the rich table


@pytest.mark.slow
def test_failed_point_is_reported_and_the_others_finish(swept):
    tmp, out, env, r = swept
    rows = _rows(out)
    for f in (0.5, 1.0):
        bad = [row for row in rows if row["point"] == _bad(f)]
        assert len(bad) == 1 and bad[0]["status"] == "failed"
        assert "contact stiffness k_n too low" in bad[0]["error"]
        failed = json.loads((out / "points" / _bad(f) / "failed.json").read_text())
        assert "\n" not in failed["error"] and "BlowUp" in failed["error"]
        assert not (out / "points" / _bad(f) / "summary.json").exists()
        assert (out / "points" / _good(f) / "summary.json").exists()
        assert f"{_bad(f)}: FAILED: BlowUp" in r.stdout
    assert "2 of 4 point(s) failed" in r.stderr and "Traceback" not in r.stderr



@pytest.mark.slow
def test_sweep_writes_its_report_with_the_failed_points(swept):
    """The sweep's own report (DIR/report.html) in headless Chromium: its figures and the
    sweep's plots loaded, the table within the page, both failed points with their reason."""
    from tests.test_sweep_report import check_rendered, chromium

    tmp, out, env, r = swept
    assert f"{out / 'report.html'}" in r.stdout
    with chromium(out / "report.html") as driver:
        check_rendered(driver, 6, {_bad(f): "contact stiffness k_n too low" for f in (0.5, 1.0)})

def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _start_cluster(tmp, env):
    """`dask scheduler` and one `dask worker` (one thread), as a user starts them by hand."""
    dask = Path(sys.executable).with_name("dask")
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    procs = [subprocess.Popen([str(dask), "scheduler", "--host", "127.0.0.1", "--port",
                               str(port), "--no-dashboard"], env=env, cwd=tmp,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    t0 = time.time()
    while True:  # wait until the scheduler listens
        try:
            socket.create_connection(("127.0.0.1", port), timeout=1).close()
            break
        except OSError:
            if time.time() - t0 > 60 or procs[0].poll() is not None:
                raise RuntimeError("dask scheduler did not start")
            time.sleep(0.3)
    procs.append(subprocess.Popen([str(dask), "worker", address, "--nthreads", "1",
                                   "--nworkers", "1", "--no-dashboard", "--memory-limit", "0"],
                                  env=env, cwd=tmp, stdout=subprocess.DEVNULL,
                                  stderr=subprocess.DEVNULL))
    return address, procs


def _stop(procs):
    for p in reversed(procs):
        p.terminate()
    for p in reversed(procs):
        try:
            p.wait(timeout=20)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()


def _on_cluster(tmp, out, env, factors, counts):
    import psutil
    from distributed import Client

    address, procs = _start_cluster(tmp, env)
    try:
        with Client(address, timeout="60s") as c:
            c.wait_for_workers(1, timeout=60)
        r = _cli(*_sweep_args(out, factors, counts, "--scheduler", address), env=env)
        worker_pids = {procs[1].pid} | {p.pid for p in
                                         psutil.Process(procs[1].pid).children(recursive=True)}
    finally:
        _stop(procs)
    return r, worker_pids


@pytest.mark.slow
def test_sweep_on_a_scheduler_started_by_hand(swept, tmp_path):
    """The kept points of the fixture (copied) and a failing one run as tasks of a worker
    started with `dask worker`: one numba thread there too (set by the task itself)."""
    _, src, env, _ = swept
    out = tmp_path / "copy"
    shutil.copytree(src, out)
    before = _mtimes(out, [_good(0.5), _good(1.0)])
    r, worker_pids = _on_cluster(tmp_path, out, env, "0.5,1", f"{GOOD_KN},{BAD_KN}")
    assert r.returncode == 1, r.stderr
    assert "tcp://127.0.0.1" in r.stdout
    assert _mtimes(out, [_good(0.5), _good(1.0)]) == before
    record = json.loads((out / "sweep.json").read_text())
    for name in (_good(0.5), _good(1.0), _bad(0.5)):
        run = record["points"][name]["last_run"]
        assert run["worker"]["pid"] in worker_pids  # ran on the hand-started worker
        assert run["worker"]["numba_threads"] == 1
    assert record["points"][_good(0.5)]["last_run"]["status"] == "kept"
    assert record["points"][_bad(0.5)]["status"] == "failed"


@pytest.mark.slow
def test_new_point_computed_on_a_scheduler_started_by_hand(swept, tmp_path):
    _, src, env, _ = swept
    out = tmp_path / "copy"
    shutil.copytree(src, out)
    r, worker_pids = _on_cluster(tmp_path, out, env, "0.5,1,1.5", f"{GOOD_KN}")
    assert r.returncode == 0, r.stderr
    record = json.loads((out / "sweep.json").read_text())
    run = record["points"][_good(1.5)]["last_run"]
    assert run["status"] == "done" and run["worker"]["pid"] in worker_pids
    assert (out / "points" / _good(1.5) / "summary.json").exists()


def _one_line_error(r):
    assert r.returncode == 2, (r.stdout, r.stderr)
    assert r.stderr.startswith("error: ") and r.stderr.count("\n") == 1, r.stderr
    assert "Traceback" not in r.stderr


@pytest.mark.slow
def test_foreign_corrupt_or_other_base_dir_is_a_one_line_error(swept, tmp_path):
    _, src, env, _ = swept
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("mine\n")
    corrupt = tmp_path / "corrupt"
    corrupt.mkdir()
    (corrupt / "sweep.json").write_text('{"kind": "vibroflow sw')
    for folder, words in ((foreign, "not a vibroflow sweep folder"),
                          (corrupt, "corrupt sweep record")):
        listing = sorted(p.name for p in folder.iterdir())
        r = _cli("sweep", "tub47-quick", "--factors", "0.5,1", "--out", folder,
                 *_sets(FIXED), env=env)
        _one_line_error(r)
        assert words in r.stderr
        assert sorted(p.name for p in folder.iterdir()) == listing  # nothing written
    # a marker of another kind; the fixture's folder with another base scenario or other
    # varied keys: refused, naming the difference (the same check as the CLI's, in-process)
    from vibroflow.errors import InputError
    from vibroflow.study.sweep import check_sweep_dir
    from vibroflow.study.sweep_points import parse_vary, plan_sweep

    other = tmp_path / "other"
    other.mkdir()
    (other / "sweep.json").write_text('{"kind": "vibroflow study"}')
    for folder, sets, vary, words in (
            (other, FIXED, [f"contacts.0.k_n={GOOD_KN}"], "not a vibroflow sweep record"),
            (src, [*FIXED, "run.seed=7"], [f"contacts.0.k_n={GOOD_KN}"],
             "run.seed = 1 there, 7 now"),
            (src, [*FIXED, f"contacts.0.k_n={GOOD_KN}"], [], "not of motion.amplitude_factor")):
        plan = plan_sweep("tub47-quick", [0.5], parse_vary(vary), sets)
        with pytest.raises(InputError) as e:
            check_sweep_dir(folder, plan)
        assert words in e.value.message and "\n" not in e.value.message, e.value.message


def test_bad_factors_or_vary_are_one_line_errors_naming_them(tmp_path):
    from vibroflow.errors import InputError
    from vibroflow.study.sweep_points import parse_factors, parse_vary, plan_sweep

    def plan(factors="0.5,1", vary=(), sets=FIXED):
        return plan_sweep("tub47-quick", parse_factors(factors), parse_vary(list(vary)),
                          list(sets))

    cases = [(dict(factors="0.5,x"), "--factors"), (dict(factors="-1"), "amplitude_factor"),
             (dict(vary=["fill.cont=1,2"]), "fill.cont"),
             (dict(vary=["fill.count=300,-5"]), "fill.count"),
             (dict(vary=["fill.count"]), "--vary 'fill.count'"),
             (dict(vary=["motion.amplitude_factor=1,2"]), "--factors"),
             (dict(vary=["run.seed=[1,2]"]), "run.seed"),
             (dict(vary=["lagrangian.nope=1,2"]), "lagrangian.nope"),
             (dict(vary=["run.seed=1,2"], sets=[*FIXED, "run.seed=3"]), "run.seed")]
    for kwargs, word in cases:
        with pytest.raises(InputError) as e:
            plan(**kwargs)
        assert word in e.value.message and "\n" not in e.value.message, e.value.message
    # the CLI: exit 2, one line, nothing made
    r = _cli("sweep", "tub47-quick", "--vary", "fill.count=300,-5", "--out", tmp_path / "new",
             env=_env(tmp_path))
    _one_line_error(r)
    assert "fill.count" in r.stderr and not (tmp_path / "new").exists()
    # good input: the points are the product, names stable and readable, values typed
    p = plan("1,0.5,1.0", ["run.seed=1,2"])
    assert [q.name for q in p.points] == [
        "amplitude_factor=1.0,run.seed=1", "amplitude_factor=1.0,run.seed=2",
        "amplitude_factor=0.5,run.seed=1", "amplitude_factor=0.5,run.seed=2"]
    assert p.points[0].values == {"motion.amplitude_factor": 1.0, "run.seed": 1}
    assert p.points[2].scenario["motion"]["amplitude_factor"] == 0.5


@pytest.mark.slow
def test_two_reruns_together_compute_nothing_and_leave_the_folder_whole(swept):
    """Two reruns of the fixture's sweep started together on its folder: the finished points
    are kept (their stage files untouched), the failed ones are tried again and fail again,
    and sweep.json / sweep.csv are whole and the same as before."""
    _, out, env, _ = swept
    good = [_good(0.5), _good(1.0)]
    before = _mtimes(out, good)
    csv_before = {(row["point"], row["method"]): row["circulation_strength"]
                  for row in _rows(out)}
    args = _sweep_args(out, "0.5,1", f"{GOOD_KN},{BAD_KN}", "--workers", "1")
    procs = [subprocess.Popen([sys.executable, "-m", "vibroflow.cli", *map(str, args)],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                              env=env, stdin=subprocess.DEVNULL) for _ in range(2)]
    outs = [p.communicate(timeout=600) for p in procs]
    assert [p.returncode for p in procs] == [1, 1], outs
    assert _mtimes(out, good) == before
    for stdout, _ in outs:
        for name in good:  # kept at once, or waited for while the other sweep held it
            assert f"{name}: up to date, kept" in stdout, stdout
        for f in (0.5, 1.0):
            assert f"{_bad(f)}: FAILED" in stdout
    record = json.loads((out / "sweep.json").read_text())
    assert len(record["points"]) == 4
    assert {(row["point"], row["method"]): row["circulation_strength"]
            for row in _rows(out)} == csv_before
    assert not list(out.rglob(".tmp-*"))


@pytest.mark.slow
def test_two_sweeps_compute_each_new_point_once(tmp_path):
    env = _env(tmp_path)
    out = tmp_path / "sweep"
    args = _sweep_args(out, "0.5,1", f"{GOOD_KN}", "--workers", "1")
    procs = [subprocess.Popen([sys.executable, "-m", "vibroflow.cli", *map(str, args)],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                              env=env, stdin=subprocess.DEVNULL) for _ in range(2)]
    outs = [p.communicate(timeout=1200) for p in procs]
    assert [p.returncode for p in procs] == [0, 0], outs
    for f in (0.5, 1.0):
        done = sum(f"{_good(f)}: done in" in o for o, _ in outs)
        assert done == 1, outs  # computed by one sweep, kept (or waited for) by the other
        rec = json.loads((out / "points" / _good(f) / "dem" / "stage.json").read_text())
        assert rec["resumed"] is False
    rows = _rows(out)
    assert {row["point"] for row in rows if row["status"] == "done"} == {_good(0.5), _good(1.0)}
