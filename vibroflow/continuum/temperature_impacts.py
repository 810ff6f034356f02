"""Impact speeds inferred from a continuum's granular temperature, where the DEM calibration
prefers the temperature to the shear rate (docs/decisions/impact-speed.md).

The calibration's [impacts.KIND] relation v = max(b0 + b1 sqrt(T), 0)
(b0_temperature_cells_m_s, b1_temperature_cells; calibration.impact_temperature) is fitted on
the DEM's impacts against its phase-resolved coarse-grained T at the analysis cells' centres;
its preferred_relation says which of T and the shear rate the DEM's impacts follow better there.  A run that carries T (ContinuumOptions.temperature) and whose
calibration prefers T for a kind infers that kind's mean from its time-averaged T map on the
analysis cells (temperature_outputs.temperature_map): v at each node, solid-fraction weighted
over the bed (ball-ball) or the nodes within a node spacing of the U (ball-wall), as the shear
rate's inference weights them.  Its standard error is the bed-mean temperature's batch-means
error carried through the relation, b1 se(T) / (2 sqrt(T)).  Without T, or where the calibration
prefers the shear rate, the shear rate's inference stands and nothing here is written.
"""
from __future__ import annotations

import math

import numpy as np

from vibroflow.io.calibration_file import Calibration
from vibroflow.measure.phase_shear import PhaseShear, near_wall_nodes
from vibroflow.measure.stats import batch_means

from .sampling import Samples
from .temperature_outputs import temperature_map

RELATION = "v = max(b0 + b1 sqrt(T), 0)"


def temperature_relation(rel) -> tuple[float, float] | None:
    """(b0 m/s, b1) of an [impacts.KIND] table that prefers the temperature, else None: the
    relation fitted on the analysis cells' centres (b0_temperature_cells_m_s,
    b1_temperature_cells) where the calibration has it, else the coarse-grained points' one."""
    if rel is None or rel.preferred_relation != "temperature":
        return None
    for b0, b1 in ((rel.b0_temperature_cells_m_s, rel.b1_temperature_cells),
                   (rel.b0_temperature_m_s, rel.b1_temperature)):
        if b0 is not None and b1 is not None and math.isfinite(b0) and math.isfinite(b1):
            return float(b0), float(b1)
    return None


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
        impacts[name + "_mean_normal_speed"] = v
        impacts[name + "_mean_normal_speed_stderr"] = se
        out[name + "_mean_normal_speed_m_s"] = v
        out[name + "_mean_normal_speed_m_s_stderr"] = se
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
