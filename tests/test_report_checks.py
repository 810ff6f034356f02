"""The report's checks of a study folder against hand-made folders: a summary value of the wrong
type, a verdict without the strengths it judges and an unfinished stage are one-line errors
(exit code 2, nothing written) naming the file and the field; an unreadable
bulk_velocity_batches.csv is a missing piece saying what is wrong; the cost table's report row
is the page being written, not an earlier report's record; a study without a calibration says
so."""
from __future__ import annotations

import copy
import json
import os
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest

from vibroflow.errors import InputError
from vibroflow.report.data import check_finished, check_method_summary, check_summary

GOOD = {"methods": {
    "dem": {"probes": {"P1": {"vx": 0.01, "vz": -0.02, "vx_stderr": 0.001, "vz_stderr": None}},
            "circulation": {"sense": "counterclockwise", "strength": 0.003,
                            "strength_stderr": 1e-4},
            "impacts": {"ball_ball_mean_normal_speed": 0.1, "count": 12}, "wall_time_s": 10.0},
    "eulerian": {"probes": {"P1": {"vx": 0.02, "vz": None}},
                 "circulation": {"sense": "counterclockwise", "strength": 0.0017,
                                 "strength_stderr": 8e-5},
                 "against_dem": {"field_difference_E": 0.68, "circulation_agrees": False,
                                 "probe_differences_m_s": {"P1": {"dvx": 0.01, "dvz": None}}},
                 "wall_time_s": 0.3}}}


def _with(path: tuple, value) -> dict:
    s = copy.deepcopy(GOOD)
    d = s
    for k in path[:-1]:
        d = d[k]
    d[path[-1]] = value
    return s


def test_a_summary_of_numbers_and_nulls_passes():
    check_summary(Path("summary.json"), copy.deepcopy(GOOD))
    # a null strength with no verdict is a NaN the study wrote (io.atomic.json_safe)
    s = _with(("methods", "eulerian", "circulation", "strength"), None)
    s["methods"]["eulerian"]["against_dem"]["circulation_agrees"] = None
    check_summary(Path("summary.json"), s)


@pytest.mark.parametrize("path, value, field", [
    (("methods", "eulerian", "probes", "P1", "vx"), "abc",
     "methods.eulerian.probes.P1.vx is \"abc\", not a number"),
    (("methods", "dem", "circulation", "strength_stderr"), [1],
     "methods.dem.circulation.strength_stderr is [1], not a number"),
    (("methods", "dem", "impacts", "count"), 2.5, "methods.dem.impacts.count is 2.5, not an"),
    (("methods", "eulerian", "against_dem", "circulation_agrees"), "no",
     "methods.eulerian.against_dem.circulation_agrees is \"no\", not true or false"),
    (("methods", "eulerian", "against_dem", "field_difference_E"), True,
     "methods.eulerian.against_dem.field_difference_E is true, not a number"),
    (("methods", "eulerian", "circulation", "strength"), None,
     "methods.eulerian.against_dem.circulation_agrees is false without a strength to judge "
     "(methods.eulerian.circulation.strength is null)"),
    (("methods", "dem", "circulation", "strength"), None,
     "(methods.dem.circulation.strength is null)"),
])
def test_a_value_of_the_wrong_type_is_named(path, value, field):
    with pytest.raises(InputError) as e:
        check_summary(Path("/s/summary.json"), _with(path, value))
    assert e.value.message.startswith("/s/summary.json: ") and field in e.value.message
    assert "\n" not in e.value.message


def test_a_method_summarys_blocks_are_checked():
    check_method_summary(Path("m.json"), {"floor": {"take_off_phase": None,
                                                    "take_off_phase_batches": [None, 0.1]},
                                          "continuum": {"probes": {"P1": {
                                              "shear_rate_1_s": 2.0}}}})
    for bad, field in (({"floor": {"take_off_phase": "0.1"}}, "floor.take_off_phase"),
                       ({"floor": {"force_over_weight": [1, "x"]}}, "floor.force_over_weight"),
                       ({"continuum": {"probes": {"P1": {"shear_rate_1_s": {}}}}},
                        "continuum.probes.P1.shear_rate_1_s"),
                       ({"wall_contacts": {"ratio_of_sums": "n/a"}},
                        "wall_contacts.ratio_of_sums")):
        with pytest.raises(InputError, match=field.replace(".", r"\.")):
            check_method_summary(Path("m.json"), bad)


