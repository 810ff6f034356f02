"""A DEM run's start enters its checkpoint's fingerprint (vibroflow.dem.fingerprint.run_record):
a tub run whose settled bed starts the vibration with its contact histories forgotten (and a
rest, run_dem(forget_histories=True, relax_s=S)) resumes only with that start, and a run of the
scenario's own start keeps the scenario's fingerprint."""
from __future__ import annotations

import pytest

from vibroflow.dem.fingerprint import (record_fingerprint, run_record, scenario_fingerprint,
                                       scenario_record)
from vibroflow.dem.run import run_dem
from vibroflow.errors import InputError, Interrupted
from vibroflow.scenario.io import load_scenario

#: a small tub47-quick: 60 balls, 0.02 s of settling, two cycles of vibration
SMALL = ["fill.count=60", "fill.settle_time=0.02", "fill.max_settle_time=0.02",
         "run.duration=0.0426", "run.average_last=0.0426", "run.batches=2",
         "run.record_impacts=false"]


def test_the_scenarios_own_start_keeps_the_scenarios_fingerprint():
    s = load_scenario("tub47-quick")
    assert run_record(s) == scenario_record(s)
    assert record_fingerprint(run_record(s)) == scenario_fingerprint(s)
    forgot = run_record(s, forget_histories=True, relax_s=0.1)
    assert forgot["dem_start"] == {"forget_histories": True, "relax_s": 0.1}
    assert record_fingerprint(forgot) != scenario_fingerprint(s)
    assert record_fingerprint(run_record(s, True, 0.0)) != record_fingerprint(forgot)


@pytest.mark.slow  # a small tub run, interrupted and resumed (under a minute with compilation)
def test_a_checkpoint_of_a_forgotten_start_resumes_only_that_start(tmp_path, monkeypatch):
    monkeypatch.setenv("VIBROFLOW_CACHE", str(tmp_path / "cache"))
    s = load_scenario("tub47-quick", SMALL)
    out = tmp_path / "out"
    monkeypatch.setenv("VIBROFLOW_FAULT_SIGINT_AFTER_STEPS", "1000")
    with pytest.raises(Interrupted, match="checkpoint written"):
        run_dem(s, out, progress=False, forget_histories=True, relax_s=0.001)
    monkeypatch.delenv("VIBROFLOW_FAULT_SIGINT_AFTER_STEPS")
    with pytest.raises(InputError, match=r"dem_start\.forget_histories = True there, \(none\) "
                                         r"now"):
        run_dem(s, out, resume=True, progress=False)
    with pytest.raises(InputError, match=r"dem_start\.relax_s = 0\.001 there, 0\.002 now"):
        run_dem(s, out, resume=True, progress=False, forget_histories=True, relax_s=0.002)
    summary = run_dem(s, out, resume=True, progress=False, forget_histories=True,
                      relax_s=0.001)
    assert summary["settle"]["histories_forgotten"] is True
    assert summary["steps"] == 4260
