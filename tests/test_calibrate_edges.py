"""Edges of `vibroflow calibrate`: a DEM run too small to calibrate on (one line saying so,
not a NaN parameter reported as though the user had typed it), a run folder
another command holds or that cannot be written, a Ctrl-C.  One line each, no traceback,
nothing written."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys

import pytest

from tests.cli_helpers import one_line_error as _one_line

from vibroflow.errors import InputError, Interrupted

# 150 balls in tub47-quick's tub: a fluidised film with no dense cell (tests/test_calibrate.py)
TINY = ["fill.count=150", "fill.settle_time=0.1", "fill.max_settle_time=0.1",
        "run.duration=0.15", "run.average_last=0.1"]


def _cli(*args):
    env = dict(os.environ, NO_COLOR="1")
    return subprocess.run([sys.executable, "-m", "vibroflow.cli", *map(str, args)],
                          capture_output=True, text=True, env=env, stdin=subprocess.DEVNULL,
                          timeout=300)




@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    from vibroflow.dem.run import run_dem
    from vibroflow.scenario.io import load_scenario

    out = tmp_path_factory.mktemp("tiny") / "run"
    run_dem(load_scenario("tub47-quick", TINY), out_dir=out)
    return out


@pytest.fixture
def run(tiny_run, tmp_path):
    """A fresh copy of the tiny run."""
    out = tmp_path / "run"
    shutil.copytree(tiny_run, out)
    return out


def _written(run) -> set[str]:
    return {p.name for p in run.iterdir()} - {"dem.h5", "summary.json", "bulk_velocity.csv",
                                               "bulk_velocity_stderr.csv",
                                               "bulk_velocity_batches.csv", "floor.csv",
                                               ".vibroflow.lock"}


def test_too_small_a_bed_is_one_line_naming_the_measurement_and_the_remedies(run):
    line = _one_line(_cli("calibrate", run))
    assert line == (
        f"error: RUN_DIR = '{run}': the bed is too small to calibrate on: no cell of the "
        "time-averaged field has solid fraction >= 0.5, where the bed's pressure, packing and "
        "moduli are measured; give the DEM more balls (fill.count = 150) or a longer averaging "
        "window (run.average_last = 0.1 s), or coarse-grain with a wider kernel (--width, now "
        "3.18 mm)")
    assert "nan" not in line
    assert _written(run) == set()  # no fields.nc, no calibration.toml


def test_too_small_a_bed_through_the_api_on_the_file_itself(run):
    from vibroflow.calibration.calibrate import calibrate

    with pytest.raises(InputError, match="the bed is too small to calibrate on"):
        calibrate(run / "dem.h5", progress=False, pictures=False, cyclic=False)
    assert _written(run) == set()


def test_a_run_folder_another_command_holds_is_one_line(run):
    from vibroflow.io.folder_lock import folder_lock

    with folder_lock(run, "vibroflow dem"):
        line = _one_line(_cli("calibrate", run))
    assert line.startswith(f"error: RUN_DIR = '{run}': in use by process {os.getpid()} "
                           "(vibroflow dem, since ")
    assert line.endswith("); wait for it to end or give another folder")
    assert _written(run) == set()


def test_a_run_folder_that_cannot_be_written_is_one_line(run):
    if os.geteuid() == 0:  # root writes anywhere: a run folder under a file instead
        f = run.parent / "afile"
        f.write_text("x")
        line = _one_line(_cli("calibrate", f / "run"))
        assert line == (f"error: RUN_DIR = '{f / 'run'}': no such folder; give the folder of "
                        "a DEM run")
        line = _one_line(_cli("calibrate", f))
        assert line == f"error: RUN_DIR = '{f}': a file, not a folder; give the folder of a DEM run"
        return
    run.chmod(0o500)
    try:
        line = _one_line(_cli("calibrate", run))
        assert line.startswith(f"error: RUN_DIR = '{run}': not writable")
    finally:
        run.chmod(0o700)
    assert _written(run) == set()


def test_ctrl_c_in_a_calibration_is_one_line(run, monkeypatch):
    import importlib

    C = importlib.import_module("vibroflow.calibration.calibrate")  # the module, not its function

    def ctrl_c(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(C, "coarse_grain_run", ctrl_c)
    with pytest.raises(Interrupted) as e:
        C.calibrate(run, progress=False)
    assert e.value.message == (f"interrupted while calibrating {run}; nothing to resume "
                               f"(every file written is whole): run `vibroflow calibrate {run}` "
                               "again")
