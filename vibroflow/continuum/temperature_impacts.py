"""Impact speeds inferred from a continuum's granular temperature, where the DEM calibration
prefers the temperature to the shear rate (docs/decisions/impact-speed.md).

The calibration's [impacts.KIND] relation v = max(b0 + b1 sqrt(T), 0)
(b0_temperature_cells_m_s, b1_temperature_cells; calibration.impact_temperature) is fitted on
the DEM's impacts against its phase-resolved coarse-grained T at the analysis cells' centres;
its preferred_relation says which of T and the shear rate the DEM's impacts follow better
there.  A run that carries T (ContinuumOptions.temperature) and whose calibration prefers T
for a kind infers that kind's mean from its time-averaged T map on the analysis cells
(temperature_outputs.temperature_map): v at each node, solid-fraction weighted over the bed
(ball-ball) or the nodes within a node spacing of the U (ball-wall), as the shear rate's
inference weights them.  Its standard error is the bed-mean temperature's batch-means error
carried through the relation, b1 se(T) / (2 sqrt(T)); the relation's own error, from its
coefficients' errors and covariance, is beside it as KIND_mean_normal_speed_relation_stderr
(temperature_prediction_stderr), and its covariance with the DEM run's measured mean
(shear_outputs.measured_covariance_keys).  Without T, or where the calibration prefers the
shear rate, the shear rate's inference stands and nothing here is written.
"""
from __future__ import annotations

import math

import numpy as np

from vibroflow.io.calibration_file import Calibration
from vibroflow.measure.phase_shear import PhaseShear, near_wall_nodes
from vibroflow.measure.stats import affine_prediction_stderr, batch_means

from .sampling import Samples
from .shear_outputs import RelationKeys, chosen_keys, measured_covariance_keys, relation_errors
from .temperature_outputs import temperature_map

RELATION = "v = max(b0 + b1 sqrt(T), 0)"


#: the two temperature relations of an [impacts.KIND] table, in the order temperature_relation
#: prefers them
_TEMPERATURE_RELATIONS = tuple(
    RelationKeys(f"b0_temperature{tag}_m_s", f"b1_temperature{tag}",
                 f"b0_temperature{tag}_stderr_m_s", f"b1_temperature{tag}_stderr",
                 f"b0_b1_temperature{tag}_covariance_m_s",
                 f"b0_temperature{tag}_measured_covariance_m2_s2",
                 f"b1_temperature{tag}_measured_covariance_m_s") for tag in ("_cells", ""))


def _prefers_temperature(rel) -> bool:
    return rel is not None and rel.preferred_relation == "temperature"


def temperature_relation(rel) -> tuple[float, float] | None:
    """(b0 m/s, b1) of an [impacts.KIND] table that prefers the temperature, else None: the
    relation fitted on the analysis cells' centres (b0_temperature_cells_m_s,
    b1_temperature_cells) where the calibration has it, else the coarse-grained points' one."""
    keys = chosen_keys(rel, _TEMPERATURE_RELATIONS) if _prefers_temperature(rel) else None
    return None if keys is None else (float(getattr(rel, keys.c0)), float(getattr(rel, keys.c1)))


def temperature_relation_errors(rel) -> tuple[float, float, float]:
    """(se b0 m/s, se b1, cov(b0, b1) m/s) of the relation temperature_relation chooses (NaN
    where the calibration holds none)."""
    if not _prefers_temperature(rel):
        return math.nan, math.nan, math.nan
    return relation_errors(rel, _TEMPERATURE_RELATIONS)


def temperature_prediction_stderr(rel, sqrt_T, weight) -> float:
    """The calibrated relation's own error (m/s) of the weighted mean of max(b0 + b1 sqrt(T),
    0) over nodes (sqrt_T m/s, weight their weights): the relation's gradient in (b0, b1) is
    (the share of the weight where the relation is positive, the weighted mean of sqrt(T)
    there) (measure.stats.affine_prediction_stderr)."""
    gradient = _gradient(rel, sqrt_T, weight)
    if gradient is None:
        return math.nan
    share, x = gradient
    return affine_prediction_stderr(x, *temperature_relation_errors(rel), intercept_share=share)


