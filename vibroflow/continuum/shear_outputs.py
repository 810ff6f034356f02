"""The shear rate a continuum tub run reports and what it implies through the calibrated
relations: the summary's shear-rate block (`shear_rate_outputs`), the impact speeds and
granular temperature of calibration.toml [impacts] (`impact_relation`) and the shear-rate map
shear_rate.csv (`write_shear_rate_csv`)."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from vibroflow.io.atomic import write_text_atomic
from vibroflow.io.calibration_file import Calibration, ImpactRelation
from vibroflow.measure.phase_shear import PhaseShear, near_wall_nodes
from vibroflow.measure.stats import batch_means

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



def impact_relation(rel: ImpactRelation | None) -> tuple[float | None, float | None, str]:
    """(c0 m/s, c1, which) of a calibration's [impacts.KIND] table: the relation fitted on the
    continuum's own measure of the shear rate (c0_cells_m_s, c1_cells;
    calibration.impacts.impact_relations_on_cells) when the calibration has it, else the one
    fitted on the DEM's 5 mm coarse-grained field (c0_m_s, c1; a calibration without it); (None,
    None, "") without either."""
    if rel is None:
        return None, None, ""
    for c0, c1, which in ((rel.c0_cells_m_s, rel.c1_cells, "c0_cells, c1_cells"),
                          (rel.c0_m_s, rel.c1, "c0, c1")):
        if all(c is not None and math.isfinite(c) for c in (c0, c1)):
            return float(c0), float(c1), which
    return None, None, ""



def shear_rate_outputs(material, calibration: Calibration | None, probes: dict, batch,
                       n_batches, samples: Samples, phase: PhaseShear, radius_tub: float,
                       impacts: dict) -> dict:
    """Shear rate (1/s) over the bed, near the wall and in the probe cells, with batch-means
    standard errors; with a calibration, the granular temperature sqrt(T) = a d gamma_dot
    (models.md, Bagnold scaling; a from [impacts] bagnold_sqrtT_over_d_gamma_dot) and the mean
    impact speeds v = c0 + c1 d gamma_dot ([impacts.ball_ball] over the bed,
    [impacts.ball_wall] near the wall), written into the DEM's impact keys (`impacts` is
    updated in place; its counts stay 0: no impact is seen), by impact_relation.

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
        c0, c1, key = impact_relation(getattr(im, name) if im is not None else None)
        if c0 is None:
            continue
        v = c0 + c1 * d * rate
        impacts[name + "_mean_normal_speed"] = v
        impacts[name + "_mean_normal_speed_stderr"] = abs(c1) * d * rate_se
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

