"""Phase-resolved profiles of a vibrated layer by height above its floor, and its floor force.

A layer on a floor vibrated vertically, z_f(t) = A sin(psi) + const with the floor's phase
psi = omega t + phase_z, is sampled at P phases of the floor's cycle, psi / (2 pi) = k / P
(k = 0 .. P-1), over whole cycles split into batches (measure.stats).  At each sample the
material is binned in bands of height `band_m` above the floor (z - z_f, the floor's frame):

* solid fraction phi = sum of the grains' (points', cells') volume in the band / the band's
  volume (cross-section x band_m);
* granular temperature T (m^2/s^2): for grains (DEM), one third of the mass-weighted mean square
  of the velocity about the band's own mass-weighted mean velocity at that sample (the kinetic
  part of coarse_grain_fields' T = tr(sigma_k) / (3 rho)); for a continuum, its carried T,
  mass-weighted;
* the floor force F (N), given as F / (M g) (M the layer's mass), binned by the phase of the
  instant it is taken into FORCE_BINS_PER_PHASE P bins [j / Q, (j + 1) / Q), Q = 4 P,
  centred on (j + 1/2) / Q; its cycle mean is the mean of all its samples (taken at equal
  intervals: the time mean, whatever the bins' counts).

Every profile is averaged over its samples within each batch and carries the batch-means
standard error.  The take-off phase is the first phase after the force's maximum at which the
phase-averaged F / (M g) falls to `TAKE_OFF_LEVEL` (interpolated linearly between the bins'
centres): for a block on the floor, sin(psi) = 1 / Gamma with Gamma = A omega^2 / g (the floor
can no longer pull it down with gravity; tests/test_dem_plates.py).
"""
from __future__ import annotations

import math

import numpy as np

from .stats import phase_stderr, stderr_of_batches

#: F / (M g) below which the floor no longer carries the layer (a twentieth of its weight: the
#: bins' mean force of a layer in flight is zero up to a few grains still touching)
TAKE_OFF_LEVEL = 0.05
#: the floor force's phase bins per profile phase: the take-off phase is resolved to a quarter
#: of the profiles' phase step
FORCE_BINS_PER_PHASE = 4


def floor_phase(t_s, frequency_hz: float, phase_z_rad: float):
    """The floor's phase psi / (2 pi) in [0, 1) at times t (s)."""
    return np.mod(np.asarray(t_s, float) * frequency_hz + phase_z_rad / (2 * math.pi), 1.0)


def take_off_phase(force_over_weight, level: float = TAKE_OFF_LEVEL) -> float:
    """The cycle fraction at which F / (M g), given at the bin centres (k + 1/2) / P, first
    falls to `level` after its maximum (linear between centres, so within 1 / P of the
    crossing), NaN if it never does."""
    f = np.asarray(force_over_weight, float)
    P = f.size
    if P == 0 or not np.all(np.isfinite(f)):
        return math.nan
    k0 = int(np.argmax(f))
    for j in range(1, P + 1):
        a, b = f[(k0 + j - 1) % P], f[(k0 + j) % P]
        if b <= level < a:
            x = (k0 + j - 1) + (a - level) / (a - b)
            return float(np.mod((x + 0.5) / P, 1.0))
    return math.nan


