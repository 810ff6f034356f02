"""Edges of a continuum run: an output folder that cannot be written, a damaged
checkpoint, a Ctrl-C.  Each is one line (InputError: exit 2; Interrupted: exit 130) with no
traceback, and an interrupted run resumes to the uninterrupted numbers bit for bit."""
from __future__ import annotations

import math
import os
import shutil
import zipfile

import numpy as np
import pytest

from tests.cli_helpers import one_line_error as _one_line

from vibroflow.continuum.checkpoint import CHECKSUM_KEY
from vibroflow.continuum.files import CHECKPOINT_NAME
from vibroflow.continuum.formulation import formulation
from vibroflow.continuum.options import ContinuumOptions
from vibroflow.continuum.mpm import formulation as mpm_formulation
from vibroflow.continuum.tub_run import run_continuum
from vibroflow.errors import InputError, Interrupted
from vibroflow.interrupts import FAULT_SIGINT_ENV
from vibroflow.scenario.io import load_scenario

# tests/test_continuum_runs.py's Lagrangian resume scenario (4 cycles averaged in 2 batches,
# ~60 ms of vibration)
SHORT = ["run.duration=0.05", "run.average_last=0.043", "run.batches=2"]
# tests/test_continuum_runs.py's Eulerian runs (continuum_helpers.THREE_CYCLES)
SHORT_EULERIAN = ["run.duration=0.0639", "run.average_last=0.0426", "run.batches=2"]
CLI_SETS = ["--set", "run.duration=0.05", "--set", "run.average_last=0.043", "--set",
            "run.batches=2"]


# ----------------------------------------------------------------------------------------------
# options

@pytest.mark.parametrize("field", ["dx", "cfl", "settle_time", "wall_stiffness",
                                   "stiffness_factor", "flip", "bed_viscosity",
                                   "damping_length", "initial_temperature", "transfer_cfl"])
@pytest.mark.parametrize("value", [math.inf, -math.inf, math.nan, True, "0.1"])
def test_a_number_option_that_is_not_a_finite_number_is_one_line(field, value):
    """An infinite wall stiffness would make a zero step, a division by zero: every number option
    refuses what is not a finite number, naming the field."""
    kw = {"transfer_cfl": None, field: value}
    with pytest.raises(InputError, match=rf"^{field} = .*must be"):
        ContinuumOptions(**kw)


# ----------------------------------------------------------------------------------------------
# --out that cannot be written

def test_out_that_is_a_file_is_one_line(run_cli, tmp_path):
    f = tmp_path / "afile"
    f.write_text("x")
    line = _one_line(run_cli("continuum", "tub47-quick", "--out", f, *CLI_SETS))
    assert line == f"error: --out = '{f}': is a file, not a folder; give a folder"
    line = _one_line(run_cli("continuum", "tub47-quick", "--method", "eulerian", "--out",
                             f / "sub", *CLI_SETS))
    assert line == f"error: --out = '{f / 'sub'}': '{f}' is a file, not a folder"
    assert f.read_text() == "x"


def test_out_that_is_read_only_is_one_line(run_cli, tmp_path):
    if os.geteuid() == 0:  # root writes anywhere: a folder under a file cannot be made at all
        f = tmp_path / "afile"
        f.write_text("x")
        out = f / "deeper" / "run"
        line = _one_line(run_cli("continuum", "tub47-quick", "--out", out, *CLI_SETS))
        assert line.startswith(f"error: --out = '{out}': ") and "is a file" in line
        return
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        line = _one_line(run_cli("continuum", "tub47-quick", "--out", ro, *CLI_SETS))
        assert line.startswith(f"error: --out = '{ro}': ") and "not writable" in line
        line = _one_line(run_cli("continuum", "tub47-quick", "--method", "eulerian", "--out",
                                 ro / "x", *CLI_SETS))
        assert line.startswith(f"error: --out = '{ro / 'x'}': cannot be made")
        assert list(ro.iterdir()) == []
    finally:
        ro.chmod(0o700)


# ----------------------------------------------------------------------------------------------
# damaged checkpoints

