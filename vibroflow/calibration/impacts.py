"""Impact velocities from the DEM, and their relation to the local shear rate and granular
temperature, so that the continuum can infer the impact velocity from its own fields (models.md
"Impact velocity from the continuum"; docs/decisions/impact-speed.md).

Data: every new contact of the averaging window with its normal approach speed, its time and
its contact point (dem.h5 /impacts), ball-ball and ball-tub-wall apart.  They are binned on the
grid points of the coarse-grained fields (the contact point's nearest; tub frame) and on the
phase bins of the cycle, and each bin's mean impact speed is set against the coarse-grained
shear rate gamma_dot and granular temperature T at that point and phase (the phase-resolved
fields of the same window, vibroflow.calibration.run_fields; see impact_relations for why
phase-resolved).

Fits, weighted by the number of impacts in each bin (a bin's mean is that many samples):
* linear in the shear rate: v = c0 + c1 d gamma_dot (the published study's form: a Bagnold
  fluctuation ~ d gamma_dot plus a floor c0 from the vibration itself);
* against the temperature: v = a sqrt(T), compared with the Maxwellian values a = sqrt(pi) for
  two balls and sqrt(pi / 2) for a ball and a wall (models.md);
* the Bagnold relation between the two fields: sqrt(T) = b d gamma_dot.
Each fit comes with the standard errors of its coefficients (the delete-one-batch jackknife
where the fields of every batch but one are given, since one batch's cycles move many points
together), R^2 (weighted) and the relative RMS error of the predicted cell means, so a user can
judge how far to trust it.
"""
from __future__ import annotations

import math

import numpy as np

from vibroflow.dem.walls import KIND_BALL_BALL, KIND_BALL_TUB
from vibroflow.measure.phase_shear import near_wall_nodes, phase_shear_of_snapshots
from vibroflow.measure.stats import (batches_of_whole_cycles, jackknife_covariance,
                                     jackknife_stderr, phase_bins)
from vibroflow.tub.geometry import geometry_of

from .dem_result import DEMResult

KINDS = {"ball_ball": KIND_BALL_BALL, "ball_wall": KIND_BALL_TUB}
MAXWELL = {"ball_ball": math.sqrt(math.pi), "ball_wall": math.sqrt(math.pi / 2.0)}
MIN_IMPACTS_PER_CELL = 50


def weighted_linear_fit(x, y, w, intercept: bool = True) -> dict:
    """Weighted least squares y = c0 + c1 x (or y = c1 x): coefficients, their standard errors
    and covariance c0_c1_covariance (units of c0 times c1's; from the weighted residual
    variance), weighted R^2 and relative RMS error (dimensionless).
    """
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    w = np.asarray(w, float)
    ok = np.isfinite(x) & np.isfinite(y) & (w > 0)
    x, y, w = x[ok], y[ok], w[ok]
    p = 2 if intercept else 1
    nan = float("nan")
    if x.size <= p:
        return {"c0": nan, "c1": nan, "c0_stderr": nan, "c1_stderr": nan,
                "c0_c1_covariance": nan, "r2": nan, "relative_rms_error": nan,
                "points": int(x.size)}
    A = np.stack([np.ones_like(x), x], axis=1) if intercept else x[:, None]
    sw = np.sqrt(w)
    coef, *_ = np.linalg.lstsq(A * sw[:, None], y * sw, rcond=None)
    pred = A @ coef
    res = y - pred
    dof = x.size - p
    # weights are sample counts: the residual variance per unit weight estimates the scatter
    s2 = float(np.sum(w * res**2) / dof)
    cov = s2 * np.linalg.inv((A * w[:, None]).T @ A)
    ybar = np.sum(w * y) / np.sum(w)
    ss_tot = float(np.sum(w * (y - ybar) ** 2))
    r2 = 1.0 - float(np.sum(w * res**2)) / ss_tot if ss_tot > 0 else nan
    with np.errstate(invalid="ignore", divide="ignore"):
        rel = float(np.sqrt(np.sum(w * (res / y) ** 2) / np.sum(w)))
    if intercept:
        c0, c1 = float(coef[0]), float(coef[1])
        e0, e1 = float(math.sqrt(cov[0, 0])), float(math.sqrt(cov[1, 1]))
        c01 = float(cov[0, 1])
    else:
        c0, e0, c01 = 0.0, 0.0, 0.0
        c1, e1 = float(coef[0]), float(math.sqrt(cov[0, 0]))
    return {"c0": c0, "c1": c1, "c0_stderr": e0, "c1_stderr": e1, "c0_c1_covariance": c01,
            "r2": r2, "relative_rms_error": rel, "points": int(x.size)}


