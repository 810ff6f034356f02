"""Wall-contact and impact statistics (tub47.md, "What is measured").

* Wall contacts: the ratio |F_t| / F_n of every ball-tub-wall contact (the polyurethane U, not
  the glass partitions), its distribution, its mean by position along the wall (arc length s on
  the U from the bottom, + towards +x, tub/geometry.py), and the fraction of contacts at the
  Coulomb limit (sliding).  A contact sampled in several snapshots counts once per snapshot:
  these are statistics of the contacts present at the sampled instants.
* Impacts: the normal approach speed at the first instant of each new contact, ball-ball and
  ball-wall, and its mean by region.  Kinds: 0 ball-ball, 1 ball-tub wall, 2 ball-partition,
  3 plane wall.

Contacts with F_n <= 0 (a linear spring-dashpot can pull for an instant as the balls separate)
have no meaningful |F_t|/F_n and are left out of every wall-contact statistic, count included.
With batch indices (stats.batches_of_whole_cycles of the contact's snapshot or the impact's
time) the means also get batch-means standard errors.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vibroflow.measure.stats import (batch_means, batches_of_whole_cycles, quadrature_stderr,
                                     stderr_of_batches)

IMPACT_KINDS = {0: "ball_ball", 1: "ball_wall", 2: "ball_partition", 3: "plane_wall"}


@dataclass
class WallContactStats:
    """Statistics of ball-wall contacts (ratios are dimensionless).

    count : contacts used (F_n > 0); mean_ft_over_fn : mean of |F_t|/F_n; ratio_of_sums :
    sum |F_t| / sum F_n; sliding_fraction : fraction at the Coulomb limit; *_stderr : batch
    means (NaN without batches).  histogram_edges (nh+1,), histogram_counts (nh,) : the
    distribution of |F_t|/F_n.  arc_edges (na+1,) (m), arc_count, arc_mean_ft_over_fn,
    arc_sliding_fraction (na,) : by arc position along the U (NaN in empty bins; None when no
    arc positions were given).
    """

    count: int
    mean_ft_over_fn: float
    ratio_of_sums: float
    sliding_fraction: float
    mean_ft_over_fn_stderr: float
    ratio_of_sums_stderr: float
    sliding_fraction_stderr: float
    histogram_edges: np.ndarray
    histogram_counts: np.ndarray
    arc_edges: np.ndarray | None = None
    arc_count: np.ndarray | None = None
    arc_mean_ft_over_fn: np.ndarray | None = None
    arc_sliding_fraction: np.ndarray | None = None

    def as_dict(self) -> dict:
        """The summary keys (mean_ft_over_fn, ratio_of_sums, sliding_fraction, count) and their
        standard errors."""
        return {"mean_ft_over_fn": self.mean_ft_over_fn, "ratio_of_sums": self.ratio_of_sums,
                "sliding_fraction": self.sliding_fraction, "count": self.count,
                "mean_ft_over_fn_stderr": self.mean_ft_over_fn_stderr,
                "ratio_of_sums_stderr": self.ratio_of_sums_stderr,
                "sliding_fraction_stderr": self.sliding_fraction_stderr}


def binned_mean(coord, values, edges):
    """Count and mean of values in bins of coord (edges (n+1,)); NaN mean in empty bins."""
    coord = np.asarray(coord, dtype=float)
    values = np.asarray(values, dtype=float)
    nb = len(edges) - 1
    j = np.searchsorted(edges, coord, side="right") - 1
    ok = (j >= 0) & (j < nb) & np.isfinite(coord)
    # the last edge belongs to the last bin
    ok |= coord == edges[-1]
    j = np.where(coord == edges[-1], nb - 1, j)
    cnt = np.bincount(j[ok], minlength=nb)
    s = np.bincount(j[ok], weights=values[ok], minlength=nb)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = s / cnt
    return cnt, mean


def wall_contact_stats(fn, ft, sliding, arc=None, batch=None, n_batches: int | None = None,
                       histogram_edges=None, arc_edges=None) -> WallContactStats:
    """Statistics of ball-wall contacts.

    fn (C,) normal force (N), ft (C,) tangential force magnitude (N), sliding (C,) bool (at the
    Coulomb limit), arc (C,) arc position on the U (m; NaN off the U), batch (C,) batch index of
    the contact's snapshot (negative = outside the window, dropped; default: all used, one
    batch).  histogram_edges default: 40 bins on [0, max ratio]; arc_edges default: 24 bins on
    [min arc, max arc].
    """
    fn = np.asarray(fn, dtype=float)
    ft = np.asarray(ft, dtype=float)
    sl = np.asarray(sliding, dtype=bool)
    use = (fn > 0) & np.isfinite(fn) & np.isfinite(ft)
    if batch is not None:
        batch = np.asarray(batch, dtype=np.int64)
        use &= batch >= 0
        if n_batches is None:
            n_batches = int(batch.max(initial=-1)) + 1
    fn, ft, sl = fn[use], ft[use], sl[use]
    ratio = ft / fn if fn.size else np.zeros(0)
    n = int(fn.size)
    nan = float("nan")
    mean_r = float(ratio.mean()) if n else nan
    ros = float(ft.sum() / fn.sum()) if n else nan
    slf = float(sl.mean()) if n else nan
    se_r = se_ros = se_sl = nan
    if batch is not None and n and n_batches and n_batches >= 2:
        b = batch[use]
        _, se_r = batch_means(ratio, b, n_batches)
        _, se_sl = batch_means(sl.astype(float), b, n_batches)
        sft = np.bincount(b, weights=ft, minlength=n_batches)
        sfn = np.bincount(b, weights=fn, minlength=n_batches)
        with np.errstate(invalid="ignore", divide="ignore"):
            se_ros = float(stderr_of_batches(sft / sfn))
    if histogram_edges is None:
        top = float(ratio.max()) if n and ratio.max() > 0 else 1.0
        histogram_edges = np.linspace(0.0, top, 41)
    histogram_edges = np.asarray(histogram_edges, dtype=float)
    hist, _ = np.histogram(ratio, bins=histogram_edges)
    out = WallContactStats(count=n, mean_ft_over_fn=mean_r, ratio_of_sums=ros,
                           sliding_fraction=slf, mean_ft_over_fn_stderr=float(se_r),
                           ratio_of_sums_stderr=float(se_ros), sliding_fraction_stderr=float(se_sl),
                           histogram_edges=histogram_edges, histogram_counts=hist)
    if arc is not None:
        s = np.asarray(arc, dtype=float)[use]
        fin = np.isfinite(s)
        if arc_edges is None:
            lo, hi = (float(s[fin].min()), float(s[fin].max())) if fin.any() else (0.0, 1.0)
            arc_edges = np.linspace(lo, hi if hi > lo else lo + 1.0, 25)
        arc_edges = np.asarray(arc_edges, dtype=float)
        out.arc_edges = arc_edges
        out.arc_count, out.arc_mean_ft_over_fn = binned_mean(s, ratio, arc_edges)
        _, out.arc_sliding_fraction = binned_mean(s, sl.astype(float), arc_edges)
    return out


def mean_speed_stderr(impacts: dict, kind: str) -> float:
    """The standard error (m/s) of a summary `impacts` block's KIND_mean_normal_speed (kind
    "ball_ball" or "ball_wall"): the DEM's batch-means error (KIND_mean_normal_speed_stderr),
    and for a continuum's inferred speed its calibrated relation's own beside it
    (KIND_mean_normal_speed_relation_stderr), independent, in quadrature
    (stats.quadrature_stderr); NaN without the first."""
    return quadrature_stderr(impacts.get(f"{kind}_mean_normal_speed_stderr"),
                             impacts.get(f"{kind}_mean_normal_speed_relation_stderr"))


@dataclass
class ImpactStats:
    """Impact statistics: per kind (0 ball-ball, 1 ball-tub wall, 2 ball-partition, 3 plane wall)
    the count, mean normal approach speed (m/s) and its batch-means standard error (m/s)."""

    count: int
    count_by_kind: dict
    mean_normal_speed_by_kind: dict
    mean_normal_speed_stderr_by_kind: dict

    def as_dict(self) -> dict:
        """Summary keys: ball_ball_mean_normal_speed (kind 0), ball_wall_mean_normal_speed
        (kind 1, the tub's U wall), count (all impacts used), plus stderrs and per-kind data."""
        m, se = self.mean_normal_speed_by_kind, self.mean_normal_speed_stderr_by_kind
        return {"ball_ball_mean_normal_speed": m["ball_ball"],
                "ball_wall_mean_normal_speed": m["ball_wall"],
                "count": self.count,
                "ball_ball_mean_normal_speed_stderr": se["ball_ball"],
                "ball_wall_mean_normal_speed_stderr": se["ball_wall"],
                "count_by_kind": dict(self.count_by_kind),
                "mean_normal_speed_by_kind": dict(m),
                "mean_normal_speed_stderr_by_kind": dict(se)}


def _accumulate_impacts(sums, counts, kind, v, batch) -> None:
    """Add impacts (kind (M,) int, normal speed v (M,) m/s, batch (M,) int, negative = outside
    the window) to the per-kind, per-batch sums and counts (arrays (kinds, batches))."""
    nk, nb_ = sums.shape
    use = (batch >= 0) & (batch < nb_) & np.isfinite(v) & (kind >= 0) & (kind < nk)
    flat = kind[use] * nb_ + batch[use]
    sums += np.bincount(flat, weights=v[use], minlength=nk * nb_).reshape(nk, -1)
    counts += np.bincount(flat, minlength=nk * nb_).reshape(nk, -1)


def _impact_stats_of(sums, counts) -> ImpactStats:
    """ImpactStats from per-kind, per-batch sums and counts: the mean over all impacts used and
    the standard error of the batch means (NaN with fewer than 2 batches or an empty batch)."""
    n_batches = sums.shape[1]
    out_c, out_m, out_se = {}, {}, {}
    for k, name in IMPACT_KINDS.items():
        c = counts[k]
        out_c[name] = int(c.sum())
        out_m[name] = float(sums[k].sum() / c.sum()) if c.sum() > 0 else float("nan")
        if n_batches >= 2 and np.all(c > 0):
            out_se[name] = float(stderr_of_batches(sums[k] / c))
        else:
            out_se[name] = float("nan")
    return ImpactStats(count=int(counts.sum()), count_by_kind=out_c,
                       mean_normal_speed_by_kind=out_m, mean_normal_speed_stderr_by_kind=out_se)


def impact_stats(kind, normal_speed, batch=None, n_batches: int | None = None) -> ImpactStats:
    """Mean normal approach speed (m/s) and counts by kind.

    kind (M,) int (see IMPACT_KINDS), normal_speed (M,) m/s, batch (M,) batch index of the
    impact's time (negative = outside the averaging window, dropped; default all, one batch).
    A kind with no impact gets NaN mean and 0 count.
    """
    kind = np.asarray(kind, dtype=np.int64)
    v = np.asarray(normal_speed, dtype=float)
    if batch is None:
        batch = np.zeros(kind.shape[0], np.int64)
        n_batches = 1
    batch = np.asarray(batch, dtype=np.int64)
    if n_batches is None:
        n_batches = max(1, int(batch.max(initial=-1)) + 1)
    nk = max(IMPACT_KINDS) + 1
    sums, counts = np.zeros((nk, n_batches)), np.zeros((nk, n_batches))
    _accumulate_impacts(sums, counts, kind, v, batch)
    return _impact_stats_of(sums, counts)


def impact_stats_chunked(kind, normal_speed, time, t_start: float, t_end: float,
                         frequency: float, n_batches: int,
                         chunk: int = 2_000_000) -> ImpactStats:
    """impact_stats over impacts read in chunks (arrays or h5py datasets of M rows), so that a
    tub47 run's tens of millions of impacts never sit in memory at once.

    The impacts of the averaging window [t_start, t_end) are batched by whole cycles
    (stats.batches_of_whole_cycles) and reduced exactly as impact_stats does.
    """
    nk = max(IMPACT_KINDS) + 1
    sums, counts = np.zeros((nk, n_batches)), np.zeros((nk, n_batches))
    for _rows, bt, kd, v in impact_chunks(time, kind, normal_speed, t_start, t_end, frequency,
                                          n_batches, chunk):
        _accumulate_impacts(sums, counts, kd, v, bt)
    return _impact_stats_of(sums, counts)


def impact_chunks(time, kind, normal_speed, t_start: float, t_end: float, frequency: float,
                  n_batches: int, chunk: int):
    """The impacts (arrays or h5py datasets of M rows) read chunk rows at a time: for each
    chunk (its rows as a slice, each impact's batch of whole cycles of the window [t_start,
    t_end) or -1 outside it, its kind (int64) and its normal speed (m/s))."""
    m = int(kind.shape[0])
    for a in range(0, m, chunk):
        rows = slice(a, min(m, a + chunk))
        yield (rows, batches_of_whole_cycles(np.asarray(time[rows], dtype=float), t_start, t_end,
                                             frequency, n_batches),
               np.asarray(kind[rows], dtype=np.int64), np.asarray(normal_speed[rows], dtype=float))


def mean_by_region(position_tub, values, cell_size: float):
    """Mean of values by square region of the tub frame's x-z plane (cells of side cell_size
    centred on its multiples, as the bulk table).  Returns (x, z, count, mean) over the regions
    that hold at least one value (m, m, -, unit of values)."""
    p = np.asarray(position_tub, dtype=float)
    v = np.asarray(values, dtype=float)
    if v.size == 0:
        e = np.zeros(0)
        return e, e, np.zeros(0, dtype=np.int64), e
    h = float(cell_size)
    i = np.floor(p[:, 0] / h + 0.5).astype(np.int64)
    k = np.floor(p[:, 2] / h + 0.5).astype(np.int64)
    keys, inv = np.unique(np.stack([k, i], axis=1), axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    cnt = np.bincount(inv)
    mean = np.bincount(inv, weights=v) / cnt
    return keys[:, 1] * h, keys[:, 0] * h, cnt, mean
