"""What a continuum tub run that carries the granular temperature (ContinuumOptions.temperature)
reports of it: the summary's "granular_temperature" block (`temperature_outputs`) and the
time-averaged map temperature.csv on the analysis cells, beside the solid fraction
(`write_temperature_csv`).  A run without the temperature writes neither."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from vibroflow.io.atomic import write_text_atomic
from vibroflow.measure.phase_shear import PhaseShear
from vibroflow.measure.stats import batch_means

from .sampling import Samples

TEMPERATURE_CSV_NAME = "temperature.csv"

#: the map's columns and their units (SI; "1": a number)
TEMPERATURE_COLUMNS = {"x": "m", "z": "m", "granular_temperature_m2_s2": "m2 s-2",
                       "solid_fraction": "1", "samples": "1"}


def temperature_map(samples: Samples) -> np.ndarray | None:
    """The time-averaged granular temperature (m^2/s^2, (nz, nx) on the analysis cells): the
    mean over the samples that held material in a cell of the mass-weighted mean T there; 0 in
    a cell that never held material.  None without the temperature or the cells."""
    if not samples.temperature or samples.cell_grid is None:
        return None
    n = samples.temperature_cell_n
    return np.divide(samples.temperature_cell_sum, n, out=np.zeros_like(n), where=n > 0)


def write_temperature_csv(path: Path, samples: Samples, phase: PhaseShear | None) -> bool:
    """Write the temperature map atomically (TEMPERATURE_COLUMNS): every analysis cell, at its
    centre x, z (m), its time-averaged granular temperature (temperature_map, 0 where no
    material), the solid fraction of the phase-resolved field's window mean (as
    shear_rate.csv's; 0 where none) and the samples that held material there.  False (nothing
    written) without the temperature."""
    T = temperature_map(samples)
    if T is None:
        return False
    h, nxh, nz = samples.cell_grid
    lines = [",".join(TEMPERATURE_COLUMNS)]
    for k in range(nz):
        for i in range(2 * nxh + 1):
            f = float(phase.solid_fraction[k, i]) if phase is not None else 0.0
            f = f if np.isfinite(f) else 0.0
            lines.append(f"{(i - nxh) * h!r},{k * h!r},{float(T[k, i])!r},{f!r},"
                         f"{int(samples.temperature_cell_n[k, i])}")
    write_text_atomic(path, "\n".join(lines) + "\n")
    return True


def temperature_outputs(samples: Samples, batch: np.ndarray, n_batches: int,
                        wrote_map: bool) -> dict:
    """The summary's "granular_temperature" block: the mass-weighted mean T over the material
    (m^2/s^2) with its batch-means standard error, the map's file and its columns' units.
    {} without the temperature."""
    if not samples.temperature:
        return {}
    values = samples.temperature_all
    ok = np.isfinite(values)
    m, se = (batch_means(values[ok], batch[ok], n_batches) if ok.any()
             else (float("nan"), float("nan")))
    block = {"mean_m2_s2": m, "mean_m2_s2_stderr": se,
             "definition": "mass-weighted mean of the granular temperature T over the "
                           "material at the samples"}
    if wrote_map:
        block["map_csv"] = TEMPERATURE_CSV_NAME
        block["map_units"] = dict(TEMPERATURE_COLUMNS)
    return {"granular_temperature": block}