class BatchCounts:
    """Impact counts and speed sums binned on `ncell` (phase, point) bins, in total and per
    batch of whole cycles: the pooled means and the means without one batch that the
    delete-one-batch jackknife refits on."""

    def __init__(self, ncell: int, n_batches: int):
        self.ncell, self.nb = int(ncell), int(n_batches)
        self.count = np.zeros(self.ncell)
        self.total = np.zeros(self.ncell)
        self.count_b = np.zeros(self.nb * self.ncell)
        self.total_b = np.zeros(self.nb * self.ncell)

    def add(self, flat, speed, batch) -> None:
        """Impacts of normal speed `speed` (m/s) in bins `flat`, of batches `batch`."""
        self.count += np.bincount(flat, minlength=self.ncell)
        self.total += np.bincount(flat, weights=speed, minlength=self.ncell)
        if self.nb:
            fb = batch * self.ncell + flat
            self.count_b += np.bincount(fb, minlength=self.nb * self.ncell)
            self.total_b += np.bincount(fb, weights=speed, minlength=self.nb * self.ncell)

    def bed_mean_without(self, b: int) -> float:
        """The mean speed (m/s) of every impact binned, batch b's left out: the DEM's measured
        bed mean as the jackknife's refit without b sees it (NaN where none is left)."""
        lo = b * self.ncell
        c = self.count.sum() - self.count_b[lo:lo + self.ncell].sum()
        if not c > 0:
            return float("nan")
        return float((self.total.sum() - self.total_b[lo:lo + self.ncell].sum()) / c)

    def bed_means_without(self) -> list[float]:
        """bed_mean_without of each batch (jackknife_of_refits' `measured`)."""
        return [self.bed_mean_without(b) for b in range(self.nb)]

    def without(self, b: int, shape) -> tuple[np.ndarray, np.ndarray]:
        """The counts and mean speeds (m/s; NaN where none) of every batch but b, in `shape`."""
        lo = b * self.ncell
        c = self.count - self.count_b[lo:lo + self.ncell]
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = np.where(c > 0, (self.total - self.total_b[lo:lo + self.ncell]) / c, np.nan)
        return c.reshape(shape), mean.reshape(shape)


def jackknife_of_refits(fits: dict, refit, n_batches: int, measured=None) -> None:
    """In place: each fit of `fits` ({tag: weighted_linear_fit's dict}) gets c0_stderr,
    c1_stderr and c0_c1_covariance as the delete-one-batch jackknife (measure.stats.
    jackknife_stderr, jackknife_covariance) of refit(b), the same tags' fits made again without
    batch b; its own (the points taken as independent) kept as c0_stderr_points,
    c1_stderr_points and c0_c1_covariance_points, and stderr_batches the batches used.
    measured : the DEM's measured bed mean speed (m/s) without each batch
    (BatchCounts.bed_means_without); with it, each fit also gets c0_measured_covariance (m^2/s^2)
    and c1_measured_covariance (m/s), the jackknife covariances of its coefficients with that
    mean.  The refits' coefficients themselves are kept as c0_left_out and c1_left_out (batch
    order), for the covariance with any other statistic of the same batches.

    Why: one batch's cycles move the fields and the impact speeds of many points together, so
    the points are not independent and the least-squares errors understate the scatter.  The
    same cycles move the measured mean too, so a speed inferred through the relation and the
    DEM's measured one are correlated when both come from one run (analysis.impact_stats.
    relative_difference_stderr).  Without two batches, or where a refit fails, the jackknife
    errors are NaN."""
    refits = [refit(b) for b in range(n_batches)] if n_batches >= 2 else []
    for tag, fit in fits.items():
        fit["c0_stderr_points"], fit["c1_stderr_points"] = fit["c0_stderr"], fit["c1_stderr"]
        fit["c0_c1_covariance_points"] = fit.get("c0_c1_covariance", float("nan"))
        c0s, c1s = [r[tag]["c0"] for r in refits], [r[tag]["c1"] for r in refits]
        fit["c0_stderr"] = jackknife_stderr(c0s)
        fit["c1_stderr"] = jackknife_stderr(c1s)
        fit["c0_c1_covariance"] = jackknife_covariance(c0s, c1s)
        fit["stderr_batches"] = len(refits)
        fit["c0_left_out"], fit["c1_left_out"] = c0s, c1s
        if measured is not None:
            fit["c0_measured_covariance"] = jackknife_covariance(c0s, measured)
            fit["c1_measured_covariance"] = jackknife_covariance(c1s, measured)


