"""The walls' feed of fluctuation energy (continuum/wall_energy_flux.py): Johnson & Jackson's
flux against a hand value, a steady column against its analytic solution, energy conservation,
zero slip and zero T, the Galilean check, and both formulations' wall contacts feeding T."""
from __future__ import annotations

import math

import numpy as np
import pytest

from continuum_helpers import lattice, shaken_mpm_layer

from vibroflow.continuum.boundary import Plane
from vibroflow.continuum.constitutive import ContinuumMaterial
from vibroflow.continuum.eulerian import solver as eulerian
from vibroflow.continuum.eulerian.mesh import EulerianMesh
from vibroflow.continuum.eulerian.wall import MeshWall
from vibroflow.continuum.grid import Grid
from vibroflow.continuum.grid_update import LabFrame
from vibroflow.continuum.kinetic_theory import (LUN_SAVAGE, KineticParameters,
                                                conductivity_kg_m_s, dissipation_W_m3)
from vibroflow.continuum.mpm import solver as mpm
from vibroflow.continuum.temperature_field import TemperatureModel, fluctuation_energy_J_m
from vibroflow.continuum.temperature_step import (TemperatureGrid, edge_heating_W_m3,
                                                  step_temperature_walls)
from vibroflow.continuum.timestep import stable_dt
from vibroflow.continuum.wall_energy_flux import (FRICTION_RULE, WallEnergy, cell_wall_terms,
                                                  collision_loss_W_m2, contact_terms,
                                                  johnson_jackson_flux_W_m2, partition_terms,
                                                  slip_production_W_m2,
                                                  wall_cooling_coefficient)

PRM = KineticParameters(diameter_m=0.00635, density_kg_m3=7800.0, restitution=0.9,
                        phi_rcp=0.64, g0_form=LUN_SAVAGE)


def test_johnson_jackson_flux_against_a_hand_value():
    # phi = 0.5, T = 0.01 m^2/s^2, slip 0.2 m/s, phi' = 0.5, e_w = 0.8, rho_s = 7800 kg/m^3,
    # phi_max = 0.64, g0 = (1 - 0.5/0.64)^-1.6 = 11.3784 (Lun & Savage):
    # production 0.9069 x 0.5 x 7800 x 0.5 x 11.3784 x 0.1 x 0.04 / 0.64 = 125.76 W/m^2,
    # loss 1.3603 x 0.36 x 7800 x 0.5 x 11.3784 x 0.001 / 0.64 = 33.956 W/m^2
    assert slip_production_W_m2(0.5, 0.5, 0.01, 0.2, PRM) == pytest.approx(125.76, rel=1e-4)
    assert collision_loss_W_m2(0.8, 0.5, 0.01, PRM) == pytest.approx(33.956, rel=1e-4)
    assert johnson_jackson_flux_W_m2(0.5, 0.8, 0.5, 0.01, 0.2, PRM) == pytest.approx(
        91.81, rel=1e-3)


def test_zero_slip_and_zero_temperature_give_zero_flux():
    assert slip_production_W_m2(1.0, 0.5, 0.01, 0.0, PRM) == 0.0
    assert johnson_jackson_flux_W_m2(1.0, 0.5, 0.5, 0.0, 0.3, PRM) == 0.0
    assert johnson_jackson_flux_W_m2(1.0, 1.0, 0.5, 0.04, 0.0, PRM) == 0.0   # elastic wall


def test_the_friction_rule_is_the_wall_frictions_work_capped_at_a_diffuse_wall():
    # one cell of side 1 cm touching a wall over 1 cm, slip 0.2 m/s, phi 0.5, T 0.01: J&J with
    # phi' = 1 gives 2 x 125.76 = 251.5 W/m^2, 2.515 W/m over the contact; a friction power
    # below it (1 W/m) is the production, one above it (5 W/m) is capped there
    h = 0.01
    phi = np.full((1, 1), 0.5)
    T = np.full((1, 1), 0.01)
    for friction_W_m, expected in ((1.0, 1.0), (5.0, 2.5152837)):
        sums = np.array([[[h, h * 0.04, friction_W_m, 0.0]]])
        heat, cool = cell_wall_terms(phi, T, sums, h, 1.0, FRICTION_RULE, True, 1e-3, PRM)
        assert heat[0, 0] * h * h == pytest.approx(expected, rel=1e-6)
        assert cool[0, 0] == 0.0                  # an elastic wall loses nothing


