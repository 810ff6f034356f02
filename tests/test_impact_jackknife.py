"""The impact relation's errors on the cells (calibration.impacts.impact_relations_on_cells)
as the delete-one-batch jackknife: a known answer from batches whose impacts move together."""
from types import SimpleNamespace

import numpy as np

from vibroflow.calibration.impacts import jackknife_of_batches_fit, weighted_linear_fit


def _draw(rng, nb=8, sigma=0.02, noise=0.01, c0=0.05, c1=0.8, d=0.00635):
    """Impacts on 4 phases x 6 x 5 nodes in `nb` batches: speed c0 + c1 d gamma_dot, plus an
    offset of batch b (N(0, sigma), all its impacts alike: the bed of those cycles) and each
    point's own noise.  Returns what impact_relations_on_cells hands the jackknife."""
    shape = (4, 6, 5)
    rate = rng.uniform(0.5, 10.0, shape)
    c_b = rng.integers(60, 120, (nb,) + shape).astype(float)
    offset = rng.normal(0.0, sigma, nb)
    v_b = (c0 + c1 * d * rate)[None] + offset[:, None, None, None] \
        + rng.normal(0.0, noise, (nb,) + shape)
    sum_b = c_b * v_b
    c, total = c_b.sum(axis=0), sum_b.sum(axis=0)
    shear = SimpleNamespace(loo_phase_shear_rate=np.repeat(rate[None], nb, axis=0),
                            loo_phase_solid_fraction=np.ones((nb,) + shape))
    fit = weighted_linear_fit(d * rate.ravel(), (total / c).ravel(), c.ravel())
    return fit, c, total, c_b, sum_b, shear, d


def test_the_jackknife_carries_the_batches_scatter_that_the_points_miss():
    """Over 300 draws: the sd of the fitted c0 is sigma / sqrt(nb) (the batches' offsets
    average); the jackknife's error matches it within 15 % (rms over the draws), the points'
    own error is several times smaller (they treat 120 points as independent)."""
    rng = np.random.default_rng(7)
    c0, jk, pts = [], [], []
    for _ in range(300):
        fit, *args = _draw(rng)
        out = jackknife_of_batches_fit(fit, *args, min_impacts=50, min_sf=0.1)
        c0.append(fit["c0"])
        jk.append(out["c0_stderr"])
        pts.append(out["c0_stderr_points"])
        assert out["stderr_batches"] == 8
    sd = np.std(c0, ddof=1)
    assert abs(sd / (0.02 / np.sqrt(8)) - 1.0) < 0.15
    assert abs(np.sqrt(np.mean(np.square(jk))) / sd - 1.0) < 0.15
    assert np.sqrt(np.mean(np.square(pts))) < 0.5 * sd


def test_without_batches_the_error_is_unknown():
    rng = np.random.default_rng(1)
    fit, c, total, c_b, sum_b, shear, d = _draw(rng, nb=1)
    out = jackknife_of_batches_fit(fit, c, total, c_b, sum_b, shear, d, 50, 0.1)
    assert np.isnan(out["c0_stderr"]) and np.isnan(out["c1_stderr"])
    assert out["c0_stderr_points"] == fit["c0_stderr"]