def impact_relations(run, phase_fields, time_fields=None,
                     min_impacts: int = MIN_IMPACTS_PER_CELL, min_solid_fraction: float = 0.1,
                     histogram_bins: int = 60, chunk: int = 2_000_000,
                     leave_one_out=None) -> dict:
    """Impacts of a DEM run against its coarse-grained phase-resolved fields.

    The bed does not move rigidly with the tub: relative to it every ball oscillates at the
    vibration frequency, with a speed of the order of the tub's (A omega ~ 0.4 m/s at tub47).
    A time-averaged kinetic stress counts that oscillation as "temperature"; the fluctuation that
    makes balls collide is the one about the local velocity *at the same phase*.  So impacts are
    binned by cell and by the phase bin of their time (the snapshots' phases), and each (phase,
    cell) mean impact speed is set against that phase's shear rate and temperature -- the
    instantaneous quantities a cycle-resolving continuum computes.

    run : DEMResult, run directory or dem.h5; phase_fields : the phase-resolved Dataset of
    run_fields.coarse_grain_run (dims phase, x, z); time_fields : the time-averaged one (for the
    per-cell maps; optional).  A (phase, cell) point enters the fits when it holds at least
    `min_impacts` impacts of the kind and its solid fraction is at least `min_solid_fraction`.
    leave_one_out : run_fields.leave_one_out_dataset's fields of every batch but one; with it
    the fits' c0_stderr and c1_stderr are the delete-one-batch jackknife (jackknife_of_refits:
    each fit made again without one batch's impacts, on the fields without it), without it the
    points' own least-squares errors.

    Returns {kind: {count, mean_normal_speed, histogram {edges, counts}, map {count, mean_speed}
    (x, z), points {x, z, phase, count, mean_speed, shear_rate, temperature, solid_fraction},
    fit_shear_rate {c0 (m/s), c1 (-), ...}, fit_temperature {c1 = a, ..., maxwell}},
    "bagnold": {c1 = b, ...}, "diameter": d}.
    """
    own = not isinstance(run, DEMResult)
    res = DEMResult.open(run) if own else run
    try:
        return _relations(res, phase_fields, min_impacts, min_solid_fraction, histogram_bins,
                          chunk, leave_one_out)
    finally:
        if own:
            res.close()


def window_impacts(res: DEMResult, n_phases: int, chunk: int = 2_000_000,
                   with_batch: bool = False):
    """Yield (kind, normal speed m/s, contact point (tub frame, m), phase bin) arrays of the
    impacts of the averaging window's whole cycles, `chunk` impacts read at a time (a tub47
    run holds ~25 million); with `with_batch`, also each impact's batch of whole cycles."""
    if not res.has("impacts/kind"):
        return
    f = res.file
    sc = res.scenario
    t0, t1 = res.window()
    freq = float(sc.motion.frequency)
    m = f["impacts/kind"].shape[0]
    for a0 in range(0, m, chunk):
        a1 = min(m, a0 + chunk)
        it = f["impacts/time"][a0:a1]
        batch = batches_of_whole_cycles(it, t0, t1, freq, int(sc.run.batches))
        use = batch >= 0
        if not use.any():
            continue
        out = (f["impacts/kind"][a0:a1][use],
               f["impacts/normal_speed"][a0:a1].astype(float)[use],
               f["impacts/position_tub"][a0:a1][use], phase_bins(it[use], freq, n_phases))
        yield (*out, batch[use]) if with_batch else out


