"""Impact speeds from the granular temperature (vibroflow.calibration.impact_temperature)
against known answers.

1. Monte Carlo of Maxwellian balls: pairs with velocities N(0, T) per component and a random
   contact normal, each pair weighted by its collision rate (g . k) Theta(g . k): the weighted
   mean and 95th percentile of g . k are the formula's sqrt(pi T) and 2 sqrt(T ln 20); a ball
   against a wall at rest, sqrt(pi T / 2) and sqrt(2 T ln 20).  Unweighted, the mean |g . k|
   of random pairs is 2 sqrt(T / pi): the collision rate selects fast pairs.
2. The quantile of a histogram of a known distribution.
3. Points whose speeds follow a sqrt(T) exactly and the shear rate not at all make the
   temperature the winner with R^2 = 1, and the other way round.
4. The analysis cells' centres picked from a finer grid are the multiples of the cell size.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
import xarray as xr

from vibroflow.calibration.impact_temperature import (MAXWELL_MEAN, MAXWELL_P95,
                                                      _quantile_of_histograms,
                                                      maxwellian_impact_speed, on_nodes,
                                                      relations_of_points)


def _weighted_quantile(x, w, q):
    o = np.argsort(x)
    c = np.cumsum(w[o])
    return float(np.interp(q * c[-1], c, x[o]))


def test_maxwellian_impact_speeds_by_monte_carlo():
    rng = np.random.default_rng(11)
    T, n = 0.0064, 2_000_000
    k = rng.normal(size=(n, 3))
    k /= np.linalg.norm(k, axis=1)[:, None]
    vi = rng.normal(0.0, math.sqrt(T), (n, 3))
    vj = rng.normal(0.0, math.sqrt(T), (n, 3))
    for kind, u in (("ball_ball", np.einsum("ij,ij->i", vi - vj, k)),
                    ("ball_wall", np.einsum("ij,ij->i", vi, k))):
        w = np.where(u > 0, u, 0.0)
        mean = float(np.sum(w * u) / np.sum(w))
        assert mean == pytest.approx(maxwellian_impact_speed(T, kind), rel=5e-3)
        assert mean == pytest.approx(MAXWELL_MEAN[kind] * math.sqrt(T), rel=5e-3)
        p95 = _weighted_quantile(u[u > 0], w[u > 0], 0.95)
        assert p95 == pytest.approx(maxwellian_impact_speed(T, kind, 0.95), rel=5e-3)
        assert p95 == pytest.approx(MAXWELL_P95[kind] * math.sqrt(T), rel=5e-3)
    g = np.abs(np.einsum("ij,ij->i", vi - vj, k))
    assert g.mean() == pytest.approx(2.0 * math.sqrt(T / math.pi), rel=5e-3)


def test_quantile_of_histograms_of_a_uniform_distribution():
    edges = np.concatenate([[0.0], np.geomspace(1e-3, 2.0, 300)])
    x = np.random.default_rng(2).uniform(0.0, 1.0, 200_000)
    h, _ = np.histogram(x, bins=edges)
    for q in (0.5, 0.95):
        assert _quantile_of_histograms(h[None, :].astype(float), edges, q)[0] == \
            pytest.approx(q, rel=1e-2)


def test_the_relation_that_the_points_follow_wins():
    rng = np.random.default_rng(5)
    n, d = 400, 0.00635
    T = rng.uniform(0.001, 0.02, n)
    gam = rng.uniform(0.5, 10.0, n)
    count = rng.integers(50, 500, n)
    v = 1.2 * np.sqrt(T)
    rec = relations_of_points(v, 2.0 * v, T, gam, count, d)
    assert rec["winner"] == "temperature"
    assert rec["mean"]["temperature"]["c1"] == pytest.approx(1.2, rel=1e-9)
    assert rec["mean"]["temperature"]["r2"] == pytest.approx(1.0)
    assert rec["mean"]["temperature"]["within_0_8_1_25"] == 1.0
    assert rec["p95"]["temperature"]["c1"] == pytest.approx(2.4, rel=1e-9)
    assert rec["mean"]["shear_rate"]["r2"] < 0.1
    v = 0.01 + 3.0 * d * gam
    rec = relations_of_points(v, v, T, gam, count, d, "ball_wall")
    assert rec["winner"] == "shear_rate"
    assert rec["mean"]["shear_rate"]["c0"] == pytest.approx(0.01, rel=1e-6)
    assert rec["mean"]["shear_rate"]["c1"] == pytest.approx(3.0, rel=1e-6)


def test_on_nodes_keeps_the_analysis_cells_centres_of_a_finer_grid():
    x = np.arange(-20, 21) * 0.005
    z = np.arange(-3, 30) * 0.005
    ds = xr.Dataset({"temperature": (("phase", "x", "z"), np.ones((2, x.size, z.size)))},
                    coords={"x": x, "z": z, "phase": [0.0, np.pi]})
    nodes = on_nodes(ds, 0.015)
    np.testing.assert_allclose(nodes["x"].values, np.arange(-6, 7) * 0.015, atol=1e-12)
    np.testing.assert_allclose(nodes["z"].values, np.arange(-1, 10) * 0.015, atol=1e-12)
