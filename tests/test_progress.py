"""vibroflow.progress: the compiling line, honest time-left estimates, plain lines off a tty."""
from __future__ import annotations

import io
import os
import subprocess
import sys
import time

import numba
import numpy as np
from numba.core import event as numba_event
from rich.console import Console

from vibroflow.progress import COMPILING, RunProgress, left_text


def _plain_progress() -> tuple[RunProgress, io.StringIO]:
    buf = io.StringIO()  # not a terminal: plain lines
    return RunProgress(True, Console(file=buf)), buf


def test_a_compilation_is_announced_while_it_runs_and_its_end_said_once():
    prog, buf = _plain_progress()
    with prog:
        with numba_event.trigger_event("numba:compile"):
            # the watch's timer says it within its first second; a loaded machine may hold
            # the timer's thread back, so the test waits for the line, not for a second
            deadline = time.monotonic() + 30.0
            while not buf.getvalue() and time.monotonic() < deadline:
                time.sleep(0.05)
            during = buf.getvalue()
        time.sleep(0.5)
        with numba_event.trigger_event("numba:compile"):
            pass  # a compilation in passing: not announced
    lines = buf.getvalue().splitlines()
    assert during.startswith(COMPILING)  # while it runs
    assert lines[0].startswith(COMPILING) and lines[0].endswith(" s")
    assert sum(ln.startswith("kernels compiled") for ln in lines) == 1, lines
    assert sum(ln.startswith(COMPILING) for ln in lines) == 1, lines


def test_a_real_compilation_is_seen_by_the_watch():
    @numba.njit(cache=False)
    def kernel(x):
        return np.sqrt(x).sum()

    prog, _ = _plain_progress()
    with prog:
        kernel(np.ones(4))
    assert prog._watch.total_s() > 0.0 and prog._watch.open_s() is None


def test_time_left_waits_for_a_measured_rate_outside_compilation():
    prog, _ = _plain_progress()
    with prog:
        prog.stage("run", 1.0)
        assert prog._measure(time.perf_counter(), 0.1, 100) == (None, None)  # no rate yet
        with numba_event.trigger_event("numba:compile"):
            t = time.perf_counter()
            assert prog._measure(t + 5.0, 0.2, 200) == (None, None)  # compiling
        t = time.perf_counter()
        assert prog._measure(t, 0.2, 200) == (None, None)  # the new base after compilation
        left, rate = prog._measure(t + 2.0, 0.4, 400)
        # 0.2 simulated s in 2 wall s after compilation: 0.6 s more take 6 s
        assert abs(left - 6.0) < 0.1 and abs(rate - 100.0) < 5.0
        left, _ = prog._measure(t + 4.0, 1.2, 900)  # past the end: never negative
        assert left == 0.0


def test_left_text_is_never_negative():
    assert left_text(None) == "estimating ..."
    assert left_text(-0.4) == "0 s left"
    assert left_text(90.0) == "1.5 min left"


def test_plain_lines_are_whole():
    prog, buf = _plain_progress()
    path = "/tmp/" + "a-very-long-folder-name/" * 8 + "checkpoint.h5"
    with prog:
        prog.log(f"resuming from {path} at t = 0.1000 s [x]")
    assert f"resuming from {path} at t = 0.1000 s [x]" in buf.getvalue().splitlines()


def test_a_sweep_table_off_a_terminal_cuts_no_column():
    from vibroflow.study.sweep import print_table

    row = {"factor": 0.5, "method": "lagrangian", "status": "done",
           "circulation_strength": 1.234e-4, "circulation_strength_stderr": 1e-6,
           "circulation_sense": "clockwise", "E_against_dem": 0.25, "impact_ball_ball": 0.1,
           "impact_ball_wall": 0.2, "wall_time_s": 3.0}
    varied = ["factor", "material.ball.youngs_modulus", "lagrangian.dx", "eulerian.dx"]
    for k in varied[1:]:
        row[k] = 1.0
    buf = io.StringIO()  # not a terminal
    print_table({"rows": [row], "varied": varied}, file=buf)
    text = buf.getvalue()
    for header in ("circulation (1e-4 m²/s)", "impacts b-b / b-w (m/s)", "wall (s)", *varied[1:]):
        assert header in text, text
    assert "…" not in text


def test_progress_lines_to_a_pipe_keep_a_long_path_whole(tmp_path):
    out = tmp_path / ("a-long-folder-name-for-the-results-of-this-run/" * 4) / "out"
    code = ("from vibroflow.progress import RunProgress\n"
            "with RunProgress(True) as p:\n"
            f"    p.log('no checkpoint in {out}: starting afresh')\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       env={**os.environ, "NO_COLOR": "1"}, timeout=120)
    assert r.returncode == 0, r.stderr
    assert f"no checkpoint in {out}: starting afresh" in r.stderr.splitlines(), r.stderr