def _relations(res: DEMResult, pf, min_impacts, min_sf, histogram_bins, chunk,
               loo=None) -> dict:
    sc = res.scenario
    d = res.diameter
    x = np.asarray(pf["x"].values, float)
    z = np.asarray(pf["z"].values, float)
    n_ph = int(pf.sizes["phase"])
    h = float(x[1] - x[0]) if x.size > 1 else float(sc.analysis.cell_size)
    gam = np.asarray(pf["shear_rate"].values, float)          # (phase, x, z)
    T = np.asarray(pf["temperature"].values, float)
    phi = np.asarray(pf["solid_fraction"].values, float)
    out: dict = {"diameter": d}
    if not res.has("impacts/kind"):
        for name in KINDS:
            out[name] = None
        out["bagnold"] = None
        return out
    ncell = n_ph * x.size * z.size
    nb = 0 if loo is None else int(loo.sizes["batch"])
    counts = {name: BatchCounts(ncell, nb) for name in KINDS}
    hist = {name: None for name in KINDS}
    edges = None
    for kind, speed, pos, ph, batch in window_impacts(res, n_ph, chunk, with_batch=True):
        if edges is None:
            top = 2.0 * float(np.percentile(speed, 99.9)) if speed.size else 1.0
            edges = np.linspace(0.0, max(top, 1e-6), histogram_bins + 1)
        ia = np.floor((pos[:, 0] - x[0]) / h + 0.5).astype(np.int64)
        ib = np.floor((pos[:, 2] - z[0]) / h + 0.5).astype(np.int64)
        inside = (ia >= 0) & (ia < x.size) & (ib >= 0) & (ib < z.size)
        flat = (ph * x.size + ia) * z.size + ib
        for name, k in KINDS.items():
            sel = (kind == k) & inside
            counts[name].add(flat[sel], speed[sel], batch[sel])
            hk, _ = np.histogram(np.minimum(speed[sel], edges[-1]), bins=edges)
            hist[name] = hk if hist[name] is None else hist[name] + hk
    shape = (n_ph, x.size, z.size)
    for name in KINDS:
        c = counts[name].count.reshape(shape)
        s = counts[name].total.reshape(shape)
        if c.sum() == 0:
            out[name] = None
            continue
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = np.where(c > 0, s / c, np.nan)
            cmap = c.sum(axis=0)
            mmap = np.where(cmap > 0, s.sum(axis=0) / cmap, np.nan)
        ok = (c >= min_impacts) & np.isfinite(gam) & np.isfinite(T) & (phi >= min_sf)
        ip, ia, ib = np.nonzero(ok)
        points = {"x": x[ia], "z": z[ib], "phase": np.asarray(pf["phase"].values)[ip],
                  "count": c[ok], "mean_speed": mean[ok], "shear_rate": gam[ok],
                  "temperature": T[ok], "solid_fraction": phi[ok]}
        fit_g = weighted_linear_fit(d * gam[ok], mean[ok], c[ok])
        fit_t = weighted_linear_fit(np.sqrt(T[ok]), mean[ok], c[ok], intercept=False)
        if loo is not None:
            jackknife_of_refits({"g": fit_g, "t": fit_t},
                                _fine_refit(counts[name], loo, shape, d, min_impacts, min_sf),
                                nb, counts[name].bed_means_without())
        fit_t["maxwell"] = MAXWELL[name]
        out[name] = {"count": int(c.sum()), "mean_normal_speed": float(s.sum() / c.sum()),
                     "histogram": {"edges": edges, "counts": hist[name]},
                     "map": {"x": x, "z": z, "count": cmap, "mean_speed": mmap},
                     "cells": points, "fit_shear_rate": fit_g, "fit_temperature": fit_t}
    dense = np.isfinite(gam) & np.isfinite(T) & (phi >= max(min_sf, 0.3))
    out["bagnold"] = weighted_linear_fit(d * gam[dense], np.sqrt(T[dense]), phi[dense],
                                         intercept=False)
    return out


