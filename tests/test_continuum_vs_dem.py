"""The continuum formulations against vibroflow's DEM on tub47 and tub47-quick: the comparison
the package exists for, with the DEM as the ground truth, judged as tub47.md judges it.

References (tests/data): the ten tub47 fill seeds' tables (tub47-dem-seeds; seed-to-seed E
0.206 +- 0.026, so the fields-agree limit is 0.309), tub47's seed 1 with its calibration
(tub47-dem: circulation 2.44e-3 m^2/s counterclockwise) and tub47-quick's DEM with its
calibration (tub47-quick-dem: 3.57e-3 m^2/s; limit 1.5 x 0.166 = 0.249, tub47.md).  Each
continuum runs the same scenario with that calibration at the package's defaults, once per
module (`runs`).

What is true, said by the tests:
- tub47: the circulations agree with the DEM's in both formulations (a target met);
- tub47: the fields miss the limit (Lagrangian E 1.25 of it, Eulerian 1.42): tub47.md's target,
  asserted under a strict xfail that states the miss;
- the amplitude sweep, ten DEM seeds a factor, the continua with the factor-1.0 calibration
  (slow suite): at factor 0.5 (tub47-f0.5-dem-seeds, limit 0.219) the Lagrangian's
  circulation agrees (0.98) and the Eulerian's does not (0.72), the fields miss the limit (2.00
  and 2.17 of it); at factor 1.5 (tub47-f1.5-dem-seeds, limit 0.241) the circulations are 1.11
  and 1.14 x the seeds', beyond the tolerance, and the fields miss it (1.44 and 2.22): strict
  xfails;
- tub47-quick: both rolls are too weak (0.58 and 0.45 of the DEM's) and the fields miss the
  limit (E 0.48 and 0.67 against 0.249): the targets under strict xfails;
- regression guards (named so) hold the state reached, so that a change that makes it worse
  fails.
"""
from __future__ import annotations

from pathlib import Path

import pytest

from vibroflow.analysis.compare import field_difference, strengths_agree
from vibroflow.continuum.formulation import formulation
from vibroflow.continuum.tub_run import run_continuum
from vibroflow.io.calibration_file import read_calibration
from vibroflow.measure.bulk import read_csv
from vibroflow.scenario.io import load_scenario

DATA = Path(__file__).parent / "data"
#: the DEMs' circulations, counterclockwise: strength and standard error (m^2/s; the data's
#: README.md)
DEM = {"tub47": (2.4418e-3, 0.2183e-3), "tub47-quick": (3.5725e-3, 0.0932e-3)}
DIRS = {"tub47": DATA / "tub47-dem", "tub47-quick": DATA / "tub47-quick-dem"}
SEEDS = DATA / "tub47-dem-seeds"
#: tub47.md's fields-agree limit on tub47-quick: 1.5 x the DEM's seed-to-seed E there
QUICK_LIMIT = 0.249
METHODS = ("lagrangian", "eulerian")


def _against_dem(case: str, summary: dict, out: Path) -> dict:
    """E against the case's DEM reference, the strength over the DEM's and whether the strengths
    agree (tub47.md), of a continuum run of `case` in `out`."""
    c = summary["circulation"]
    E = field_difference(read_csv(out / "bulk_velocity.csv"),
                         read_csv(DIRS[case] / "bulk_velocity.csv"))
    s, se = DEM[case]
    return {"sense": c["sense"], "E": E, "strength_ratio": c["strength"] / s,
            "agree": strengths_agree(c["strength"], c["strength_stderr"], s, se)}


def _against_seeds(out: Path) -> dict:
    """A continuum run judged against the DEM's ten fill seeds (vibroflow.analysis.judge, as
    `vibroflow compare` prints it)."""
    from vibroflow.analysis.judge import judge, read_result

    refs = [read_result(SEEDS / f"seed{k}") for k in range(1, 11)]
    j = judge([read_result(out)], refs)
    r = j["results"][0]
    print(f"\nagainst the ten seeds: strength x{r['strength_ratio']:.2f} "
          f"({'agrees' if r['strengths_agree'] else 'differs'}), E {r['E_mean']:.3f} +- "
          f"{r['E_stderr']:.3f} against the limit {j['limit']:.3f} "
          f"({r['E_over_limit']:.2f} of it), {r['E_mean_field']:.3f} against their mean field")
    return r


