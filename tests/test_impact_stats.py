"""Impact speeds as distributions (vibroflow.analysis.impact_stats) against known answers: the
median and 95th percentile of uniform and exponential samples, the batch-means standard error
of batches with known medians, the arc length of points on a known U, the rate per unit wall
area of impacts spread uniformly over the U and the partitions, and the quarter flag."""
from __future__ import annotations

import math

import numpy as np
import pytest

from vibroflow.analysis.impact_stats import (SPEED_EDGES_M_S, histogram_quantile,
                                             impact_distributions, speed_bin, speed_flag)
from vibroflow.tub.geometry import TubGeometry, arc_to_point, point_to_arc

F_HZ, N_BATCHES = 50.0, 4
T0, T1 = 0.0, 1.0  # 50 whole cycles


def _quantile_sample(inverse_cdf, n: int) -> np.ndarray:
    """n speeds at the probabilities (i + 1/2)/n of a distribution: its quantiles exactly."""
    return inverse_cdf((np.arange(n) + 0.5) / n)


def _times(n: int) -> np.ndarray:
    """n impact times spread over the window, unrelated to their index's order."""
    return T0 + ((np.arange(n) * 7919) % n + 0.5) / n * (T1 - T0)


def _distributions(speed, kind, position, time=None, geometry=None, bin_width=0.015):
    n = speed.size
    return impact_distributions(
        _times(n) if time is None else time, kind, position, speed, t_start=T0, t_end=T1,
        frequency=F_HZ, n_batches=N_BATCHES, geometry=geometry or TubGeometry(),
        bin_width=bin_width, chunk=7001)  # chunks that split the sample unevenly


def test_median_and_p95_of_uniform_and_exponential_speeds():
    n = 200_000
    rate = 1.0 / 0.04  # exponential of mean 0.04 m/s
    uniform = _quantile_sample(lambda p: 0.3 * p, n)  # uniform on [0, 0.3] m/s
    expo = _quantile_sample(lambda p: -np.log1p(-p) / rate, n)
    speed = np.concatenate([uniform, expo])
    kind = np.concatenate([np.zeros(n, int), np.full(n, 3)])  # ball-ball, ball-plane
    d = _distributions(speed, kind, np.zeros((2 * n, 3)))
    u, e = d.stats["ball_ball"], d.stats["plane_wall"]
    assert u.count == n and e.count == n and d.stats["ball_wall"].count == 0
    # the histogram's bins are 0.46 % wide: a quantile read off it is within that
    assert u.median == pytest.approx(0.15, rel=5e-3)
    assert u.p95 == pytest.approx(0.285, rel=5e-3)
    assert e.median == pytest.approx(math.log(2.0) / rate, rel=5e-3)
    assert e.p95 == pytest.approx(math.log(20.0) / rate, rel=5e-3)
    assert u.mean == pytest.approx(0.15, rel=1e-9)  # the mean is exact, not binned
    assert e.mean == pytest.approx(1.0 / rate, rel=1e-3)
    assert math.isnan(d.stats["ball_wall"].median)


