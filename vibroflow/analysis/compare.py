"""Comparing two results cell by cell (tub47.md, "What is measured" and "Judging a comparison").

Field difference between a result a and a reference b, over the cells where both have solid
fraction >= 0.3 (scenario.analysis.min_solid_fraction):

    E(a, b) = sqrt( sum phi_b |v_a - v_b|^2 / sum phi_b ) / V_b,
    V_b     = sum phi_b |v_b| / sum phi_b,

a phi_b-weighted rms velocity difference relative to b's phi_b-weighted mean speed (-).  It is not
symmetric: b is the reference.  The DEM's seed-to-seed E is the floor every comparison is judged
against.

Where the difference lies: difference_by_region splits the sum under E's square root over
rectangles of the tub's cross-section (bed_thirds: the width and the reference bed's depth in
thirds), each region's share of E^2 beside its mean speeds and mean velocity difference.

The floor over several seeds: seed_scatter takes E over every ordered pair of n runs that differ
only in their fill seed (its mean, with the jackknife error over the runs), and
difference_to_seeds a result's E against each of them, so that a comparison and its floor are
measured on the same ensemble rather than on one pair, itself a random number.

Judging (tub47.md): two circulation strengths agree when they differ by no more than 10 % or by no
more than twice their combined standard error, whichever is larger; two fields agree when
E(a, b) <= 1.5 E_seed of the reference method.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vibroflow.errors import InputError
from vibroflow.measure.bulk import CellTable

#: tub47.md "Judging a comparison"
STRENGTH_REL_TOL = 0.10
STRENGTH_SIGMAS = 2.0
FIELD_FACTOR = 1.5


def matched_cells(a: CellTable, b: CellTable, min_solid_fraction: float = 0.3):
    """Indices (ja, jb) of the cells present in both tables (same centre) where both solid
    fractions are >= min_solid_fraction.  The tables must have the same cell size."""
    if not np.isclose(a.cell_size, b.cell_size, rtol=1e-6, atol=0.0):
        raise InputError(f"analysis.cell_size = {a.cell_size} m and {b.cell_size} m: the bulk "
                         "tables compared must be on the same grid")
    ka = {(int(i), int(k)): j for j, (i, k) in enumerate(zip(a.ix, a.iz))}
    ja, jb = [], []
    for j, (i, k) in enumerate(zip(b.ix, b.iz)):
        m = ka.get((int(i), int(k)))
        if m is not None:
            ja.append(m)
            jb.append(j)
    ja, jb = np.array(ja, dtype=np.int64), np.array(jb, dtype=np.int64)
    keep = ((a.solid_fraction[ja] >= min_solid_fraction)
            & (b.solid_fraction[jb] >= min_solid_fraction)) if ja.size else np.zeros(0, bool)
    return ja[keep], jb[keep]


def _differences(a: CellTable, b: CellTable, min_solid_fraction: float):
    """(ja, jb, w, dvx, dvz) of the compared cells (matched_cells): the weights phi_b and the
    differences v_a - v_b (m/s); an InputError when there is no compared cell."""
    ja, jb = matched_cells(a, b, min_solid_fraction)
    if ja.size == 0:
        raise InputError(f"bulk_velocity.csv: no common cell with solid fraction >= "
                         f"{min_solid_fraction} in both tables compared; they must be of the "
                         "same tub, each holding a bed")
    return ja, jb, b.solid_fraction[jb], a.vx[ja] - b.vx[jb], a.vz[ja] - b.vz[jb]


def field_difference(a: CellTable, b: CellTable, min_solid_fraction: float = 0.3) -> float:
    """E(a, b) of tub47.md (dimensionless), b the reference.  Raises InputError when no cell has
    solid fraction >= min_solid_fraction in both, or b does not move there."""
    ja, jb, w, dvx, dvz = _differences(a, b, min_solid_fraction)
    rms = np.sqrt(np.sum(w * (dvx**2 + dvz**2)) / np.sum(w))
    V_b = np.sum(w * np.hypot(b.vx[jb], b.vz[jb])) / np.sum(w)
    if V_b <= 0:
        raise InputError("bulk_velocity.csv: the reference field is at rest in the compared "
                         "cells (V_b = 0); E is measured against a moving bed")
    return float(rms / V_b)


def without_batch(t: CellTable, k: int) -> CellTable:
    """The table of every batch of t but batch k (no batches of its own): per cell the solid
    fraction the mean of the other batches' (equal batches of whole cycles) and the velocity
    their sample-weighted mean (a cell no other batch sampled: 0 m/s, 0 samples)."""
    keep = np.arange(t.n_batches) != k
    n = (t.batch_samples[keep] if t.batch_samples is not None
         else np.ones((int(keep.sum()), len(t))))
    total = n.sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        vx = np.where(total > 0, (n * np.nan_to_num(t.batch_vx[keep])).sum(axis=0) / total, 0.0)
        vz = np.where(total > 0, (n * np.nan_to_num(t.batch_vz[keep])).sum(axis=0) / total, 0.0)
    return CellTable(t.x, t.z, t.batch_phi[keep].mean(axis=0), vx, vz,
                     total.astype(np.int64), t.cell_size)


def batches_stderr(a: CellTable, b: CellTable, statistic) -> float:
    """The standard error of statistic(a, b) (a float of two cell tables) from the batches of
    both tables: the delete-one-batch jackknife (Efron & Stein 1981) over a's batches with b
    whole, and over b's with a whole, their variances added (the two runs are independent).
    For a statistic smooth in the cell means (E, an rms difference); not for a maximum or a
    median, where the delete-one jackknife is inconsistent (Efron 1982, section 3.4).  NaN
    where neither table has two batches or a left-out statistic cannot be formed
    (InputError or not finite)."""
    var, used = 0.0, False
    for first, side in ((True, a), (False, b)):
        if side.n_batches < 2:
            continue
        left_out = []
        for k in range(side.n_batches):
            t = without_batch(side, k)
            try:
                left_out.append(statistic(t, b) if first else statistic(a, t))
            except InputError:
                return float("nan")
        e = np.asarray(left_out, dtype=float)
        if not np.isfinite(e).all():
            return float("nan")
        n = e.size
        var += (n - 1) / n * float(np.sum((e - e.mean()) ** 2))
        used = True
    return float(np.sqrt(var)) if used else float("nan")


def field_difference_stderr(a: CellTable, b: CellTable, min_solid_fraction: float = 0.3) -> float:
    """The standard error (-) of E(a, b) over both tables' batches (batches_stderr).  It is E's
    scatter over the window's batches, not its bias: the batches' noise also raises E itself,
    which the seed-to-seed limit carries."""
    return batches_stderr(a, b, lambda s, t: field_difference(s, t, min_solid_fraction))


def rms_difference(a: CellTable, b: CellTable, min_solid_fraction: float = 0.3) -> float:
    """The plain root mean square of |v_a - v_b| (m/s) over the cells where both tables hold
    solid fraction >= min_solid_fraction, each cell counted once (the report's difference
    table; E weights the cells by b's solid fraction and divides by b's mean speed).  Raises
    InputError when no cell is shared."""
    _, _, _, dvx, dvz = _differences(a, b, min_solid_fraction)
    return float(np.sqrt(np.mean(dvx ** 2 + dvz ** 2)))


@dataclass(frozen=True)
class RegionDifference:
    """One region's part of E(a, b) (difference_by_region): x and z bounds of the cell centres
    (m, tub frame, [lo, hi)); cells compared; share of E^2 (-, the region's sum of
    phi_b |v_a - v_b|^2 over the whole sum, so the shares add up to 1); the phi_b-weighted mean
    speeds |v_b|, |v_a| (m/s) and mean differences of vx and vz, a - b (m/s)."""

    x_range: tuple[float, float]
    z_range: tuple[float, float]
    cells: int
    share: float
    speed_b: float
    speed_a: float
    dvx: float
    dvz: float


def bed_thirds(b: CellTable, half_width: float, min_solid_fraction: float = 0.3):
    """Region edges for difference_by_region: the tub's width in thirds (x from -half_width to
    +half_width, m) and the reference's bed in thirds of its depth (z from the lowest to the
    highest cell edge holding solid fraction >= min_solid_fraction): the floor's conveyor,
    the roll's core and the surface's return flow, each on the left, in the centre and on the
    right."""
    dense = b.solid_fraction >= min_solid_fraction
    if not dense.any():
        raise InputError(f"bulk_velocity.csv: no cell of the reference has solid fraction >= "
                         f"{min_solid_fraction}; it holds no bed")
    lo = float(b.z[dense].min()) - 0.5 * b.cell_size
    hi = float(b.z[dense].max()) + 0.5 * b.cell_size
    return (np.linspace(-half_width, half_width, 4), np.linspace(lo, hi, 4))


def difference_by_region(a: CellTable, b: CellTable, x_edges, z_edges,
                         min_solid_fraction: float = 0.3) -> list[RegionDifference]:
    """Where E(a, b) comes from: the cells of field_difference split by their centres into the
    rectangles of x_edges x z_edges (m, ascending; a centre on an inner edge goes to the upper
    region, one outside every region to none, so the shares then add up to less than 1).
    Regions in the order z band by z band from the bottom, x from the left within each."""
    ja, jb, w, dvx, dvz = _differences(a, b, min_solid_fraction)
    sq = w * (dvx**2 + dvz**2)
    total = sq.sum()
    sb = np.hypot(b.vx[jb], b.vz[jb])
    sa = np.hypot(a.vx[ja], a.vz[ja])
    xc, zc = b.x[jb], b.z[jb]
    out = []
    x_edges, z_edges = np.asarray(x_edges, float), np.asarray(z_edges, float)
    for k in range(z_edges.size - 1):
        for i in range(x_edges.size - 1):
            m = ((xc >= x_edges[i]) & (xc < x_edges[i + 1])
                 & (zc >= z_edges[k]) & (zc < z_edges[k + 1]))
            wm = w[m].sum()
            # phi_b-weighted means over the region of |v_b|, |v_a|, dvx, dvz
            means = ((w[m] * np.stack([sb[m], sa[m], dvx[m], dvz[m]])).sum(axis=1) / wm
                     if wm > 0 else np.full(4, np.nan))
            out.append(RegionDifference(
                x_range=(float(x_edges[i]), float(x_edges[i + 1])),
                z_range=(float(z_edges[k]), float(z_edges[k + 1])), cells=int(m.sum()),
                share=float(sq[m].sum() / total) if total > 0 else 0.0,
                speed_b=float(means[0]), speed_a=float(means[1]), dvx=float(means[2]),
                dvz=float(means[3])))
    return out


def strengths_agree(s_a: float, se_a: float, s_b: float, se_b: float,
                    sense_a: str | None = None, sense_b: str | None = None) -> bool:
    """Do two circulation strengths agree (tub47.md "Judging a comparison")?

    s_a, s_b : strengths (m^2/s, magnitudes); se_a, se_b : their standard errors (m^2/s; NaN
    counts as 0).  They agree when |s_a - s_b| <= max(0.10 |s_b|, 2 sqrt(se_a^2 + se_b^2)); the
    10 % is taken of b, the reference (as in E).  When both senses are given they must also be
    equal.
    """
    if sense_a is not None and sense_b is not None and sense_a != sense_b:
        return False
    se = np.hypot(np.nan_to_num(se_a), np.nan_to_num(se_b))
    return bool(abs(s_a - s_b) <= max(STRENGTH_REL_TOL * abs(s_b), STRENGTH_SIGMAS * se))


def fields_agree(E_ab: float, E_seed: float) -> bool:
    """Do two fields agree: E(a, b) <= 1.5 x the seed-to-seed E of the reference method?"""
    return bool(E_ab <= FIELD_FACTOR * E_seed)


@dataclass(frozen=True)
class SeedScatter:
    """The reference method's seed-to-seed E over n >= 2 runs that differ only in the fill's
    seed (seed_scatter): E(i, j) for every ordered pair i != j (j the reference, E being
    asymmetric), as (i, j, E) with i, j indices into the runs; their mean (-) and its standard
    error (-, the jackknife over the runs, since every run enters 2 (n - 1) of the pairs and the
    pairs are not independent; None for n < 3)."""

    pairs: tuple[tuple[int, int, float], ...]
    mean: float
    stderr: float | None

    @property
    def runs(self) -> int:
        return 1 + max(max(i, j) for i, j, _ in self.pairs)


def seed_scatter(tables, min_solid_fraction: float = 0.3) -> SeedScatter:
    """The seed-to-seed E of tub47.md measured over every pair of n >= 2 seeds instead of one
    pair.  One pair's E is itself a random number: the bed is chaotic and the roll's strength
    swings by a third from one quarter second to the next, so the floor a comparison is judged
    against is better taken as the mean over all the pairs of several seeds, with its error.

    The standard error is the delete-one jackknife (Efron & Stein 1981; Efron 1982 ch. 3) of
    the pairs' mean over the runs: theta_(k) the mean of the pairs without run k,
    se^2 = (n - 1)/n sum_k (theta_(k) - mean_k theta_(k))^2."""
    tables = list(tables)
    n = len(tables)
    if n < 2:
        raise ValueError(f"seed_scatter needs at least 2 runs, got {n}")
    E = np.full((n, n), np.nan)
    for i in range(n):
        for j in range(n):
            if i != j:
                E[i, j] = field_difference(tables[i], tables[j], min_solid_fraction)
    pairs = tuple((i, j, float(E[i, j])) for i in range(n) for j in range(n) if i != j)
    mean = float(np.nanmean(E))
    stderr = None
    if n >= 3:
        theta = np.array([np.nanmean(np.delete(np.delete(E, k, 0), k, 1)) for k in range(n)])
        stderr = float(np.sqrt((n - 1) / n * np.sum((theta - theta.mean()) ** 2)))
    return SeedScatter(pairs=pairs, mean=mean, stderr=stderr)


@dataclass(frozen=True)
class SeedsDifference:
    """E(a, seed k) of a result a against each of n runs of the reference method that differ
    only in their fill seed (difference_to_seeds): the values (-), their mean and its standard
    error (-, the values' standard deviation over sqrt(n); None for n = 1)."""

    values: tuple[float, ...]
    mean: float
    stderr: float | None


def difference_to_seeds(a: CellTable, tables,
                        min_solid_fraction: float = 0.3) -> SeedsDifference:
    """E(a, b_k) against every seed's field b_k (each the reference in turn), so that a is
    judged against the same ensemble that seed_scatter measures the floor on: fields agree when
    the mean is no more than 1.5 times the seed-to-seed mean (fields_agree)."""
    values = tuple(field_difference(a, b, min_solid_fraction) for b in tables)
    if not values:
        raise ValueError("difference_to_seeds needs at least 1 reference run")
    n = len(values)
    stderr = float(np.std(values, ddof=1) / np.sqrt(n)) if n > 1 else None
    return SeedsDifference(values=values, mean=float(np.mean(values)), stderr=stderr)


def ensemble_mean(tables) -> CellTable:
    """The mean field of n runs that differ only in their fill seed: on the cells every run
    holds, the mean solid fraction and the sample-weighted mean velocity (the pooled mean of all
    the runs' ball-samples in the cell, as one longer run would average them), with the
    samples added up.  The reference with the seeds' noise averaged down by about sqrt(n):
    E(a, ensemble_mean) is nearer the systematic part of a's difference than E(a, one seed)
    (the runs' own E against the mean of the others says how near)."""
    tables = list(tables)
    if not tables:
        raise ValueError("ensemble_mean needs at least 1 run")
    h = tables[0].cell_size
    for t in tables[1:]:
        if not np.isclose(t.cell_size, h, rtol=1e-6, atol=0.0):
            raise InputError(f"analysis.cell_size = {t.cell_size} m and {h} m: the bulk tables "
                             "averaged must be on the same grid")
    keys = [{(int(i), int(k)): j for j, (i, k) in enumerate(zip(t.ix, t.iz))} for t in tables]
    common = sorted(set.intersection(*(set(k) for k in keys)))
    idx = np.array([[k[c] for c in common] for k in keys], dtype=np.int64).reshape(
        len(tables), len(common))
    phi = np.stack([t.solid_fraction[j] for t, j in zip(tables, idx)])
    n = np.stack([t.samples[j] for t, j in zip(tables, idx)]).astype(float)
    vx = np.stack([t.vx[j] for t, j in zip(tables, idx)])
    vz = np.stack([t.vz[j] for t, j in zip(tables, idx)])
    w = np.where(n.sum(axis=0) > 0, n, 1.0)   # cells with no sample: the plain mean
    ix = np.array([c[0] for c in common], dtype=float)
    iz = np.array([c[1] for c in common], dtype=float)
    return CellTable(x=ix * h, z=iz * h, solid_fraction=phi.mean(axis=0),
                     vx=(w * vx).sum(axis=0) / w.sum(axis=0),
                     vz=(w * vz).sum(axis=0) / w.sum(axis=0),
                     samples=n.sum(axis=0).astype(np.int64), cell_size=h)
