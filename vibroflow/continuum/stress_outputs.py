"""The continuum's phase-resolved stress on the analysis cells, as the DEM's calibration measures
its own (stress.csv, `phase_stress`, `write_stress_csv`): at each sampling phase of the cycle
the material's stress averaged over the window's cycles, then the pressure, the equivalent
shear stress and the friction coefficient of that mean (calibration/coarse_grain_fields.
rheology: average first, then derive), and the inertial number from the phase-resolved shear
rate of the same cells (measure.phase_shear, the shear_rate.csv field's phases).  It lets the
continua's mu(I) be read in the same cells and phases as the DEM's (docs/validation.md
section 30).

The stress is the elastic-plastic stress the states carry (Pa, [xx, zz, xz, yy], tension
positive), the volume-weighted mean over the points (or cells) in each analysis cell at each
sample (sampling.Samples.add_cell_stresses); the kinetic pressure of a run with the granular
temperature is not in it.  Units: m, Pa, 1/s, and numbers ("1")."""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vibroflow.io.atomic import write_text_atomic
from vibroflow.measure.phase_shear import PhaseShear
from vibroflow.measure.stats import batches_of_whole_cycles, phase_bins

from .sampling import Samples

STRESS_CSV_NAME = "stress.csv"
#: each batch's pressure and friction in the cells and phases of stress.csv
STRESS_BATCHES_CSV_NAME = "stress_batches.csv"

#: the map's columns and their units (SI; "1": a number)
STRESS_COLUMNS = {"x": "m", "z": "m", "phase": "1", "solid_fraction": "1",
                  "shear_rate": "s-1", "pressure": "Pa", "shear_stress": "Pa",
                  "friction_coefficient": "1", "friction_coefficient_stderr": "1",
                  "inertial_number": "1", "samples": "1"}
#: stress_batches.csv's columns and their units
STRESS_BATCH_COLUMNS = {"batch": "1", "x": "m", "z": "m", "phase": "1", "pressure": "Pa",
                        "friction_coefficient": "1"}


