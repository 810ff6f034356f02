"""The report's section "Stress by height and phase": where each method's bed sits against the
yield of its calibrated mu(I), the DEM's coarse-grained cells (the calibration's fields.nc,
phase-resolved) beside each continuum's stress.csv, read by vibroflow.analysis.stress_state.
Per method: its dense cells and phases, the median friction mu = tau_eq / p and pressure, the
share of the cells at or above the calibrated mu_s, and by phase of the cycle the median mu of
the lowest and the highest third of its cells' heights (docs/validation.md section 30); each
with its batch-means standard error, the statistic taken again on each batch's own stress in
the same cells (the DEM's fields.nc batches, a continuum's stress_batches.csv)."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vibroflow.analysis.stress_state import (batch_errors, continuum_points, dem_points,
                                             height_phase_table, share_at_yield)
from vibroflow.calibration.run_fields import read_fields
from vibroflow.continuum.stress_outputs import STRESS_CSV_NAME
from vibroflow.errors import InputError
from vibroflow.report.data import CALIBRATION, DEM, StudyData


@dataclass(frozen=True)
class StressRows:
    """The section's table: head, and per method (name, dense cells x phases, median mu,
    median p (Pa), share at or above mu_s, [the lowest / highest third's median mu by phase,
    None where a third has no cell]), each number a (value, batch-means standard error) pair
    and a third (low, high, low's error, high's error), the errors NaN without the method's
    batches (analysis.stress_state.batch_errors); the calibrated mu_s (NaN without it) and a
    note for each method left out, with why."""

    head: list
    rows: list
    mu_s: float
    missing: list


def _points(data: StudyData, name: str) -> dict:
    if name == DEM:
        return dem_points(read_fields(data.out / CALIBRATION / "fields.nc",
                                      phase_resolved=True))
    return continuum_points(data.method_dir(name) / STRESS_CSV_NAME)


def stress_rows(data: StudyData) -> StressRows:
    """The table of every method whose stress can be read; the others in `missing`."""
    cal = data.calibration
    mu_s = float(cal.rheology.mu_s) if cal is not None else float("nan")
    n_phases = int(data.scenario.run.phases_per_cycle) if data.scenario is not None else 8
    head = ["method", "dense cells x phases", "median mu", "median p (Pa)",
            "share at or above mu_s"] + [f"phase {k}/{n_phases} (fraction of the cycle)" for k in range(n_phases)]
    rows, missing = [], []
    for name in data.methods:
        try:
            pts = _points(data, name)
            tab = height_phase_table(pts)
        except (InputError, OSError, KeyError, ValueError) as exc:
            missing.append(f"{name}: {getattr(exc, 'message', str(exc))}")
            continue
        by_phase = {r["phase"]: r for r in tab["rows"]}
        share = share_at_yield(pts, mu_s) if math.isfinite(mu_s) else float("nan")
        se = batch_errors(pts, mu_s) or {}
        nan = float("nan")
        thirds = [None if k not in by_phase else
                  (by_phase[k]["mu_low"], by_phase[k]["mu_high"])
                  + tuple(se.get("thirds", {}).get(k, (nan, nan)))
                  for k in range(n_phases)]
        rows.append((name, int(pts["mu"].size),
                     (float(np.median(pts["mu"])), se.get("median_mu", nan)),
                     (float(np.median(pts["pressure"])), se.get("median_pressure", nan)),
                     (share, se.get("share", nan)), thirds))
    return StressRows(head=head, rows=rows, mu_s=mu_s, missing=missing)