def _fine_refit(counts: BatchCounts, loo, shape, d: float, min_impacts: int, min_sf: float):
    """refit(b) of _relations' two fits without batch b (jackknife_of_refits)."""
    def refit(b):
        c, mean = counts.without(b, shape)
        gam = np.asarray(loo["shear_rate"].values[b], float)
        T = np.asarray(loo["temperature"].values[b], float)
        phi = np.asarray(loo["solid_fraction"].values[b], float)
        ok = (c >= min_impacts) & np.isfinite(gam) & np.isfinite(T) & (phi >= min_sf)
        return {"g": weighted_linear_fit(d * gam[ok], mean[ok], c[ok]),
                "t": weighted_linear_fit(np.sqrt(T[ok]), mean[ok], c[ok], intercept=False)}
    return refit


def jackknife_of_batches_fit(fit: dict, c, total, c_b, sum_b, shear, d: float, min_impacts: int,
                             min_sf: float) -> dict:
    """c0_stderr, c1_stderr and c0_c1_covariance of impact_relations_on_cells' fit as the
    delete-one-batch jackknife: the fit made again without batch b's impacts (counts
    c - c_b[b], speed sums total - sum_b[b], each (n_phases, nz, nx)) on the phase fields
    without batch b (PhaseShear.loo_*); the points' own errors kept as c0_stderr_points,
    c1_stderr_points, c0_c1_covariance_points; c0_measured_covariance and
    c1_measured_covariance with the mean of the impacts binned, and the refits' c0_left_out and
    c1_left_out (jackknife_of_refits).  Without two batches (or when a fit without one fails)
    the jackknife errors are NaN."""
    nb = 0 if shear.loo_phase_shear_rate is None else c_b.shape[0]

    def refit(b):
        ck = c - c_b[b]
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = np.where(ck > 0, (total - sum_b[b]) / ck, np.nan)
        rate = shear.loo_phase_shear_rate[b]
        ok = (ck >= min_impacts) & np.isfinite(rate) & (shear.loo_phase_solid_fraction[b] >= min_sf)
        return {"fit": weighted_linear_fit(d * rate[ok], mean[ok], ck[ok])}

    n_left = c.sum() - c_b.reshape(c_b.shape[0], -1).sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        measured = (total.sum() - sum_b.reshape(sum_b.shape[0], -1).sum(axis=1)) / n_left
    fits = {"fit": dict(fit)}
    jackknife_of_refits(fits, refit, nb, measured)
    return {key: fits["fit"][key] for key in (
        "c0_stderr", "c1_stderr", "c0_c1_covariance", "c0_stderr_points", "c1_stderr_points",
        "c0_c1_covariance_points", "stderr_batches", "c0_measured_covariance",
        "c1_measured_covariance", "c0_left_out", "c1_left_out") if key in fits["fit"]}


