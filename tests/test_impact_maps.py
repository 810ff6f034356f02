"""The impact-map difference of vibroflow.analysis.impact_maps on hand-computed maps, and a map's
CSV round trip."""
from __future__ import annotations

import math

import numpy as np
import pytest

from vibroflow.analysis.impact_maps import (rate_difference, read_map_csv, speed_difference,
                                            write_map_csv)


def _map(rate, speed):
    n = len(rate)
    return {"patch": np.arange(n), "patch_name": [f"p{k}" for k in range(n)],
            "area_m2": np.full(n, 1e-4), "rate": np.asarray(rate, float),
            "rate_stderr": np.full(n, 0.1), "speed": np.asarray(speed, float),
            "speed_stderr": np.full(n, 0.01)}


def test_the_map_differences_are_the_hand_computed_ones(tmp_path):
    b = _map([1.0, 1.0, 1.0, 1.0], [1.0, 1.0, 1.0, 1.0])
    a = _map([2.0, 0.0, 1.0, 1.0], [1.0, np.nan, 2.0, 1.0])
    # rates: differences 1, -1, 0, 0 -> rms sqrt(2/4), over b's mean rate 1
    assert rate_difference(a, b) == pytest.approx(math.sqrt(0.5), rel=1e-12)
    # speeds: the three patches with impacts in both, b's rates as weights: differences 0, 1, 0
    assert speed_difference(a, b) == pytest.approx(math.sqrt(1.0 / 3.0), rel=1e-12)
    assert rate_difference(b, b) == 0.0 and speed_difference(b, b) == 0.0
    back = read_map_csv(write_map_csv(tmp_path / "m.csv", a))
    assert back["patch_name"] == a["patch_name"]
    assert np.array_equal(back["rate"], a["rate"])
    assert np.array_equal(np.isnan(back["speed"]), np.isnan(a["speed"]))
    with pytest.raises(ValueError, match="no impacts"):
        rate_difference(a, _map([0.0] * 4, [np.nan] * 4))