def invariants(stress: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(p, tau_eq) (Pa) of plane-strain stresses (..., 4) [xx, zz, xz, yy], tension positive:
    p = -tr(sigma) / 3 (compression positive) and tau_eq = sqrt(tau:tau / 2), tau the
    deviator (the DEM's coarse_grain_fields.rheology, whose xy and yz parts are 0 here)."""
    s = np.asarray(stress, float)
    p = -(s[..., 0] + s[..., 1] + s[..., 3]) / 3.0
    dxx, dzz, dyy = s[..., 0] + p, s[..., 1] + p, s[..., 3] + p
    tau = np.sqrt(0.5 * (dxx ** 2 + dzz ** 2 + dyy ** 2 + 2.0 * s[..., 2] ** 2))
    return p, tau


@dataclass
class PhaseStress:
    """The phase-resolved stress on the analysis cells: x (nx,), z (nz,) cell centres (m);
    stress (n_phases, nz, nx, 4) Pa the mean over the window's samples at each phase (NaN where
    no sample held material); pressure, shear_stress (Pa), friction (1), its batch-means
    standard error friction_stderr (from each batch's own phase mean), inertial_number (1, from
    the phase shear rate), shear_rate (1/s), solid_fraction (1), samples (the samples that held
    material), each (n_phases, nz, nx); batch_pressure (Pa) and batch_friction (1), each batch
    of whole cycles' own phase means, (n_batches, n_phases, nz, nx)."""
    x: np.ndarray
    z: np.ndarray
    stress: np.ndarray
    pressure: np.ndarray
    shear_stress: np.ndarray
    friction: np.ndarray
    friction_stderr: np.ndarray
    inertial_number: np.ndarray
    shear_rate: np.ndarray
    solid_fraction: np.ndarray
    samples: np.ndarray
    batch_pressure: np.ndarray
    batch_friction: np.ndarray


def _sums(stack: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Over axis 0 of (S, ..., 4): the sum of the rows that hold a stress (no NaN) and their
    count."""
    held = np.isfinite(stack).all(axis=-1)
    return np.where(held[..., None], stack, 0.0).sum(axis=0), held.sum(axis=0)


def _mean(total: np.ndarray, n: np.ndarray) -> np.ndarray:
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n[..., None] > 0, total / n[..., None], np.nan)


def _friction(stress: np.ndarray) -> np.ndarray:
    p, tau = invariants(stress)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(p > 0, tau / np.where(p > 0, p, 1.0), np.nan)


def phase_stress(samples: Samples, times: np.ndarray, frequency: float, n_phases: int,
                 window: tuple[float, float], n_batches: int, phase: PhaseShear,
                 solid_density: float, diameter: float) -> PhaseStress | None:
    """The PhaseStress of a run's samples at times (S,) s in the averaging window (t0, t1) s of
    a vibration of `frequency` Hz with n_phases sampling phases and n_batches batches of whole
    cycles; `phase` the run's PhaseShear on the same cells (its phase_shear_rate and
    phase_solid_fraction), solid_density (kg/m^3) and the ball diameter d (m) for I =
    gamma_dot d / sqrt(p / rho_s).  None without the analysis cells or samples."""
    if samples.cell_grid is None or times.size == 0:
        return None
    S = times.size
    stack = samples.stress_cell[:S]
    bins = phase_bins(times, frequency, n_phases)
    batch = batches_of_whole_cycles(times, window[0], window[1], frequency, n_batches)
    shape = stack.shape[1:]
    total = np.zeros((n_batches, n_phases) + shape)
    count = np.zeros((n_batches, n_phases) + shape[:-1], np.int64)
    for b in range(n_batches):
        for k in range(n_phases):
            total[b, k], count[b, k] = _sums(stack[(bins == k) & (batch == b)])
    # each batch's own phase mean gives its friction; a cell a batch never held makes the
    # error NaN (the standard deviation of a NaN)
    batch_mean = _mean(total, count)
    per_batch = _friction(batch_mean)
    held = count.sum(axis=0)
    mean = _mean(total.sum(axis=0), held)
    p, tau = invariants(mean)
    mu = _friction(mean)
    with np.errstate(invalid="ignore"):
        se = per_batch.std(axis=0, ddof=1) / math.sqrt(n_batches) if n_batches > 1 \
            else np.full(mu.shape, np.nan)
    gd = np.asarray(phase.phase_shear_rate, float)
    with np.errstate(invalid="ignore", divide="ignore"):
        I = np.where(p > 0, gd * diameter / np.sqrt(np.where(p > 0, p, 1.0) / solid_density),
                     np.nan)
    return PhaseStress(x=np.asarray(phase.x, float), z=np.asarray(phase.z, float),
                       stress=mean, pressure=p, shear_stress=tau, friction=mu,
                       friction_stderr=se, inertial_number=I, shear_rate=gd,
                       solid_fraction=np.asarray(phase.phase_solid_fraction, float),
                       samples=held, batch_pressure=invariants(batch_mean)[0],
                       batch_friction=per_batch)


def _num(v) -> str:
    return repr(float(v)) if np.isfinite(v) else ""


def _held(ps: PhaseStress) -> np.ndarray:
    """(phase, iz, ix) of every cell and phase that held material, phase by phase, row by row:
    the rows of stress.csv and of each batch's block of stress_batches.csv."""
    return np.argwhere(ps.samples > 0)


def write_stress_csv(path: Path, ps: PhaseStress | None) -> bool:
    """Write the phase-resolved stress map atomically (STRESS_COLUMNS, SI): a row for each
    analysis cell and phase at which the cell held material in some sample.  False (nothing
    written) without it."""
    if ps is None:
        return False
    lines = [",".join(STRESS_COLUMNS)] + [",".join([
        repr(float(ps.x[ix])), repr(float(ps.z[iz])), str(k),
        _num(ps.solid_fraction[k, iz, ix]), _num(ps.shear_rate[k, iz, ix]),
        _num(ps.pressure[k, iz, ix]), _num(ps.shear_stress[k, iz, ix]),
        _num(ps.friction[k, iz, ix]), _num(ps.friction_stderr[k, iz, ix]),
        _num(ps.inertial_number[k, iz, ix]), str(int(ps.samples[k, iz, ix]))])
        for k, iz, ix in _held(ps)]
    write_text_atomic(path, "\n".join(lines) + "\n")
    return True


def write_stress_batches_csv(path: Path, ps: PhaseStress | None) -> bool:
    """Write each batch's pressure and friction (STRESS_BATCH_COLUMNS, SI) atomically: a row
    for each batch and each cell and phase of stress.csv, empty where the batch held no
    material there.  False (nothing written) without the map or with fewer than two
    batches: there is no batches' scatter to give."""
    if ps is None or ps.batch_friction.shape[0] < 2:
        return False
    held = _held(ps)
    lines = [",".join(STRESS_BATCH_COLUMNS)] + [",".join([
        str(b), repr(float(ps.x[ix])), repr(float(ps.z[iz])), str(k),
        _num(ps.batch_pressure[b, k, iz, ix]), _num(ps.batch_friction[b, k, iz, ix])])
        for b in range(ps.batch_friction.shape[0]) for k, iz, ix in held]
    write_text_atomic(path, "\n".join(lines) + "\n")
    return True
