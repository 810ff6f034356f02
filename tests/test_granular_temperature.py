"""The granular temperature's closures and step against known answers: Haff's law of homogeneous
cooling, the algebraic temperature of steady simple shear and its Bagnold scaling, the decay of
a Fourier mode by conduction, energy conservation and a wall flux's energy, and the closures'
limits (ideal gas, divergence at random close packing, Lun et al.'s pressure)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from vibroflow.continuum.kinetic_theory import (LUN_SAVAGE, KineticParameters,
                                                pressure_Pa, radial_distribution,
                                                shear_viscosity_Pa_s)
from vibroflow.continuum.temperature_step import (TemperatureGrid, conduct, edge_heating_W_m3,
                                                  fluctuation_energy_J_m, step_temperature)

STEEL = KineticParameters(diameter_m=0.00635, density_kg_m3=7800.0, restitution=0.8,
                          phi_rcp=0.64)
GRID = TemperatureGrid(spacing_m=0.019)


def g0_paper(phi, phi_c):
    """Chialvo & Sundaresan (2013): Carnahan-Starling plus 1.1596 phi^2 / (phi_c - phi)^1.5."""
    return (2 - phi) / (2 * (1 - phi) ** 3) + 1.1596 * phi ** 2 / (phi_c - phi) ** 1.5


def eta_factor(phi, e, g0):
    """Gidaspow's (1994) shear viscosity over rho_s d sqrt(T) (-)."""
    return (4 / 5 * phi ** 2 * g0 * (1 + e) / math.sqrt(math.pi)
            + 10 * math.sqrt(math.pi) / (96 * (1 + e) * g0) * (1 + 4 / 5 * phi * g0 * (1 + e)) ** 2)


def gamma_factor(phi, e, g0):
    """The dissipation 12 (1 - e^2) phi^2 g0 / sqrt(pi) over rho_s T^(3/2) / d (-)."""
    return 12 * (1 - e ** 2) * phi ** 2 * g0 / math.sqrt(math.pi)


def uniform(value, shape=(4, 3)):
    return np.full(shape, float(value))


def advance(T, phi, dt, n, production=None, heating=None, shear_rate=0.0, prm=STEEL,
            grid=GRID):
    zeros = np.zeros_like(T)
    rate = np.full_like(T, shear_rate)
    for _ in range(n):
        P = zeros if production is None else production(T)
        T = step_temperature(T, phi, P, zeros if heating is None else heating, rate, dt, grid,
                             prm)
    return T


@pytest.mark.parametrize("dt_over_tau", [0.01, 0.3, 3.0, 100.0])
def test_homogeneous_cooling_follows_haffs_law_at_any_step(dt_over_tau):
    phi, T0 = 0.45, 0.01
    e, d = STEEL.restitution, STEEL.diameter_m
    # (3/2) rho_s phi dT/dt = -Gamma  =>  T = T0 / (1 + t / tau)^2, tau = 2 / (a sqrt(T0))
    a = gamma_factor(phi, e, g0_paper(phi, STEEL.phi_rcp)) / (1.5 * phi * d)
    tau = 2 / (a * math.sqrt(T0))
    dt = dt_over_tau * tau
    n = max(1, int(round(5 * tau / dt)))
    T = advance(uniform(T0), uniform(phi), dt, n)
    haff = T0 / (1 + n * dt / tau) ** 2
    assert np.allclose(T, haff, rtol=0.02)
    assert np.all(T > 0)


def steady_shear_temperature(shear_rate, phi, prm):
    """Stepped: production eta(phi, T) gamma_dot^2 from the closure, until steady."""
    d, e = prm.diameter_m, prm.restitution
    g0 = g0_paper(phi, prm.phi_rcp)
    T_alg = eta_factor(phi, e, g0) * (d * shear_rate) ** 2 / gamma_factor(phi, e, g0)
    a = gamma_factor(phi, e, g0) / (1.5 * phi * d)
    tau = 2 / (a * math.sqrt(T_alg))

    def production(T):
        return np.array([[shear_viscosity_Pa_s(phi, t, prm) * shear_rate ** 2 for t in row]
                         for row in T])

    T = advance(uniform(0.01 * T_alg, (2, 2)), uniform(phi, (2, 2)), 0.05 * tau, 1000,
                production=production, shear_rate=shear_rate, prm=prm)
    return T, T_alg


@pytest.mark.parametrize("phi", [0.1, 0.5])
def test_steady_simple_shear_balances_production_and_dissipation(phi):
    d = STEEL.diameter_m
    T1, alg1 = steady_shear_temperature(5.0, phi, STEEL)
    T2, alg2 = steady_shear_temperature(20.0, phi, STEEL)
    assert np.allclose(T1, alg1, rtol=0.01)
    assert np.allclose(T2, alg2, rtol=0.01)
    # Bagnold scaling T ~ (d gamma_dot)^2
    assert T2.mean() / T1.mean() == pytest.approx((20.0 * d) ** 2 / (5.0 * d) ** 2, rel=0.01)


def test_a_fourier_mode_decays_at_the_analytic_rate_by_conduction():
    nx, nz, h = 64, 48, 0.01
    kappa, capacity = 3.0, 1.5 * 7800 * 0.5
    x = (np.arange(nx) + 0.5) * h
    z = (np.arange(nz) + 0.5) * h
    kx, kz = math.pi / (nx * h), 2 * math.pi / (nz * h)  # zero-flux modes: cosines
    mode = np.outer(np.cos(kx * x), np.cos(kz * z))
    rate = kappa * (kx ** 2 + kz ** 2) / capacity  # 1/s
    T = 0.01 + 0.002 * mode
    dt = 0.01 / rate
    n = 150
    cap, kap = uniform(capacity, (nx, nz)), uniform(kappa, (nx, nz))
    for _ in range(n):
        T = conduct(T, cap, kap, dt, h)
    amplitude = np.sum((T - 0.01) * mode) / np.sum(mode * mode)
    measured = -math.log(amplitude / 0.002) / (n * dt)
    assert measured == pytest.approx(rate, rel=0.02)
    # zero-flux edges: the mean is kept
    assert T.mean() == pytest.approx(0.01, rel=1e-12)


