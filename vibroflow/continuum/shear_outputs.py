"""The shear rate a continuum tub run reports and what it implies through the calibrated
relations: the summary's shear-rate block (`shear_rate_outputs`), the impact speeds and
granular temperature of calibration.toml [impacts] (`impact_relation`) and the shear-rate map
shear_rate.csv (`write_shear_rate_csv`)."""
from __future__ import annotations

import math
from pathlib import Path
from typing import NamedTuple

import numpy as np

from vibroflow.io.atomic import write_text_atomic
from vibroflow.io.calibration_file import Calibration, ImpactRelation
from vibroflow.measure.phase_shear import PhaseShear, near_wall_nodes
from vibroflow.measure.stats import (affine_prediction_covariance, affine_prediction_stderr,
                                     batch_means)
from vibroflow.numbers import number_or_nan

from .sampling import Samples

def write_shear_rate_csv(path: Path, samples: Samples, phase: PhaseShear | None,
                         calibration: Calibration | None, diameter: float) -> None:
    """The continuum's cycle-mean shear-rate map on the analysis cells (the DEM's cells), with
    the impact speeds it implies by the calibrated v = c0 + c1 d gamma_dot ([impacts.ball_ball],
    [impacts.ball_wall] by impact_relation; empty without a calibration), atomically: columns x, z
    (m, cell centres), shear_rate (1/s, the phase-resolved field's cycle mean at the cell's
    centre, as the DEM's; shear_rate_outputs), solid_fraction (of that field),
    instantaneous_shear_rate (1/s, mean over the samples that held material in the cell of the
    points' mean there), samples (those samples), impact_ball_ball, impact_ball_wall (m/s, from
    shear_rate).  A cell is written when either rate is known there."""
    if samples.cell_grid is None:
        return
    h, nxh, nz = samples.cell_grid
    im = calibration.impacts if calibration is not None else None
    fits = [impact_relation(getattr(im, k) if im is not None else None)[:2]
            for k in ("ball_ball", "ball_wall")]
    lines = ["x,z,shear_rate,solid_fraction,instantaneous_shear_rate,samples,"
             "impact_ball_ball,impact_ball_wall"]

    def num(v):
        return repr(float(v)) if np.isfinite(v) else ""

    for k in range(nz):
        for i in range(2 * nxh + 1):
            n = samples.rate_cell_n[k, i]
            inst = float(samples.rate_cell_sum[k, i] / n) if n > 0 else float("nan")
            g = float(phase.shear_rate[k, i]) if phase is not None else float("nan")
            f = float(phase.solid_fraction[k, i]) if phase is not None else float("nan")
            if not (np.isfinite(g) or n > 0):
                continue
            v = ["" if c0 is None or not np.isfinite(g) else repr(float(c0 + c1 * diameter * g))
                 for c0, c1 in fits]
            lines.append(f"{(i - nxh) * h!r},{k * h!r},{num(g)},{num(f)},{num(inst)},{int(n)},"
                         f"{v[0]},{v[1]}")
    write_text_atomic(path, "\n".join(lines) + "\n")



class RelationKeys(NamedTuple):
    """The [impacts.KIND] keys of one fitted relation v = c0 + c1 x: its coefficients, their
    standard errors and covariance, their covariances with the DEM's measured mean speed, and
    their values with each batch left out (the jackknife's; None where not written)."""
    c0: str
    c1: str
    c0_stderr: str
    c1_stderr: str
    covariance: str
    c0_measured_covariance: str
    c1_measured_covariance: str
    c0_left_out: str | None = None
    c1_left_out: str | None = None

    @property
    def which(self) -> str:
        return f"{self.c0.removesuffix('_m_s')}, {self.c1}"


def shear_relation_keys(tag: str) -> RelationKeys:
    """The keys of v = c0 + c1 d gamma_dot, tag "_cells" (fitted on the continuum's measure of
    the shear rate) or "" (on the DEM's coarse-grained field)."""
    return RelationKeys(f"c0{tag}_m_s", f"c1{tag}", f"c0{tag}_stderr_m_s", f"c1{tag}_stderr",
                        f"c0_c1{tag}_covariance_m_s", f"c0{tag}_measured_covariance_m2_s2",
                        f"c1{tag}_measured_covariance_m_s", f"c0{tag}_left_out_m_s",
                        f"c1{tag}_left_out")


#: the two shear-rate relations of an [impacts.KIND] table, in the order impact_relation
#: prefers them
_SHEAR_RELATIONS = (shear_relation_keys("_cells"), shear_relation_keys(""))


