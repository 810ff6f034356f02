"""Impact speeds from the granular temperature against impact speeds from the shear rate: which
relation the DEM supports (docs/decisions/impact-speed.md).

Kinetic theory (smooth spheres, Maxwellian velocities of temperature T, each component of
variance T; Chapman & Cowling 1970, The Mathematical Theory of Non-uniform Gases, ch. 16;
Brilliantov & Poeschel 2004, Kinetic Theory of Granular Gases, ch. 3): two balls collide at
the rate (g . k) Theta(g . k) per pair and unit solid angle of the normal k, g = v_i - v_j.  The
relative velocity is Maxwellian of variance 2T per component, so its normal component g_n is
N(0, 2T), and weighted by the rate the colliding pairs' g_n has the density
g_n exp(-g_n^2 / 4T) / (2T) on g_n > 0: a Rayleigh distribution of scale s = sqrt(2T).  Hence
    mean normal impact speed  s sqrt(pi/2) = sqrt(pi T)              (1.772 sqrt(T)),
    its p-quantile            s sqrt(-2 ln(1 - p)); p95 = 2 sqrt(T ln 20)   (3.462 sqrt(T)).
A ball striking a wall at rest: c_n is N(0, T), weighted by c_n on c_n > 0, a Rayleigh of scale
sqrt(T): mean sqrt(pi T / 2), p95 sqrt(2 T ln 20).  (The mean |g_n| of random pairs, not
weighted by their collision rate, would be 2 sqrt(T / pi): collisions select fast pairs.)

The DEM's test: the impacts of the averaging window binned by phase bin and grid point of the
phase-resolved coarse-grained fields (as impacts.impact_relations), and per (phase, point) with
at least `min_impacts` impacts the mean and the 95th percentile of the normal speed, set
against sqrt(T) (v = a sqrt(T), and v = b0 + b1 sqrt(T)) and against d gamma_dot (v = c0 + c1
d gamma_dot) on the same points, each fit weighted by the counts: R^2, relative rms error and
the per-point residuals (the share of points whose prediction lies within 0.8 - 1.25 of the
measured value, and the median |ln(predicted / measured)|).
"""
from __future__ import annotations

import math

import numpy as np

from .dem_result import DEMResult
from .impacts import (KINDS, MIN_IMPACTS_PER_CELL, BatchCounts, jackknife_of_refits,
                      weighted_linear_fit, window_impacts)

#: mean and p95 of the normal impact speed over sqrt(T) for Maxwellian balls (module notes)
MAXWELL_MEAN = {"ball_ball": math.sqrt(math.pi), "ball_wall": math.sqrt(math.pi / 2.0)}
MAXWELL_P95 = {"ball_ball": 2.0 * math.sqrt(math.log(20.0)),
               "ball_wall": math.sqrt(2.0 * math.log(20.0))}
N_SPEED_BINS = 240
#: the histograms' lowest edge (m/s); the bins are geometric up to twice the window's p99.9
SPEED_FLOOR = 1e-4


def maxwellian_impact_speed(T, kind: str = "ball_ball", quantile: float | None = None):
    """The mean (quantile None) or the `quantile` of the normal impact speed (m/s) of
    Maxwellian balls at temperature T (m^2/s^2): ball_ball against each other, ball_wall against
    a wall at rest (module notes)."""
    T = np.asarray(T, float)
    scale = np.sqrt((2.0 if kind == "ball_ball" else 1.0) * T)
    if quantile is None:
        return scale * math.sqrt(math.pi / 2.0)
    return scale * math.sqrt(-2.0 * math.log(1.0 - quantile))


def _quantile_of_histograms(h, edges, q):
    """The q-quantile of each row of histograms h (n, bins), linear within a bin."""
    c = np.cumsum(h, axis=1)
    tot = c[:, -1:]
    target = q * tot
    k = np.argmax(c >= target, axis=1)
    before = np.where(k > 0, np.take_along_axis(c, np.maximum(k - 1, 0)[:, None], 1)[:, 0], 0.0)
    inbin = np.take_along_axis(h, k[:, None], 1)[:, 0]
    frac = np.where(inbin > 0, (target[:, 0] - before) / np.where(inbin > 0, inbin, 1.0), 0.0)
    return edges[k] + frac * (edges[k + 1] - edges[k])