class LayerProfiles:
    """Sums of the samples by (batch, phase, band); module docstring.  cross_section: the
    band's area (m^2, 3D grains) or width (m, a plane continuum per metre), so that volumes
    of the samples are in m^3 or m^2 alike."""

    def __init__(self, n_phases: int, n_bands: int, band_m: float, n_batches: int,
                 cross_section: float):
        self.n_phases, self.n_bands, self.band_m = int(n_phases), int(n_bands), float(band_m)
        self.n_batches, self.cross_section = int(n_batches), float(cross_section)
        shape = (self.n_batches, self.n_phases, self.n_bands)
        self.mass = np.zeros(shape)
        self.mass_T = np.zeros(shape)
        self.volume = np.zeros(shape)
        self.samples = np.zeros(shape[:2])
        self.n_force_bins = FORCE_BINS_PER_PHASE * self.n_phases
        self.force = np.zeros((self.n_batches, self.n_force_bins))
        self.force_samples = np.zeros((self.n_batches, self.n_force_bins))

    def _bands(self, z):
        return np.clip((np.asarray(z) / self.band_m).astype(np.int64), 0, self.n_bands - 1)

    def add_grains(self, batch: int, phase: int, z, vel, mass, volume) -> None:
        """One sample of grains: heights z above the floor (m), velocities vel (N, 3) m/s,
        masses (kg) and volumes (m^3)."""
        k = self._bands(z)
        nb = self.n_bands
        m = np.bincount(k, mass, nb)
        mean = np.stack([np.bincount(k, mass * vel[:, c], nb) for c in range(vel.shape[1])], 1)
        mean /= np.maximum(m, 1e-300)[:, None]
        dev2 = np.sum((vel - mean[k]) ** 2, axis=1) / 3.0
        self._add(batch, phase, m, np.bincount(k, mass * dev2, nb), np.bincount(k, volume, nb))

    def add_field(self, batch: int, phase: int, z, mass, volume, T) -> None:
        """One sample of a continuum's points or cells: heights z (m), masses, volumes and
        temperatures T (m^2/s^2)."""
        k = self._bands(z)
        nb = self.n_bands
        self._add(batch, phase, np.bincount(k, mass, nb), np.bincount(k, mass * T, nb),
                  np.bincount(k, volume, nb))

    def _add(self, batch, phase, m, mT, vol):
        self.mass[batch, phase] += m
        self.mass_T[batch, phase] += mT
        self.volume[batch, phase] += vol
        self.samples[batch, phase] += 1

    def add_force(self, batch: int, phase_fraction: float, force_over_weight: float) -> None:
        """The floor's force F / (M g) at the floor phase psi / (2 pi) = phase_fraction."""
        k = int(phase_fraction * self.n_force_bins) % self.n_force_bins
        self.force[batch, k] += force_over_weight
        self.force_samples[batch, k] += 1

    def result(self) -> dict:
        """Means and batch-means standard errors (SI), phases psi / (2 pi) and band centres."""
        # NaN where a band held no mass or a phase bin no floor-force sample (a layer that
        # records no floor force has none at all)
        with np.errstate(invalid="ignore", divide="ignore"):
            T_b = self.mass_T / self.mass
            phi_b = self.volume / (self.samples[..., None] * self.cross_section * self.band_m)
            f_b = self.force / self.force_samples
            f = self.force.sum(0) / self.force_samples.sum(0)
            f_cycle = self.force.sum() / self.force_samples.sum()
            f_cycle_b = self.force.sum(1) / self.force_samples.sum(1)
        T = self.mass_T.sum(0) / np.where(self.mass.sum(0) > 0, self.mass.sum(0), np.nan)
        phi = self.volume.sum(0) / (self.samples.sum(0)[:, None] * self.cross_section
                                    * self.band_m)
        off_b = np.array([take_off_phase(fb) for fb in f_b])
        off = take_off_phase(f)
        return {"phase": (np.arange(self.n_phases) / self.n_phases).tolist(),
                "force_phase": ((np.arange(self.n_force_bins) + 0.5)
                                / self.n_force_bins).tolist(),
                "height_m": ((np.arange(self.n_bands) + 0.5) * self.band_m).tolist(),
                "temperature_m2_s2": T.tolist(),
                "temperature_stderr_m2_s2": stderr_of_batches(T_b).tolist(),
                "solid_fraction": phi.tolist(),
                "solid_fraction_stderr": stderr_of_batches(phi_b).tolist(),
                "floor_force_over_weight": f.tolist(),
                "floor_force_over_weight_stderr": stderr_of_batches(f_b).tolist(),
                "floor_force_cycle_mean_over_weight": float(f_cycle),
                "floor_force_cycle_mean_stderr": stderr_of_batches(f_cycle_b),
                "take_off_phase": off,
                "take_off_phase_stderr": phase_stderr(off_b, off)}

