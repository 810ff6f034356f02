"""Whole-part measures of what a part feels, to judge one method's parts.nc against another's
(the DEM's): the impact map's difference and the cycle means of the force and the torque.

- `map_difference`: over the patches where both maps have a value, sum |v - v_ref| over
  sum v_ref (the L1 difference relative to the reference map's size), beside the same sum of
  `errors` times the reference's batch-means standard errors over sum v_ref: the difference
  the reference's own noise gives, against which the first is judged (docs/validation.md
  section 25; tests/test_part_maps.py).
- `cycle_mean`: the mean over the phase bins of a by-phase quantity (parts.nc's force,
  torque), its standard error the bins' errors combined in quadrature over the bin count (each
  bin averages its own samples).  Units: those of the inputs (m/s; N; N m).
"""
from __future__ import annotations

import numpy as np

#: the map difference's allowance: two of the reference's standard errors per patch
MAP_ERRORS = 2.0


def map_difference(v, v_ref, se_ref, errors: float = MAP_ERRORS) -> tuple[float, float, int]:
    """(the map's difference from the reference, the reference noise's, the patches counted)
    over the patches where v, v_ref and se_ref are all finite (module docstring); NaNs when
    none is or the reference sums to zero."""
    v, v_ref, se_ref = (np.asarray(a, float) for a in (v, v_ref, se_ref))
    both = np.isfinite(v) & np.isfinite(v_ref) & np.isfinite(se_ref)
    total = float(v_ref[both].sum())
    if not both.any() or total <= 0.0:
        return float("nan"), float("nan"), int(both.sum())
    return (float(np.abs(v[both] - v_ref[both]).sum() / total),
            float(errors * se_ref[both].sum() / total), int(both.sum()))


def cycle_mean(values, stderr) -> tuple[np.ndarray, np.ndarray]:
    """(mean, standard error) over the phase bins (axis 0) of values (phase, ...) with their
    batch-means errors stderr alike, bins with a non-finite value left out."""
    values, stderr = np.asarray(values, float), np.asarray(stderr, float)
    ok = np.isfinite(values) & np.isfinite(stderr)
    n = ok.sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(ok, values, 0.0).sum(axis=0) / n
        se = np.sqrt((np.where(ok, stderr, 0.0) ** 2).sum(axis=0)) / n
    return np.where(n > 0, mean, np.nan), np.where(n > 0, se, np.nan)