def test_zero_flux_edges_conserve_the_fluctuation_energy_with_empty_cells():
    rng = np.random.default_rng(3)
    elastic = STEEL._replace(restitution=1.0)  # no dissipation
    shape = (20, 15)
    phi = rng.uniform(0.05, 0.6, shape)
    phi[:, 11:] = 0.0  # the bed's free surface: empty cells above
    phi[3, 5] = 0.0
    T = rng.uniform(0.001, 0.05, shape)
    E0 = fluctuation_energy_J_m(T, phi, GRID, elastic)
    T = advance(T, phi, 0.05, 50, prm=elastic)
    assert fluctuation_energy_J_m(T, phi, GRID, elastic) == pytest.approx(E0, rel=1e-12)
    assert np.all(T >= 0)


def test_a_given_edge_flux_adds_flux_times_area_times_time():
    rng = np.random.default_rng(4)
    elastic = STEEL._replace(restitution=1.0)
    shape = (12, 10)
    phi = rng.uniform(0.2, 0.6, shape)
    T = rng.uniform(0.001, 0.05, shape)
    flux, dt, n = 35.0, 0.002, 40  # W/m^2 through the floor
    heating = edge_heating_W_m3(shape, GRID.spacing_m, bottom_W_m2=flux)
    E0 = fluctuation_energy_J_m(T, phi, GRID, elastic)
    T = advance(T, phi, dt, n, heating=heating, prm=elastic)
    gained = fluctuation_energy_J_m(T, phi, GRID, elastic) - E0
    floor_m = shape[0] * GRID.spacing_m  # per metre of thickness
    assert gained == pytest.approx(flux * floor_m * n * dt, rel=1e-10)


def test_the_pressure_tends_to_the_ideal_gas_and_g0_diverges_at_close_packing():
    T = 0.02
    for phi in (1e-4, 1e-6):
        ideal = STEEL.density_kg_m3 * phi * T
        assert pressure_Pa(phi, T, STEEL) / ideal == pytest.approx(1.0, abs=10 * phi)
    for prm in (STEEL, STEEL._replace(g0_form=LUN_SAVAGE)):
        near = [radial_distribution(prm.phi_rcp - gap, prm) for gap in (1e-1, 1e-2, 1e-3, 1e-4)]
        assert all(b > a for a, b in zip(near, near[1:]))
        assert all(b > 10 * a for a, b in zip(near[1:], near[2:]))  # as gap^-1.5 or steeper
        assert near[-1] > 1e4
        assert math.isfinite(radial_distribution(prm.phi_rcp + 0.1, prm))
    # the dilute limit is Carnahan-Starling's, whose expansion is 1 + 5 phi / 2
    for prm in (STEEL, STEEL._replace(g0_form=LUN_SAVAGE)):
        assert radial_distribution(1e-4, prm) == pytest.approx(1 + 2.5e-4, rel=1e-6)


@pytest.mark.parametrize("phi, e", [(0.3, 0.9), (0.55, 0.7)])
def test_lun_pressure_against_the_papers_formula(phi, e):
    prm = STEEL._replace(restitution=e)
    T, rho_s = 0.015, prm.density_kg_m3
    paper = rho_s * phi * T * (1 + 2 * (1 + e) * phi * g0_paper(phi, prm.phi_rcp))
    assert pressure_Pa(phi, T, prm) == pytest.approx(paper, rel=1e-12)


def test_jenkins_correlation_length_raises_the_steady_shear_temperature_as_its_balance_says():
    # Gamma / (L/d) with L/d = c_L d gamma_dot / sqrt(T) > 1: eta gamma_dot^2 = Gamma d / L gives
    # T = (E c_L / G)^(2/3) (d gamma_dot)^2, E and G the viscosity's and dissipation's factors
    phi, d, e = 0.55, STEEL.diameter_m, STEEL.restitution
    g0 = g0_paper(phi, STEEL.phi_rcp)
    E, G = eta_factor(phi, e, g0), gamma_factor(phi, e, g0)
    c_L = 10 * math.sqrt(E / G)
    prm = STEEL._replace(correlation_coefficient=c_L)
    for shear_rate in (5.0, 20.0):
        T, _ = steady_shear_temperature(shear_rate, phi, prm)
        expected = (E * c_L / G) ** (2 / 3) * (d * shear_rate) ** 2
        assert np.allclose(T, expected, rtol=0.01)


def test_implicit_conduction_keeps_a_spike_positive_and_bounded_at_a_huge_step():
    shape, h = (9, 7), 0.01
    T = np.zeros(shape)
    T[4, 3] = 1.0
    cap = uniform(10.0, shape)  # a dilute gas: little capacity
    cap[0, :] = 0.0  # an empty column
    kap = uniform(50.0, shape)
    kap[0, :] = 0.0
    out = conduct(T, cap, kap, 1e3, h)
    assert np.all(out >= 0) and out.max() <= 1.0
    # conserved to the round-off of a system of condition ~ dt kappa / (h^2 capacity) = 5e8
    assert np.sum(cap * out) == pytest.approx(np.sum(cap * T), rel=1e-6)