def test_batch_means_standard_error_of_batches_with_known_medians():
    """Batch k (cycles 12.5 k .. of the 50) holds a uniform sample on [0, 1 + k/10] m/s: batch
    medians 0.5 (1 + k/10), so the standard error is std(0.5, 0.55, 0.6, 0.65)/2 by hand."""
    per = 40_000
    speeds, times = [], []
    cycles = np.bincount(np.arange(50) * N_BATCHES // 50)  # 13, 12, 13, 12 cycles
    start = np.concatenate([[0], np.cumsum(cycles)]) / F_HZ
    for k in range(N_BATCHES):
        speeds.append(_quantile_sample(lambda p: (1.0 + 0.1 * k) * p, per))
        times.append(start[k] + (np.arange(per) + 0.5) / per * (start[k + 1] - start[k]))
    speed = np.concatenate(speeds)
    d = _distributions(speed, np.zeros(speed.size, int), np.zeros((speed.size, 3)),
                       time=np.concatenate(times))
    s = d.stats["ball_ball"]
    by_hand = 0.05 * math.sqrt(5.0 / 3.0) / 2.0  # std(0, 1, 2, 3; ddof=1) = sqrt(5/3)
    assert s.median_stderr == pytest.approx(by_hand, rel=1e-2)
    assert s.mean_stderr == pytest.approx(by_hand, rel=1e-3)
    assert s.p95_stderr == pytest.approx(1.9 * by_hand, rel=1e-2)


def test_impacts_outside_the_window_are_left_out():
    speed = np.full(4, 0.1)
    time = np.array([-0.01, 0.2, 0.7, 1.0])  # t_end itself begins the next cycle
    d = _distributions(speed, np.zeros(4, int), np.zeros((4, 3)), time=time)
    assert d.stats["ball_ball"].count == 2 and d.seconds == pytest.approx(1.0)


def test_arc_length_of_points_on_a_known_u():
    R = 0.15
    theta = np.array([-1.2, -0.5, 0.0, 0.3, 0.5 * math.pi])
    x, z = R * np.sin(theta), R - R * np.cos(theta)
    assert point_to_arc(x, z, R) == pytest.approx(R * theta, abs=1e-15)
    # the vertical walls: a quarter circle, then the height above z = R
    assert point_to_arc(np.array([R, -R]), np.array([0.25, 0.3]), R) == pytest.approx(
        [0.5 * math.pi * R + 0.10, -(0.5 * math.pi * R + 0.15)])


def test_rate_per_area_of_impacts_spread_uniformly_over_the_u():
    geo = TubGeometry(radius=0.15, rim_height=0.4, length=0.02)
    half = 0.5 * geo.wall_arc_length()
    n_bins = math.ceil(2 * half / 0.015)
    n = n_bins * 300
    s = -half + (np.arange(n) + 0.5) / n * 2 * half  # evenly along the profile
    x, z = (np.asarray(a) for a in arc_to_point(s, geo.radius))
    pos = np.stack([x, np.full(n, 0.01), z], axis=1)
    d = _distributions(np.full(n, 0.2), np.ones(n, int), pos, geometry=geo)
    u = d.u
    # N impacts over the whole U (area 2 half L) in T = 1 s
    assert u.rate == pytest.approx(np.full(n_bins, n / (2 * half * geo.length * 1.0)), rel=1e-9)
    assert u.count.sum() == n
    assert u.mean == pytest.approx(np.full(n_bins, 0.2), rel=1e-9)
    assert u.p95 == pytest.approx(np.full(n_bins, 0.2), rel=5e-3)
    assert d.partitions.count.sum() == 0


def test_rate_per_area_of_impacts_spread_uniformly_over_the_partitions():
    """One impact per mm^2 of each partition (a 1 mm grid over the U's cross-section, on both)
    in 1 s: 1e6 impacts per m^2 and second in every height band, up to the grid's edge
    effects at the circle."""
    geo = TubGeometry(radius=0.15, rim_height=0.4, length=0.02)
    eps = 1e-3
    gx, gz = np.meshgrid(np.arange(-0.15 + eps / 2, 0.15, eps), np.arange(eps / 2, 0.4, eps))
    inside = geo.inside(gx.ravel(), gz.ravel())
    x, z = gx.ravel()[inside], gz.ravel()[inside]
    m = x.size
    pos = np.concatenate([np.stack([x, np.zeros(m), z], 1),
                          np.stack([x, np.full(m, geo.length), z], 1)])
    d = _distributions(np.full(2 * m, 0.05), np.full(2 * m, 2), pos, geometry=geo,
                       bin_width=0.016)  # 25 bands of 16 grid rows each
    p = d.partitions
    assert p.edges[0] == 0.0 and p.edges[-1] == pytest.approx(0.4)
    deep = p.centres > 0.05  # bands where the circle's staircase is a small part of the area
    assert p.rate[deep] == pytest.approx(np.full(deep.sum(), 1.0 / eps**2), rel=0.01)
    assert p.count.sum() == 2 * m


def test_speed_bins_and_quantile_of_a_single_bin():
    assert speed_bin(np.array([0.0, 5e-7, -1e-5, np.nan, 1e3]))[:4].tolist() == [0, 0, 0, -1]
    assert speed_bin(np.array([1e3]))[0] == SPEED_EDGES_M_S.size - 2
    counts = np.zeros(SPEED_EDGES_M_S.size - 1)
    counts[10] = 4
    # linear within the bin: the median is its middle
    assert histogram_quantile(counts, 0.5) == pytest.approx(
        0.5 * (SPEED_EDGES_M_S[10] + SPEED_EDGES_M_S[11]))


def test_an_impact_of_numerically_zero_approach_speed_is_counted_and_averaged():
    # a contact's approach speed of -1e-5 m/s is round-off around zero: the distribution counts
    # it in its lowest bin and its mean is the plain mean of the speeds, as the summary's
    speed = np.array([0.2, 0.1, -1.0e-5, 0.3] * 50)
    d = _distributions(speed, np.zeros(speed.size, int), np.zeros((speed.size, 3)))
    st = d.stats["ball_ball"]
    assert st.count == speed.size
    assert st.mean == pytest.approx(speed.mean(), rel=1e-12)
    assert d.histograms["ball_ball"].sum(axis=0)[0] == 50


def test_an_inferred_speed_off_by_more_than_a_quarter_is_flagged():
    assert speed_flag(0.625, 0.5) == (0.25, False)   # exactly a quarter: not more
    assert speed_flag(0.375, 0.5) == (-0.25, False)
    rel, flag = speed_flag(0.626, 0.5)
    assert flag is True and rel == pytest.approx(0.252)
    assert speed_flag(0.3, 0.5)[1] is True
    assert speed_flag(float("nan"), 0.5)[1] is None
    assert speed_flag(0.1, 0.0)[1] is None and speed_flag(None, 0.5)[1] is None


def test_the_relative_difference_carries_both_speeds_errors():
    """r = i / m - 1 with i = 0.6 +- 0.03 and m = 0.5 +- 0.02 m/s: the delta method's
    hypot(0.03, 1.2 x 0.02) / 0.5 = 0.07684; and over 200 000 draws of the two speeds with
    those errors, the sd of r is that within 3 % (errors of 5 and 4 %, where the first order
    holds).  A missing error or a speed at rest: unknown."""
    from vibroflow.analysis.impact_stats import relative_difference_stderr

    se = relative_difference_stderr(0.6, 0.03, 0.5, 0.02)
    assert se == pytest.approx(math.hypot(0.03, 1.2 * 0.02) / 0.5, rel=1e-12)
    rng = np.random.default_rng(3)
    r = rng.normal(0.6, 0.03, 200_000) / rng.normal(0.5, 0.02, 200_000) - 1.0
    assert np.std(r) == pytest.approx(se, rel=0.03)
    assert math.isnan(relative_difference_stderr(0.6, float("nan"), 0.5, 0.02))
    assert math.isnan(relative_difference_stderr(0.6, 0.03, 0.0, 0.02))
    assert math.isnan(relative_difference_stderr(None, 0.03, 0.5, 0.02))
