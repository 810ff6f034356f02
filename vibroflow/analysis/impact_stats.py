"""Impact speeds as distributions, and the ball-wall impacts along the U (the report's "Impact
speed distributions"; dem.h5 /impacts, vibroflow.dem.output).

The impacts of the averaging window's whole cycles are batched in time as every average of the
study (vibroflow.measure.stats.batches_of_whole_cycles) and reduced as they are read, chunk by
chunk: a tub47 run holds tens of millions, never all in memory.

* Per kind (ball-ball, ball-U, ball-partition, ball-plane): a histogram of the normal approach
  speed on fixed log-spaced bins (SPEED_EDGES_M_S: 500 a decade from 1e-6 to 100 m/s, so a
  quantile read off it is within 0.5 % of the sample's), per batch.  Mean, median and 95th
  percentile come from all batches together; their standard errors are the batch-means ones,
  std(batch values, ddof=1) / sqrt(n_batches), of the per-batch mean, median and percentile.
* Along the U: the ball-U impacts binned by the arc length s of their contact point
  (tub.geometry.point_to_arc), each bin a wall strip of area ds L (L the tub's length between
  the partitions); on the partitions: binned by height z, a band's area the U's cross-section
  between its edges on both partitions.  Per bin the impact rate per unit wall area
  count / (area T) (1/(m^2 s), T the window's whole cycles over the frequency), the mean and the
  95th percentile normal speed, each with its batch-means standard error.
* A continuum's inferred speed is flagged when it differs from the DEM's measured one by more
  than FLAG_RELATIVE_DIFFERENCE of the DEM's (speed_flag).

Units: SI (m, s, m/s, 1/(m^2 s)).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vibroflow.measure.contacts import IMPACT_KINDS, impact_chunks
from vibroflow.measure.stats import cycles_in_window, stderr_of_batches
from vibroflow.numbers import is_finite_number
from vibroflow.tub.geometry import TubGeometry, cross_section_area, point_to_arc

#: speed bin edges (m/s): 0, then 500 log-spaced bins a decade from 1e-6 to 100 m/s
SPEED_EDGES_M_S = np.concatenate([[0.0], np.geomspace(1.0e-6, 1.0e2, 4001)])
#: an inferred speed is flagged when |inferred - measured| > this times the measured one
FLAG_RELATIVE_DIFFERENCE = 0.25
#: impacts a wall bin needs before its mean and 95th percentile speed are given
MIN_IMPACTS_PER_BIN = 20
KIND_U, KIND_PARTITION = 1, 2


def speed_bin(v) -> np.ndarray:
    """Index of each speed's bin in SPEED_EDGES_M_S: speeds above the last edge go to the last
    bin, speeds below 0 m/s to the first (an impact whose approach speed is numerically zero,
    -1e-5 m/s, is still an impact, so every kind's count is the summary's); NaN gets -1."""
    v = np.asarray(v, dtype=float)
    j = np.searchsorted(SPEED_EDGES_M_S, v, side="right") - 1
    j = np.clip(j, 0, SPEED_EDGES_M_S.size - 2)
    return np.where(np.isfinite(v), j, -1)


def histogram_quantile(counts, q: float, edges=SPEED_EDGES_M_S) -> float:
    """The q-quantile (0 < q < 1) of a sample given by its histogram counts on `edges`, the
    value where the cumulative count reaches q times the total, linear within its bin; NaN for
    an empty histogram."""
    c = np.asarray(counts, dtype=float)
    total = c.sum()
    if total <= 0:
        return float("nan")
    cum = np.cumsum(c)
    target = q * total
    j = int(np.searchsorted(cum, target, side="left"))
    below = cum[j - 1] if j > 0 else 0.0
    frac = (target - below) / c[j] if c[j] > 0 else 0.0
    return float(edges[j] + frac * (edges[j + 1] - edges[j]))


@dataclass(frozen=True)
class SpeedStats:
    """Statistics of one set of impacts' normal speeds (m/s), each with its batch-means
    standard error (NaN with fewer than two batches holding impacts)."""
    count: int
    mean: float
    mean_stderr: float
    median: float
    median_stderr: float
    p95: float
    p95_stderr: float


def speed_stats(hist, sums) -> SpeedStats:
    """SpeedStats from per-batch histograms hist (n_batches, bins) on SPEED_EDGES_M_S and
    per-batch speed sums (n_batches,) (m/s)."""
    hist = np.asarray(hist, dtype=float)
    sums = np.asarray(sums, dtype=float)
    n_b = hist.sum(axis=1)
    total = hist.sum(axis=0)
    nan = float("nan")
    with np.errstate(invalid="ignore", divide="ignore"):
        b_mean = np.where(n_b > 0, sums / n_b, nan)
    b_med = np.array([histogram_quantile(h, 0.5) for h in hist])
    b_p95 = np.array([histogram_quantile(h, 0.95) for h in hist])
    n = int(total.sum())
    return SpeedStats(count=n, mean=float(sums.sum() / n) if n else nan,
                      mean_stderr=float(stderr_of_batches(b_mean)),
                      median=histogram_quantile(total, 0.5),
                      median_stderr=float(stderr_of_batches(b_med)),
                      p95=histogram_quantile(total, 0.95),
                      p95_stderr=float(stderr_of_batches(b_p95)))


@dataclass(frozen=True)
class WallProfile:
    """Impacts on a wall binned along a coordinate (edges (m)): per bin the wall area (m^2),
    count, rate per unit area (1/(m^2 s)), mean and 95th percentile normal speed (m/s, NaN in a
    bin with fewer than MIN_IMPACTS_PER_BIN impacts), each with its batch-means standard error."""
    coordinate: str
    edges: np.ndarray
    area_m2: np.ndarray
    count: np.ndarray
    rate: np.ndarray
    rate_stderr: np.ndarray
    mean: np.ndarray
    mean_stderr: np.ndarray
    p95: np.ndarray
    p95_stderr: np.ndarray

    @property
    def centres(self) -> np.ndarray:
        return 0.5 * (self.edges[1:] + self.edges[:-1])


class _WallBins:
    """Accumulator of one wall's impacts by coordinate bin and batch."""

    def __init__(self, coordinate: str, edges, area_m2, n_batches: int):
        self.coordinate = coordinate
        self.edges = np.asarray(edges, dtype=float)
        self.area = np.asarray(area_m2, dtype=float)
        nbin = self.edges.size - 1
        self.hist = np.zeros((nbin, n_batches, SPEED_EDGES_M_S.size - 1), dtype=np.int64)
        self.sums = np.zeros((nbin, n_batches))

    def add(self, coord, speed, batch) -> None:
        nbin, n_b, ns = self.hist.shape
        j = np.searchsorted(self.edges, coord, side="right") - 1
        k = speed_bin(speed)
        ok = (j >= 0) & (j < nbin) & (k >= 0) & (batch >= 0) & (batch < n_b)
        flat = (j[ok] * n_b + batch[ok]) * ns + k[ok]
        self.hist += np.bincount(flat, minlength=self.hist.size).reshape(self.hist.shape)
        self.sums += np.bincount(j[ok] * n_b + batch[ok], weights=speed[ok],
                                 minlength=nbin * n_b).reshape(nbin, n_b)

    def profile(self, seconds_per_batch: np.ndarray) -> WallProfile:
        count_b = self.hist.sum(axis=2).astype(float)            # (bins, batches)
        seconds = float(seconds_per_batch.sum())
        with np.errstate(invalid="ignore", divide="ignore"):
            rate_b = count_b / (self.area[:, None] * seconds_per_batch[None, :])
            rate = count_b.sum(axis=1) / (self.area * seconds)
        nbin = count_b.shape[0]
        stats = [speed_stats(self.hist[i], self.sums[i]) for i in range(nbin)]
        enough = count_b.sum(axis=1) >= MIN_IMPACTS_PER_BIN

        def pick(name):
            return np.array([getattr(s, name) if ok else np.nan
                             for s, ok in zip(stats, enough)])

        return WallProfile(coordinate=self.coordinate, edges=self.edges, area_m2=self.area,
                           count=count_b.sum(axis=1).astype(np.int64), rate=rate,
                           rate_stderr=np.asarray(stderr_of_batches(rate_b, axis=1)),
                           mean=pick("mean"), mean_stderr=pick("mean_stderr"),
                           p95=pick("p95"), p95_stderr=pick("p95_stderr"))


