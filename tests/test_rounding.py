"""vibroflow.rounding: a value and its standard error rounded together (the error to two
significant figures, the value to its last place: JCGM 100:2008 section 7.2.6), by hand."""
from __future__ import annotations

import math

import pytest

from vibroflow.rounding import plus_minus


@pytest.mark.parametrize("x, se, text", [
    (0.0023012, 0.0053, "0.0023 ± 0.0053"),
    (1.046, 0.2036, "1.05 ± 0.20"),          # the error keeps its second figure, a 0
    (0.001675, 8.3e-5, "0.001675 ± 0.000083"),
    (0.003187, 0.000199, "0.00319 ± 0.00020"),
    (0.0141, 0.01005, "0.014 ± 0.010"),
    (31.94, 2.04, "31.9 ± 2.0"),
    (-0.0231, 0.0049, "-0.0231 ± 0.0049"),
    (0.96, 0.996, "1.0 ± 1.0"),              # 0.996 rounds up a decade: two figures still
    (12.0, 9.97, "12 ± 10"),
    (123456.0, 2100.0, "123500 ± 2100"),
    (5e-9, 1e-9, "5.0e-09 ± 1.0e-09"),       # beyond the fixed range: a shared exponent form
])
def test_value_and_error_by_hand(x, se, text):
    assert plus_minus(x, se) == text


def test_without_an_error_the_value_keeps_its_format():
    assert plus_minus(0.5, None) == "0.5"
    assert plus_minus(1.23456, 0.0) == "1.235"
    assert plus_minus(1.23456, math.nan, ".3g") == "1.23"
    assert plus_minus(math.nan, 0.1) == "n/a"
    assert plus_minus(True, 0.1) == "n/a"
