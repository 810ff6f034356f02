"""What counts as a number read from a file or a summary (vibroflow.numbers)."""
import math

import numpy as np

from vibroflow.numbers import is_finite_number, number_or_nan


def test_a_finite_number_is_a_real_finite_value_and_not_a_bool():
    for v in (0, 1, -2.5, np.float32(0.5), np.int64(3), np.float64(1e-300)):
        assert is_finite_number(v), v
    for v in (math.nan, math.inf, -math.inf, np.float32("nan"), None, True, False, "1.0",
              [1.0], 1 + 0j):
        assert not is_finite_number(v), v


def test_a_value_becomes_a_float_or_nan():
    assert number_or_nan(3) == 3.0 and isinstance(number_or_nan(3), float)
    assert number_or_nan(np.float32(0.5)) == 0.5
    assert number_or_nan(math.inf) == math.inf
    for v in (None, True, "0.1", {}):
        assert math.isnan(number_or_nan(v)), v