def _run(method: str, case: str, out: Path, **options) -> dict:
    scenario = load_scenario(case)
    cal = read_calibration(DIRS[case] / "calibration.toml")
    summary = run_continuum(scenario, out, method, calibration=cal,
                            options=formulation(method).options(**options))
    result = {"summary": summary, **_against_dem(case, summary, out)}
    if case == "tub47":
        result["seeds"] = _against_seeds(out)
    print(f"\n{method} {case}: E {result['E']:.3f}, strength x{result['strength_ratio']:.2f}")
    return result


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Each (method, case) run once for the module, when a test first asks for it."""
    done: dict[tuple[str, str], dict] = {}

    def get(method: str, case: str) -> dict:
        if (method, case) not in done:
            done[method, case] = _run(method, case, tmp_path_factory.mktemp(f"{method}-{case}"))
        return done[method, case]

    return get


@pytest.mark.parametrize("method", METHODS)
def test_circulation_on_tub47_agrees_with_the_dem_seeds(runs, method):
    """tub47.md: the continuum's strength within 10 % or twice the combined standard error of
    the DEM's, against the ten seeds' mean and against seed 1; the same sense."""
    r = runs(method, "tub47")
    assert r["sense"] == "counterclockwise"
    assert r["seeds"]["strengths_agree"]
    assert r["agree"]


MISS = ("a systematic difference: the DEM's agitated bed, which the continuum lacks "
        "(docs/validation.md)")


@pytest.mark.parametrize("method", [
    pytest.param("lagrangian", marks=pytest.mark.xfail(
        strict=True, reason=f"E is 1.25 x the limit (0.386 +- 0.015 against 0.309): {MISS}")),
    pytest.param("eulerian", marks=pytest.mark.xfail(
        strict=True, reason=f"E is 1.42 x the limit (0.437 +- 0.015 against 0.309): {MISS}")),
])
def test_field_on_tub47_meets_the_fields_agree_limit(runs, method):
    """tub47.md's target: E against the ten seeds at most 1.5 x their seed-to-seed E."""
    assert runs(method, "tub47")["seeds"]["E_over_limit"] <= 1.0


@pytest.mark.parametrize("method, guard", [("lagrangian", 1.35), ("eulerian", 1.55)])
def test_regression_guard_field_on_tub47(runs, method, guard):
    """Regression guard, not a target: E against the ten seeds stays below `guard` x the limit
    (measured 1.25 and 1.42) and the difference is systematic (against the seeds' mean field it
    is smaller than against each seed)."""
    r = runs(method, "tub47")
    assert r["seeds"]["E_over_limit"] < guard
    if method == "lagrangian":
        assert r["seeds"]["E_mean_field"] < r["seeds"]["E_mean"]


@pytest.mark.slow
def test_regression_guard_lagrangian_transfers_beat_one_transfer_a_step(runs, tmp_path):
    """Regression guard of a model choice (continuum/mpm/formulation.py DEFAULT_TRANSFER_CFL): the
    transfers' rate set apart from the step gives a field closer to the DEM's than one APIC
    transfer a step at cfl 0.075 (E 0.46 against seed 1)."""
    default = runs("lagrangian", "tub47")
    one = _run("lagrangian", "tub47", tmp_path / "one-transfer", cfl=0.075, transfer_cfl=None)
    assert default["E"] < 0.40
    assert default["E"] < one["E"] - 0.05


def test_eulerian_conserves_mass_on_tub47(runs):
    assert abs(runs("eulerian", "tub47")["summary"]["continuum"]["mass_error"]) < 1e-12


@pytest.mark.parametrize("method", [
    pytest.param("lagrangian", marks=pytest.mark.xfail(
        strict=True, reason=f"strength 0.58 of the DEM's, E 0.48 against 0.249: {MISS}")),
    pytest.param("eulerian", marks=pytest.mark.xfail(
        strict=True, reason=f"strength 0.45 of the DEM's, E 0.67 against 0.249: {MISS}")),
])
def test_on_tub47_quick_the_dem_flow_is_met(runs, method):
    """tub47.md's targets on tub47-quick: strength within 10 % of the DEM's, E at most the limit
    0.249."""
    r = runs(method, "tub47-quick")
    assert abs(r["strength_ratio"] - 1.0) <= 0.10 and r["E"] <= QUICK_LIMIT


@pytest.mark.parametrize("method, E_max, s_range", [("lagrangian", 0.55, (0.45, 1.3)),
                                                     ("eulerian", 0.70, (0.40, 1.3))])
def test_regression_guard_on_tub47_quick(runs, method, E_max, s_range):
    """Regression guard, not a target: the state reached on tub47-quick."""
    r = runs(method, "tub47-quick")
    assert r["sense"] == "counterclockwise"
    assert r["E"] < E_max
    assert s_range[0] < r["strength_ratio"] < s_range[1]