def test_the_partitions_touch_a_pressed_column_over_both_faces():
    # a column of cross-section 1e-4 m^2 between partitions 0.05 m apart touches them over
    # 2 x 1e-4 / 0.05 = 4e-3 m per metre; its friction power is the partition friction's
    # 2 mu_p p V / L_y |v| = 2 x 0.3 x 1000 x 1e-4 / 0.05 x 0.5 = 0.6 W/m (below the step's
    # cap m |v| / dt); a column without pressure does not touch them
    v = np.array([[0.3, -0.4], [0.3, -0.4]])
    stress = np.array([[-1000.0, -1000.0, 0.0, -1000.0], [100.0, 100.0, 0.0, 100.0]])
    out = np.zeros((2, 4))
    partition_terms(v, np.array([0.5, 0.5]), np.array([1e-4, 1e-4]), stress, 0.3, 0.05, 1e-4,
                    out)
    assert out[0] == pytest.approx([4e-3, 4e-3 * 0.25, 0.6, 0.0], rel=1e-12)
    assert np.all(out[1] == 0.0)


def _kappa_gamma_factors(phi):
    """K, G of kappa = K sqrt(T), Gamma = G T^(3/2) at a uniform phi (hand-derivable from the
    closures: both are exact powers of T)."""
    return conductivity_kg_m_s(phi, 1.0, PRM), dissipation_W_m3(phi, 1.0, 0.0, PRM)


def _steady(T0, phi, n, h, heat, cool, dt=2e-3, steps=6000):
    grid = TemperatureGrid(spacing_m=h)
    T = np.full((1, n), T0)
    ph = np.full((1, n), phi)
    zero = np.zeros((1, n))
    for _ in range(steps):
        T = step_temperature_walls(T, ph, zero, heat, cool, zero, dt, grid, PRM)
    return T[0]


def _column(phi, H, n):
    h = H / n
    z = (np.arange(n) + 0.5) * h
    K, G = _kappa_gamma_factors(phi)
    lam = math.sqrt(1.5 * G / K)
    return h, z, K, lam


def test_a_steady_column_heated_from_its_floor_matches_the_analytic_profile():
    # (2K/3) w'' = G w for w = T^(3/2), zero flux at the top z = H, flux q0 in at z = 0:
    # w = A cosh(lam (H - z)), lam = sqrt(3G / 2K), (2K/3) A lam sinh(lam H) = q0
    phi, H, n, q0 = 0.3, 0.03, 60, 200.0
    h, z, K, lam = _column(phi, H, n)
    A = q0 / (2.0 * K / 3.0 * lam * math.sinh(lam * H))
    exact = (A * np.cosh(lam * (H - z))) ** (2.0 / 3.0)
    heat = edge_heating_W_m3((1, n), h, bottom_W_m2=q0)
    T = _steady(exact.mean(), phi, n, h, heat, np.zeros((1, n)))
    assert np.max(np.abs(T / exact - 1.0)) < 0.03


