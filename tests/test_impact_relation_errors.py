"""The calibrated impact relation's own error in a continuum's inferred impact speed: the
coefficients' covariance (measure.stats.jackknife_covariance), the error of a prediction
(affine_prediction_stderr) and of a weighted mean of a clipped affine relation
(continuum.temperature_impacts.temperature_prediction_stderr), against textbook answers and
Monte Carlo."""
import math

import numpy as np
import pytest

from vibroflow.calibration.impacts import weighted_linear_fit
from vibroflow.measure.stats import (affine_prediction_stderr, jackknife_covariance,
                                     jackknife_stderr, quadrature_stderr)


def test_the_jackknife_covariance_of_two_batch_means_is_their_covariance_over_n():
    """For the means of x and y left one batch out, (n - 1) / n sum (a_k - a)(b_k - b) is the
    sample covariance of the batch values over n (as jackknife_stderr of a mean is its
    batch-means error); its diagonal is jackknife_stderr squared."""
    rng = np.random.default_rng(3)
    x = rng.normal(size=9)
    y = 0.4 * x + rng.normal(size=9)
    n = x.size
    loo_x = (x.sum() - x) / (n - 1)
    loo_y = (y.sum() - y) / (n - 1)
    want = np.cov(x, y, ddof=1)[0, 1] / n
    assert jackknife_covariance(loo_x, loo_y) == pytest.approx(want, rel=1e-12)
    assert jackknife_covariance(loo_x, loo_x) == pytest.approx(jackknife_stderr(loo_x) ** 2,
                                                               rel=1e-12)
    assert math.isnan(jackknife_covariance([1.0], [2.0]))
    assert math.isnan(jackknife_covariance([1.0, np.nan], [2.0, 3.0]))


def test_a_least_squares_prediction_has_the_textbook_error():
    """An unweighted straight-line fit's prediction at x has the standard error
    s sqrt(1/n + (x - mean x)^2 / Sxx) (the standard result, e.g. Draper & Smith, Applied
    Regression Analysis, chapter 1); the fit's coefficient errors and covariance through
    affine_prediction_stderr give it, at the points' mean and far from it."""
    rng = np.random.default_rng(5)
    x = rng.uniform(0.0, 0.05, 40)
    y = 0.01 + 2.5 * x + rng.normal(0.0, 0.004, x.size)
    fit = weighted_linear_fit(x, y, np.ones_like(x))
    res = y - (fit["c0"] + fit["c1"] * x)
    s = math.sqrt(np.sum(res**2) / (x.size - 2))
    sxx = np.sum((x - x.mean()) ** 2)
    for at in (x.mean(), 0.0, 0.12):
        want = s * math.sqrt(1.0 / x.size + (at - x.mean()) ** 2 / sxx)
        got = affine_prediction_stderr(at, fit["c0_stderr"], fit["c1_stderr"],
                                       fit["c0_c1_covariance"])
        assert got == pytest.approx(want, rel=1e-9)
    # the intercept and the slope of points right of x = 0 are anticorrelated
    assert fit["c0_c1_covariance"] < 0.0


def test_without_the_covariance_the_error_is_bounded_at_any_correlation():
    """se0 + |x| se1 bounds sqrt(se0^2 + x^2 se1^2 + 2 x rho se0 se1) for every rho in [-1, 1]
    and is reached at rho = sign(x); a missing error gives NaN."""
    e0, e1 = 0.002, 0.08
    for x in (-0.03, 0.0, 0.02):
        bound = affine_prediction_stderr(x, e0, e1, None)
        assert bound == pytest.approx(e0 + abs(x) * e1, rel=1e-15)
        for rho in np.linspace(-1.0, 1.0, 21):
            exact = affine_prediction_stderr(x, e0, e1, rho * e0 * e1)
            assert exact <= bound * (1 + 1e-12)
        assert affine_prediction_stderr(x, e0, e1, math.copysign(1.0, x) * e0 * e1) == \
            pytest.approx(bound, rel=1e-9)
    assert math.isnan(affine_prediction_stderr(0.01, float("nan"), e1, 0.0))
    assert math.isnan(affine_prediction_stderr(None, e0, e1, 0.0))


