"""Cyclic simple shear (vibroflow.calibration.cyclic_shear): the loop measures against analytic
loops, and the DEM packing's secant modulus against its independent quasi-static modulus and the
modulus reduction of granular media (Hardin & Drnevich 1972)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from vibroflow.calibration.cyclic_shear import (cycle_measures, run_cyclic_shear,
                                                secant_modulus_at, tub_strain_amplitude)
from vibroflow.errors import InputError

P_BED = 3370.0  # Pa, tub47-quick's measured bed pressure


def _cycle(n=2000):
    t = np.linspace(0.0, 1.0, n, endpoint=False)
    return t, 2.0 * math.pi * t


def test_kelvin_voigt_loop():
    """tau = G gamma + eta gamma_dot: the loop's secant modulus is |G*| = sqrt(G^2 + (eta w)^2)
    and its damping ratio eta w / (2 |G*|) (the ellipse's area pi eta w gamma_0^2)."""
    G, eta, w, g0 = 2.0e5, 300.0, 2 * math.pi * 47.0, 0.004
    t, ph = _cycle()
    gamma = g0 * np.sin(ph)
    tau = G * gamma + eta * g0 * w * np.cos(ph) + 1000.0  # a mean stress changes nothing
    m = cycle_measures(gamma, tau, np.full_like(tau, 3000.0))
    G_star = math.hypot(G, eta * w)
    assert m["secant_shear_modulus"] == pytest.approx(G_star, rel=1e-4)
    assert m["damping_ratio"] == pytest.approx(eta * w / (2 * G_star), rel=1e-3)
    assert m["loop_energy_J_m3"] == pytest.approx(math.pi * eta * w * g0**2, rel=1e-3)


def test_masing_elastic_perfectly_plastic_loop():
    """An elastic-perfectly-plastic material (yield strain gamma_y < gamma_0): a parallelogram
    loop, G_sec = tau_y / gamma_0 and D = 2 (gamma_0 - gamma_y) / (pi gamma_0)."""
    G, gy, g0 = 1.0e6, 0.001, 0.004
    t, ph = _cycle(8000)
    gamma = g0 * np.sin(ph)
    tau = np.empty_like(gamma)
    s, prev = 0.0, gamma[-1]
    for _ in range(2):  # the second pass starts on the closed loop
        for i, g in enumerate(gamma):
            s = float(np.clip(s + G * (g - prev), -G * gy, G * gy))
            prev = g
            tau[i] = s
    m = cycle_measures(gamma, tau, np.full_like(tau, 1.0e4))
    assert m["secant_shear_modulus"] == pytest.approx(G * gy / g0, rel=1e-3)
    assert m["damping_ratio"] == pytest.approx(2 * (g0 - gy) / (math.pi * g0), rel=5e-3)
    assert m["peak_stress_ratio"] == pytest.approx(G * gy / 1.0e4, rel=1e-9)


def test_tub_strain_amplitude_inverts_the_cycle_mean():
    g0, f = 0.007, 47.0
    _, ph = _cycle(100000)
    mean_rate = np.abs(g0 * 2 * math.pi * f * np.cos(ph)).mean()
    assert tub_strain_amplitude(mean_rate, f) == pytest.approx(g0, rel=1e-6)
    with pytest.raises(InputError, match="frequency"):
        tub_strain_amplitude(1.0, 0.0)


def test_bad_amplitudes_are_input_errors():
    from vibroflow.scenario.io import load_scenario

    sc = load_scenario("tub47-quick", [])
    with pytest.raises(InputError, match="strain_amplitudes"):
        run_cyclic_shear(sc, [0.0], pressure=P_BED)
    with pytest.raises(InputError, match="discard_cycles"):
        run_cyclic_shear(sc, [1e-3], pressure=P_BED, cycles=3, discard_cycles=2)


@pytest.fixture(scope="module")
def dem_cycles():
    from vibroflow.scenario.io import load_scenario

    sc = load_scenario("tub47-quick", [])
    recs = run_cyclic_shear(sc, [3e-5, 1e-3, 1e-2], pressure=P_BED, n_balls=200, cycles=4,
                            discard_cycles=2)
    return sc, recs


def test_small_amplitude_limit_is_the_quasi_static_modulus(dem_cycles):
    """As gamma_0 -> 0 the cyclic secant modulus tends to the small-strain shear modulus that
    the independent quasi-static test (elastic.py: stress steps of both signs, relaxed) finds
    for the same balls, pressure and packing procedure."""
    from vibroflow.calibration.elastic import elastic_moduli

    sc, recs = dem_cycles
    G_static = elastic_moduli(sc, pressure=P_BED, n_balls=200)["shear_modulus"]
    assert 0.8 * G_static < recs[0]["secant_shear_modulus"] < 1.35 * G_static
    # nearly elastic: little more than the contacts' own viscous loss (restitution 0.85)
    assert recs[0]["damping_ratio"] < 0.15


def test_modulus_reduction_and_damping_growth(dem_cycles):
    """Granular media soften and dissipate more as the strain amplitude grows (Hardin &
    Drnevich 1972): G_sec falls by several times between 3e-5 and 1e-2 and D grows; the
    mobilised stress ratio stays below the media's steady friction at large I."""
    _, recs = dem_cycles
    G = [r["secant_shear_modulus"] for r in recs]
    D = [r["damping_ratio"] for r in recs]
    assert G[0] > 2.0 * G[1] > 2.0 * G[2] / 1.0 and G[1] > G[2]
    assert D[1] > 2.0 * D[0]
    assert all(r["peak_stress_ratio"] < 0.6 for r in recs)
    # interpolation in log strain returns the measured points and lies between them
    assert secant_modulus_at(recs, 1e-3)[0] == pytest.approx(G[1])
    assert G[2] < secant_modulus_at(recs, 3e-3)[0] < G[1]