def test_a_stage_under_way_is_an_unfinished_study(tmp_path):
    (tmp_path / "dem").mkdir()
    (tmp_path / "dem" / "stage.json").write_text("{}")
    (tmp_path / "report").mkdir()
    (tmp_path / "report" / "pending.json").write_text("{}")  # the page being written
    check_finished(tmp_path)
    (tmp_path / "lagrangian").mkdir()
    (tmp_path / "lagrangian" / "pending.json").write_text('{"stage": "lagrangian"}')
    with pytest.raises(InputError, match="lagrangian/pending.json: the study has not finished"):
        check_finished(tmp_path)


def _cli(*args):
    env = dict(os.environ, NO_COLOR="1")
    return subprocess.run([sys.executable, "-m", "vibroflow.cli", *map(str, args)],
                          capture_output=True, text=True, env=env, stdin=subprocess.DEVNULL)


def test_vibroflow_report_of_a_corrupt_or_unfinished_study_is_one_line(tmp_path):
    """Nothing is written: the checks come before the tables, the figures and the page."""
    cases = {}
    for name, summary, field in (
            ("wrong-type", _with(("methods", "dem", "probes", "P1", "vx"), "abc"),
             "methods.dem.probes.P1.vx"),
            ("no-strength", _with(("methods", "eulerian", "circulation", "strength"), None),
             "methods.eulerian.against_dem.circulation_agrees"),
            ("unfinished", GOOD, "eulerian/pending.json")):
        d = tmp_path / name
        d.mkdir()
        (d / "study.json").write_text(json.dumps({"kind": "vibroflow study"}))
        (d / "summary.json").write_text(json.dumps(summary))
        cases[d] = field
    (tmp_path / "unfinished" / "eulerian").mkdir()
    (tmp_path / "unfinished" / "eulerian" / "pending.json").write_text("{}")
    for d, field in cases.items():
        before = sorted(p.relative_to(d) for p in d.rglob("*"))
        r = _cli("report", d)
        assert r.returncode == 2, r.stderr
        assert r.stderr.startswith("error: ") and r.stderr.count("\n") == 1, r.stderr
        assert str(d) in r.stderr and field in r.stderr, r.stderr
        assert sorted(p.relative_to(d) for p in d.rglob("*")) == before


def test_an_unreadable_batches_file_is_a_missing_piece(tmp_path):
    from vibroflow.report.cell_tables import batches_note, csv_table

    run = tmp_path / "eulerian"
    run.mkdir()
    (run / "bulk_velocity.csv").write_text("x,z,solid_fraction,vx,vz,samples\n"
                                           "0,0,0.5,0.01,0.02,10\n0.015,0,0.5,0.03,0.04,10\n")
    data = SimpleNamespace(out=tmp_path, notes={},
                           summary={"methods": {"eulerian": {
                               "bulk_velocity_csv": "eulerian/bulk_velocity.csv"}}},
                           scenario=SimpleNamespace(analysis=SimpleNamespace(cell_size=0.015)))
    t = csv_table(data, "eulerian")
    assert t.batch_vx is None and data.notes == {}  # no file: no batches, nothing wrong
    (run / "bulk_velocity_batches.csv").write_text("garbage\n1,2\n")
    t = csv_table(data, "eulerian")
    assert t.batch_vx is None
    note = data.notes[batches_note("eulerian")]
    assert note.startswith(f"{run / 'bulk_velocity_batches.csv'}: unreadable (header garbage")
    (run / "bulk_velocity_batches.csv").write_text(
        "batch,x,z,solid_fraction,vx_m_s,vz_m_s,samples\n"
        "0,0,0,0.5,0.01,0.02,5\n0,0.015,0,0.5,0.03,0.04,5\n"
        "1,0,0,0.5,0.01,0.02,5\n1,0.015,0,0.5,0.03,0.04,5\n")
    data.notes.clear()
    t = csv_table(data, "eulerian")
    assert t.batch_vx is not None and data.notes == {}


def test_the_report_row_is_the_page_being_written():
    from vibroflow.report.html import _cost

    data = SimpleNamespace(
        summary={"methods": {"dem": {"wall_time_s": 10.0}}}, continuum_methods=[],
        stages={"dem": {"wall_time_s": 12.0, "finished": "2026-12-07T12:00:00+0000"},
                "report": {"wall_time_s": 10.7, "finished": "2026-12-07T12:18:47+0000"}})
    rows = {r[0].text: r for r in _cost(data)["rows"]}
    assert [c.value for c in rows["dem"][1:3]] == ["12.0", "10.0"]
    assert rows["report"][1].text == "n/a" and rows["report"][-1].text == "being written"
    assert "10.7" not in " ".join(c.text for c in rows["report"])


def test_no_calibration_is_said_as_such():
    from vibroflow.report.html import no_impact_comparison

    data = SimpleNamespace(impacts=object(), calibration=None,
                           notes={"calibration": "no calibration/calibration.toml in the study"})
    assert no_impact_comparison(data, None) == ["no calibration/calibration.toml in the study"]
    data.calibration = object()
    assert no_impact_comparison(data, None) == ["the calibration has no ball-ball impact "
                                                "relation"]


