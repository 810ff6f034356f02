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


def test_the_jackknife_covariance_gives_a_predictions_error():
    """Over 300 draws whose batches move together (_draw), the sd of the fitted relation's
    prediction c0 + c1 x at x = 0 and at x = 0.08 (past the points' d gamma_dot of 0.003 -
    0.064) is the jackknife's affine_prediction_stderr (c0_stderr, c1_stderr and their
    jackknife covariance) within 15 % (rms over the draws); the points' own covariance, which
    treats the 120 points as independent, misses it by over half."""
    from vibroflow.measure.stats import affine_prediction_stderr

    rng = np.random.default_rng(9)
    for x in (0.0, 0.08):
        pred, jk, pts = [], [], []
        for _ in range(300):
            fit, *args = _draw(rng)
            out = jackknife_of_batches_fit(fit, *args, min_impacts=50, min_sf=0.1)
            pred.append(fit["c0"] + fit["c1"] * x)
            jk.append(affine_prediction_stderr(x, out["c0_stderr"], out["c1_stderr"],
                                               out["c0_c1_covariance"]))
            pts.append(affine_prediction_stderr(x, out["c0_stderr_points"],
                                                out["c1_stderr_points"],
                                                out["c0_c1_covariance_points"]))
        sd = np.std(pred, ddof=1)
        assert abs(np.sqrt(np.mean(np.square(jk))) / sd - 1.0) < 0.15
        assert np.sqrt(np.mean(np.square(pts))) < 0.5 * sd


def test_a_batch_offset_shared_by_the_relation_and_the_measured_mean_cancels_in_the_ratio():
    """The DEM's cycles of one batch move its impact speeds everywhere alike (the offset of
    _draw): the relation's intercept and the measured bed mean move
    together.  Over 300 draws, a speed inferred at x = 1.5 and 2 times the impacts' mean
    d gamma_dot against the same run's measured mean: the sd of i / m - 1 is
    relative_difference_stderr's with the relation's jackknife covariance with the mean
    (jackknife_of_batches_fit's c0/c1_measured_covariance, affine_prediction_covariance) within
    15 % (rms over the draws); taken as independent, the error is over three times too large."""
    from vibroflow.analysis.impact_stats import relative_difference_stderr
    from vibroflow.measure.stats import (affine_prediction_covariance, affine_prediction_stderr,
                                         stderr_of_batches)

    rng = np.random.default_rng(11)
    for factor in (1.5, 2.0):
        r, with_cov, independent = [], [], []
        for _ in range(300):
            fit, c, total, c_b, sum_b, shear, d = _draw(rng)
            out = jackknife_of_batches_fit(fit, c, total, c_b, sum_b, shear, d, 50, 0.1)
            x = factor * float(np.sum(c * d * shear.loo_phase_shear_rate[0]) / c.sum())
            i = fit["c0"] + fit["c1"] * x
            si = affine_prediction_stderr(x, out["c0_stderr"], out["c1_stderr"],
                                          out["c0_c1_covariance"])
            m = float(total.sum() / c.sum())
            nb = c_b.shape[0]
            sm = stderr_of_batches(sum_b.reshape(nb, -1).sum(1) / c_b.reshape(nb, -1).sum(1))
            cov = affine_prediction_covariance(x, out["c0_measured_covariance"],
                                               out["c1_measured_covariance"])
            r.append(i / m - 1.0)
            with_cov.append(relative_difference_stderr(i, si, m, sm, cov))
            independent.append(relative_difference_stderr(i, si, m, sm))
        sd = np.std(r, ddof=1)
        assert abs(np.sqrt(np.mean(np.square(with_cov))) / sd - 1.0) < 0.15
        assert np.sqrt(np.mean(np.square(independent))) > 3.0 * sd


def test_without_batches_the_error_is_unknown():
    rng = np.random.default_rng(1)
    fit, c, total, c_b, sum_b, shear, d = _draw(rng, nb=1)
    out = jackknife_of_batches_fit(fit, c, total, c_b, sum_b, shear, d, 50, 0.1)
    assert np.isnan(out["c0_stderr"]) and np.isnan(out["c1_stderr"])
    assert np.isnan(out["c0_c1_covariance"])
    assert out["c0_stderr_points"] == fit["c0_stderr"]


