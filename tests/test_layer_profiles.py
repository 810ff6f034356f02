"""The vibrated layer's measures (vibroflow.measure.layer_profiles) on inputs of known answer:
the take-off of a block on a floor of peak acceleration Gamma g, a Maxwellian gas's
temperature about a drifting band mean, a packing's solid fraction, batch-means errors."""
from __future__ import annotations

import math

import numpy as np
import pytest

from vibroflow.measure.layer_profiles import (TAKE_OFF_LEVEL, LayerProfiles, floor_phase,
                                              take_off_phase)


@pytest.mark.parametrize("gamma", [1.2, 2.0, 5.0, 13.3])
def test_a_block_takes_off_where_sin_psi_is_one_over_gamma(gamma):
    # a block riding the floor: F / (M g) = 1 - Gamma sin(psi) while positive
    P = 64
    s = (np.arange(P) + 0.5) / P
    force = np.maximum(0.0, 1.0 - gamma * np.sin(2 * math.pi * s))
    # where the force falls to TAKE_OFF_LEVEL; to zero (sin psi = 1 / Gamma) just after
    exact = math.asin((1.0 - TAKE_OFF_LEVEL) / gamma) / (2 * math.pi)
    assert abs(take_off_phase(force) - exact) < 1.0 / P
    assert 0 < math.asin(1.0 / gamma) / (2 * math.pi) - exact < 0.02


def test_a_floor_that_always_carries_the_layer_has_no_take_off():
    s = (np.arange(16) + 0.5) / 16
    assert math.isnan(take_off_phase(1.0 - 0.8 * np.sin(2 * math.pi * s)))


def test_the_floor_phase_is_that_of_its_displacement():
    f, phase = 47.0, 0.5 * math.pi
    assert floor_phase(0.0, f, phase) == pytest.approx(0.25)
    top = floor_phase(0.75 / f, f, phase)
    assert min(top, 1.0 - top) < 1e-12


def test_a_maxwellian_gas_in_a_drifting_band_has_its_temperature_and_solid_fraction():
    rng = np.random.default_rng(3)
    T, n, band, area, vball = 0.02, 20000, 0.01, 0.05**2, 1.0e-9
    acc = LayerProfiles(n_phases=2, n_bands=3, band_m=band, n_batches=4, cross_section=area)
    for b in range(4):
        for k in range(2):
            z = rng.uniform(band, 2 * band, n)  # all in band 1
            # the band drifts as a body (0.3 m/s up): no temperature in the drift
            vel = rng.normal(0.0, math.sqrt(T), (n, 3)) + np.array([0.0, 0.0, 0.3])
            acc.add_grains(b, k, z, vel, np.full(n, 1e-3), np.full(n, vball))
        for j in range(acc.n_force_bins):
            acc.add_force(b, (j + 0.5) / acc.n_force_bins, 1.0 + 0.01 * rng.normal())
    r = acc.result()
    T_band = np.array(r["temperature_m2_s2"])[:, 1]
    se = np.array(r["temperature_stderr_m2_s2"])[:, 1]
    # the estimate about the sample's own mean: T (1 - 1/n), well inside 1 %
    assert np.all(np.abs(T_band - T) < 0.01 * T)
    assert np.all((se > 0) & (se < 0.01 * T))
    assert np.array(r["solid_fraction"])[:, 1] == pytest.approx(n * vball / (area * band))
    assert np.all(np.isnan(np.array(r["temperature_m2_s2"])[:, 0]))
    assert r["floor_force_cycle_mean_over_weight"] == pytest.approx(1.0, abs=0.02)