def chosen_keys(rel, candidates) -> RelationKeys | None:
    """The first of `candidates` (RelationKeys) whose two coefficients `rel` ([impacts.KIND])
    holds finite; None if none."""
    if rel is None:
        return None
    for keys in candidates:
        if all(math.isfinite(number_or_nan(getattr(rel, k, None))) for k in (keys.c0, keys.c1)):
            return keys
    return None


def relation_errors(rel, candidates) -> tuple[float, float, float]:
    """(se of the intercept (m/s), se of the slope, their covariance (m/s)) of the relation
    `candidates` choose in `rel` (as impact_relation or temperature_impacts.temperature_relation
    choose it); NaN where the calibration holds none (an older calibration: no covariance,
    measure.stats.affine_prediction_stderr then bounds the error)."""
    keys = chosen_keys(rel, candidates)
    if keys is None:
        return math.nan, math.nan, math.nan
    return tuple(number_or_nan(getattr(rel, k, None))
                 for k in (keys.c0_stderr, keys.c1_stderr, keys.covariance))


def relation_left_out(rel, candidates) -> tuple[np.ndarray, np.ndarray] | None:
    """(c0 m/s, c1) of the relation `candidates` choose in `rel`, each batch of its DEM run
    left out in turn (the jackknife's refits, in batch order); None where the calibration holds
    none or they do not pair up."""
    keys = chosen_keys(rel, candidates)
    if keys is None or keys.c0_left_out is None:
        return None
    c0, c1 = (getattr(rel, k, None) for k in (keys.c0_left_out, keys.c1_left_out))
    if not c0 or not c1 or len(c0) != len(c1):
        return None
    return np.asarray(c0, float), np.asarray(c1, float)


def measured_covariance_keys(impacts: dict, kind: str, rel, candidates, x,
                             intercept_share: float = 1.0) -> None:
    """In place: `impacts`' KIND_mean_normal_speed_relation_measured_covariance (m^2/s^2), the
    covariance of the prediction intercept_share c0 + c1 x of the relation `candidates` choose
    in `rel` with the DEM's measured mean speed of its calibration run
    (measure.stats.affine_prediction_covariance of the calibration's *_measured_covariance_*
    keys), and KIND_mean_normal_speed_relation_measured_mean (m/s), that mean
    (rel.mean_normal_speed_m_s), by which a comparison knows the run (report.impact_figures).
    Nothing where the calibration holds neither (an older calibration)."""
    keys = chosen_keys(rel, candidates)
    if keys is None:
        return
    cov = affine_prediction_covariance(
        x, *(number_or_nan(getattr(rel, k, None))
             for k in (keys.c0_measured_covariance, keys.c1_measured_covariance)),
        intercept_share=intercept_share)
    mean = number_or_nan(getattr(rel, "mean_normal_speed_m_s", None))
    if math.isfinite(cov) and math.isfinite(mean):
        impacts[kind + "_mean_normal_speed_relation_measured_covariance"] = cov
        impacts[kind + "_mean_normal_speed_relation_measured_mean"] = mean


def impact_relation(rel: ImpactRelation | None) -> tuple[float | None, float | None, str]:
    """(c0 m/s, c1, which) of a calibration's [impacts.KIND] table: the relation fitted on the
    continuum's own measure of the shear rate (c0_cells_m_s, c1_cells;
    calibration.impacts.impact_relations_on_cells) when the calibration has it, else the one
    fitted on the DEM's 5 mm coarse-grained field (c0_m_s, c1; a calibration without it); (None,
    None, "") without either.  Its errors: impact_relation_errors."""
    keys = chosen_keys(rel, _SHEAR_RELATIONS)
    if keys is None:
        return None, None, ""
    return float(getattr(rel, keys.c0)), float(getattr(rel, keys.c1)), keys.which


def impact_relation_errors(rel: ImpactRelation | None) -> tuple[float, float, float]:
    """(se c0 m/s, se c1, cov(c0, c1) m/s) of the relation impact_relation chooses."""
    return relation_errors(rel, _SHEAR_RELATIONS)


def impact_relation_left_out(rel: ImpactRelation | None):
    """(c0 m/s, c1) of the relation impact_relation chooses with each batch left out
    (relation_left_out), or None."""
    return relation_left_out(rel, _SHEAR_RELATIONS)



