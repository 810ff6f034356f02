"""The tub-cell mu(I), phi(I) fit's errors (calibration/tub_rheology.py, jackknife_rheology):
the delete-one-batch jackknife over the coarse-grainer's batches against the known spread of
the fitted constants over synthetic draws whose batches err together."""
from __future__ import annotations

import math

import numpy as np
import pytest

from vibroflow.calibration.tub_rheology import (RHEOLOGY_CONSTANTS, _scatter_of, fit_tub_cells,
                                                jackknife_rheology)

MU_S, MU_2, I_0, PHI_MAX, PHI_MIN = 0.28, 0.52, 0.03, 0.57, 0.34


def _draw(seed, n_batches=6, n=300, shift=0.03, rel=0.01):
    """Dense cells with mu(I) and phi(I) as stated, seen through n_batches batches: a batch
    shifts every cell's mu by a common s_b ~ N(0, shift) and its phi by s_b / 10 (one bed's
    cells err together), each cell adds its own scatter rel.  The scatter of the batches'
    mean fields, and the batches' fields (n_batches, n)."""
    rng = np.random.default_rng(seed)
    I = np.exp(rng.uniform(np.log(1e-3), np.log(0.3), n))
    mu0 = MU_S + (MU_2 - MU_S) / (1.0 + I_0 / I)
    phi0 = PHI_MAX - (PHI_MAX - PHI_MIN) * I
    s = shift * rng.standard_normal((n_batches, 1))
    mu = mu0 + s + rel * rng.standard_normal((n_batches, n))
    phi = phi0 + 0.1 * s + 0.1 * rel * rng.standard_normal((n_batches, n))
    Ib = np.broadcast_to(I, mu.shape).copy()
    p = np.full(mu.shape, 1e3)
    batches = {"inertial_number": Ib, "friction_coefficient": mu, "solid_fraction": phi,
               "pressure": p}
    scatter = {"phase": _scatter_of(I, mu.mean(axis=0), phi.mean(axis=0), p[0])}
    return scatter, batches


def test_the_values_stand_and_the_errors_follow_the_spread_over_draws():
    est = {k: [] for k in RHEOLOGY_CONSTANTS}
    jack = {k: [] for k in RHEOLOGY_CONSTANTS}
    lsq = {k: [] for k in RHEOLOGY_CONSTANTS}
    for seed in range(25):
        scatter, batches = _draw(seed)
        plain = fit_tub_cells(scatter)
        fit = fit_tub_cells(scatter, batches=batches)
        assert fit["stderr_method"] == "delete-one-batch jackknife over 6 batches"
        for k in RHEOLOGY_CONSTANTS:
            assert fit[k] == plain[k]  # the values: the fit on every batch
            assert fit[k + "_stderr_least_squares"] == plain[k + "_stderr"]
            est[k].append(fit[k]), jack[k].append(fit[k + "_stderr"])
            lsq[k].append(plain[k + "_stderr"])
    # the constants that carry the batches' common shift: the jackknife follows their spread
    # over the 25 draws (its sd known to about 15 %, each jackknife error to about a third),
    # the points' own covariance falls far short of it (I_0 carries none of the shift)
    for k in ("mu_s", "mu_2", "phi_max", "phi_min"):
        spread = np.std(est[k], ddof=1)
        assert np.sqrt(np.mean(np.square(jack[k]))) == pytest.approx(spread, rel=0.4), k
        assert np.sqrt(np.mean(np.square(lsq[k]))) < 0.5 * spread, k


def test_one_batch_leaves_the_fits_own_errors():
    scatter, batches = _draw(0, n_batches=1)
    assert jackknife_rheology(fit_tub_cells(scatter), batches) == {}


def test_a_left_out_fit_that_fails_gives_nan():
    scatter, batches = _draw(1, n_batches=3)
    batches["solid_fraction"][1] = 0.05  # a mean holding batch 1 has no dense cell
    fit = fit_tub_cells(scatter)
    out = jackknife_rheology(fit, batches)
    assert all(math.isnan(out[k + "_stderr"]) for k in RHEOLOGY_CONSTANTS)