def _residuals(pred, meas, w):
    with np.errstate(invalid="ignore", divide="ignore"):
        r = pred / meas
    ok = np.isfinite(r) & (r > 0)
    if not np.sum(w[ok]) > 0:  # no cell to judge on (a short run): unknown, not 0/0
        return {"within_0_8_1_25": math.nan, "median_abs_log_ratio": math.nan}
    inside = (r[ok] >= 0.8) & (r[ok] <= 1.25)
    return {"within_0_8_1_25": float(np.sum(w[ok] * inside) / np.sum(w[ok])),
            "median_abs_log_ratio": float(np.median(np.abs(np.log(r[ok]))))}


def _fits(y, sqrtT, dg, w):
    out = {}
    for tag, x, icpt in (("temperature", sqrtT, False), ("temperature_affine", sqrtT, True),
                         ("shear_rate", dg, True)):
        f = weighted_linear_fit(x, y, w, intercept=icpt)
        f.update(_residuals(f["c0"] + f["c1"] * x, y, w))
        out[tag] = f
    return out


def compare_impact_relations(run, phase_fields, min_impacts: int = MIN_IMPACTS_PER_CELL,
                             min_solid_fraction: float = 0.1, chunk: int = 2_000_000,
                             leave_one_out=None) -> dict:
    """The mean and p95 impact speeds of each (phase, point) against sqrt(T) and d gamma_dot
    (module notes).  run: DEMResult, run directory or dem.h5; phase_fields: the phase-resolved
    Dataset of run_fields.coarse_grain_run; leave_one_out: the same fields of every batch but
    one (run_fields.leave_one_out_dataset, on the same points: on_nodes applies to it too), with
    which the mean's fits carry the delete-one-batch jackknife's c0_stderr and c1_stderr
    (impacts.jackknife_of_refits; the points' own errors as c0_stderr_points, c1_stderr_points).

    Returns {kind: None (no impacts) or {points, count, maxwell_mean, maxwell_p95, cells
    {sqrt_T, d_gamma_dot, mean, p95, count: one value a (phase, point)},
    mean {temperature {c1 = a, ...}, temperature_affine {c0, c1}, shear_rate {c0 m/s, c1}},
    p95 {the same}, each fit with weighted_linear_fit's keys plus within_0_8_1_25 and
    median_abs_log_ratio, winner ("temperature" or "shear_rate": the higher R^2 of the mean
    among the shear rate and the temperature's better form)}, "diameter": d}."""
    own = not isinstance(run, DEMResult)
    res = DEMResult.open(run) if own else run
    try:
        return _compare(res, phase_fields, min_impacts, min_solid_fraction, chunk,
                        leave_one_out)
    finally:
        if own:
            res.close()


def on_nodes(phase_fields, cell_size: float):
    """The phase-resolved fields at the analysis cells' centres (multiples of cell_size, m), the
    nodes a continuum run measures on: impacts binned on them go to the nearest node, so the
    fits of compare_impact_relations on this Dataset are the continuum's like-for-like
    relations (as impacts.impact_relations_on_cells is for the shear rate)."""
    def at(v):
        v = np.asarray(v, float)
        k = v / cell_size
        return v[np.abs(k - np.round(k)) < 1e-6]
    return phase_fields.sel(x=at(phase_fields["x"].values), z=at(phase_fields["z"].values))


