"""numpy's summation order compiled (continuum/numpy_sum.py) against numpy itself: the same
sums and means bit for bit over lengths that take every branch of numpy's pairwise summation
(fewer than 8 terms, one block of up to 128, runs split once and many times, at offsets into
an array), and the exact sum of integers where no order rounds."""
from __future__ import annotations

import math

import numpy as np

from vibroflow.continuum.numpy_sum import pairwise_mean, pairwise_sum


def test_numpys_sums_and_means_bit_for_bit():
    rng = np.random.default_rng(11)
    lengths = list(range(0, 300)) + [511, 512, 513, 1023, 1024, 1025, 4099, 65537]
    for n in lengths:
        x = rng.standard_normal(n + 9) * 10.0 ** rng.uniform(-4, 4, n + 9)
        lo = int(rng.integers(0, 9))
        run = x[lo:lo + n]
        assert pairwise_sum(x, lo, n) == run.sum(), n
        if n:
            assert pairwise_mean(x, lo, n) == run.mean(), n


def test_order_matters_and_is_numpys():
    # terms whose sum depends on the order: a naive running sum gives another number
    x = np.array([1.0e16] + [1.0] * 200 + [-1.0e16])
    naive = 0.0
    for v in x:
        naive += v
    assert pairwise_sum(x, 0, x.size) == x.sum() != naive


def test_exact_sums_and_empty_runs():
    x = np.arange(1000, dtype=np.float64)
    assert pairwise_sum(x, 0, 1000) == 999 * 1000 / 2
    assert pairwise_sum(x, 10, 0) == 0.0
    assert math.isnan(pairwise_mean(x, 3, 0))
    assert pairwise_mean(x, 1, 3) == 2.0
