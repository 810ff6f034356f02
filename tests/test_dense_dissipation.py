"""The dense sliding loss Gamma_f = k_f p sqrt(T) / d in the temperature's balance
(kinetic_theory.sliding_dissipation_W_m3, temperature_step.exact_cooling_sliding): its exact
cooling against an independent integration, the steady balance against its algebraic root, and
off (k_f = 0) the plain balance's numbers, bit for bit."""
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from vibroflow.continuum.kinetic_theory import (KineticParameters, dissipation_W_m3,
                                                sliding_dissipation_W_m3, sliding_rate)
from vibroflow.continuum.temperature_step import (TemperatureGrid, exact_cooling,
                                                  exact_cooling_sliding, step_temperature,
                                                  step_temperature_pressed)

PRM = KineticParameters(diameter_m=0.00635, density_kg_m3=7800.0, restitution=0.85,
                        phi_rcp=0.635, sliding_coefficient=0.358)


@pytest.mark.parametrize("a, b", [(3.0, 0.0), (0.0, 0.05), (3.0, 0.05), (400.0, 2.0)])
def test_exact_cooling_with_sliding_matches_an_independent_integration(a, b):
    T0, dt = 2e-3, 0.004
    ref = solve_ivp(lambda t, y: [-a * max(y[0], 0) ** 1.5 - b * math.sqrt(max(y[0], 0))],
                    (0, dt), [T0], rtol=1e-11, atol=1e-16).y[0, -1]
    got = exact_cooling_sliding(T0, a, b, dt)
    assert got == pytest.approx(max(ref, 0.0), rel=1e-6, abs=1e-14)
    if b == 0.0:
        assert got == exact_cooling(T0, a, dt)


def test_sliding_loss_stops_at_zero_in_finite_time():
    # a = 0: sqrt(T) falls linearly, b t / 2, and stays at 0
    assert exact_cooling_sliding(1e-4, 0.0, 0.1, 0.2) == pytest.approx((1e-2 - 0.01) ** 2,
                                                                       abs=1e-18)
    assert exact_cooling_sliding(1e-4, 5.0, 0.1, 10.0) == 0.0


def test_steady_balance_with_the_sliding_loss_reaches_its_algebraic_temperature():
    phi, p, prod = 0.56, 4500.0, 20000.0
    T_root = brentq(lambda T: dissipation_W_m3(phi, T, 0.0, PRM)
                    + sliding_dissipation_W_m3(p, T, PRM) - prod, 1e-12, 10.0, xtol=1e-16)
    # by hand: the sliding loss's rate b and the loss itself
    assert sliding_rate(phi, p, PRM) == pytest.approx(0.358 * p / (0.00635 * 1.5 * 7800 * phi))
    shape = (3, 3)
    grid = TemperatureGrid(spacing_m=0.01)
    err = []
    for dt in (1e-4, 5e-5):
        T = np.full(shape, 1e-3)
        for _ in range(int(round(0.4 / dt))):
            T = step_temperature_pressed(T, np.full(shape, phi), np.full(shape, prod),
                                         np.zeros(shape), np.zeros(shape), np.zeros(shape),
                                         np.full(shape, p), dt, grid, PRM)
        err.append(T[1, 1] / T_root - 1.0)
    # the Strang split's steady state is second order in dt (temperature_step.py)
    assert abs(err[0]) < 3e-4
    assert err[0] / err[1] == pytest.approx(4.0, rel=0.05)
    # without the sliding loss Lun's Gamma alone balances far hotter
    T_lun = brentq(lambda T: dissipation_W_m3(phi, T, 0.0, PRM) - prod, 1e-12, 10.0)
    assert T_lun > 2.5 * T_root


def test_off_the_balance_is_the_plain_one_bit_for_bit():
    rng = np.random.default_rng(2)
    shape = (6, 5)
    T = rng.uniform(0, 3e-3, shape)
    phi = rng.uniform(0, 0.6, shape)
    prod = rng.uniform(0, 1e4, shape)
    grid = TemperatureGrid(spacing_m=0.01)
    off = PRM._replace(sliding_coefficient=0.0)
    a = step_temperature(T, phi, prod, np.zeros(shape), np.zeros(shape), 1e-4, grid, off)
    b = step_temperature_pressed(T, phi, prod, np.zeros(shape), np.zeros(shape),
                                 np.zeros(shape), rng.uniform(0, 5e3, shape), 1e-4, grid, off)
    assert np.array_equal(a, b)


def test_the_shear_cells_points_give_k_f_and_the_calibration_switches_it_on_only_when_asked():
    from types import SimpleNamespace

    from vibroflow.calibration.shear_temperature import kinetic_parameters, sliding_table
    from vibroflow.continuum.temperature_field import calibrated_kinetic_parameters
    cell = kinetic_parameters(0.00635, 7800.0, 0.85)
    rows = []
    for phi, gd, T, p, k_f in ((0.598, 3.6, 4.3e-4, 4300.0, 0.35),
                               (0.564, 36.0, 1.7e-2, 4600.0, 0.37)):
        # tau_eq = mu_eq p closes tau gamma_dot = Lun's Gamma + k_f p sqrt(T) / d by hand
        tau = (dissipation_W_m3(phi, T, gd, cell) + k_f * p * math.sqrt(T) / 0.00635) / gd
        rows.append({"phi": phi, "shear_rate": gd, "granular_temperature": T,
                     "mu_eq": tau / p, "mean_pressure": p})
    rows.append({**rows[0], "steady": False, "granular_temperature": 1.0})
    tab = sliding_table(rows, 0.00635, 7800.0, 0.85)
    assert tab["sliding_coefficient"] == pytest.approx(0.36, rel=1e-12)
    assert tab["sliding_coefficient_stderr"] == pytest.approx(0.01, rel=1e-9)
    assert tab["dense_dissipation"] is False
    base = KineticParameters()
    kin = SimpleNamespace(sliding_coefficient=0.36, dense_dissipation=False, phi_rcp=None)
    assert calibrated_kinetic_parameters(base, SimpleNamespace(kinetic=kin)) == base
    kin.dense_dissipation = True
    on = calibrated_kinetic_parameters(base, SimpleNamespace(kinetic=kin))
    assert on == base._replace(sliding_coefficient=0.36)
