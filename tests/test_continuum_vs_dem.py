"""The continuum formulations against vibroflow's DEM on tub47 and tub47-quick: the comparison
the package exists for (issues 4 and 6), with the DEM as the ground truth.

The references are DEM runs (tests/data/tub47-dem, the reference case: circulation 2.44e-3
m^2/s counterclockwise, seed-to-seed E 0.135 against seed 2, so tub47.md's fields-agree limit
is 0.20; over ten seeds the seed-to-seed E is 0.206 +- 0.026 and the limit 0.31,
benchmarks/README.md "Session 18", whose ten runs' tables are tests/data/tub47-dem-seeds; and
tests/data/tub47-quick-dem: 3.57e-3 m^2/s, seed-to-seed E 0.156): their cell tables and the
calibrations measured on them.  Each continuum runs the same scenario with that calibration, at
the package's defaults, and is judged with tub47.md's measures (vibroflow.analysis.compare).

On tub47 the circulations agree as tub47.md judges them (within 10 % or twice the combined
standard error) and the fields do not (E 0.34 and 0.43 for this settling time, against the
limit 0.20): the E bounds are what the formulations reach (benchmarks/README.md "Session 11";
over four settling times the Lagrangian's E is 0.347 +- 0.006), guards against regressions,
not tub47.md's target.  The Lagrangian check also runs session 8's default (one APIC transfer
a step at cfl 0.075: E 0.46 here), which the transfers' rate decoupled from the step
(continuum/run.py, DEFAULT_TRANSFER_CFL) improves on.

tub47-quick (3 balls between the partitions instead of 10) is where the defaults were not
chosen, and where they do worse: both rolls are too weak (0.58 and 0.51 of the DEM's; with
session 8's defaults 0.83 and 0.68) and the fields as far or farther from the DEM's (E 0.48 and
0.61, against 0.43 and 0.54).  Its bounds guard that state and say so.
"""
from __future__ import annotations

from pathlib import Path

import pytest

from vibroflow.measure.bulk import read_csv
from vibroflow.analysis.compare import field_difference, strengths_agree
from vibroflow.io.calibration_file import read_calibration
from vibroflow.scenario.io import load_scenario

DATA = Path(__file__).parent / "data"
#: the DEMs' circulations, counterclockwise: strength and standard error (m^2/s; the data's
#: README.md)
DEM = {"tub47": (2.4418e-3, 0.2183e-3), "tub47-quick": (3.5725e-3, 0.0932e-3)}
DIRS = {"tub47": DATA / "tub47-dem", "tub47-quick": DATA / "tub47-quick-dem"}


def _against_dem(case: str, summary: dict, out: Path) -> tuple[float, float, bool]:
    """(E against the DEM, strength over the DEM's, whether the strengths agree) of a continuum
    run of `case` in `out`."""
    c = summary["circulation"]
    assert c["sense"] == "counterclockwise"
    E = field_difference(read_csv(out / "bulk_velocity.csv"),
                         read_csv(DIRS[case] / "bulk_velocity.csv"))
    s, se = DEM[case]
    return E, c["strength"] / s, strengths_agree(c["strength"], c["strength_stderr"], s, se)


def _run(method: str, case: str, out: Path, **options):
    scenario = load_scenario(case)
    cal = read_calibration(DIRS[case] / "calibration.toml")
    if method == "lagrangian":
        from vibroflow.continuum.run import LagrangianOptions, run_lagrangian

        summary = run_lagrangian(scenario, out, calibration=cal,
                                 options=LagrangianOptions(**options))
    else:
        from vibroflow.continuum.eulerian.run import EulerianOptions, run_eulerian

        summary = run_eulerian(scenario, out, calibration=cal,
                               options=EulerianOptions(**options))
    return summary, _against_dem(case, summary, out)


SEEDS = DATA / "tub47-dem-seeds"


def _against_seeds(out: Path) -> dict:
    """A continuum run judged against the DEM's ten fill seeds (vibroflow.analysis.judge, as
    `vibroflow compare` prints it): the floor measured on them (0.206 +- 0.026, limit 0.309)."""
    from vibroflow.analysis.judge import judge, read_result

    refs = [read_result(SEEDS / f"seed{k}") for k in range(1, 11)]
    j = judge([read_result(out)], refs)
    r = j["results"][0]
    print(f"\nagainst the ten seeds: strength x{r['strength_ratio']:.2f} "
          f"({'agrees' if r['strengths_agree'] else 'differs'}), E {r['E_mean']:.3f} +- "
          f"{r['E_stderr']:.3f} against the limit {j['limit']:.3f} "
          f"({r['E_over_limit']:.2f} of it), {r['E_mean_field']:.3f} against their mean field")
    return r


def test_lagrangian_on_tub47_agrees_in_strength_and_beats_session_8(tmp_path):
    """Against seed 1 (E < 0.40) and against the ensemble of ten seeds: the circulations agree,
    the field misses the limit by a quarter (measured 1.25 of it: E 0.386 +- 0.015 against
    0.309), a systematic difference (0.356 against the seeds' mean field); the bound guards
    that state, it is not tub47.md's target."""
    _, (E, s, agree) = _run("lagrangian", "tub47", tmp_path / "new")
    r = _against_seeds(tmp_path / "new")
    assert r["strengths_agree"]
    assert r["E_over_limit"] < 1.35
    assert r["E_mean_field"] < r["E_mean"]
    _, (E_old, s_old, _) = _run("lagrangian", "tub47", tmp_path / "old", cfl=0.075,
                                transfer_cfl=None)
    print(f"\nLagrangian tub47: E {E:.3f}, strength x{s:.2f}; one transfer at cfl 0.075: "
          f"E {E_old:.3f}, strength x{s_old:.2f}")
    assert agree
    assert E < 0.40
    assert E < E_old - 0.05


def test_eulerian_on_tub47_agrees_in_strength(tmp_path):
    """Against seed 1 (E < 0.50) and against the ten seeds: the circulations agree, the field
    misses the limit by two fifths (measured 1.42 of it: E 0.437 +- 0.015)."""
    summary, (E, s, agree) = _run("eulerian", "tub47", tmp_path / "eul")
    r = _against_seeds(tmp_path / "eul")
    assert r["strengths_agree"]
    assert r["E_over_limit"] < 1.55
    print(f"\nEulerian tub47: E {E:.3f}, strength x{s:.2f}")
    assert agree
    assert E < 0.50
    assert abs(summary["continuum"]["mass_error"]) < 1e-12


@pytest.mark.parametrize("method, E_max, s_range", [("lagrangian", 0.55, (0.45, 1.3)),
                                                     ("eulerian", 0.70, (0.40, 1.3))])
def test_on_tub47_quick_against_the_dem(tmp_path, method, E_max, s_range):
    """tub47-quick, where the defaults were not chosen: bounds that guard the state reached
    (module docstring: both rolls too weak), not tub47.md's targets."""
    _, (E, s, _) = _run(method, "tub47-quick", tmp_path / method)
    print(f"\n{method} tub47-quick: E {E:.3f}, strength x{s:.2f}")
    assert E < E_max
    assert s_range[0] < s < s_range[1]

