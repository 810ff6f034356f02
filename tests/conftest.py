"""Shared test fixtures: running the real command line, writing scenario files."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def pytest_configure(config):
    # Ctrl-C tests send SIGINT to themselves or to a command they start; a runner started in
    # the background by a non-interactive shell ignores SIGINT, and its children inherit the
    # ignoring, so the tests would see no Ctrl-C: Python's own handler, as in a terminal
    signal.signal(signal.SIGINT, signal.default_int_handler)


@pytest.fixture
def run_cli(tmp_path):
    """Run `python -m vibroflow.cli ARGS...` in a fresh folder (tmp_path/"cwd" by default);
    returns the CompletedProcess (text stdout/stderr, never raises on a non-zero exit)."""
    cwd = tmp_path / "cwd"
    cwd.mkdir(exist_ok=True)

    def run(*args: str, cwd: Path = cwd, timeout: float = 300) -> subprocess.CompletedProcess:
        env = dict(os.environ, NO_COLOR="1", COLUMNS="200", PYTHONDONTWRITEBYTECODE="1")
        return subprocess.run([sys.executable, "-m", "vibroflow.cli", *map(str, args)],
                              cwd=cwd, env=env, capture_output=True, text=True,
                              timeout=timeout, stdin=subprocess.DEVNULL)

    return run


@pytest.fixture
def write_toml(tmp_path):
    """Write TOML text to tmp_path/NAME and return the path."""

    def write(text: str, name: str = "scenario.toml") -> Path:
        path = tmp_path / name
        path.write_text(text, encoding="utf-8")
        return path

    return write


@pytest.fixture(scope="session")
def study_run(tmp_path_factory):
    """The tiny study (tests.test_calibrate.SMALL: 400 balls, 0.2 s of vibration), run once for
    the whole session with its report stage: (scenario, folder, summary, echoed lines, the fill
    cache it used).  Tests read the folder; only slow ones rerun stages in it."""
    from tests.test_calibrate import SMALL
    from vibroflow.report.stage import report_stage
    from vibroflow.scenario.io import load_scenario
    from vibroflow.study import run_study

    tmp = tmp_path_factory.mktemp("study")
    cache = tmp / "cache"
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("VIBROFLOW_CACHE", str(cache))
        scenario = load_scenario("tub47-quick", SMALL)
        lines: list[str] = []
        out = tmp / "run"
        summary = run_study(scenario, out, echo=lines.append, extra_stages=[report_stage()])
    return scenario, out, summary, lines, cache


@pytest.fixture
def study(study_run, monkeypatch):
    """The session's tiny study as (scenario, folder, summary, echoed lines), with
    VIBROFLOW_CACHE at its fill cache while the test runs (a rerun finds the fill there)."""
    scenario, out, summary, lines, cache = study_run
    monkeypatch.setenv("VIBROFLOW_CACHE", str(cache))
    return scenario, out, summary, lines