def test_an_inferred_speeds_error_adds_the_runs_and_the_relations_in_quadrature():
    assert quadrature_stderr(0.003, 0.004) == pytest.approx(0.005, rel=1e-15)
    assert quadrature_stderr(0.003, None) == 0.003
    assert quadrature_stderr(0.003, float("nan")) == 0.003
    assert math.isnan(quadrature_stderr(None, 0.004))


def _temperature_relation(b0, b1, e0, e1, cov):
    from vibroflow.io.calibration_file import ImpactRelation

    return ImpactRelation(preferred_relation="temperature", b0_temperature_cells_m_s=b0,
                          b1_temperature_cells=b1, b0_temperature_cells_stderr_m_s=e0,
                          b1_temperature_cells_stderr=e1,
                          b0_b1_temperature_cells_covariance_m_s=cov)


def test_the_temperature_relations_error_over_a_map_matches_monte_carlo():
    """The solid-fraction weighted mean of max(b0 + b1 sqrt(T), 0) over a map, with (b0, b1)
    drawn 40 000 times from a normal of the calibration's errors and covariance: its standard
    deviation is temperature_prediction_stderr's within 2 % (the nodes where the relation is
    zero, sqrt(T) well below -b0/b1, stay zero: the gradient holds the weight where it is
    positive only)."""
    from vibroflow.continuum.temperature_impacts import (temperature_prediction_stderr,
                                                         temperature_relation,
                                                         temperature_relation_errors)

    b0, b1, e0, e1, rho = -0.06, 1.35, 0.0023, 0.053, -0.8
    rel = _temperature_relation(b0, b1, e0, e1, rho * e0 * e1)
    assert temperature_relation(rel) == (b0, b1)
    assert temperature_relation_errors(rel) == (e0, e1, pytest.approx(rho * e0 * e1))
    rng = np.random.default_rng(11)
    sqrt_T = np.concatenate([rng.uniform(0.07, 0.15, 60), rng.uniform(0.0, 0.02, 20)])
    w = rng.uniform(0.3, 0.6, sqrt_T.size)
    got = temperature_prediction_stderr(rel, sqrt_T, w)
    cov = np.array([[e0**2, rho * e0 * e1], [rho * e0 * e1, e1**2]])
    draws = rng.multivariate_normal([b0, b1], cov, 40_000)
    v = np.maximum(draws[:, :1] + draws[:, 1:] * sqrt_T[None], 0.0)
    means = v @ w / w.sum()
    assert np.std(means, ddof=1) == pytest.approx(got, rel=0.02)
    # a calibration that prefers the shear rate gives the temperature no relation
    from vibroflow.io.calibration_file import ImpactRelation

    assert math.isnan(temperature_prediction_stderr(
        ImpactRelation(preferred_relation="shear_rate"), sqrt_T, w))


def test_the_relations_errors_are_those_of_the_pair_the_run_uses():
    """impact_relation_errors gives the errors of the pair impact_relation chooses: the cells'
    fit where the calibration has it, else the fine one; NaN where none is written."""
    from vibroflow.continuum.shear_outputs import impact_relation_errors
    from vibroflow.io.calibration_file import ImpactRelation

    both = ImpactRelation(c0_m_s=0.01, c1=3.0, c0_stderr_m_s=0.001, c1_stderr=0.1,
                          c0_c1_covariance_m_s=-5e-5, c0_cells_m_s=0.005, c1_cells=4.0,
                          c0_cells_stderr_m_s=0.002, c1_cells_stderr=0.2,
                          c0_c1_cells_covariance_m_s=-2e-4)
    assert impact_relation_errors(both) == (0.002, 0.2, -2e-4)
    fine = ImpactRelation(c0_m_s=0.01, c1=3.0, c0_stderr_m_s=0.001, c1_stderr=0.1)
    e0, e1, cov = impact_relation_errors(fine)
    assert (e0, e1) == (0.001, 0.1) and math.isnan(cov)
    assert all(math.isnan(e) for e in impact_relation_errors(None))