def shear_rate_outputs(material, calibration: Calibration | None, probes: dict, batch,
                       n_batches, samples: Samples, phase: PhaseShear, radius_tub: float,
                       impacts: dict) -> dict:
    """Shear rate (1/s) over the bed, near the wall and in the probe cells, with batch-means
    standard errors; with a calibration, the granular temperature sqrt(T) = a d gamma_dot
    (models.md, Bagnold scaling; a from [impacts] bagnold_sqrtT_over_d_gamma_dot) and the mean
    impact speeds v = c0 + c1 d gamma_dot ([impacts.ball_ball] over the bed,
    [impacts.ball_wall] near the wall), written into the DEM's impact keys (`impacts` is
    updated in place; its counts stay 0: no impact is seen), by impact_relation: each
    KIND_mean_normal_speed_stderr is the run's batch-means error carried through the relation,
    |c1| d se(gamma_dot), and KIND_mean_normal_speed_relation_stderr the calibrated relation's
    own at that shear rate (measure.stats.affine_prediction_stderr of its coefficients' errors);
    the two are independent, so a comparison with the DEM adds them in quadrature.  The
    relation's covariance with its DEM run's measured mean is beside them
    (measured_covariance_keys): a comparison with that run's mean subtracts it.

    The shear rate is that of the phase-resolved velocity field (`phase`, the DEM
    calibration's definition, on which its impact relation was fitted; analysis.phase_shear
    says why), solid-fraction weighted over the analysis cells' centres: the bed (every node
    with material), near the wall (nodes less than a cell from the U) and each probe's cell.
    The mean of the points' instantaneous shear rates (their velocity gradients at the sampled
    instants, fluctuations included) is kept beside it as instantaneous_*."""
    d = material.diameter

    def mean_se(values):
        ok = np.isfinite(values)
        if not ok.any():
            return float("nan"), float("nan")
        return batch_means(values[ok], batch[ok], n_batches)

    near = near_wall_nodes(phase, radius_tub)
    m, se = phase.weighted_mean()
    mw, sew = phase.weighted_mean(near)
    im_, ise = mean_se(samples.rate_all)
    iw, iwse = mean_se(samples.rate_wall)
    out: dict = {"shear_rate": {
        "mean_1_s": m, "mean_1_s_stderr": se, "near_wall_1_s": mw, "near_wall_1_s_stderr": sew,
        # the slow roll's share: the shear rate of the time-averaged field (the rest of mean_1_s
        # is the bed's deformation within each cycle)
        "roll_mean_1_s": phase.roll_mean(),
        "definition": ("cycle mean of the shear rate of the phase-resolved velocity field "
                       "(averaged at each sampling phase over the window's cycles, on the "
                       "analysis cells' centres), as the DEM calibration measures it; "
                       "solid-fraction weighted"),
        "instantaneous_mean_1_s": im_, "instantaneous_mean_1_s_stderr": ise,
        "instantaneous_near_wall_1_s": iw, "instantaneous_near_wall_1_s_stderr": iwse}}
    im = calibration.impacts if calibration is not None else None
    a = im.bagnold_sqrtT_over_d_gamma_dot if im is not None else None
    out_probes = {}
    for q, (name, pr) in enumerate(probes.items()):
        k, i = phase.node_of(pr.x, pr.z)
        inside = np.zeros(phase.shear_rate.shape, bool)
        if 0 <= k < inside.shape[0] and 0 <= i < inside.shape[1]:
            inside[k, i] = True
        pm, pse = phase.weighted_mean(inside)
        qm, qse = mean_se(samples.rate_probe[:, q])
        out_probes[name] = {"shear_rate_1_s": pm, "shear_rate_1_s_stderr": pse,
                            "instantaneous_shear_rate_1_s": qm,
                            "instantaneous_shear_rate_1_s_stderr": qse,
                            "granular_temperature_m2_s2": (a * d * pm) ** 2 if a else None}
    out["probes"] = out_probes
    inferred = {}
    which = set()
    for name, rate, rate_se in (("ball_ball", m, se), ("ball_wall", mw, sew)):
        rel = getattr(im, name) if im is not None else None
        c0, c1, key = impact_relation(rel)
        if c0 is None:
            continue
        v = c0 + c1 * d * rate
        impacts[name + "_mean_normal_speed"] = v
        impacts[name + "_mean_normal_speed_stderr"] = abs(c1) * d * rate_se
        impacts[name + "_mean_normal_speed_relation_stderr"] = affine_prediction_stderr(
            d * rate, *impact_relation_errors(rel))
        measured_covariance_keys(impacts, name, rel, _SHEAR_RELATIONS, d * rate)
        inferred[name + "_mean_normal_speed_m_s"] = v
        which.add(key)
    if inferred:
        impacts["inferred_from_shear_rate"] = (
            "v = c0 + c1 d gamma_dot (calibration.toml [impacts] " + ", ".join(sorted(which))
            + "), gamma_dot of the phase-resolved field on the analysis cells; count = 0: no "
            "impact is seen")
        inferred["relation"] = ", ".join(sorted(which))
    if a:
        inferred["granular_temperature_m2_s2"] = (a * d * m) ** 2
    out["impacts_from_shear_rate"] = inferred or None
    return out