@pytest.fixture(scope="module")
def stopped(tmp_path_factory):
    """A Lagrangian and an Eulerian run of the short scenarios stopped with a checkpoint."""
    tmp = tmp_path_factory.mktemp("stopped")
    s = load_scenario("tub47-quick", SHORT)
    assert run_continuum(s, tmp / "lagrangian", stop_after_steps=40) is None
    se = load_scenario("tub47-quick", SHORT_EULERIAN)
    opt = formulation("eulerian").options(dx=0.015)
    assert run_continuum(se, tmp / "eulerian", "eulerian", options=opt,
                         stop_after_steps=40) is None
    return {"lagrangian": (tmp / "lagrangian", s, {}),
            "eulerian": (tmp / "eulerian", se, {"options": opt})}


def _flip_a_byte(p):
    data = bytearray(p.read_bytes())
    data[len(data) // 2] ^= 0xFF
    p.write_bytes(bytes(data))


def _truncate(p):
    p.write_bytes(p.read_bytes()[: p.stat().st_size // 2])


def _empty(p):
    p.write_bytes(b"")


def _not_npz(p):
    p.write_text("this is not a checkpoint\n")


def _consistent_zip_wrong_numbers(p):
    """A whole, readable npz whose arrays differ from its checksum (one velocity changed): only
    the sha256 can tell."""
    with np.load(p) as f:
        arrays = {k: f[k] for k in f.files}
    arrays["state/v"] = arrays["state/v"].copy()
    arrays["state/v"][0, 0] += 1e-9
    with open(p, "wb") as fh:
        np.savez(fh, **arrays)
    assert zipfile.ZipFile(p).testzip() is None


DAMAGE = {"flipped byte": (_flip_a_byte, "checksum mismatch"),
          "truncated": (_truncate, "truncated"),
          "empty": (_empty, "empty"),
          "not an npz": (_not_npz, "not a checkpoint"),
          "wrong numbers": (_consistent_zip_wrong_numbers, "checksum mismatch")}


def _damaged_copy(stopped, method, tmp_path, damage):
    src, s, kw = stopped[method]
    out = tmp_path / method
    shutil.copytree(src, out)
    DAMAGE[damage][0](out / CHECKPOINT_NAME)
    return out, s, kw


@pytest.mark.parametrize("damage", list(DAMAGE))
def test_damaged_lagrangian_checkpoint_is_refused_in_one_line(stopped, tmp_path, damage):
    out, s, _ = _damaged_copy(stopped, "lagrangian", tmp_path, damage)
    before = (out / CHECKPOINT_NAME).read_bytes()
    with pytest.raises(InputError) as e:
        run_continuum(s, out, resume=True)
    assert e.value.message == (f"--resume: {out / CHECKPOINT_NAME} is damaged "
                               f"({DAMAGE[damage][1]}); run without --resume to start afresh")
    assert (out / CHECKPOINT_NAME).read_bytes() == before  # left as found
    assert not (out / "summary.json").exists()


@pytest.mark.parametrize("damage", ["flipped byte", "truncated", "wrong numbers"])
def test_damaged_eulerian_checkpoint_is_refused_in_one_line(stopped, tmp_path, damage):
    out, s, kw = _damaged_copy(stopped, "eulerian", tmp_path, damage)
    with pytest.raises(InputError) as e:
        run_continuum(s, out, "eulerian", resume=True, **kw)
    assert e.value.message == (f"--resume: {out / CHECKPOINT_NAME} is damaged "
                               f"({DAMAGE[damage][1]}); run without --resume to start afresh")


def test_damaged_checkpoint_on_the_command_line_is_one_line_exit_2(stopped, run_cli,
                                                                   tmp_path):
    out, _, _ = _damaged_copy(stopped, "lagrangian", tmp_path, "truncated")
    line = _one_line(run_cli("continuum", "tub47-quick", "--out", out, "--resume", *CLI_SETS))
    assert line == (f"error: --resume: {out / CHECKPOINT_NAME} is damaged (truncated); run "
                    "without --resume to start afresh")


def test_checkpoint_carries_its_checksum_and_another_scenario_is_still_refused(stopped,
                                                                               tmp_path):
    out, s, _ = _damaged_copy(stopped, "lagrangian", tmp_path, "empty")
    shutil.copy(stopped["lagrangian"][0] / CHECKPOINT_NAME, out / CHECKPOINT_NAME)
    with np.load(out / CHECKPOINT_NAME) as f:
        assert CHECKSUM_KEY in f.files and len(str(f[CHECKSUM_KEY])) == 64
    other = load_scenario("tub47-quick", SHORT + ["fill.count=380"])
    with pytest.raises(InputError, match=r"is the checkpoint of another run \(scenario\.fill\."
                                         r"count = \d+ there, 380 now\)"):
        run_continuum(other, out, resume=True)


# ----------------------------------------------------------------------------------------------
# Ctrl-C

def _strip(summary):
    for key in ("wall_time_s", "compile_time_s", "particle_steps_per_s", "bulk_velocity_csv"):
        summary.pop(key)
    summary["continuum"].pop("wall_time_s")
    return summary


@pytest.mark.parametrize("method", ["lagrangian", "eulerian"])
def test_ctrl_c_checkpoints_and_the_resume_gives_the_uninterrupted_numbers(
        method, tmp_path, monkeypatch):
    """A SIGINT in the vibration (the fault-injection hook, half-way): Interrupted naming the
    time and the folder, a checkpoint of that instant; --resume then ends with the same
    bulk_velocity.csv and summary, bit for bit, as a run never interrupted."""
    if method == "lagrangian":
        s, kw = load_scenario("tub47-quick", SHORT), {}
    else:
        s = load_scenario("tub47-quick", SHORT_EULERIAN)
        kw = {"options": formulation("eulerian").options(dx=0.015)}

    whole = run_continuum(s, tmp_path / "whole", method, **kw)
    out = tmp_path / "split"
    monkeypatch.setenv(FAULT_SIGINT_ENV, str(whole["steps"] // 2))
    with pytest.raises(Interrupted) as e:
        run_continuum(s, out, method, **kw)
    monkeypatch.delenv(FAULT_SIGINT_ENV)
    msg = e.value.message
    assert msg.startswith("interrupted at t = 0.0") and "\n" not in msg
    assert msg.endswith(f" s; resume with --resume (vibroflow continuum ... --out {out} "
                        "--resume)")
    t = float(msg.split("t = ")[1].split(" s")[0])
    assert 0.3 * s.run.duration < t < 0.9 * s.run.duration
    assert (out / CHECKPOINT_NAME).is_file() and not (out / "summary.json").exists()
    resumed = run_continuum(s, out, method, resume=True, **kw)
    assert not (out / CHECKPOINT_NAME).exists()
    assert (out / "bulk_velocity.csv").read_bytes() == \
        (tmp_path / "whole" / "bulk_velocity.csv").read_bytes()
    assert _strip(resumed) == _strip(whole)


def test_ctrl_c_while_settling_says_there_is_nothing_to_resume(tmp_path, monkeypatch):
    s = load_scenario("tub47-quick", SHORT)

    def ctrl_c(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(mpm_formulation, "advance", ctrl_c)  # the settling's first steps
    with pytest.raises(Interrupted) as e:
        run_continuum(s, tmp_path / "o")
    assert e.value.message == "interrupted while settling; nothing to resume, run again"
    assert not (tmp_path / "o" / CHECKPOINT_NAME).exists()


def test_second_ctrl_c_stops_at_once_without_a_checkpoint(tmp_path, monkeypatch):
    """Two SIGINTs before the loop's next look: no checkpoint of a state that may be half-way
    through a sample; the message says there is nothing to resume."""
    import signal

    s = load_scenario("tub47-quick", SHORT)
    calls = {"n": 0}
    advance = mpm_formulation.advance

    def twice(system, state, m):
        advance(system, state, m)
        if state.t > 0.0 and state.step > 0 and system.frame.__class__.__name__ == "TubFrame":
            calls["n"] += 1
            if calls["n"] == 3:
                os.kill(os.getpid(), signal.SIGINT)
                os.kill(os.getpid(), signal.SIGINT)

    monkeypatch.setattr(mpm_formulation, "advance", twice)
    with pytest.raises(Interrupted) as e:
        run_continuum(s, tmp_path / "o")
    assert e.value.message.startswith("interrupted at t = ")
    assert e.value.message.endswith(", before a first checkpoint; nothing to resume, run again")
    assert not (tmp_path / "o" / CHECKPOINT_NAME).exists()