def _temperature_draw(rng, nb=8, sigma=0.02, noise=0.01, b0=0.03, b1=1.5):
    """Impacts on 4 phases x 6 x 5 points in `nb` batches: mean speed b0 + b1 sqrt(T), plus an
    offset of batch b (N(0, sigma), all its impacts alike) and each point's own noise; the
    fields without each batch as run_fields.leave_one_out_dataset gives them."""
    import xarray as xr

    from vibroflow.calibration.impacts import BatchCounts

    shape = (4, 6, 5)
    T = rng.uniform(1e-4, 1e-2, shape)
    rate = rng.uniform(0.5, 10.0, shape)
    c_b = rng.integers(60, 120, (nb,) + shape).astype(float)
    v_b = (b0 + b1 * np.sqrt(T))[None] + rng.normal(0.0, sigma, nb)[:, None, None, None] \
        + rng.normal(0.0, noise, (nb,) + shape)
    counts = BatchCounts(int(np.prod(shape)), nb)
    counts.count_b = c_b.ravel()
    counts.total_b = (c_b * v_b).ravel()
    counts.count = c_b.sum(axis=0).ravel()
    counts.total = (c_b * v_b).sum(axis=0).ravel()
    dims = ("batch", "phase", "x", "z")
    loo = xr.Dataset({"temperature": (dims, np.repeat(T[None], nb, axis=0)),
                      "shear_rate": (dims, np.repeat(rate[None], nb, axis=0)),
                      "solid_fraction": (dims, np.full((nb,) + shape, 0.5))})
    return counts, loo, T, rate


def test_the_temperature_relations_errors_carry_the_batches_scatter():
    """compare_impact_relations' affine fit v = b0 + b1 sqrt(T) with the jackknife refits
    (impact_temperature._refit): over 300 draws the rms jackknife error of b0 matches the
    sd of the fitted b0 (sigma / sqrt(nb), the batches' offsets) within 15 %, where the points'
    own error is under half of it."""
    from vibroflow.calibration.impact_temperature import _refit, relations_of_points
    from vibroflow.calibration.impacts import jackknife_of_refits

    rng = np.random.default_rng(3)
    d = 0.00635
    b0, jk, pts = [], [], []
    for _ in range(300):
        counts, loo, T, rate = _temperature_draw(rng)
        mean = counts.total / counts.count
        rec = relations_of_points(mean, mean, T.ravel(), rate.ravel(), counts.count, d)
        jackknife_of_refits(rec["mean"], _refit(counts, loo, 50, 0.1, d), 8)
        ta = rec["mean"]["temperature_affine"]
        assert ta["stderr_batches"] == 8
        b0.append(ta["c0"])
        jk.append(ta["c0_stderr"])
        pts.append(ta["c0_stderr_points"])
    sd = np.std(b0, ddof=1)
    assert abs(sd / (0.02 / np.sqrt(8)) - 1.0) < 0.15
    assert abs(np.sqrt(np.mean(np.square(jk))) / sd - 1.0) < 0.15
    assert np.sqrt(np.mean(np.square(pts))) < 0.5 * sd


def test_the_fine_relations_refit_without_each_batch():
    """impact_relations' two fits (impacts._fine_refit): without batch b the fit of v on
    sqrt(T) is made on the other batches' impacts alone; with the batches' offsets the
    jackknife's error of a exceeds the points' own."""
    from vibroflow.calibration.impacts import _fine_refit, jackknife_of_refits

    rng = np.random.default_rng(4)
    counts, loo, T, rate = _temperature_draw(rng, b0=0.0)
    shape = T.shape
    c, mean = counts.without(2, shape)
    cb = counts.count_b.reshape((8,) + shape)
    vb = counts.total_b.reshape((8,) + shape) / cb
    keep = [b for b in range(8) if b != 2]
    np.testing.assert_allclose(mean, (cb[keep] * vb[keep]).sum(0) / cb[keep].sum(0), rtol=1e-12)
    refit = _fine_refit(counts, loo, shape, 0.00635, 50, 0.1)
    direct = weighted_linear_fit(np.sqrt(T).ravel(), mean.ravel(), c.ravel(), intercept=False)
    assert refit(2)["t"]["c1"] == direct["c1"]
    m = (counts.total / counts.count).reshape(shape)
    fits = {"t": weighted_linear_fit(np.sqrt(T).ravel(), m.ravel(), counts.count,
                                     intercept=False),
            "g": weighted_linear_fit(0.00635 * rate.ravel(), m.ravel(), counts.count)}
    jackknife_of_refits(fits, refit, 8)
    assert fits["t"]["c1_stderr"] > fits["t"]["c1_stderr_points"]
    assert fits["g"]["stderr_batches"] == 8
