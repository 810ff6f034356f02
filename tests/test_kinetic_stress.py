"""The granular temperature in the stress (vibroflow/continuum/kinetic_stress.py; models.md 5.7):
the gas's kinetic viscosity against hand values and Chapman & Enskog's dilute limit, the
kinetic pressure's cap at the connection packing, the balance temperature against the
dissipation it balances, and steady simple shear: the T-coupled return map gives the
calibrated mu(I) at the balance temperature and mu(r I) at a fixed hotter one."""
from __future__ import annotations

import math

import numpy as np
import pytest

from vibroflow.continuum.constitutive import ContinuumMaterial
from vibroflow.continuum.kinetic_stress import (RATE_RATIO, balance_temperature,
                                                kinetic_stress, kinetic_stress_cells)
from vibroflow.continuum.kinetic_theory import (KineticParameters, dissipation_W_m3,
                                                frictional_pressure_Pa, pressure_Pa,
                                                shear_viscosity_Pa_s, sliding_dissipation_W_m3)
from vibroflow.continuum.rheology import mu_of_I
from vibroflow.continuum.stress_update import update_stress_points_rated
from vibroflow.continuum.temperature_field import production_W_m3
from vibroflow.continuum.temperature_step import (TemperatureGrid, step_temperature,
                                                  step_temperature_pressed)
from vibroflow.continuum.timestep import kinetic_temperature_limit, kinetic_wave_speed

PRM = KineticParameters(diameter_m=0.00635, density_kg_m3=7800.0, restitution=0.9,
                        phi_rcp=0.64)


def test_gidaspow_viscosity_against_a_hand_value():
    # phi = 0.3, T = 0.01 m^2/s^2, e = 0.9: g0 = 2.478134 + 1.1596 0.09 / 0.34^1.5 = 3.004554,
    # rho_s d sqrt(T) = 4.953 kg/m^2/s; collisional 0.8 0.09 4.953 3.004554 1.9 / sqrt(pi)
    # = 1.148575 Pa s, kinetic 10 sqrt(pi) 4.953 / (96 1.9 3.004554) (1 + 0.8 0.3 3.004554
    # 1.9)^2 = 0.899836 Pa s
    assert shear_viscosity_Pa_s(0.3, 0.01, PRM) == pytest.approx(2.048411, rel=1e-6)


def test_dilute_viscosity_is_chapman_enskogs_hard_sphere_value():
    # elastic hard spheres, phi -> 0: eta = 5 m sqrt(T / pi) / (16 d^2) = 5 sqrt(pi) rho_s d
    # sqrt(T) / 96 (Chapman & Cowling), 0.457238 Pa s at T = 0.01 m^2/s^2
    elastic = PRM._replace(restitution=1.0)
    assert shear_viscosity_Pa_s(1e-9, 0.01, elastic) == pytest.approx(0.4572377, rel=1e-6)


def _one(density, T, L, stress=(0.0, 0.0, 0.0, 0.0), gamma_dot=0.0, phase=0, prm=PRM,
         phi_cap=0.6, T_cap=np.inf, eta_factor=np.inf):
    out = np.empty((1, 5))
    kinetic_stress(np.array([density]), np.array([T]), np.array([L], float),
                   np.array([stress], float), np.array([gamma_dot]),
                   np.array([phase], np.int8), prm, phi_cap, T_cap, eta_factor, out)
    return out[0]


