"""The granular temperature seen: a continuum run that carries it samples it and writes its
time-averaged map temperature.csv (units in the column names and the summary), positive where
there is material and zero in empty cells; `vibroflow continuum --temperature` and the study's
`--set METHOD.temperature=...` reach the option, a bad value is one line; the report's data
gathers the DEM's fields onto the analysis cells and sets each continuum's map beside its
difference to the DEM's.
"""
from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest
import xarray as xr

from cli_helpers import one_line_error
from continuum_helpers import THREE_CYCLES
from vibroflow.continuum.sampling import Samples
from vibroflow.continuum.temperature_outputs import (TEMPERATURE_COLUMNS, temperature_map,
                                                     write_temperature_csv)
from vibroflow.errors import InputError
from vibroflow.report import figures
from vibroflow.report.temperature_maps import PHI_KEY, T_KEY, temperature_maps
from vibroflow.scenario.io import load_scenario
from vibroflow.study.methods import method
from vibroflow.study.pipeline import split_settings
from vibroflow.tub.geometry import geometry_of


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


# the Eulerian carrying the temperature loses mass at tub47-quick's rim at the default Courant
# number (the step's limit, not its outputs'): it runs here at cfl 0.1, in the slow suite (its
# command compiles the Eulerian's fused loop with T, 30 s on a fresh clone; the outputs are the
# Lagrangian's code)
@pytest.mark.parametrize("method, args", [
    ("lagrangian", []), pytest.param("eulerian", ["--cfl", "0.1"], marks=pytest.mark.slow)])
