"""The granular temperature seen: a continuum run that carries it samples it and writes its
time-averaged map temperature.csv (units in the column names and the summary), positive where
there is material and zero in empty cells; `vibroflow continuum --temperature` and the study's
`--set METHOD.temperature=...` reach the option, a bad value is one line.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

from cli_helpers import one_line_error
from continuum_helpers import THREE_CYCLES
from vibroflow.continuum.sampling import Samples
from vibroflow.continuum.temperature_outputs import (TEMPERATURE_COLUMNS, temperature_map,
                                                     write_temperature_csv)
from vibroflow.errors import InputError
from vibroflow.study.methods import method
from vibroflow.study.pipeline import split_settings


def test_samples_average_the_temperature_mass_weighted_in_each_cell(tmp_path):
    """Two samples: a cell holding masses 1 and 3 at T = 1 and 2 m^2/s^2 has the mass-weighted
    7/4 at each; a cell holding T = 4 then 2 averages to 3; a cell never holding material is 0;
    the per-sample mean is the mass-weighted mean over all material; the arrays survive a
    checkpoint; a run without the option carries none of them."""
    h = 0.015
    x = np.array([[0.0, 0.0], [0.002, 0.003], [0.03, 0.045], [0.0, 0.0]])
    mass = np.array([1.0, 3.0, 2.0, 0.0])   # the last: an empty cell or point
    s = Samples(2, 4, 0, cell_grid=(h, 6, 8), temperature=True)
    s.add_temperatures(0, x, mass, np.array([1.0, 2.0, 4.0, 9.0]))
    s.add_temperatures(1, x, mass, np.array([1.0, 2.0, 2.0, 9.0]))
    T = temperature_map(s)
    assert T[0, 6] == pytest.approx(1.75) and T[3, 8] == pytest.approx(3.0)
    assert np.count_nonzero(T) == 2
    np.testing.assert_allclose(s.temperature_all, [(1 + 6 + 8) / 6, (1 + 6 + 4) / 6])
    back = Samples.from_arrays(s.arrays(), 2, 4, 0, (h, 6, 8), temperature=True)
    np.testing.assert_array_equal(temperature_map(back), T)
    assert write_temperature_csv(tmp_path / "t.csv", s, None)
    rows = np.genfromtxt(tmp_path / "t.csv", delimiter=",", names=True)
    assert list(rows.dtype.names) == list(TEMPERATURE_COLUMNS)
    assert rows.size == 8 * 13
    assert not any(k.startswith("temperature") for k in Samples(2, 4, 0, (h, 6, 8)).arrays())
    assert not write_temperature_csv(tmp_path / "off.csv", Samples(2, 4, 0, (h, 6, 8)), None)
    assert not (tmp_path / "off.csv").exists()


def test_continuum_command_with_temperature_writes_its_map(run_cli, tmp_path):
    """`vibroflow continuum --temperature` on a short tub47-quick: temperature.csv on every
    analysis cell, T > 0 in the cells that held material and 0 in the others, and the summary's
    granular_temperature block with its units."""
    out = tmp_path / "o"
    r = run_cli("continuum", "tub47-quick", "--out", out, "--temperature",
                "--initial-temperature", "0.001", *[a for kv in THREE_CYCLES
                                                      for a in ("--set", kv)])
    assert r.returncode == 0, r.stderr
    rows = np.genfromtxt(out / "temperature.csv", delimiter=",", names=True)
    held = rows["samples"] > 0
    assert held.any() and (~held).any()
    assert (rows["granular_temperature_m2_s2"][held] > 0).all()
    assert (rows["granular_temperature_m2_s2"][~held] == 0).all()
    block = json.loads((out / "summary.json").read_text())["continuum"]["granular_temperature"]
    assert block["mean_m2_s2"] > 0 and block["map_csv"] == "temperature.csv"
    assert block["map_units"]["granular_temperature_m2_s2"] == "m2 s-2"


def test_a_bad_initial_temperature_is_one_line(run_cli, tmp_path):
    r = run_cli("continuum", "tub47-quick", "--out", tmp_path / "o", "--temperature",
                "--initial-temperature", "-1")
    assert one_line_error(r) == ("error: initial_temperature = -1.0: must be a temperature "
                                 ">= 0 m^2/s^2")
    assert not (tmp_path / "o").exists()


def test_a_study_sets_the_temperature_and_refuses_a_bad_value():
    _, settings = split_settings(["lagrangian.temperature=true", "eulerian.temperature=1"])
    assert method("lagrangian").make_options(settings["lagrangian"]).temperature is True
    with pytest.raises(InputError, match=r"temperature = 1: must be true or false"):
        method("eulerian").make_options(settings["eulerian"])