def test_a_partly_filled_eulerian_cell_reads_its_own_solid_fraction():
    # a 1 cm cell half filled with material at phi 0.6 (rho 4680 kg/m^3, m 0.234 kg/m): the
    # cell's solid fraction is 0.3, where Lun's pressure at T = 0.01 m^2/s^2, e = 0.9 is
    # 7800 0.3 0.01 (1 + 2 1.9 0.3 3.004554) = 103.5495 Pa and Gidaspow's viscosity 2.048411
    # Pa s (above); acting through the material's half of the cell, the stress is twice
    # those, so that the cell's force is the cell's pressure on its whole area
    rate, h, f = 20.0, 0.01, 0.5
    rho = 0.6 * 7800.0
    out = np.empty((1, 5))
    kinetic_stress_cells(np.array([rho]), np.array([f * rho * h * h]), h, np.array([0.01]),
                         np.array([[0.0, rate, 0.0, 0.0]]), np.zeros((1, 4)), np.zeros(1),
                         np.zeros(1, np.int8), PRM, 0.6, np.inf, np.inf, out)
    assert out[0, 0] == pytest.approx(-103.5495 / f, rel=1e-6)
    assert out[0, 1] == pytest.approx(-103.5495 / f, rel=1e-6)
    assert out[0, 2] == pytest.approx(2.048411 * rate / f, rel=1e-6)


def test_a_full_eulerian_cell_is_a_points_kinetic_stress():
    # f = 1: the cell's solid fraction is its material's, to round-off (m / (rho h^2) is 1
    # within an ulp), gas and connected
    rho = np.array([0.55, 0.59, 0.3]) * 7800.0
    h = 0.01
    args = (np.array([0.02, 0.005, 0.01]), np.array([[1.0, 2.0, -3.0, 0.5]] * 3),
            np.array([[-50.0, -80.0, 10.0, -60.0]] * 3), np.array([0.0, 3.0, 0.0]),
            np.array([0, 1, 0], np.int8), PRM, 0.6, 0.05, 1e-3)
    a = np.empty((3, 5))
    b = np.empty((3, 5))
    kinetic_stress(rho, *args, a)
    kinetic_stress_cells(rho, rho * h * h, h, *args, b)
    np.testing.assert_allclose(b, a, rtol=1e-14, atol=0.0)


def test_a_sheared_gas_carries_the_kinetic_viscosity_and_both_pressures():
    prm = PRM._replace(frictional_Pa=0.05, frictional_phi_min=0.2)
    rate, T, phi = 20.0, 0.01, 0.3
    s = _one(phi * 7800.0, T, (0.0, rate, 0.0, 0.0), prm=prm)
    p = pressure_Pa(phi, T, prm) + frictional_pressure_Pa(phi, prm)
    # frictional: 0.05 (0.1)^2 / 0.34^5 = 0.0005 / 0.0045435 = 0.1100463 Pa
    assert frictional_pressure_Pa(phi, prm) == pytest.approx(0.1100463, rel=1e-6)
    assert s[2] == pytest.approx(2.048411 * rate, rel=1e-6)   # 2 eta D_xz, D_xz = L_xz / 2
    assert s[0] == s[1] == s[3] == pytest.approx(-p, rel=1e-12)
    assert s[RATE_RATIO] == 1.0
    # the viscosity capped at (3/160) rho dx^2 / dt in a nearly empty cell
    cap = _one(1.0, T, (0.0, rate, 0.0, 0.0), eta_factor=1.0)
    assert cap[2] == pytest.approx(3.0 / 160.0 * rate, rel=1e-12)


def test_connected_material_gets_only_the_capped_kinetic_pressure():
    # above the connection packing phi_cap the elastic-plastic pressure carries the compression:
    # Lun's pressure stays at its phi_cap value, no deviatoric part
    T = 0.01
    s = _one(0.63 * 7800.0, T, (0.0, 5.0, 0.0, 0.0), stress=(-1e3, -1e3, 0.0, -1e3), phase=1)
    assert s[0] == s[1] == s[3] == pytest.approx(-pressure_Pa(0.6, T, PRM), rel=1e-12)
    assert s[2] == 0.0
    # no temperature: nothing added, the plain mu(I) law
    assert list(_one(0.63 * 7800.0, 0.0, (0.0, 5.0, 0.0, 0.0), phase=2)) == [0, 0, 0, 0, 1]


