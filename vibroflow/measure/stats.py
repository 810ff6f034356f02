"""Batch means: the standard error of every time average (tub47.md, "Procedure" step 3).

The roll in the tub is steady on average but its strength fluctuates by +-30 % from one quarter
second to the next, so samples a few cycles apart are strongly correlated and the naive standard
error sigma/sqrt(n_samples) is far too small.  tub47.md therefore asks for batch means: the
averaging window is split into (at least 4) equal batches of *whole* vibration cycles, each batch
gives one mean, and the standard error is the scatter of the batch means,

    stderr = std(batch means, ddof=1) / sqrt(n_batches).

Choices made here (tub47's window is 2.0 s x 47 Hz = 94 cycles, not divisible by 4 batches):

* Cycles are split as evenly as possible: cycle k (0-based) goes to batch floor(k n_b / n_c), so
  94 cycles make batches of 24, 23, 24, 23 cycles; no whole cycle is thrown away.
* The grand mean is the mean over all samples (equivalently the batch means weighted by their
  sample counts), so it does not depend on the batching; the standard error uses the unweighted
  scatter of the batch means (batches differ by at most one cycle, ~4 % in size at tub47's
  numbers, which changes the error estimate by far less than its own uncertainty).
* Samples of an incomplete trailing cycle (when the window is not a whole number of cycles), and
  samples outside the window, get batch index -1 and are not used.
"""
from __future__ import annotations

import warnings

import numpy as np

from vibroflow.numbers import is_finite_number

#: tolerance (in cycles) when placing a sample on a cycle boundary: a snapshot written at
#: t_start + k/f with round-off still belongs to cycle k.
CYCLE_TOLERANCE = 1.0e-6


def cycles_in_window(t_start: float, t_end: float, frequency: float) -> int:
    """Number of whole vibration cycles in [t_start, t_end) (s, s, Hz)."""
    return int(np.floor((t_end - t_start) * frequency + CYCLE_TOLERANCE))


def batches_of_whole_cycles(times, t_start: float, t_end: float, frequency: float,
                            n_batches: int) -> np.ndarray:
    """Batch index (0 .. n_batches-1, or -1 = not used) of each sample time.

    Parameters
    ----------
    times : (S,) sample times (s), on the same clock as the tub motion (t = 0 at the start of
        vibration).
    t_start, t_end : the averaging window (s); it is half-open, [t_start, t_end): a snapshot at
        exactly t_end is phase 0 of the *next* cycle and is not used, so snapshots written at
        t_start + j / (p f), j = 0 .. p n_cycles - 1, are all used and every cycle holds p of them.
    frequency : vibration frequency f (Hz).
    n_batches : number of batches (tub47.md: at least 4).

    The window holds n_c = floor((t_end - t_start) f) whole cycles; samples of an incomplete
    trailing cycle get -1 (dropped).  Cycle k goes to batch floor(k n_batches / n_c): the cycles are
    split as evenly as possible (94 cycles in 4 batches: 24, 23, 24, 23).

    Raises ValueError when the window holds fewer whole cycles than batches.
    """
    if n_batches < 1:
        raise ValueError(f"n_batches = {n_batches}: must be at least 1")
    if frequency <= 0:
        raise ValueError(f"frequency = {frequency}: must be > 0 Hz")
    n_cycles = cycles_in_window(t_start, t_end, frequency)
    if n_cycles < n_batches:
        raise ValueError(f"averaging window [{t_start}, {t_end}) s holds {n_cycles} whole cycles "
                         f"at {frequency} Hz: need at least n_batches = {n_batches}")
    t = np.asarray(times, dtype=float)
    cycle = np.floor((t - t_start) * frequency + CYCLE_TOLERANCE).astype(np.int64)
    ok = (cycle >= 0) & (cycle < n_cycles)
    batch = np.full(t.shape, -1, dtype=np.int64)
    batch[ok] = (cycle[ok] * n_batches) // n_cycles
    return batch


