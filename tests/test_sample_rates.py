"""A sample's shear-rate selections in one compiled pass (eulerian/sample_rates.py) against
numpy's masks: the same cells in the same order and the same means bit for bit; the rates
against gamma_dot = sqrt(2 D':D') of simple shear (L = [[0, g], [0, 0]]: gamma_dot = g)."""
from __future__ import annotations

import numpy as np

from vibroflow.continuum.eulerian.sample_rates import held_rates, held_rates_work
from vibroflow.continuum.sampling import shear_rate


def test_selections_are_numpys_masks():
    rng = np.random.default_rng(3)
    n, half = 400, 0.5
    cells = np.sort(rng.choice(n, 300, replace=False)).astype(np.int64)
    L = rng.normal(size=(n, 5))
    mass = rng.random(n)
    volume = rng.random(n)
    stress = rng.normal(size=(n, 4))
    index = rng.integers(-1, 50, cells.size).astype(np.int64)
    near_wall = rng.random(cells.size) < 0.2
    probes = [np.flatnonzero(rng.random(cells.size) < 0.05) for _ in range(4)] + \
        [np.zeros(0, np.int64)]
    members = np.concatenate([np.zeros(0, np.int64)] + probes).astype(np.int64)
    ptr = np.cumsum([0] + [len(m) for m in probes]).astype(np.int64)
    out = held_rates_work(cells.size, probes)
    n_held, n_wall = held_rates(L, mass, half, cells, index, volume, stress, near_wall,
                                members, ptr, out)

    rate = shear_rate(L[:, :4])[cells]
    held = mass[cells] >= half
    assert 0 < n_held < cells.size and 0 < n_wall
    np.testing.assert_array_equal(out.held, held)
    np.testing.assert_array_equal(out.rate[:n_held], rate[held])
    np.testing.assert_array_equal(out.index[:n_held], index[held])
    np.testing.assert_array_equal(out.volume[:n_held], volume[cells[held]])
    np.testing.assert_array_equal(out.stress[:n_held], stress[cells[held]])
    np.testing.assert_array_equal(out.wall[:n_wall], rate[held & near_wall])
    assert out.rate[:n_held].mean() == rate[held].mean()
    # the means, taken in numpy's order, are numpy's of the masks' selections
    assert out.means[0] == rate[held].mean()
    assert out.means[1] == rate[held & near_wall].mean()
    k = 0
    for q, m in enumerate(probes):
        want = rate[m][held[m]]
        assert out.probe_n[q] == want.size
        np.testing.assert_array_equal(out.probe[k:k + want.size], want)
        if want.size:
            assert out.means[2 + q] == want.mean()
        else:
            assert np.isnan(out.means[2 + q])
        k += want.size


def test_simple_shear_rate():
    g = 3.7
    L = np.array([[0.0, g, 0.0, 0.0]])
    out = held_rates_work(1, [])
    n_held, _ = held_rates(L, np.ones(1), 0.5, np.zeros(1, np.int64), np.zeros(1, np.int64),
                           np.ones(1), np.zeros((1, 4)), np.zeros(1, np.bool_),
                           np.zeros(0, np.int64), np.zeros(1, np.int64), out)
    assert n_held == 1 and abs(out.rate[0] - g) < 1e-12 * g