def test_a_gas_compressed_past_the_connection_packing_reads_both_pressures_there():
    # a disconnected cell may be compressed past phi_cap in a step (the Eulerian's remap): both
    # pressures are read at phi_cap, so the frictional one's (phi_rcp - phi)^-5 stays bounded
    # (Fr 10.6 Pa, phi_min 0.573, phi_rcp 0.635, the joint fit on the DEM draw of
    # tests/data/tub47-quick-dem, validation.md 24: at phi_cap 0.6, 10.6 0.027^2 / 0.035^5 =
    # 147.2 Pa; at 0.6349 it would be 1.2e17 Pa)
    prm = PRM._replace(phi_rcp=0.635, frictional_Pa=10.6, frictional_phi_min=0.573)
    T = 0.01
    s = _one(0.6349 * 7800.0, T, (0.0, 0.0, 0.0, 0.0), prm=prm)
    p = pressure_Pa(0.6, T, prm) + 10.6 * 0.027 ** 2 / 0.035 ** 5
    assert s[0] == s[1] == s[3] == pytest.approx(-p, rel=1e-9)


@pytest.mark.parametrize("k_f", [0.0, 0.36])
@pytest.mark.parametrize("c_L", [0.0, 2.0])
def test_the_balance_temperature_balances_the_plastic_work(c_L, k_f):
    prm = PRM._replace(correlation_coefficient=c_L, sliding_coefficient=k_f)
    for phi, tau, rate, p in ((0.58, 400.0, 10.0, 1e3), (0.5, 50.0, 0.1, 2e2),
                              (0.6, 1e4, 50.0, 2e4), (0.58, 400.0, 10.0, 1e6)):
        T = balance_temperature(phi, tau, rate, prm, p)
        loss = dissipation_W_m3(phi, T, rate, prm) + sliding_dissipation_W_m3(p, T, prm)
        assert loss == pytest.approx(tau * rate, rel=1e-10)
        if k_f == 0.0:   # no sliding loss: the pressure is not read
            assert T == balance_temperature(phi, tau, rate, prm)
    assert balance_temperature(0.58, 400.0, 0.0, prm, 1e3) == 0.0


def test_the_sliding_balance_tends_to_its_own_root_where_lun_s_loss_vanishes():
    # e -> 1: Gamma -> 0 and tau gamma_dot = k_f p sqrt(T) / d, T = (tau gamma_dot d / (k_f p))^2
    prm = PRM._replace(restitution=1.0 - 1e-9, sliding_coefficient=0.36)
    T = balance_temperature(0.58, 400.0, 10.0, prm, 1e3)
    assert T == pytest.approx((400.0 * 10.0 * 0.00635 / (0.36 * 1e3)) ** 2, rel=1e-6)


def _steady_shear(rate, T_fixed=None, steps=6000, dt=1e-5, p0=1e3, prm=PRM):
    """One connected point in simple shear (L_xz = rate) from the isotropic stress -p0, its
    return map's rate ratio from kinetic_stress and its T from the balance on one cell
    (T_fixed: T held there; with prm's dense sliding loss the balance reads the point's
    pressure); returns (tau / p, I, T, T_bal, r)."""
    mat = ContinuumMaterial(critical_solid_fraction=0.6)
    params = mat.as_array()
    rho = np.array([mat.critical_density * 1.01])
    stress = np.array([[-p0, -p0, 0.0, -p0]])
    L = np.array([[0.0, rate, 0.0, 0.0]])
    gd = np.zeros(1)
    st = np.zeros(1, np.int8)
    T = np.array([T_fixed if T_fixed is not None else 0.0])
    s_kin = np.zeros((1, 5))
    power = np.zeros(1)
    phi = np.array([[rho[0] / PRM.density_kg_m3]])
    grid = TemperatureGrid(spacing_m=0.01)
    zero = np.zeros((1, 1))
    for _ in range(steps):
        kinetic_stress(rho, T, L, stress, gd, st, prm, 0.6 * 1.01, np.inf, np.inf, s_kin)
        update_stress_points_rated(stress, L, rho, dt, params, gd, st,
                                   s_kin[:, RATE_RATIO].copy())
        production_W_m3(stress, L, gd, s_kin, power)
        if T_fixed is None and prm.sliding_coefficient > 0.0:
            pm = np.full((1, 1), -(stress[0, 0] + stress[0, 1] + stress[0, 3]) / 3)
            T = step_temperature_pressed(T.reshape(1, 1), phi, power.reshape(1, 1), zero, zero,
                                         zero, pm, dt, grid, prm).ravel()
        elif T_fixed is None:
            T = step_temperature(T.reshape(1, 1), phi, power.reshape(1, 1), zero, zero, dt,
                                 grid, prm).ravel()
    s = stress[0]
    p = -(s[0] + s[1] + s[3]) / 3
    d = np.array([s[0] + p, s[1] + p, s[3] + p])
    tau = math.sqrt(0.5 * (d @ d) + s[2] ** 2)
    I = rate * mat.diameter / math.sqrt(p / mat.solid_density)
    tb = balance_temperature(phi[0, 0], tau, gd[0], prm, p)
    return tau / p, I, mat, T[0], tb, s_kin[0, RATE_RATIO]


