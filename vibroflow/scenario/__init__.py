"""Scenarios: the validated record of a run (`model`) and its TOML form (`io`).

    from vibroflow.scenario import load_scenario, dump_scenario
    s = load_scenario("tub47-quick", ["run.duration=0.2"])
"""
from vibroflow.scenario.io import (
    PRESETS,
    apply_overrides,
    dump_scenario,
    load_scenario,
    parse_scenario,
    scenario_hash,
)
from vibroflow.scenario.model import Scenario

__all__ = ["PRESETS", "Scenario", "apply_overrides", "dump_scenario", "load_scenario",
           "parse_scenario", "scenario_hash"]