def test_the_sweep_table_gives_an_inferred_speed_both_errors(tmp_path):
    """A sweep point's row: a continuum's inferred speed carries its run's and its relation's
    errors in quadrature (3 and 4 mm/s: 5 mm/s), the DEM's measured speed its own; a missing
    error is an empty cell (None), as every other column's."""
    import json

    from vibroflow.study.sweep_folder import point_dir
    from vibroflow.study.sweep_table import point_rows

    folder = point_dir(tmp_path, "p0")
    folder.mkdir(parents=True)
    summary = {"methods": {
        "dem": {"impacts": {"ball_ball_mean_normal_speed": 0.045,
                            "ball_ball_mean_normal_speed_stderr": 0.001,
                            "ball_wall_mean_normal_speed": 0.156}},
        "lagrangian": {"impacts": {"ball_ball_mean_normal_speed": 0.079,
                                   "ball_ball_mean_normal_speed_stderr": 0.003,
                                   "ball_ball_mean_normal_speed_relation_stderr": 0.004}}}}
    (folder / "summary.json").write_text(json.dumps(summary))
    rows = {r["method"]: r for r in point_rows(tmp_path, "p0", {"amplitude_factor": 1.0})}
    assert rows["lagrangian"]["impact_ball_ball_stderr"] == pytest.approx(0.005, rel=1e-12)
    assert rows["dem"]["impact_ball_ball_stderr"] == 0.001
    assert rows["dem"]["impact_ball_wall_stderr"] is None
    assert rows["lagrangian"]["impact_ball_wall_stderr"] is None


def test_a_speed_inferred_from_the_temperature_is_compared_too():
    """The report's flag table compares every inferred bed mean, from the shear rate or from
    the granular temperature (continuum.temperature_impacts drops inferred_from_shear_rate when
    both kinds come from T), and the impact table says which."""
    from types import SimpleNamespace

    from vibroflow.report.impact_figures import inferred_from, speed_comparisons

    dem = {"ball_ball_mean_normal_speed": 0.05, "ball_ball_mean_normal_speed_stderr": 0.001,
           "ball_wall_mean_normal_speed": 0.15, "ball_wall_mean_normal_speed_stderr": 0.003}
    hot = {"ball_ball_mean_normal_speed": 0.07, "ball_ball_mean_normal_speed_stderr": 0.003,
           "ball_ball_mean_normal_speed_relation_stderr": 0.004,
           "ball_wall_mean_normal_speed": 0.16, "ball_wall_mean_normal_speed_stderr": 0.002,
           "inferred_from_temperature": "ball_ball, ball_wall: v = max(b0 + b1 sqrt(T), 0)"}
    data = SimpleNamespace(summary={"methods": {"dem": {"impacts": dem},
                                                "lagrangian": {"impacts": hot}}},
                           continuum_methods=["lagrangian"], impacts=None)
    rows = speed_comparisons(data)
    assert [(r["kind"], r["method"]) for r in rows] == [("ball-ball", "lagrangian"),
                                                        ("ball-U wall", "lagrangian")]
    assert rows[0]["relative"] == pytest.approx(0.4)
    assert rows[0]["inferred_stderr"] == pytest.approx(0.005)
    assert rows[0]["flagged"] and not rows[1]["flagged"]
    assert inferred_from(hot) == ["granular temperature"]
    assert inferred_from({**hot, "inferred_from_shear_rate": "v = c0 + c1 d gamma_dot"}) == [
        "shear rate", "granular temperature"]
    assert inferred_from(dem) == []


def test_the_relative_differences_error_subtracts_the_covariance_by_hand():
    """r = i / m - 1 with i 0.06 +- 0.004, m 0.05 +- 0.003 and cov(i, m) 5e-6 m^2/s^2:
    sqrt(0.004^2 + 1.2^2 0.003^2 - 2 1.2 5e-6) / 0.05 = 0.08236; without the covariance
    hypot(0.004, 1.2 0.003) / 0.05; a covariance past |rho| = 1 gives 0, not NaN."""
    from vibroflow.analysis.impact_stats import relative_difference_stderr

    want = math.sqrt(0.004**2 + 1.2**2 * 0.003**2 - 2 * 1.2 * 5e-6) / 0.05
    assert relative_difference_stderr(0.06, 0.004, 0.05, 0.003, 5e-6) == pytest.approx(
        want, rel=1e-12)
    assert relative_difference_stderr(0.06, 0.004, 0.05, 0.003, None) == pytest.approx(
        math.hypot(0.004, 1.2 * 0.003) / 0.05, rel=1e-12)
    assert relative_difference_stderr(0.06, 0.004, 0.05, 0.003, 1.0) == 0.0