def test_a_steady_column_fed_by_johnson_jackson_at_its_floor_matches_the_analytic_profile():
    # the floor's flux is the wall law at the floor's T0 = T(0): q0 = P sqrt(T0) - C T0^(3/2)
    # with P, C Johnson & Jackson's production and loss factors; with the column's
    # q0 = (2K/3) A lam sinh(lam H), T0^(3/2) = A cosh(lam H) (previous test) T0 is the root of
    # P sqrt(T0) - C T0^(3/2) = (2K/3) lam tanh(lam H) T0^(3/2)
    # on 1 mm cells at a step (5e-5 s) that resolves the wall cell's relaxation time
    # 1 / (a_w sqrt(T)) ~ 2 ms (the runs' cells are 10 times larger, their steps 5 times smaller)
    phi, H, n, slip, spec, ew = 0.3, 0.03, 30, 0.5, 0.4, 0.7
    h, z, K, lam = _column(phi, H, n)
    P = slip_production_W_m2(spec, phi, 1.0, slip, PRM)
    C = collision_loss_W_m2(ew, phi, 1.0, PRM)
    T0 = P / (C + 2.0 * K / 3.0 * lam * math.tanh(lam * H))
    assert P * math.sqrt(T0) - C * T0 ** 1.5 == pytest.approx(
        2.0 * K / 3.0 * lam * math.tanh(lam * H) * T0 ** 1.5, rel=1e-9)
    exact = T0 * (np.cosh(lam * (H - z)) / math.cosh(lam * H)) ** (2.0 / 3.0)
    sums = np.zeros((1, n, 4))
    sums[0, 0] = (h, h * slip ** 2, 0.0, 0.0)
    T = np.full((1, n), 0.5 * T0)
    ph = np.full((1, n), phi)
    zero = np.zeros((1, n))
    grid = TemperatureGrid(spacing_m=h)
    for _ in range(40000):
        heat, cool = cell_wall_terms(ph, T, sums, h, ew, spec, False, 1e-3, PRM)
        T = step_temperature_walls(T, ph, zero, heat, cool, zero, 5e-5, grid, PRM)
    assert np.max(np.abs(T[0] / exact - 1.0)) < 0.03


def test_the_wall_loss_alone_cools_exactly_and_takes_what_its_flux_says():
    # one closed cell touching a wall over its side h, elastic collisions (e = 1): the loss
    # dT/dt = -a_w T^(3/2) gives T = T0 / (1 + a_w sqrt(T0) t / 2)^2, a_w = (2/3) x the loss
    # factor x h / h^2 / (rho_s phi); the energy lost is the loss flux's integral over the wall
    prm = PRM._replace(restitution=1.0)
    phi, h, T0, ew, t = 0.4, 0.01, 0.02, 0.6, 0.5
    a_w = collision_loss_W_m2(ew, phi, 1.0, prm) * h / (h * h) / (1.5 * prm.density_kg_m3 * phi)
    assert wall_cooling_coefficient(ew, phi, h, h, prm) == pytest.approx(a_w, rel=1e-12)
    grid = TemperatureGrid(spacing_m=h)
    T = np.full((1, 1), T0)
    one = np.full((1, 1), phi)
    zero = np.zeros((1, 1))
    cool = np.full((1, 1), a_w)
    for _ in range(10):
        T = step_temperature_walls(T, one, zero, zero, cool, zero, t / 10, grid, prm)
    exact = T0 / (1.0 + 0.5 * a_w * math.sqrt(T0) * t) ** 2
    assert T[0, 0] == pytest.approx(exact, rel=1e-12)
    # energy lost = int_0^t loss(T(s)) h ds = 1.5 rho phi h^2 (T0 - T(t)) analytically
    lost = 1.5 * prm.density_kg_m3 * phi * h * h * (T0 - T[0, 0])
    s = np.linspace(0.0, t, 20001)
    Ts = T0 / (1.0 + 0.5 * a_w * math.sqrt(T0) * s) ** 2
    flux = collision_loss_W_m2(ew, phi, 1.0, prm) * Ts ** 1.5 * h
    assert lost == pytest.approx(np.trapezoid(flux, s), rel=1e-6)