#: the amplitude sweep's DEM ensembles: tub47 at each factor on fill seeds 1 - N (each
#: folder's README gives N and the commands), against which the continua run with the
#: factor-1.0 calibration, as `vibroflow sweep` runs them
SWEEP = {0.5: DATA / "tub47-f0.5-dem-seeds", 1.5: DATA / "tub47-f1.5-dem-seeds"}


@pytest.fixture(scope="module")
def in_sweep(tmp_path_factory):
    """Each (factor, method) run once for the module, with the factor-1.0 calibration, and
    judged against the factor's DEM seeds (vibroflow.analysis.judge, as `vibroflow compare`)."""
    from vibroflow.analysis.judge import judge, read_result, run_folders

    done: dict[tuple[float, str], dict] = {}

    def get(factor: float, method: str) -> dict:
        if (factor, method) not in done:
            out = tmp_path_factory.mktemp(f"{method}-f{factor}")
            scenario = load_scenario("tub47", [f"motion.amplitude_factor={factor}"])
            cal = read_calibration(DIRS["tub47"] / "calibration.toml")
            run_continuum(scenario, out, method, calibration=cal,
                          options=formulation(method).options())
            refs = [read_result(p) for p in run_folders([SWEEP[factor]])]
            j = judge([read_result(out)], refs)
            r = j["results"][0]
            print(f"\n{method} at factor {factor} against {len(refs)} seeds: strength "
                  f"x{r['strength_ratio']:.2f}, E {r['E_mean']:.3f} +- {r['E_stderr']:.3f} "
                  f"against the limit {j['limit']:.3f} ({r['E_over_limit']:.2f} of it)")
            done[factor, method] = {**r, "limit": j["limit"], "seeds": len(refs)}
        return done[factor, method]

    return get


def _miss(text: str):
    return pytest.mark.xfail(strict=True, reason=f"{text}: {MISS}")


def _strength_miss(ratio: float, factor: float):
    return pytest.mark.xfail(strict=True, reason=(
        f"strength {ratio:.2f} x the ten seeds' mean at factor {factor}, beyond max(10 %, 2 "
        "combined standard errors)"))


@pytest.mark.slow
@pytest.mark.parametrize("factor, method", [
    pytest.param(0.5, "lagrangian", marks=_miss(
        "E is 2.00 x the limit at factor 0.5 (0.439 +- 0.007 against 0.219)")),
    pytest.param(0.5, "eulerian", marks=_miss(
        "E is 2.17 x the limit at factor 0.5 (0.476 +- 0.006 against 0.219)")),
    pytest.param(1.5, "lagrangian", marks=_miss(
        "E is 1.44 x the limit at factor 1.5 (0.347 +- 0.011 against 0.241)")),
    pytest.param(1.5, "eulerian", marks=_miss(
        "E is 2.22 x the limit at factor 1.5 (0.533 +- 0.018 against 0.241)")),
])
def test_field_in_the_amplitude_sweep_meets_the_fields_agree_limit(in_sweep, factor, method):
    """tub47.md's target in the amplitude sweep: E against the factor's DEM seeds at most
    1.5 x their own seed-to-seed E."""
    assert in_sweep(factor, method)["E_over_limit"] <= 1.0


@pytest.mark.slow
@pytest.mark.parametrize("factor, method, guard", [(0.5, "lagrangian", 2.4),
                                                   (0.5, "eulerian", 2.5),
                                                   (1.5, "lagrangian", 1.6),
                                                   (1.5, "eulerian", 2.5)])
def test_regression_guard_in_the_amplitude_sweep(in_sweep, factor, method, guard):
    """Regression guard, not a target: the circulation keeps the DEM's sense and E against the
    factor's seeds stays below `guard` x their limit (measured: the xfails' reasons above)."""
    r = in_sweep(factor, method)
    assert r["sense"] == "counterclockwise"
    assert r["E_over_limit"] < guard


@pytest.mark.slow
@pytest.mark.parametrize("factor, method", [
    (0.5, "lagrangian"),
    pytest.param(0.5, "eulerian", marks=_strength_miss(0.72, 0.5)),
    pytest.param(1.5, "lagrangian", marks=_strength_miss(1.11, 1.5)),
    pytest.param(1.5, "eulerian", marks=_strength_miss(1.14, 1.5)),
])
def test_circulation_in_the_amplitude_sweep_agrees_with_the_dem_seeds(in_sweep, factor, method):
    """tub47.md: the continuum's strength within 10 % or twice the combined standard error of
    the factor's seeds' mean."""
    assert in_sweep(factor, method)["strengths_agree"]