def test_an_impact_of_numerically_zero_speed_is_counted(tmp_path):
    """Ten ball-ball impacts in the window, one at -1.15e-5 m/s (numerically zero, as a DEM
    run's dem.h5 holds): all ten counted, that one in the lowest bin [0, 1e-6] m/s, the mean the
    plain mean of the ten speeds (the summary's mean, vibroflow/measure/contacts.py); an
    impact outside the window is not counted."""
    import h5py
    import numpy as np

    from vibroflow.report.impact_figures import read_distributions
    from vibroflow.scenario.io import load_scenario
    from vibroflow.tub.geometry import geometry_of

    sc = load_scenario("tub47-quick")
    t0 = sc.run.duration - sc.run.average_last
    speeds = np.array([-1.15e-5, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 5.0])
    times = np.concatenate([t0 + (np.arange(10) + 0.5) / 10 * sc.run.average_last * 0.9,
                            [0.5 * t0]])
    (tmp_path / "dem").mkdir()
    with h5py.File(tmp_path / "dem" / "dem.h5", "w") as f:
        f["impacts/time"] = times
        f["impacts/kind"] = np.zeros(11, np.int64)
        f["impacts/position_tub"] = np.zeros((11, 3))
        f["impacts/normal_speed"] = speeds
    data = SimpleNamespace(out=tmp_path, scenario=sc, geometry=geometry_of(sc))
    dist, why = read_distributions(data)
    assert why is None
    st = dist.stats["ball_ball"]
    assert st.count == 10
    assert st.mean == pytest.approx((4.5 - 1.15e-5) / 10, rel=1e-12)
    assert int(dist.histograms["ball_ball"][:, 0].sum()) == 1


def test_kinetic_energy_blocks_cover_every_whole_cycle_and_the_halves_their_own():
    """47 Hz to 0.3 s: 14 whole cycles, blocks of 5 (about 0.1 s): 0-5, 5-10 and the 4 left,
    each the mean of its own cycles' value (the cycle's index here); the window [0.1, 0.3) s
    holds 9 whole cycles, its halves 4 from 0.1 s and 5 from 0.1 + 4/47 s."""
    import numpy as np

    from vibroflow.report import bed_state

    f = 47.0
    t = (np.arange(int(0.3 * f * 40)) + 0.5) / (40 * f)
    e = np.floor(t * f)
    ct, cm = bed_state.cycle_means(t, e, f)
    np.testing.assert_allclose(ct, np.array([2.5, 7.5, 12.0]) / f)
    np.testing.assert_allclose(cm, [2.0, 7.0, 11.5])
    ke = bed_state.kinetic_energy(t, 0.07 + 0 * t, 0.1, 0.3, f, 4)
    (a1, z1), (a2, z2) = ke.half_spans
    assert (a1, z1, a2) == pytest.approx((0.1, 0.1 + 4 / f, 0.1 + 4 / f))
    assert z2 == pytest.approx(0.1 + 9 / f)


def test_the_take_off_carries_its_batches_standard_error():
    """Batches 0.10, 0.12, 0.11, 0.13 about 0.115: std (ddof 1) 0.012910 over sqrt(4).  A phase
    is on a circle: batches 0.993, 0.999, 0.099, 0.092 about the run's 0.064 lie at -0.071,
    -0.065, +0.035, +0.028 from it (sd 0.0576 over sqrt(4)), where their plain sd would read
    0.52.  None where a batch never leaves the floor."""
    import math

    import numpy as np

    from vibroflow.measure.floor_force import take_off_stderr as _take_off_stderr

    se = _take_off_stderr({"take_off_phase": 0.115,
                           "take_off_phase_batches": [0.10, 0.12, 0.11, 0.13]})
    assert se == pytest.approx(math.sqrt(0.0005 / 3) / 2, rel=1e-9)
    wrapped = _take_off_stderr({"take_off_phase": 0.064,
                                "take_off_phase_batches": [0.993, 0.999, 0.099, 0.092]})
    d = np.array([-0.071, -0.065, 0.035, 0.028])
    assert wrapped == pytest.approx(np.std(d, ddof=1) / 2, rel=1e-9)
    assert math.isnan(_take_off_stderr({"take_off_phase": 0.25,
                                        "take_off_phase_batches": [None, 0.2, 0.3, 0.25]}))
    assert math.isnan(_take_off_stderr({"take_off_phase_batches": [0.1, 0.2]}))
    assert math.isnan(_take_off_stderr({}))