def test_the_slip_production_integrated_equals_the_energy_gained():
    # a closed 3 x 4 grid, elastic grains and walls (no loss): the fluctuation energy gains
    # exactly the wall cells' production x wall length x dt every step, conduction moving it
    prm = PRM._replace(restitution=1.0)
    h, dt = 0.01, 1e-3
    phi = np.full((3, 4), 0.45)
    T = np.full((3, 4), 0.01)
    sums = np.zeros((3, 4, 4))
    sums[:, 0, 0] = h
    sums[:, 0, 1] = h * 0.3 ** 2
    grid = TemperatureGrid(spacing_m=h)
    zero = np.zeros((3, 4))
    for _ in range(50):
        e0 = fluctuation_energy_J_m(phi * prm.density_kg_m3 * h * h, T)
        gain = sum(slip_production_W_m2(0.5, 0.45, T[i, 0], 0.3, prm) for i in range(3)) * h * dt
        heat, cool = cell_wall_terms(phi, T, sums, h, 1.0, 0.5, False, 1e-3, prm)
        T = step_temperature_walls(T, phi, zero, heat, cool, zero, dt, grid, prm)
        e1 = fluctuation_energy_J_m(phi * prm.density_kg_m3 * h * h, T)
        assert e1 - e0 == pytest.approx(gain, rel=1e-9)


def test_a_contact_moving_with_its_wall_feeds_nothing_and_the_landing_is_the_dashpot_loss():
    n = np.array([[0.0, 1.0], [0.6, 0.8]])
    fn = np.array([5.0, 5.0])
    ft = np.array([0.3, -0.2])
    m = np.array([0.2, 0.2])
    l = np.array([0.01, 0.01])
    wall = np.array([0.7, -0.4])
    v = np.array(wall) + np.zeros((2, 2))
    out = np.zeros((2, 4))
    contact_terms(fn, ft, n, v - wall, m, l, 1e7, 0.2, 1e-4, out)
    assert np.all(out[:, 1:] == 0.0)          # same velocity as the wall: no slip, no landing
    out[:] = 0.0
    rel = np.array([[0.3, -0.5], [0.0, 0.0]])   # sliding at 0.3 m/s, landing at 0.5 m/s
    contact_terms(fn, ft, n, rel, m, l, 1e7, 0.2, 1e-4, out)
    c = 2 * 0.2 * math.sqrt(0.2 * 1e7 * 0.01)
    assert out[0] == pytest.approx([0.01, 0.01 * 0.09, 0.3 * 0.3, c * 0.25], rel=1e-12)
    assert np.all(out[1, 1:] == 0.0)


MAT = ContinuumMaterial()
DX = 0.01


def _sliding_block(method, wall_speed, block_speed):
    """A block of the critical density resting on a floor (gravity on) that moves at
    wall_speed (m/s) along x, the block moving at block_speed, T0 small: (system, state)."""
    walls = WallEnergy(restitution=0.8, specularity=1.0, landing=True)
    prm = KineticParameters(diameter_m=MAT.diameter, density_kg_m3=MAT.solid_density)
    sp = DX / 2
    kn = (MAT.bulk_modulus + 4 * MAT.shear_modulus / 3) / sp
    if method == "lagrangian":
        grid = Grid.periodic_strip(0.08, 0.0, 0.06, DX)
        floor = Plane((0.0, 0.0), (0.0, 1.0), kn, friction=0.3, velocity=(wall_speed, 0.0))
        system = mpm.MPMSystem(grid, MAT, stable_dt(MAT, DX, sp, [floor]),
                               frame=LabFrame((0.0, -9.81)), boundaries=[floor],
                               temperature=TemperatureModel(prm, DX, 1e-4, False, walls))
        state = mpm.init_state(system, lattice(0.0, 0.08, 0.0, 0.03, sp), sp * sp,
                               MAT.critical_density)
        state.v[:, 0] = block_speed
        return system, state
    mesh = EulerianMesh.box(0.0, 0.08, 0.0, 0.06, DX, periodic=True)
    wall = MeshWall((MAT.bulk_modulus + 4 * MAT.shear_modulus / 3) / mesh.h, 0.3)
    system = eulerian.EulerianSystem(mesh, MAT, stable_dt(MAT, DX, mesh.h, [wall]),
                                     frame=LabFrame((0.0, -9.81)), wall=wall,
                                     temperature=TemperatureModel(prm, mesh.h, 1e-4, False,
                                                                  walls))
    fill = mesh.inside & (system.x[:, 1] < 0.03)
    state = eulerian.init_state(system, np.where(fill, MAT.critical_density * mesh.h ** 2, 0.0))
    state.v[fill, 0] = block_speed
    return system, state