def _gradient(rel, sqrt_T, weight) -> tuple[float, float] | None:
    """(share, x): the weighted mean of max(b0 + b1 sqrt(T), 0)'s gradient in (b0, b1) over
    nodes (temperature_prediction_stderr); None without the relation or weight."""
    b = temperature_relation(rel)
    w, s = np.asarray(weight, float), np.asarray(sqrt_T, float)
    total = float(np.sum(w))
    if b is None or not total > 0:
        return None
    on = (b[0] + b[1] * s) > 0
    return float(np.sum(w[on])) / total, float(np.sum(w[on] * s[on])) / total


def impacts_from_temperature(calibration: Calibration | None, samples: Samples,
                             phase: PhaseShear | None, radius_tub: float, batch: np.ndarray,
                             n_batches: int, impacts: dict) -> dict:
    """The summary's "impacts_from_temperature" block ({} when nothing is inferred from T);
    the kinds inferred replace the shear rate's values in `impacts` (the DEM's keys
    KIND_mean_normal_speed and _stderr, updated in place; its inferred_from_shear_rate goes when
    both kinds come from T)."""
    T = temperature_map(samples)
    im = calibration.impacts if calibration is not None else None
    if T is None or phase is None or im is None:
        return {}
    phi = np.nan_to_num(np.asarray(phase.solid_fraction, float))
    held = (phi > 0) & (T > 0)
    near = near_wall_nodes(phase, radius_tub)
    values = samples.temperature_all
    ok = np.isfinite(values)
    T_bed, T_se = (batch_means(values[ok], batch[ok], n_batches) if ok.any()
                   else (float("nan"), float("nan")))
    out: dict = {}
    for name in ("ball_ball", "ball_wall"):
        rel = temperature_relation(getattr(im, name))
        region = held & (near if name == "ball_wall" else True)
        if rel is None or not region.any():
            continue
        b0, b1 = rel
        v_node = np.maximum(b0 + b1 * np.sqrt(T[region]), 0.0)
        w = phi[region]
        v = float(np.sum(w * v_node) / np.sum(w))
        se = (abs(b1) * T_se / (2.0 * math.sqrt(T_bed)) if T_bed > 0 else float("nan"))
        se_rel = temperature_prediction_stderr(getattr(im, name), np.sqrt(T[region]), w)
        impacts[name + "_mean_normal_speed"] = v
        impacts[name + "_mean_normal_speed_stderr"] = se
        impacts[name + "_mean_normal_speed_relation_stderr"] = se_rel
        for key in ("_mean_normal_speed_relation_measured_covariance",
                    "_mean_normal_speed_relation_measured_mean"):
            impacts.pop(name + key, None)  # the shear rate's relation's, if it set them
        gradient = _gradient(getattr(im, name), np.sqrt(T[region]), w)
        if gradient is not None:
            measured_covariance_keys(impacts, name, getattr(im, name), _TEMPERATURE_RELATIONS,
                                     gradient[1], intercept_share=gradient[0])
        out[name + "_mean_normal_speed_m_s"] = v
        out[name + "_mean_normal_speed_m_s_stderr"] = se
        out[name + "_mean_normal_speed_m_s_relation_stderr"] = se_rel
    if not out:
        return {}
    out["relation"] = (RELATION + " (calibration.toml [impacts.KIND] "
                       "b0_temperature_cells_m_s, b1_temperature_cells, preferred_relation = "
                       "\"temperature\"), T the time-averaged map on the analysis cells, "
                       "solid-fraction weighted")
    done = [k for k in ("ball_ball", "ball_wall") if k + "_mean_normal_speed_m_s" in out]
    kinds = ", ".join(done)
    if len(done) == 2:  # the shear rate's inference is in continuum.impacts_from_shear_rate
        impacts.pop("inferred_from_shear_rate", None)
    impacts["inferred_from_temperature"] = (f"{kinds}: {out['relation']}; count = 0: no impact "
                                            "is seen")
    return {"impacts_from_temperature": out}
