"""The scenario a calibration was measured on (calibration.toml's [scenario]): written after the
other tables and read back byte for byte, and checked against the scenario a solver runs: other
media or another tub is one line naming the field and both values unless
--allow-other-calibration is given; a calibration without [scenario] is used with a warning."""
from __future__ import annotations

import os
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from tests.cli_helpers import one_line_error
from vibroflow.errors import InputError
from vibroflow.io.calibration_file import Calibration, read_calibration, write_calibration
from vibroflow.io.calibration_source import check_calibration_source, scenario_source
from vibroflow.scenario.io import load_scenario

DATA = Path(__file__).parent / "data"
QUICK_CAL = DATA / "tub47-quick-dem" / "calibration.toml"


def _with_source(sc) -> Calibration:
    """tub47-quick's real calibration with the [scenario] of `sc` added."""
    tables = tomllib.loads(QUICK_CAL.read_text(encoding="utf-8"))
    return Calibration.from_dict({**tables, "scenario": scenario_source(sc)})


def test_the_source_is_the_scenarios_media_and_tub_and_round_trips(tmp_path):
    sc = load_scenario("tub47-quick")
    src = scenario_source(sc)
    assert src["case"] == "tub47-quick"
    assert src["media"]["diameter_m"] == sc.fill.diameter == 0.00635
    assert src["media"]["density_kg_m3"] == sc.materials["steel"].density
    assert src["media"]["ball_ball_restitution"] == 0.85
    assert {"ball_wall_friction", "ball_partition_restitution"} <= set(src["media"])
    assert src["tub"] == {"radius_m": sc.tub.radius, "rim_height_m": sc.tub.rim_height,
                          "length_m": sc.tub.length, "periodic": False}
    cal = _with_source(sc)
    path = write_calibration(tmp_path / "calibration.toml", cal)
    text = path.read_text(encoding="utf-8")
    # the tables the file had keep their bytes and order; [scenario] comes last
    old = QUICK_CAL.read_text(encoding="utf-8")
    assert text.startswith(old.rstrip("\n")) and text.index("[scenario]") > len(old.rstrip())
    again = read_calibration(path)
    assert again.scenario.media.diameter_m == 0.00635
    assert write_calibration(tmp_path / "again.toml", again).read_bytes() == path.read_bytes()
    assert check_calibration_source(again, sc) is None


def test_other_media_or_another_tub_is_one_line_naming_field_and_values():
    cal = _with_source(load_scenario("tub47-quick", ["fill.diameter=0.008"]))
    quick = load_scenario("tub47-quick")
    with pytest.raises(InputError) as e:
        check_calibration_source(cal, quick, where="cal.toml")
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith("cal.toml: scenario.media.diameter_m = 0.008")
    assert "0.00635" in msg and "--allow-other-calibration" in msg
    warning = check_calibration_source(cal, quick, allow=True)
    assert warning.startswith("warning: ") and "0.008" in warning and "\n" not in warning
    # the tub (tub47 is three times as long) and a contact law are compared too
    with pytest.raises(InputError, match=r"scenario\.tub\.length_m = 0\.01905 .* 0\.0635"):
        check_calibration_source(_with_source(quick), load_scenario("tub47"))
    with pytest.raises(InputError, match=r"scenario\.media\.ball_ball_friction = 0\.2 .* 0\.3"):
        check_calibration_source(cal.model_copy(update={"scenario": _with_source(
            quick).scenario}), load_scenario("tub47-quick", ["contacts.0.friction=0.3"]))
    # a change the calibration does not depend on (the seed, the ball count) is no mismatch
    assert check_calibration_source(_with_source(quick), load_scenario(
        "tub47-quick", ["run.seed=7", "fill.count=4000"])) is None


def test_a_calibration_without_a_source_is_used_with_a_warning():
    warning = check_calibration_source(read_calibration(QUICK_CAL), load_scenario("tub47-quick"))
    assert warning.startswith("warning: ") and "[scenario]" in warning and "\n" not in warning


# ----------------------------------------------------------------------------------------------
# `vibroflow continuum --calibration` on the command line

def _cli(*args, tmp):
    env = dict(os.environ, VIBROFLOW_CACHE=str(tmp / "cache"), NO_COLOR="1")
    return subprocess.run([sys.executable, "-m", "vibroflow.cli", *map(str, args)],
                          capture_output=True, text=True, env=env, stdin=subprocess.DEVNULL)


def test_continuum_refuses_a_calibration_of_other_media_unless_allowed(tmp_path):
    path = write_calibration(tmp_path / "cal8mm.toml", _with_source(
        load_scenario("tub47-quick", ["fill.diameter=0.008"])))
    out = tmp_path / "out"
    r = _cli("continuum", "tub47-quick", "--calibration", path, "-o", out,
             "--stop-after-steps", "0", tmp=tmp_path)
    line = one_line_error(r)
    assert "scenario.media.diameter_m = 0.008" in line and "0.00635" in line
    assert "--allow-other-calibration" in line and not out.exists()
    r = _cli("continuum", "tub47-quick", "--calibration", path, "-o", out,
             "--stop-after-steps", "0", "--allow-other-calibration", tmp=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "warning: " in r.stderr and "0.008" in r.stderr
    assert (out / "checkpoint.npz").is_file()


def test_continuum_warns_on_a_calibration_without_a_source(tmp_path):
    r = _cli("continuum", "tub47-quick", "--calibration", QUICK_CAL, "-o", tmp_path / "out",
             "--stop-after-steps", "0", tmp=tmp_path)
    assert r.returncode == 0, r.stderr
    assert [ln for ln in r.stderr.splitlines() if ln.startswith("warning: ")] == [
        f"warning: --calibration {QUICK_CAL} has no [scenario] table: cannot check that it was "
        "measured on this scenario's media and tub"]


def test_continuum_takes_one_of_scenario_and_like(tmp_path):
    assert "give one of them" in one_line_error(_cli(
        "continuum", "tub47-quick", "--like", tmp_path, "-o", tmp_path / "o", tmp=tmp_path))
    assert "SCENARIO is missing" in one_line_error(_cli(
        "continuum", "-o", tmp_path / "o", tmp=tmp_path))
    assert "--like" in one_line_error(_cli(
        "continuum", "--like", tmp_path, "-o", tmp_path / "o", tmp=tmp_path))