@pytest.mark.parametrize("method", ["lagrangian", "eulerian"])
def test_a_block_sliding_on_a_floor_is_heated_and_one_moving_with_it_is_not(method):
    # Galilean: a floor and a block moving together at 0.5 m/s (the Lagrangian Plane moves;
    # the Eulerian wall is the mesh's, at rest) feed what both at rest feed, to round-off
    adv = mpm.advance if method == "lagrangian" else eulerian.advance
    energies = []
    for wall_speed, block_speed in ((0.0, 0.5), (0.0, 0.0), (0.5, 0.5)):
        if method == "eulerian" and wall_speed:
            continue
        system, state = _sliding_block(method, wall_speed, block_speed)
        adv(system, state, 40)
        energies.append(fluctuation_energy_J_m(state.mass, state.temperature))
    assert energies[0] > 100.0 * energies[1]
    if method == "lagrangian":
        assert energies[2] == pytest.approx(energies[1], rel=1e-9)


def _shaken_layer(gamma, coupled, cycles=1):
    """continuum_helpers.shaken_mpm_layer with its T carried (coupled: with the kinetic
    pressure): the phases (-) and the floor's total normal force (N/m) of every step of the
    last of `cycles` cycles, and the layer's weight (N/m)."""
    prm = KineticParameters(diameter_m=MAT.diameter, density_kg_m3=MAT.solid_density)
    model = TemperatureModel(prm, DX, 1e-4, coupled, WallEnergy(restitution=0.8))
    phase, force = [], []
    for ph, state, floor in shaken_mpm_layer(gamma, temperature=model, cycles=cycles):
        phase.append(ph)
        force.append(state.history[floor.slot]["fn"].sum())
    return np.array(phase), np.array(force), 9.81 * state.mass.sum()


@pytest.mark.parametrize("coupled", [False, True])
def test_the_wall_law_lets_a_shaken_layer_take_off_and_land_as_an_inelastic_block(coupled):
    # a completely inelastic block resting on a floor z_w = A sin(omega t) leaves it when the
    # floor's acceleration -A omega^2 sin(omega t) falls to -g, at the phase
    # asin(1 / gamma) / (2 pi), and lands where its parabola meets the floor again (Mehta &
    # Luck 1990, Phys. Rev. Lett. 65, 393): at gamma = 1.5, phases 0.1161 and 0.6837 (the
    # landing solved here); the settled layer's floor force is zero in between in its first
    # cycle, T carried passively (the wall law alone) or with its kinetic pressure
    gamma = 1.5
    p0 = math.asin(1.0 / gamma)
    s = np.linspace(p0 + 1e-9, p0 + 2.0 * math.pi, 400001)
    height = (math.sin(p0) + math.cos(p0) * (s - p0) - 0.5 * (s - p0) ** 2 / gamma - np.sin(s))
    landing = s[np.argmax(height < 0.0)] / (2.0 * math.pi)
    assert landing == pytest.approx(0.6837, abs=1e-3)
    phase, force, weight = _shaken_layer(gamma, coupled)
    first_free = phase[np.argmax(force <= 0.0)]
    back = phase[(phase > first_free) & (force > 0.0)][0]
    assert first_free == pytest.approx(p0 / (2.0 * math.pi), abs=0.02)
    assert back == pytest.approx(landing, abs=0.03)
    assert force[phase > back].max() > weight