def test_the_covariance_with_the_measured_mean_is_used_against_its_own_dem_run_only():
    """A continuum's summary carries its relation's covariance with the mean its calibration
    measured (shear_outputs.measured_covariance_keys: s cov(c0, m) + x cov(c1, m), worked by
    hand) and that mean; the report uses the covariance against a DEM whose mean is that one to
    round-off, and treats another run's mean as independent."""
    from vibroflow.continuum.shear_outputs import _SHEAR_RELATIONS, measured_covariance_keys
    from vibroflow.io.calibration_file import ImpactRelation
    from vibroflow.report.impact_figures import measured_covariance

    rel = ImpactRelation(mean_normal_speed_m_s=0.0446, c0_cells_m_s=0.011, c1_cells=2.55,
                         c0_cells_measured_covariance_m2_s2=6e-7,
                         c1_cells_measured_covariance_m_s=-4e-6)
    impacts = {}
    measured_covariance_keys(impacts, "ball_ball", rel, _SHEAR_RELATIONS, 0.0111)
    cov = 6e-7 + 0.0111 * -4e-6
    assert impacts["ball_ball_mean_normal_speed_relation_measured_covariance"] == pytest.approx(
        cov, rel=1e-12)
    assert impacts["ball_ball_mean_normal_speed_relation_measured_mean"] == 0.0446
    assert measured_covariance(impacts, "ball_ball", 0.0446) == pytest.approx(cov, rel=1e-12)
    assert measured_covariance(impacts, "ball_ball", 0.0446 * (1 + 1e-13)) is not None
    assert measured_covariance(impacts, "ball_ball", 0.0431) is None
    assert measured_covariance(impacts, "ball_wall", 0.156) is None
    # an older calibration without the covariances writes neither key
    older = {}
    measured_covariance_keys(older, "ball_ball", ImpactRelation(
        mean_normal_speed_m_s=0.0446, c0_cells_m_s=0.011, c1_cells=2.55), _SHEAR_RELATIONS,
        0.0111)
    assert older == {}


def _probe_study(measured_mean, left_out=True):
    """A study's pieces that inferred_impact_speed_covariances reads: one probe whose cell the
    continuum shears at 2 1/s, a relation c0 + c1 d gamma_dot with its four refits, the DEM's
    cell mean without each batch, and the DEM's bed mean 0.0446 m/s."""
    from types import SimpleNamespace

    c0s, c1s = np.array([0.010, 0.012, 0.011, 0.009]), np.array([2.6, 2.4, 2.5, 2.7])
    fit = {"c0": 0.0105, "c1": 2.55, "c0_stderr": 0.001, "c1_stderr": 0.1, "covariance": 0.0,
           "left_out": (c0s, c1s) if left_out else None, "measured_mean": measured_mean}
    cell = np.array([0.050, 0.054, 0.051, 0.049])
    probe = SimpleNamespace(x=0.0, z=0.05)
    return SimpleNamespace(
        impact_fit=lambda kind: fit, diameter=0.004,
        summary={"methods": {"dem": {"impacts": {"ball_ball_mean_normal_speed": 0.0446}}}},
        continuum_block=lambda name: {"probes": {"P1": {"shear_rate_1_s": 2.0}}},
        scenario=SimpleNamespace(analysis=SimpleNamespace(probes={"P1": probe})),
        impacts=SimpleNamespace(left_out_at=lambda x, z: cell)), c0s, c1s, cell


def test_a_probe_cells_covariance_is_the_jackknifes_of_the_refits_and_the_cells_mean():
    """A probe cell's inferred speed against the DEM's speed in that cell (report.figures.
    inferred_impact_speed_covariances): (n - 1) / n sum_b (p_b - mean p)(m_b - mean m) with
    p_b = c0_b + c1_b d gamma_dot, worked by hand, where the calibration's run is the study's
    DEM (its measured mean the DEM's to round-off); nothing against another run or without the
    refits."""
    from vibroflow.report.figures import inferred_impact_speed_covariances

    data, c0s, c1s, cell = _probe_study(0.0446)
    p = c0s + c1s * 0.004 * 2.0
    want = 3.0 / 4.0 * float(np.sum((p - p.mean()) * (cell - cell.mean())))
    got = inferred_impact_speed_covariances(data, "lagrangian")
    assert got["P1"] == pytest.approx(want, rel=1e-12)
    assert inferred_impact_speed_covariances(_probe_study(0.0431)[0], "lagrangian") == {}
    assert inferred_impact_speed_covariances(_probe_study(0.0446, left_out=False)[0],
                                             "lagrangian") == {}