def _compare(res, pf, min_impacts, min_sf, chunk, loo=None):
    d = res.diameter
    x = np.asarray(pf["x"].values, float)
    z = np.asarray(pf["z"].values, float)
    n_ph = int(pf.sizes["phase"])
    h = float(x[1] - x[0])
    gam = np.asarray(pf["shear_rate"].values, float).ravel()
    T = np.asarray(pf["temperature"].values, float).ravel()
    phi = np.asarray(pf["solid_fraction"].values, float).ravel()
    ncell = n_ph * x.size * z.size
    out: dict = {"diameter": d}
    nb = 0 if loo is None else int(loo.sizes["batch"])
    counts = {k: BatchCounts(ncell, nb) for k in KINDS}
    hist: dict = {k: {} for k in KINDS}
    edges = None
    for kind, speed, pos, ph, batch in window_impacts(res, n_ph, chunk, with_batch=True):
        if edges is None:
            top = 2.0 * float(np.percentile(speed, 99.9)) if speed.size else 1.0
            edges = np.concatenate([[0.0], np.geomspace(SPEED_FLOOR, max(top, 2 * SPEED_FLOOR),
                                                        N_SPEED_BINS)])
        ia = np.floor((pos[:, 0] - x[0]) / h + 0.5).astype(np.int64)
        ib = np.floor((pos[:, 2] - z[0]) / h + 0.5).astype(np.int64)
        inside = (ia >= 0) & (ia < x.size) & (ib >= 0) & (ib < z.size)
        flat = (ph * x.size + ia) * z.size + ib
        sb = np.clip(np.searchsorted(edges, speed, side="right") - 1, 0, N_SPEED_BINS - 1)
        for name, code in KINDS.items():
            sel = (kind == code) & inside
            counts[name].add(flat[sel], speed[sel], batch[sel])
            # histograms per (phase, point), kept only where impacts fall (sparse rows)
            cells, inv = np.unique(flat[sel], return_inverse=True)
            hc = np.zeros((cells.size, N_SPEED_BINS), np.float32)
            np.add.at(hc, (inv, sb[sel]), 1.0)
            store = hist[name]
            for c, row in zip(cells.tolist(), hc):
                if c in store:
                    store[c] += row
                else:
                    store[c] = row
    for name in KINDS:
        c = counts[name].count
        ok = (c >= min_impacts) & np.isfinite(gam) & np.isfinite(T) & (T > 0) & (phi >= min_sf)
        idx = np.nonzero(ok)[0]
        if idx.size < 3:
            out[name] = None
            continue
        mean = counts[name].total[idx] / c[idx]
        p95 = _quantile_of_histograms(np.stack([hist[name][int(i)] for i in idx]).astype(float),
                                      edges, 0.95)
        rec = relations_of_points(mean, p95, T[idx], gam[idx], c[idx], d, name)
        if loo is not None:
            jackknife_of_refits(rec["mean"], _refit(counts[name], loo, min_impacts, min_sf, d),
                                nb, counts[name].bed_means_without())
        rec["count"] = int(c.sum())
        out[name] = rec
    return out


def _refit(counts: BatchCounts, loo, min_impacts: int, min_sf: float, d: float):
    """refit(b): the mean's three fits (_fits) without batch b, on the fields without it."""
    def refit(b):
        c, mean = counts.without(b, (counts.ncell,))
        gam = np.asarray(loo["shear_rate"].values[b], float).ravel()
        T = np.asarray(loo["temperature"].values[b], float).ravel()
        phi = np.asarray(loo["solid_fraction"].values[b], float).ravel()
        ok = (c >= min_impacts) & np.isfinite(gam) & np.isfinite(T) & (T > 0) & (phi >= min_sf)
        return _fits(mean[ok], np.sqrt(T[ok]), d * gam[ok], c[ok])
    return refit


def relations_of_points(mean, p95, T, shear_rate, count, diameter: float,
                        kind: str = "ball_ball") -> dict:
    """The fits of compare_impact_relations on given points: mean and p95 impact speeds (m/s),
    temperatures T (m^2/s^2), shear rates (1/s) and impact counts (the weights), d (m)."""
    w = np.asarray(count, float)
    sT = np.sqrt(np.asarray(T, float))
    dg = diameter * np.asarray(shear_rate, float)
    rec = {"points": int(w.size), "maxwell_mean": MAXWELL_MEAN[kind],
           "maxwell_p95": MAXWELL_P95[kind],
           "mean": _fits(np.asarray(mean, float), sT, dg, w),
           "p95": _fits(np.asarray(p95, float), sT, dg, w),
           "cells": {"sqrt_T": sT, "d_gamma_dot": dg, "mean": np.asarray(mean, float),
                     "p95": np.asarray(p95, float), "count": w}}
    m = rec["mean"]
    r2_T = max(m["temperature"]["r2"], m["temperature_affine"]["r2"])
    rec["winner"] = "temperature" if r2_T > m["shear_rate"]["r2"] else "shear_rate"
    return rec


