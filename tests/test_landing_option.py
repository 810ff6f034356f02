"""The Eulerian landing as a user option (`vibroflow continuum --temperature --landing pairs |
columns`, ContinuumOptions.landing): refused in one line where it has no meaning (another value,
the Lagrangian formulation, no temperature), named in a run's fingerprint only where it is not
the default (a run without it keeps its fingerprint, a resume with the other landing is
refused), carried by a study's `--set eulerian.landing=...`, and reaching the WallEnergy the
Eulerian step reads.  On a loose block falling onto the floor with a passive T (it does not act
on the stress), the two landings give different temperatures and the same flow to the bit, the
flow of the block without any T.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from cli_helpers import one_line_error
from continuum_helpers import eulerian_block

from vibroflow.continuum.checkpoint import check_resumable, run_fingerprint
from vibroflow.continuum.eulerian import solver as eulerian
from vibroflow.continuum.formulation import formulation
from vibroflow.continuum.options import options_record
from vibroflow.continuum.temperature_field import temperature_model
from vibroflow.errors import InputError
from vibroflow.scenario.io import load_scenario
from vibroflow.study.methods import method
from vibroflow.study.pipeline import split_settings


@pytest.mark.parametrize("args, message", [
    (["--method", "lagrangian", "--temperature", "--landing", "columns"],
     "error: --landing = 'columns': columns is Eulerian only (--method eulerian); with "
     "--method lagrangian only pairs"),
    (["--method", "eulerian", "--landing", "columns"],
     "error: --landing = 'columns': only with --temperature; without it only pairs"),
    (["--method", "eulerian", "--temperature", "--landing", "rows"],
     "error: --landing = 'rows': must be pairs or columns"),
])
def test_the_cli_refuses_a_landing_without_meaning_in_one_line(args, message, run_cli, tmp_path):
    r = run_cli("continuum", "tub47-quick", "--out", tmp_path / "o", *args)
    assert one_line_error(r) == message
    assert not (tmp_path / "o").exists()


def test_the_options_and_a_study_carry_the_landing_and_refuse_it_elsewhere():
    eul, lag = formulation("eulerian"), formulation("lagrangian")
    assert eul.options(temperature=True, landing="columns").landing == "columns"
    with pytest.raises(InputError, match=r"^landing = 'columns': the Lagrangian"):
        lag.options(temperature=True, landing="columns")
    with pytest.raises(InputError, match=r"^landing = 'columns': only with the temperature"):
        eul.options(landing="columns")
    _, settings = split_settings(["eulerian.temperature=true", "eulerian.landing='columns'",
                                  "lagrangian.temperature=true", "lagrangian.landing='columns'"])
    assert method("eulerian").make_options(settings["eulerian"]).landing == "columns"
    # a bare word reads as a scenario field's does (the shell eats unescaped quotes)
    assert split_settings(["eulerian.landing=columns"])[1]["eulerian"] == {"landing": "columns"}
    with pytest.raises(InputError, match=r"^lagrangian\.landing = 'columns'"):
        method("lagrangian").make_options(settings["lagrangian"])


def test_the_fingerprint_names_the_landing_only_off_its_default():
    s = load_scenario("tub47-quick")
    eul = formulation("eulerian")
    plain = eul.options()
    # a run without the temperature, or with it and the default landing: the record of the
    # options without the field, so that a run without the option keeps its fingerprint
    assert "landing" not in options_record(plain)
    pairs = eul.options(temperature=True, initial_temperature=0.01)
    assert "landing" not in options_record(pairs)
    columns = dataclasses.replace(pairs, landing="columns")
    assert options_record(columns)["landing"] == "columns"
    fp_pairs = run_fingerprint(s, None, pairs, None)
    fp_columns = run_fingerprint(s, None, columns, None)
    assert fp_pairs != fp_columns
    check_resumable("ckpt", {"fingerprint": fp_pairs, "method": "eulerian"}, fp_pairs,
                    "eulerian")
    with pytest.raises(InputError):
        check_resumable("ckpt", {"fingerprint": fp_pairs, "method": "eulerian"}, fp_columns,
                        "eulerian")
    # the option reaches the walls' WallEnergy that the Eulerian step reads
    assert temperature_model(s, columns, 0.01).walls.columns is True
    assert temperature_model(s, pairs, 0.01).walls.columns is False
    assert temperature_model(s, plain, 0.01) is None


def _fall(columns: bool | None, steps: int = 300):
    """A 3 cm block at 0.9 of the critical density falling at 0.5 m/s onto the floor (it
    lands within the steps), T passive from 0; columns None: the block without T."""
    system, state = eulerian_block((0.0, -0.5), 0.03, looseness=0.9, dx=0.01,
                                   columns=bool(columns))
    if columns is None:
        system = dataclasses.replace(system, temperature=None)
    eulerian.advance(system, state, steps)
    return state


def test_a_landing_heats_differently_by_pairs_and_by_columns_and_moves_nothing():
    pairs, columns, without = _fall(False), _fall(True), _fall(None)
    heat_pairs = float(np.sum(pairs.mass * pairs.temperature))
    heat_columns = float(np.sum(columns.mass * columns.temperature))
    # both landings turn some of the fall's energy into T, by different counts
    assert heat_pairs > 0.0 and heat_columns > 0.0
    assert abs(heat_columns - heat_pairs) > 1e-3 * max(heat_pairs, heat_columns)
    # T is passive here: the flow is the same to the bit, and the one without T
    for s in (columns, without):
        np.testing.assert_array_equal(s.mass, pairs.mass)
        np.testing.assert_array_equal(s.v, pairs.v)
        np.testing.assert_array_equal(s.stress, pairs.stress)