def impact_relations_on_cells(run, cell_size: float | None = None,
                              min_impacts: int = MIN_IMPACTS_PER_CELL,
                              min_solid_fraction: float = 0.1, chunk: int = 2_000_000) -> dict:
    """The impact relation v = c0 + c1 d gamma_dot fitted against the shear rate *as a
    continuum run measures it*: the phase-resolved velocity field of the DEM's snapshots on the
    analysis cells' centres (vibroflow.measure.phase_shear, the same code the continuum
    drivers use on their samples), not the 5 mm coarse-grained field of `impact_relations`.

    Why: the fine field resolves the one-to-two-diameter slip layer at the wall, where its shear
    rate is 4 - 5 1/s against 1.6 - 1.9 in the bed (tub47); a continuum on a grid of three
    diameters cannot, so the fine relation applied to a continuum's shear rate would predict
    ball-wall impacts at less than half the DEM's speed.  Fitting on the continuum's own
    measure makes the inference like for like: a continuum whose flow is the DEM's infers the
    DEM's mean impact speeds.

    Impacts of the averaging window are binned by phase bin and by the node nearest their
    contact point; a (phase, node) point enters the fit with at least `min_impacts` impacts and
    solid fraction at least `min_solid_fraction`, weighted by its count.  The points are not
    independent: one batch's cycles move the shear rate and the impact speeds of many points
    together.  So c0_stderr and c1_stderr are the delete-one-batch jackknife (measure.stats.
    jackknife_stderr) of the fit made again on every batch of whole cycles but one, the
    impacts and the phase fields alike; c0_stderr_points and c1_stderr_points keep
    weighted_linear_fit's, which treats the points as independent.  Returns {kind: fit
    (weighted_linear_fit's keys, c0 in m/s, with the measured mean_normal_speed and the
    mean_normal_speed_solid_weighted that a continuum's bed or near-wall mean stands for),
    "cell_size_m", "bed_mean_shear_rate_1_s",
    "near_wall_shear_rate_1_s" (the DEM's own values of the continuum's two measures, with
    their standard errors)}."""
    own = not isinstance(run, DEMResult)
    res = DEMResult.open(run) if own else run
    try:
        sc = res.scenario
        geo = geometry_of(sc)
        f = res.file
        shear = phase_shear_of_snapshots(
            sc, f["snapshots/position"], f["snapshots/velocity"], f["snapshots/tub_pose"][()],
            4.0 / 3.0 * math.pi * res.radius**3, res.times, cell_size, min_solid_fraction,
            leave_one_out=True)
        h, n_ph = shear.h, shear.phase_shear_rate.shape[0]
        nz, nx = shear.shear_rate.shape
        nxh = (nx - 1) // 2
        d = res.diameter
        out: dict = {"cell_size_m": h}
        m, se = shear.weighted_mean()
        near = near_wall_nodes(shear, geo.radius)
        mw, sew = shear.weighted_mean(near)
        out.update(bed_mean_shear_rate_1_s=m, bed_mean_shear_rate_1_s_stderr=se,
                   bed_roll_shear_rate_1_s=shear.roll_mean(),
                   near_wall_shear_rate_1_s=mw, near_wall_shear_rate_1_s_stderr=sew)
        ncell = n_ph * nz * nx
        loo = shear.loo_phase_shear_rate
        nb = 0 if loo is None else loo.shape[0]
        counts = {name: BatchCounts(ncell, nb) for name in KINDS}
        for kind, speed, pos, ph, batch in window_impacts(res, n_ph, chunk, with_batch=True):
            i = np.floor(pos[:, 0] / h + 0.5).astype(np.int64) + nxh
            k = np.floor(pos[:, 2] / h + 0.5).astype(np.int64)
            inside = (i >= 0) & (i < nx) & (k >= 0) & (k < nz)
            flat = (ph * nz + k) * nx + i
            for name, code in KINDS.items():
                sel = (kind == code) & inside
                counts[name].add(flat[sel], speed[sel], batch[sel])
        for name in KINDS:
            cs = counts[name]
            c = cs.count.reshape(n_ph, nz, nx)
            if c.sum() == 0:
                out[name] = None
                continue
            total = cs.total.reshape(c.shape)
            with np.errstate(invalid="ignore", divide="ignore"):
                mean = np.where(c > 0, total / c, np.nan)
            phi = shear.phase_solid_fraction
            ok = (c >= min_impacts) & np.isfinite(shear.phase_shear_rate) & (
                phi >= min_solid_fraction)
            fit = weighted_linear_fit(d * shear.phase_shear_rate[ok], mean[ok], c[ok])
            fit.update(jackknife_of_batches_fit(fit, c, total, cs.count_b.reshape((nb,) + c.shape),
                                                cs.total_b.reshape((nb,) + c.shape), shear, d,
                                                min_impacts, min_solid_fraction))
            fit["count"] = int(c.sum())
            fit["mean_normal_speed"] = float(total.sum() / c.sum())
            # the mean a continuum's inference stands for: each node's mean impact speed,
            # weighted by its solid fraction over the bed (ball-ball) or the near-wall nodes
            # (ball-wall), where the measured mean weights every impact alike
            c_node = c.sum(axis=0)
            with np.errstate(invalid="ignore", divide="ignore"):
                v_node = total.sum(axis=0) / c_node
            region = (near if name == "ball_wall" else np.ones_like(near)) & (
                c_node >= min_impacts) & (shear.solid_fraction > 0)
            w = shear.solid_fraction[region]
            fit["mean_normal_speed_solid_weighted"] = (
                float(np.sum(w * v_node[region]) / np.sum(w)) if w.size else float("nan"))
            out[name] = fit
        return out
    finally:
        if own:
            res.close()