def batch_means(values_per_sample, batch_of_sample, n_batches: int, weights=None):
    """Grand mean and batch-means standard error of per-sample values.

    Parameters
    ----------
    values_per_sample : (S,) or (S, ...) values, one row a sample (any unit).
    batch_of_sample : (S,) int batch index of each sample; negative = not used.
    n_batches : number of batches n_b (>= 2 for a standard error).
    weights : optional (S,) non-negative sample weights (default 1).

    Returns
    -------
    (mean, stderr) with the shape of one sample: mean = weighted mean of all used samples (the
    batch means weighted by their total weight); stderr = std(batch means, ddof=1)/sqrt(n_b).
    A batch with no weight makes the standard error NaN (it cannot be estimated honestly).
    """
    v = np.asarray(values_per_sample, dtype=float)
    b = np.asarray(batch_of_sample, dtype=np.int64)
    if b.shape != v.shape[:1]:
        raise ValueError(f"batch_of_sample has shape {b.shape}: must be ({v.shape[0]},)")
    w = np.ones(v.shape[0]) if weights is None else np.asarray(weights, dtype=float)
    use = (b >= 0) & (b < n_batches)
    v, b, w = v[use], b[use], w[use]
    flat = v.reshape(v.shape[0], -1)
    wsum = np.bincount(b, weights=w, minlength=n_batches)
    sums = np.stack([np.bincount(b, weights=w * flat[:, k], minlength=n_batches)
                     for k in range(flat.shape[1])], axis=1)
    total_w = wsum.sum()
    mean = sums.sum(axis=0) / total_w if total_w > 0 else np.full(flat.shape[1], np.nan)
    with np.errstate(invalid="ignore", divide="ignore"):
        bmeans = sums / wsum[:, None]
    if n_batches >= 2 and np.all(wsum > 0):
        stderr = bmeans.std(axis=0, ddof=1) / np.sqrt(n_batches)
    else:
        stderr = np.full(flat.shape[1], np.nan)
    shape = v.shape[1:]
    if shape == ():
        return float(mean[0]), float(stderr[0])
    return mean.reshape(shape), stderr.reshape(shape)


def stderr_of_batches(batch_values, axis: int = 0):
    """Standard error from per-batch values (batches along `axis`): std(ddof=1)/sqrt(n_b).

    NaN batches (no data in that batch) are skipped, n_b counting only finite ones; fewer than
    two finite batches give NaN.
    """
    a = np.asarray(batch_values, dtype=float)
    finite = np.isfinite(a)
    n = finite.sum(axis=axis)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.nansum(a, axis=axis) / n
        dev = np.where(finite, a - np.expand_dims(mean, axis), 0.0)
        var = (dev**2).sum(axis=axis) / (n - 1)
        se = np.sqrt(var / n)
    se = np.where(n >= 2, se, np.nan)
    return float(se) if np.ndim(se) == 0 else se


def phase_stderr(batch_phases, centre: float) -> float:
    """The batch-means standard error (cycles) of phases, cycle fractions in [0, 1), about the
    run's own phase `centre`: each batch's phase is taken as its signed distance to the centre
    on the circle, (v - centre + 1/2) mod 1 - 1/2, so that batches at 0.99 and 0.09 are 0.10
    apart, not 0.90.  NaN when the centre is not finite (stderr_of_batches otherwise)."""
    v = np.asarray(batch_phases, dtype=float)
    if not np.isfinite(centre):
        return float("nan")
    return stderr_of_batches(np.mod(v - float(centre) + 0.5, 1.0) - 0.5)


def jackknife_stderr(leave_one_out) -> float:
    """Delete-one-batch jackknife standard error of a statistic from its values theta_k
    computed with batch k left out (Quenouille 1956, Tukey 1958; Efron & Stein 1981):
    sqrt((n - 1) / n sum_k (theta_k - mean theta)^2).  For the batch mean it is the batch-means
    standard error exactly (stderr_of_batches); for a fitted constant it carries the
    correlation between the cells of one batch that a per-cell least-squares covariance
    ignores.  NaN when fewer than two values are given or any is not finite."""
    a = np.asarray(leave_one_out, dtype=float).ravel()
    n = a.size
    if n < 2 or not np.all(np.isfinite(a)):
        return float("nan")
    return float(np.sqrt((n - 1) / n * np.sum((a - a.mean()) ** 2)))