def u_arc_bins(geometry: TubGeometry, bin_width: float) -> tuple[np.ndarray, np.ndarray]:
    """Arc-length bins (m) of the U from rim to rim, bin_width wide (the last ones meet at the
    rims), and each one's wall area ds L (m^2)."""
    half = 0.5 * geometry.wall_arc_length()
    n = max(1, int(math.ceil(2.0 * half / bin_width - 1e-9)))
    edges = np.linspace(-half, half, n + 1)
    return edges, np.diff(edges) * geometry.length


def partition_height_bins(geometry: TubGeometry, bin_width: float):
    """Height bins (m) from the bottom to the rim and each one's wall area on both partitions
    (m^2): twice the U's cross-section between the band's edges (none when the tub is
    periodic: no partitions)."""
    n = max(1, int(math.ceil(geometry.rim_height / bin_width - 1e-9)))
    edges = np.linspace(0.0, geometry.rim_height, n + 1)
    below = np.array([cross_section_area(geometry.radius, z) for z in edges])
    sides = 0.0 if geometry.periodic else 2.0
    return edges, sides * np.diff(below)


@dataclass(frozen=True)
class ImpactDistributions:
    """The window's impacts: per kind name (IMPACT_KINDS' names) the per-batch speed
    histograms (n_batches, bins) on SPEED_EDGES_M_S and their SpeedStats; the U's and the
    partitions' WallProfile; the window's length (s) and batches."""
    histograms: dict
    stats: dict
    u: WallProfile
    partitions: WallProfile
    seconds: float
    n_batches: int