def test_continuum_command_with_temperature_writes_its_map(method, args, run_cli, tmp_path):
    """`vibroflow continuum --temperature` on a short tub47-quick: temperature.csv on every
    analysis cell, T > 0 in the cells that held material and 0 in the others, and the summary's
    granular_temperature block with its units and the run's initial T and landing."""
    out = tmp_path / "o"
    r = run_cli("continuum", "tub47-quick", "--out", out, "--method", method, *args,
                "--temperature",
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
    # the run's temperature options, as given (the landing at its default)
    assert block["initial_m2_s2"] == 0.001 and block["landing"] == "pairs"
    # the U wall's feed by region and phase (continuum/wall_feed.py), every sample measured
    feed = json.loads((out / "summary.json").read_text())["wall_feed"]
    assert set(feed["by_region_W_m2"]) == {"floor", "arcs", "side walls"}
    rows = np.genfromtxt(out / "wall_feed.csv", delimiter=",", names=True)
    assert np.isfinite(rows["u_wall_W_m2"]).all() and (rows["samples"] > 0).all()


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


def _dem_fields(x, z, T, phi, rho):
    dims = ("x", "z")
    return xr.Dataset({"temperature": (dims, T), "solid_fraction": (dims, phi),
                       "density": (dims, rho)}, coords={"x": x, "z": z})


def test_report_sets_each_continuum_beside_the_dem_and_their_difference(tmp_path):
    """The DEM's 5 mm fields gathered onto the 15 mm analysis cells: T mass-weighted (a cell
    of two points at T = 1, density 1 and four at T = 4, density 2 gives 3.4), the solid fraction the
    mean, 0 where no mass; a continuum with temperature.csv is set beside its difference
    (continuum minus DEM), one without it is listed as such."""
    s = load_scenario("tub47-quick")
    h = float(s.analysis.cell_size)
    x = np.arange(-0.16, 0.16 + 1e-9, 0.005)
    z = np.arange(0.0, 0.06 + 1e-9, 0.005)
    X, Z = np.meshgrid(x, z, indexing="ij")
    near = (np.abs(X) < 0.5 * h - 1e-9) & (np.abs(Z) < 0.5 * h - 1e-9)   # cell (0, 0)
    left = near & (X < -1e-9)
    T = np.where(left, 1.0, 4.0) * near
    rho = np.where(left, 1.0, 2.0) * near
    phi = np.where(near, 0.5, 0.0)
    # 3 grid points x 2 rows in cell (0, 0): x = -0.005 (T 1, rho 1), x = 0 and 0.005 (T 4,
    # rho 2)
    want = (2 * 1 * 1 + 4 * 2 * 4) / (2 * 1 + 4 * 2)
    (tmp_path / "lagrangian").mkdir()
    (tmp_path / "lagrangian" / "temperature.csv").write_text(
        "x,z,granular_temperature_m2_s2,solid_fraction,samples\n0.0,0.0,5.0,0.6,4\n"
        f"{h!r},0.0,1.0,0.2,4\n")
    data = SimpleNamespace(
        geometry=geometry_of(s), scenario=s, dem_fields=_dem_fields(x, z, T, phi, rho),
        continuum_methods=["lagrangian", "eulerian"], out=tmp_path,
        summary={"methods": {"dem": {}, "lagrangian": {}, "eulerian": {}}})
    maps = temperature_maps(data)
    i0 = int(np.argmin(np.abs(maps.x)))
    assert maps.dem[T_KEY][0, i0] == pytest.approx(want)
    assert maps.dem[PHI_KEY][0, i0] == pytest.approx(0.5)
    assert np.count_nonzero(maps.dem[T_KEY]) == 1
    assert maps.without == ["eulerian"] and list(maps.continua) == ["lagrangian"]
    lag = maps.continua["lagrangian"]
    assert lag[T_KEY][0, i0] == 5.0 and lag[T_KEY][0, i0 + 1] == 1.0
    np.testing.assert_allclose(lag["temperature_difference_m2_s2"], lag[T_KEY] - maps.dem[T_KEY])
    assert lag["temperature_difference_m2_s2"][0, i0] == pytest.approx(5.0 - want)
    assert lag["solid_fraction_difference"][0, i0 + 1] == pytest.approx(0.2)
    data.fields = {}
    assert figures.temperature_maps(data, maps).startswith(b"\x89PNG")


def test_report_takes_each_continuums_difference_against_the_dems_thermal_temperature(tmp_path):
    """With the thermal T in the fields the DEM shows both cycle means, the continuum's
    difference is to the thermal T, and E is tub47.md's for a scalar, by hand: cells (0, 0) and
    (1, 0) at phi 0.5 with thermal T 1 and 2, the continuum's 5 and 1 at phi 0.6:
    E = sqrt((16 + 1) / 2) / 1.5; against the phase-resolved T (4 and 4): sqrt((1 + 9) / 2) / 4."""
    s = load_scenario("tub47-quick")
    h = float(s.analysis.cell_size)
    x = np.arange(-0.16, 0.16 + 1e-9, 0.005)
    z = np.arange(0.0, 0.06 + 1e-9, 0.005)
    X, Z = np.meshgrid(x, z, indexing="ij")
    row = np.abs(Z) < 0.5 * h - 1e-9
    c0 = row & (np.abs(X) < 0.5 * h - 1e-9)
    c1 = row & (np.abs(X - h) < 0.5 * h - 1e-9)
    on = c0 | c1
    ds = _dem_fields(x, z, 9.0 * on, np.where(on, 0.5, 0.0), 1.0 * on)
    dims = ("x", "z")
    ds["temperature_cycle_mean"] = (dims, 4.0 * on)
    ds["thermal_temperature_cycle_mean"] = (dims, 1.0 * c0 + 2.0 * c1)
    ds["thermal_temperature_cycle_mean_stderr"] = (dims, 0.1 * on)
    (tmp_path / "lagrangian").mkdir()
    (tmp_path / "lagrangian" / "temperature.csv").write_text(
        "x,z,granular_temperature_m2_s2,solid_fraction,samples\n0.0,0.0,5.0,0.6,4\n"
        f"{h!r},0.0,1.0,0.6,4\n")
    data = SimpleNamespace(
        geometry=geometry_of(s), scenario=s, dem_fields=ds, continuum_methods=["lagrangian"],
        out=tmp_path, summary={"methods": {"dem": {}, "lagrangian": {}}})
    maps = temperature_maps(data)
    i0 = int(np.argmin(np.abs(maps.x)))
    assert maps.dem[T_KEY][0, i0] == pytest.approx(4.0)
    assert maps.dem_thermal[T_KEY][0, i0 + 1] == pytest.approx(2.0)
    lag = maps.continua["lagrangian"]
    assert lag["temperature_difference_m2_s2"][0, i0] == pytest.approx(4.0)
    assert lag["temperature_difference_m2_s2"][0, i0 + 1] == pytest.approx(-1.0)
    assert lag["E_thermal"] == pytest.approx(np.sqrt(8.5) / 1.5)
    assert lag["E_phase_resolved"] == pytest.approx(np.sqrt(5.0) / 4.0)
    assert maps.E_dem_error == pytest.approx(0.1 / 1.5)
    data.fields = {}
    assert figures.temperature_maps(data, maps).startswith(b"\x89PNG")
