"""The report's "Impact speed distributions": the DEM's impact speeds by kind as histograms with
their median and 95th percentile, the ball-wall impacts along the U and on the partitions
(vibroflow.analysis.impact_stats), and each continuum's inferred speed set against the DEM's
measured one, flagged beyond a quarter (impact_stats.speed_flag).

dem.h5's impacts are read in slices (a tub47 run holds tens of millions); the figures are PNG
bytes (matplotlib, Agg).  Units: SI (m, s, m/s, 1/(m^2 s)).
"""
from __future__ import annotations

import math

import h5py
import numpy as np

from vibroflow.analysis.impact_stats import (SPEED_EDGES_M_S, ImpactDistributions,
                                             impact_distributions,
                                             relative_difference_stderr, same_measured_mean,
                                             speed_flag)
from vibroflow.io.pictures import pyplot
from vibroflow.measure.contacts import mean_speed_stderr
from vibroflow.numbers import number_or_nan
from vibroflow.report.data import DEM, MIN_IMPACTS_PER_CELL, StudyData
from vibroflow.report.figures import (inferred_impact_speed_covariances,
                                      inferred_impact_speed_errors, inferred_impact_speeds,
                                      png_bytes)

#: the kinds drawn and tabled, as the page names them (IMPACT_KINDS' names)
KIND_LABELS = {"ball_ball": "ball-ball", "ball_wall": "ball-U wall",
               "ball_partition": "ball-partition", "plane_wall": "ball-plane"}
#: what the summary's ball-wall speed is (kind 1, the U)
SUMMARY_KINDS = {"ball_ball": "ball-ball", "ball_wall": "ball-U wall"}
#: fine speed bins merged into one drawn bin (25 of 500 a decade: 20 a decade)
DRAWN_BIN = 25
COLOURS = {"ball_ball": "C0", "ball_wall": "C3", "ball_partition": "C2", "plane_wall": "C4"}


def read_distributions(data: StudyData) -> tuple[ImpactDistributions | None, str | None]:
    """The DEM's impacts of the averaging window's whole cycles as distributions, or None and
    why (no dem.h5, no impacts, unreadable)."""
    h5 = data.out / DEM / "dem.h5"
    if not h5.is_file():
        return None, f"no {DEM}/dem.h5: no measured impacts"
    if data.scenario.tub is None:
        return None, "the scenario has no tub: no U to map the impacts on"
    run = data.scenario.run
    try:
        with h5py.File(h5, "r") as f:
            if "impacts/time" not in f or f["impacts/time"].shape[0] == 0:
                return None, ("the DEM result holds no impacts (a LIGGGHTS import does not "
                              "report them)")
            g = f["impacts"]
            return impact_distributions(
                g["time"], g["kind"], g["position_tub"], g["normal_speed"],
                t_start=run.duration - run.average_last, t_end=run.duration,
                frequency=float(data.scenario.motion.frequency), n_batches=int(run.batches),
                geometry=data.geometry, bin_width=float(data.scenario.analysis.cell_size)), None
    except (OSError, KeyError, ValueError) as exc:
        return None, f"{h5}: impacts unreadable ({type(exc).__name__}: {exc})"