def impact_distributions(time, kind, position_tub, normal_speed, *, t_start: float,
                         t_end: float, frequency: float, n_batches: int,
                         geometry: TubGeometry, bin_width: float,
                         chunk: int = 1_000_000) -> ImpactDistributions:
    """The distributions of the impacts (arrays or h5py datasets of M rows: time (s), kind,
    position_tub (M, 3) m, normal_speed m/s) of the window [t_start, t_end) (s) at `frequency`
    (Hz), batched by whole cycles into n_batches, read chunk rows at a time; the wall profiles
    bin_width (m) wide."""
    nk = max(IMPACT_KINDS) + 1
    ns = SPEED_EDGES_M_S.size - 1
    hist = np.zeros((nk, n_batches, ns), dtype=np.int64)
    sums = np.zeros((nk, n_batches))
    u = _WallBins("arc length along the U, s (m)", *u_arc_bins(geometry, bin_width), n_batches)
    part = _WallBins("height on the partitions, z (m)",
                     *partition_height_bins(geometry, bin_width), n_batches)
    for rows, bt, kd, v in impact_chunks(time, kind, normal_speed, t_start, t_end, frequency,
                                         n_batches, chunk):
        sb = speed_bin(v)
        ok = (bt >= 0) & (sb >= 0) & (kd >= 0) & (kd < nk)
        flat = (kd[ok] * n_batches + bt[ok]) * ns + sb[ok]
        hist += np.bincount(flat, minlength=hist.size).reshape(hist.shape)
        sums += np.bincount(kd[ok] * n_batches + bt[ok], weights=v[ok],
                            minlength=nk * n_batches).reshape(nk, n_batches)
        on_u, on_p = ok & (kd == KIND_U), ok & (kd == KIND_PARTITION)
        if on_u.any() or on_p.any():
            pos = np.asarray(position_tub[rows], dtype=float)
            u.add(point_to_arc(pos[on_u, 0], pos[on_u, 2], geometry.radius), v[on_u],
                  bt[on_u])
            part.add(pos[on_p, 2], v[on_p], bt[on_p])
    n_cycles = cycles_in_window(t_start, t_end, frequency)
    cycles_b = np.bincount(np.arange(n_cycles) * n_batches // n_cycles, minlength=n_batches)
    seconds_b = cycles_b / float(frequency)
    names = {k: IMPACT_KINDS[k] for k in range(nk)}
    return ImpactDistributions(
        histograms={names[k]: hist[k] for k in range(nk)},
        stats={names[k]: speed_stats(hist[k], sums[k]) for k in range(nk)},
        u=u.profile(seconds_b), partitions=part.profile(seconds_b),
        seconds=float(seconds_b.sum()), n_batches=int(n_batches))


def speed_flag(inferred, measured) -> tuple[float, bool | None]:
    """(relative difference (inferred - measured) / measured, flagged): flagged when it exceeds
    FLAG_RELATIVE_DIFFERENCE in size; (NaN, None) when either is missing or measured is not
    positive."""
    if not all(is_finite_number(x) for x in (inferred, measured)) or measured <= 0:
        return float("nan"), None
    rel = (float(inferred) - float(measured)) / float(measured)
    return rel, bool(abs(rel) > FLAG_RELATIVE_DIFFERENCE)


def same_measured_mean(calibrated_mean, measured) -> bool:
    """Whether a calibration's measured mean speed (m/s) is a DEM run's `measured` one to
    round-off: the calibration was made on that run (the same impacts), so its relation and
    the run's measured speeds move together from batch to batch.  Another fill seed's or case's
    mean differs in its leading digits."""
    vals = (calibrated_mean, measured)
    if not all(is_finite_number(x) for x in vals):
        return False
    return abs(float(calibrated_mean) - float(measured)) <= 1e-9 * abs(float(measured))


def relative_difference_stderr(inferred, inferred_stderr, measured, measured_stderr,
                               covariance=None) -> float:
    """The standard error of speed_flag's relative difference r = i / m - 1 (the delta
    method): sqrt(se_i^2 + (i / m)^2 se_m^2 - 2 (i / m) cov(i, m)) / m, with `covariance`
    cov(i, m) (m^2/s^2) where the inferred speed's relation was calibrated on the run that
    measured m (the same cycles move both: calibration.impacts.jackknife_of_refits), the two
    independent without it (None or not finite).  NaN when a speed or an error is missing or
    measured is not positive."""
    vals = (inferred, inferred_stderr, measured, measured_stderr)
    if not all(is_finite_number(x) for x in vals) or measured <= 0:
        return float("nan")
    i, si, m, sm = (float(x) for x in vals)
    var = si**2 + (i / m * sm) ** 2
    if is_finite_number(covariance):
        # two covariance estimates of one set of batches can overshoot |rho| = 1 a little
        var = max(var - 2.0 * i / m * float(covariance), 0.0)
    return float(math.sqrt(var) / m)