def test_steady_simple_shear_keeps_the_calibrated_mu_of_I_at_the_balance_temperature():
    ratio, I, mat, T, tb, r = _steady_shear(10.0)
    assert T == pytest.approx(tb, rel=1e-3)            # the balance reached its algebraic T
    assert ratio == pytest.approx(float(mu_of_I(I, mat.mu_s, mat.mu_2, mat.I_0)), rel=1e-4)


def test_with_the_sliding_loss_steady_shear_keeps_the_calibrated_mu_of_I_at_its_own_balance():
    # the balance that carries T loses k_f p sqrt(T) / d as well as Lun's Gamma; the stress's
    # T_bal is where that same balance rests, so steady shear is again r = 1, mu(I) exactly
    prm = PRM._replace(sliding_coefficient=0.36)
    ratio, I, mat, T, tb, r = _steady_shear(10.0, prm=prm)
    lun_only = _steady_shear(10.0)[3]
    assert T < 0.75 * lun_only                         # the sliding loss takes its share
    assert T == pytest.approx(tb, rel=1e-3)
    assert r == pytest.approx(1.0, rel=1e-3)
    assert ratio == pytest.approx(float(mu_of_I(I, mat.mu_s, mat.mu_2, mat.I_0)), rel=1e-4)


def test_material_hotter_than_its_shear_flows_at_mu_of_r_I():
    # T four times the balance value: r = 1/2, the friction mu(I / 2) (analytic steady state)
    ratio, I, mat, T, tb, r = _steady_shear(10.0)
    hot, I_hot, _, _, tb_hot, r_hot = _steady_shear(10.0, T_fixed=4.0 * tb)
    assert r_hot == pytest.approx(math.sqrt(tb_hot / (4.0 * tb)), rel=1e-12)
    assert hot == pytest.approx(float(mu_of_I(r_hot * I_hot, mat.mu_s, mat.mu_2, mat.I_0)),
                                rel=1e-4)
    assert hot < ratio


def test_the_kinetic_wave_is_the_ideal_gas_sound_dilute_and_capped_at_the_elastic_one():
    # phi -> 0: p = rho_s phi T, dp/drho = T, the isothermal sound speed sqrt(T)
    assert kinetic_wave_speed(1e-6, 0.01, PRM) == pytest.approx(0.1, rel=1e-4)
    # the limit T makes the wave at phi_cap as fast as the elastic one (c_k^2 linear in T)
    T_cap = kinetic_temperature_limit(16.2, 0.57, PRM)
    assert kinetic_wave_speed(0.57, T_cap, PRM) == pytest.approx(16.2, rel=1e-6)
    # beyond it the pressure reads T_cap: hotter material adds no stiffness
    s = _one(0.57 * 7800.0, 10.0 * T_cap, (0.0, 0.0, 0.0, 0.0), phase=1, phi_cap=0.57,
             T_cap=T_cap)
    assert s[0] == pytest.approx(-pressure_Pa(0.57, T_cap, PRM), rel=1e-12)