def speed_histograms(dist: ImpactDistributions) -> bytes:
    """Probability density of the normal impact speed per unit ln v, by kind, on a log speed
    axis, with the median (dashed) and 95th percentile (dotted) of each."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(8.0, 4.2))
    edges = SPEED_EDGES_M_S[1::DRAWN_BIN]
    for name, label in KIND_LABELS.items():
        st = dist.stats[name]
        if st.count == 0:
            continue
        total = dist.histograms[name].sum(axis=0)
        # the first fine bin is [0, 1e-6 m/s]: left out of the log axis
        c = np.add.reduceat(total[1:], np.arange(0, total.size - 1, DRAWN_BIN))[:edges.size - 1]
        dens = c / (st.count * np.diff(np.log(edges)))
        keep = np.nonzero(c)[0]
        if keep.size == 0:
            continue
        lo, hi = keep.min(), keep.max() + 1
        off = int(total[0])  # [0, 1e-6] m/s: counted, off the log axis
        ax.stairs(dens[lo:hi], edges[lo:hi + 1], color=COLOURS[name],
                  label=f"{label} ({st.count} impacts"
                  + (f", {off} of them below {edges[0]:.0e} m/s, not drawn)" if off else ")"))
        for q, ls in ((st.median, "--"), (st.p95, ":")):
            if q >= edges[0]:
                ax.axvline(q, color=COLOURS[name], ls=ls, lw=1.1)
    ax.set_xscale("log")
    ax.set_xlabel("normal approach speed v (m/s)")
    ax.set_ylabel("probability density per unit ln v (1)")
    ax.set_title("DEM impact speeds in the averaging window: median dashed, 95th percentile "
                 "dotted", fontsize=9)
    ax.legend(fontsize=8)
    return png_bytes(fig)


def wall_map(dist: ImpactDistributions) -> bytes:
    """Ball-wall impacts along the U (against the arc length s from the bottom, + towards +x)
    and on the partitions (against the height z): the rate per unit wall area, and the mean and
    95th percentile normal speed, with their batch-means standard errors as error bars."""
    plt = pyplot()
    fig, axes = plt.subplots(2, 2, figsize=(11.0, 6.4), sharex="col")
    for col, (prof, where) in enumerate(((dist.u, "U wall"), (dist.partitions, "partitions"))):
        x = prof.centres
        top, bottom = axes[0, col], axes[1, col]
        if prof.count.sum() == 0:
            top.text(0.5, 0.5, f"no impacts on the {where}", ha="center",
                     transform=top.transAxes)
        top.errorbar(x, prof.rate, yerr=prof.rate_stderr, fmt="o-", ms=3, color="C3")
        top.set_ylabel("impact rate per wall area (1/(m² s))")
        top.set_title(f"{where}: impacts per unit area and time", fontsize=9)
        bottom.errorbar(x, prof.mean, yerr=prof.mean_stderr, fmt="o-", ms=3, color="C0",
                        label="mean")
        bottom.errorbar(x, prof.p95, yerr=prof.p95_stderr, fmt="s--", ms=3, color="C1",
                        label="95th percentile")
        bottom.set_ylabel("normal impact speed (m/s)")
        bottom.set_xlabel(prof.coordinate)
        bottom.legend(fontsize=8)
        for ax in (top, bottom):
            ax.grid(alpha=0.3)
    fig.suptitle("DEM ball-wall impacts of the averaging window "
                 f"({dist.seconds:.3g} s, {dist.n_batches} batches)", fontsize=10)
    fig.tight_layout()
    return png_bytes(fig)


def inferred_from(impacts: dict) -> list[str]:
    """What a method's summary `impacts` block says its mean speeds are inferred from: "shear
    rate" (continuum.shear_outputs), "granular temperature" (continuum.temperature_impacts,
    where the calibration prefers T and the run carries it; one kind or both), or nothing (a
    DEM's measured impacts)."""
    return [source for key, source in (("inferred_from_shear_rate", "shear rate"),
                                       ("inferred_from_temperature", "granular temperature"))
            if impacts.get(key)]


def measured_covariance(impacts: dict, kind: str, measured: float) -> float | None:
    """The covariance (m^2/s^2) of a continuum's inferred KIND mean speed with the DEM's
    measured one, `measured` (m/s), where its relation was calibrated on that DEM run: the
    summary's KIND_mean_normal_speed_relation_measured_covariance, when the mean its
    calibration measured (_relation_measured_mean) is `measured` (same_measured_mean).  None
    otherwise: the two are independent."""
    own = number_or_nan(impacts.get(f"{kind}_mean_normal_speed_relation_measured_mean"))
    cov = number_or_nan(impacts.get(f"{kind}_mean_normal_speed_relation_measured_covariance"))
    return cov if math.isfinite(cov) and same_measured_mean(own, measured) else None


def speed_comparisons(data: StudyData) -> list[dict]:
    """Each continuum's inferred impact speed against the DEM's measured one: the bed means of
    the summary (ball-ball, ball-U wall; inferred from the shear rate or the granular
    temperature, as the run's summary says) and the ball-ball speed in each probe's cell, from
    its shear rate (the DEM's when the cell holds at least MIN_IMPACTS_PER_CELL impacts).  A
    dict a row: where, kind, method, measured, measured_stderr, inferred, inferred_stderr (m/s:
    the run's error and the calibrated relation's, measure.contacts.mean_speed_stderr),
    relative (the relative difference), relative_stderr (its error from the two speeds', less
    their covariance where the relation was calibrated on this DEM run: measured_covariance for
    a bed mean, figures.inferred_impact_speed_covariances for a probe cell) and flagged (True,
    False or None when not comparable)."""
    dem = (data.summary["methods"].get(DEM) or {}).get("impacts") or {}
    rows = []
    for name in data.continuum_methods:
        im = data.summary["methods"][name].get("impacts") or {}
        if not inferred_from(im):
            continue
        for key, label in SUMMARY_KINDS.items():
            m, i = number_or_nan(dem.get(f"{key}_mean_normal_speed")), number_or_nan(
                im.get(f"{key}_mean_normal_speed"))
            rel, flag = speed_flag(i, m)
            sm = number_or_nan(dem.get(f"{key}_mean_normal_speed_stderr"))
            si = mean_speed_stderr(im, key)
            rows.append({"where": "bed mean", "kind": label, "method": name, "measured": m,
                         "measured_stderr": sm, "inferred": i, "inferred_stderr": si,
                         "relative": rel,
                         "relative_stderr": relative_difference_stderr(
                             i, si, m, sm, measured_covariance(im, key, m)),
                         "flagged": flag})
        if data.impacts is None:
            continue
        inferred = inferred_impact_speeds(data, name)
        errors = inferred_impact_speed_errors(data, name)
        covariances = inferred_impact_speed_covariances(data, name)
        for probe, p in data.scenario.analysis.probes.items():
            v, count = data.impacts.at(p.x, p.z)
            m = v if count >= MIN_IMPACTS_PER_CELL else math.nan
            i = number_or_nan(inferred.get(probe))
            rel, flag = speed_flag(i, m)
            se = data.impacts.stderr_at(p.x, p.z) if count >= MIN_IMPACTS_PER_CELL else math.nan
            si = number_or_nan(errors.get(probe))
            rows.append({"where": f"probe {probe} cell", "kind": "ball-ball", "method": name,
                         "measured": m, "measured_stderr": se, "inferred": i,
                         "inferred_stderr": si, "relative": rel,
                         "relative_stderr": relative_difference_stderr(
                             i, si, m, se, covariances.get(probe)),
                         "flagged": flag})
    return rows


def impact_distribution_section(data: StudyData) -> dict:
    """What the section shows: the two figures (PNG bytes, None without measured impacts), the
    statistics by kind (SpeedStats, kinds with impacts only), the comparisons
    (speed_comparisons), why a piece is missing, and `below`: the impacts in the lowest speed
    bin [0, lowest_edge] m/s, counted in the statistics but off the histograms' log axis."""
    dist, why = read_distributions(data)
    out = {"why": why, "histograms": None, "wall_map": None, "stats": [],
           "comparisons": speed_comparisons(data)}
    if dist is not None:
        out.update(histograms=speed_histograms(dist), wall_map=wall_map(dist),
                   stats=[(KIND_LABELS[k], s) for k, s in dist.stats.items() if s.count > 0],
                   seconds=dist.seconds, n_batches=dist.n_batches,
                   below=int(sum(int(h[:, 0].sum()) for h in dist.histograms.values())),
                   lowest_edge=float(SPEED_EDGES_M_S[1]))
    return out
