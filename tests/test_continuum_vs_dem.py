"""The continuum formulations against vibroflow's DEM on tub47-quick: the comparison the package
exists for (issues 4 and 6), with the DEM as the ground truth.

The reference is a DEM run of tub47-quick (tests/data/tub47-quick-dem: its cell table and the
calibration measured on it; circulation 3.57e-3 m^2/s counterclockwise, seed-to-seed E 0.156).
Each continuum runs the same scenario with that calibration, at the package's defaults, and is
judged with tub47.md's measures (vibroflow.analysis.compare.field_difference, the circulation).
The bounds are what the formulations reach (benchmarks/README.md "Session 8": over four
settling times the Lagrangian's E is 0.43, strength 0.83 of the DEM's; the Eulerian's 0.54,
0.68), not tub47.md's targets (E <= 0.23), which neither meets: they guard the accuracy
reached against regressions.  The Lagrangian check also runs the grid and step of sessions 3 - 7
(dx half the analysis cell, cfl 0.3), whose field is further from the DEM's (E 0.62 for this
settling time): the default grid of 3 ball diameters and step are what bring the continuum's
roll over the whole bed (continuum/run.py, DEFAULT_CFL)."""
from __future__ import annotations

from pathlib import Path

import pytest

from vibroflow.analysis.bulk import read_csv
from vibroflow.analysis.compare import field_difference
from vibroflow.calibration.calibrate import read_calibration
from vibroflow.scenario.io import load_scenario

DATA = Path(__file__).parent / "data" / "tub47-quick-dem"
DEM_STRENGTH = 3.5725e-3  # m^2/s, counterclockwise (DATA/README.md)


def _against_dem(summary: dict, out: Path) -> tuple[float, float]:
    """(E against the DEM, strength over the DEM's) of a continuum run in `out`."""
    assert summary["circulation"]["sense"] == "counterclockwise"
    E = field_difference(read_csv(out / "bulk_velocity.csv"), read_csv(DATA / "bulk_velocity.csv"))
    return E, summary["circulation"]["strength"] / DEM_STRENGTH


def test_lagrangian_roll_matches_the_dem_better_on_its_default_grid_and_step(tmp_path):
    from vibroflow.continuum.run import LagrangianOptions, run_lagrangian

    scenario = load_scenario("tub47-quick")
    cal = read_calibration(DATA / "calibration.toml")
    new = run_lagrangian(scenario, tmp_path / "new", calibration=cal)
    E_new, s_new = _against_dem(new, tmp_path / "new")
    old = run_lagrangian(scenario, tmp_path / "old", calibration=cal,
                         options=LagrangianOptions(dx=0.5 * scenario.analysis.cell_size, cfl=0.3))
    E_old, s_old = _against_dem(old, tmp_path / "old")
    print(f"\nLagrangian: default E {E_new:.3f}, strength x{s_new:.2f}; "
          f"7.5 mm, cfl 0.3: E {E_old:.3f}, strength x{s_old:.2f}")
    assert E_new < 0.5
    assert 0.7 < s_new < 1.3
    assert E_new < E_old - 0.1


def test_eulerian_roll_against_the_dem(tmp_path):
    from vibroflow.continuum.eulerian.run import run_eulerian

    scenario = load_scenario("tub47-quick")
    out = run_eulerian(scenario, tmp_path / "eul", calibration=read_calibration(
        DATA / "calibration.toml"))
    E, s = _against_dem(out, tmp_path / "eul")
    print(f"\nEulerian: E {E:.3f}, strength x{s:.2f}")
    assert E < 0.65
    assert 0.5 < s < 1.3
    assert abs(out["continuum"]["mass_error"]) < 1e-12
