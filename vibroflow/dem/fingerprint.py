"""A scenario's identity on disk: the record and fingerprint that a DEM checkpoint and dem.h5
carry, so that a resume goes on only with the scenario that wrote them (io.record_diff names
the first field that differs when it is another).
"""
from __future__ import annotations

import hashlib
import json

from ..scenario.io import dump_scenario


def scenario_toml(scenario) -> str:
    """The scenario as TOML text (dem.h5's attribute), or as JSON when it cannot be dumped."""
    try:
        return dump_scenario(scenario)
    except Exception:  # a scenario TOML cannot hold: the JSON record says the same
        return json.dumps(scenario.model_dump(mode="json"))


#: run fields that shape no DEM number: run.checkpoint_every (a wall-clock interval) and
#: run.force_chunks (the continuum's scatter chunks; the DEM's sums do not depend on them)
NOT_DEM_FIELDS = ("checkpoint_every", "force_chunks")


def scenario_record(scenario) -> dict:
    """The scenario as plain data, less the run fields that shape no DEM number
    (NOT_DEM_FIELDS): the DEM checkpoint's record and the study's DEM stage inputs."""
    record = scenario.model_dump(mode="json")
    run = record.get("run", {})
    for name in NOT_DEM_FIELDS:
        run.pop(name, None)
    return record


def run_record(scenario, forget_histories: bool = False, relax_s: float = 0.0) -> dict:
    """scenario_record, plus "dem_start" where the settled bed starts the vibration otherwise
    than the scenario says (run_dem's forget_histories and relax_s): a checkpoint of one start
    resumes only that start, and a run of the scenario's own start keeps its fingerprint."""
    record = scenario_record(scenario)
    if forget_histories and not scenario.explicit:  # given balls have no settled histories
        record["dem_start"] = {"forget_histories": True, "relax_s": float(relax_s)}
    return record


def record_fingerprint(record: dict) -> str:
    """sha256 of a run record (run_record, scenario_record)."""
    text = json.dumps(record, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def scenario_fingerprint(scenario) -> str:
    """sha256 of scenario_record: a checkpoint resumes only the scenario that wrote it."""
    return record_fingerprint(scenario_record(scenario))