def jackknife_covariance(left_out_a, left_out_b) -> float:
    """Delete-one-batch jackknife covariance of two statistics from their values with batch k
    left out, (n - 1) / n sum_k (a_k - mean a)(b_k - mean b) (Efron & Stein 1981): its
    diagonal is jackknife_stderr squared.  The errors of a fitted pair's prediction need it
    (affine_prediction_stderr).  NaN as jackknife_stderr."""
    a = np.asarray(left_out_a, dtype=float).ravel()
    b = np.asarray(left_out_b, dtype=float).ravel()
    n = a.size
    if n < 2 or b.size != n or not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
        return float("nan")
    return float((n - 1) / n * np.sum((a - a.mean()) * (b - b.mean())))


def affine_prediction_stderr(x, c0_stderr, c1_stderr, covariance=None,
                             intercept_share: float = 1.0) -> float:
    """The standard error of a prediction s c0 + c1 x of a fitted relation v = c0 + c1 x from
    its coefficients' errors and covariance (units of c0): sqrt(s^2 se0^2 + x^2 se1^2 + 2 s x
    cov), s the share of the prediction the intercept enters (1 for one point; the share of
    the weight where the relation is used, for a weighted mean of it over points).  Without
    the covariance (None or not finite) the bound that holds at any correlation of the two,
    s se0 + |x| se1.  NaN when x or an error is missing."""
    vals = (x, c0_stderr, c1_stderr, intercept_share)
    if not all(is_finite_number(v) for v in vals):
        return float("nan")
    x, e0, e1, s = (float(v) for v in vals)
    if not is_finite_number(covariance):
        return abs(s) * e0 + abs(x) * e1
    var = (s * e0) ** 2 + (x * e1) ** 2 + 2.0 * s * x * float(covariance)
    # a covariance from another estimate than the errors can overshoot |rho| = 1 a little
    return float(np.sqrt(max(var, 0.0)))


def affine_prediction_covariance(x, c0_covariance, c1_covariance,
                                 intercept_share: float = 1.0) -> float:
    """The covariance of a prediction s c0 + c1 x of a fitted relation with another statistic,
    from its coefficients' covariances with that statistic: s cov(c0, .) + x cov(c1, .)
    (s as in affine_prediction_stderr).  NaN when x or a covariance is missing."""
    vals = (x, c0_covariance, c1_covariance, intercept_share)
    if not all(is_finite_number(v) for v in vals):
        return float("nan")
    x, k0, k1, s = (float(v) for v in vals)
    return s * k0 + x * k1


def quadrature_stderr(stderr, other_stderr) -> float:
    """A number's standard error with an independent second error added in quadrature (a
    continuum's inferred impact speed: its run's batch-means error and its calibrated
    relation's, affine_prediction_stderr); the first alone where the second is missing (an
    older calibration without the relation's errors); NaN without the first."""
    if not is_finite_number(stderr):
        return float("nan")
    if not is_finite_number(other_stderr):
        return float(stderr)
    return float(np.hypot(float(stderr), float(other_stderr)))


def jackknife_of_batches(statistic, batches, keys) -> dict:
    """Delete-one-batch jackknife errors {key: se} of the numbers `statistic(*means)` returns
    (a dict; {} or a missing key: that left-out value failed, so its error is NaN), where
    `means` are the arrays of `batches` (each (n_batches, ...)) averaged over every batch but
    one, NaN batches of a cell skipped (a cell no kept batch sampled stays NaN).  {} with
    fewer than two batches."""
    arrays = [np.asarray(a, dtype=float) for a in batches]
    nb = arrays[0].shape[0]
    if nb < 2:
        return {}
    left_out = {k: [] for k in keys}
    for b in range(nb):
        keep = np.arange(nb) != b
        with np.errstate(invalid="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN cells: NaN, said above
            means = [np.nanmean(a[keep], axis=0) for a in arrays]
        values = statistic(*means)
        for k in keys:
            left_out[k].append(values.get(k, float("nan")))
    return {k: jackknife_stderr(v) for k, v in left_out.items()}


def phase_bins(times, frequency: float, n_phases: int) -> np.ndarray:
    """Phase bin k = 0 .. n_phases-1 of each time (s): the nearest of the phases k / n_phases of
    the cycle (phase 0 = t a multiple of 1/f, as dem.h5's /snapshots/phase)."""
    frac = np.mod(np.asarray(times, float) * frequency + CYCLE_TOLERANCE, 1.0)
    return np.mod(np.floor(frac * n_phases + 0.5).astype(np.int64), n_phases)