AFFINE_MODEL = "v = max(b0 + b1 sqrt(T), 0) (m/s), T the phase-resolved granular temperature"


def _measured_covariance_keys(fit: dict, tag: str) -> dict:
    """The affine relation's b0 and b1 covariances with the DEM's measured mean speed
    (m^2/s^2, m/s; impacts.jackknife_of_refits), tag after "temperature" in each name."""
    nan = float("nan")
    return {f"b0_temperature{tag}_measured_covariance_m2_s2": fit.get("c0_measured_covariance",
                                                                       nan),
            f"b1_temperature{tag}_measured_covariance_m_s": fit.get("c1_measured_covariance",
                                                                     nan)}


def temperature_relation_keys(rec: dict, rec_cells: dict | None = None,
                              r2_shear_cells: float | None = None) -> dict:
    """The keys compare_impact_relations' record `rec` of one kind adds to calibration.toml's
    [impacts.KIND] (io.calibration_file.ImpactRelation): the affine relation of the mean,
    b0 (m/s) and b1, the p95 relations, the R^2 and the share within 0.8 - 1.25 of each form;
    from `rec_cells` (the same on the analysis cells' centres, on_nodes) the affine relation a
    continuum uses, b0_temperature_cells_m_s and b1_temperature_cells, and preferred_relation:
    "temperature" where its R^2 on the cells beats the shear rate's on the continuum's measure
    (r2_shear_cells, impacts.impact_relations_on_cells), else "shear_rate" (without the cells'
    fits, the winner on the fine points)."""
    m, q = rec["mean"], rec["p95"]
    ta, sr, t1 = m["temperature_affine"], m["shear_rate"], m["temperature"]
    out = {}
    winner = rec["winner"]
    if rec_cells is not None:
        tc = rec_cells["mean"]["temperature_affine"]
        out = {"b0_temperature_cells_m_s": tc["c0"], "b0_temperature_cells_stderr_m_s":
               tc["c0_stderr"], "b1_temperature_cells": tc["c1"],
               "b1_temperature_cells_stderr": tc["c1_stderr"],
               "b0_b1_temperature_cells_covariance_m_s": tc.get("c0_c1_covariance",
                                                                 float("nan")),
               **_measured_covariance_keys(tc, "_cells"),
               "r2_temperature_affine_cells": tc["r2"], "points_temperature_cells":
               tc["points"]}
        if r2_shear_cells is not None and math.isfinite(r2_shear_cells):
            winner = "temperature" if tc["r2"] > r2_shear_cells else "shear_rate"
    return {**out, "b0_temperature_m_s": ta["c0"], "b0_temperature_stderr_m_s": ta["c0_stderr"],
            "b1_temperature": ta["c1"], "b1_temperature_stderr": ta["c1_stderr"],
            "b0_b1_temperature_covariance_m_s": ta.get("c0_c1_covariance", float("nan")),
            **_measured_covariance_keys(ta, ""),
            "r2_temperature_affine": ta["r2"],
            "within_0_8_1_25_temperature": t1["within_0_8_1_25"],
            "within_0_8_1_25_temperature_affine": ta["within_0_8_1_25"],
            "within_0_8_1_25_shear_rate": sr["within_0_8_1_25"],
            "p95_a_temperature": q["temperature"]["c1"],
            "p95_a_maxwellian": rec["maxwell_p95"],
            "p95_r2_temperature": q["temperature"]["r2"],
            "p95_b0_temperature_m_s": q["temperature_affine"]["c0"],
            "p95_b1_temperature": q["temperature_affine"]["c1"],
            "p95_r2_temperature_affine": q["temperature_affine"]["r2"],
            "p95_c0_m_s": q["shear_rate"]["c0"], "p95_c1": q["shear_rate"]["c1"],
            "p95_r2_shear_rate": q["shear_rate"]["r2"],
            "preferred_relation": winner}
