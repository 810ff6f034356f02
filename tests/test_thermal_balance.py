"""The DEM's thermal balance (calibration/contact_power.py, thermal_balance.py) against hand
values: a head-on dashpot's loss gamma v_n^2, a sliding contact's mu |F_n| |v_slip|, CDT rolling's
mu_r R_eff |F_n| |w_r|, zero for a rigid rotation of touching balls and of a ball on a wall in a
spinning frame, the coarse-grained loss integrating to the contacts' total, and the production
of a simple shear of a uniform stress."""
import numpy as np
import pytest

from vibroflow.calibration.contact_power import (elastic_energy_J, pair_power_loss,
                                                 wall_power_loss)
from vibroflow.calibration.thermal_balance import ThermalBalanceGrainer

R = 0.003


def _one(a):
    return np.asarray(a, float)[None, :]


def test_head_on_dashpot_loses_gamma_vn2_and_the_spring_stores_the_rest():
    k_n, gamma, v_n, delta = 1.0e5, 0.3, 0.4, 1.0e-5
    # i above j, approaching at v_n: u . n = -v_n; F_n = k_n delta - gamma (u . n)
    b = _one([0.0, 0.0, 2 * R - delta])
    F_n = k_n * delta + gamma * v_n
    normal, tang, roll = pair_power_loss(b, [R], [R], _one([0, 0, -v_n / 2]),
                                         _one([0, 0, v_n / 2]), _one([0, 0, 0]),
                                         _one([0, 0, 0]), _one([0, 0, F_n]))
    storage_rate = k_n * delta * v_n            # d/dt (k_n delta^2 / 2), delta' = v_n
    assert normal[0] - storage_rate == pytest.approx(gamma * v_n**2, rel=1e-12)
    assert tang[0] == pytest.approx(0.0, abs=1e-15) and roll[0] == 0.0
    assert elastic_energy_J(b, [2 * R], _one([0, 0, F_n]), k_n, 1.0) == \
        pytest.approx(0.5 * k_n * delta**2, rel=1e-9)


def test_sliding_contact_loses_mu_Fn_vslip_with_spins_in_the_slip():
    mu, F_n, v_slip = 0.2, 3.0, 0.05
    # the slip of i's surface against j's: a translation plus the spin's part -r w x n
    w_i = np.array([0.0, 4.0, 0.0])             # r w x n with n = z: (r w_y, 0, 0)
    v_i = np.array([v_slip + R * w_i[1], 0.0, 0.0])
    u = v_i - np.cross(R * w_i, [0, 0, 1.0])
    assert u[0] == pytest.approx(v_slip)
    F = _one([-mu * F_n, 0.0, F_n])             # Coulomb's limit against the slip
    normal, tang, roll = pair_power_loss(_one([0, 0, 2 * R]), [R], [R], _one(v_i),
                                         _one([0, 0, 0]), _one(w_i), _one([0, 0, 0]), F)
    assert tang[0] == pytest.approx(mu * F_n * v_slip, rel=1e-12)
    assert normal[0] == pytest.approx(0.0, abs=1e-15)
    # at a wall (n = z, the wall j of radius 0) the same slip loses the same
    wn, wt, _ = wall_power_loss(_one([0, 0, R]), [R], _one(v_i), _one(w_i), F)
    assert wt[0] == pytest.approx(mu * F_n * v_slip, rel=1e-12) and wn[0] == 0.0


def test_cdt_rolling_loses_mu_r_reff_Fn_wr_and_nothing_for_twist():
    mu_r, F_n = 0.002, 5.0
    w_i = np.array([3.0, 0.0, 7.0])             # rolling part 3 about x, twist 7 about n = z
    _, _, roll = pair_power_loss(_one([0, 0, 2 * R]), [R], [R], _one([0, 0, 0]),
                                 _one([0, 0, 0]), _one(w_i), _one([0, 0, 0]),
                                 _one([0, 0, F_n]), mu_r)
    assert roll[0] == pytest.approx(mu_r * (R / 2) * F_n * 3.0, rel=1e-12)


def test_rigid_rotation_of_touching_balls_and_a_ball_on_a_spinning_wall_loses_nothing():
    rng = np.random.default_rng(3)
    Om = np.array([0.4, -2.0, 1.1])
    # three balls touching (delta = 0) in a triangle, moving as one body: v = Om x r, w = Om
    c = np.array([[0.0, 0.0, 0.0], [2 * R, 0.0, 0.0], [R, 0.0, np.sqrt(3) * R]])
    v0 = np.array([0.3, 0.1, -0.2])
    v = v0 + np.cross(Om, c)
    i, j = np.array([0, 0, 1]), np.array([1, 2, 2])
    F = rng.normal(size=(3, 3))                  # any forces, tangential parts included
    parts = pair_power_loss(c[i] - c[j], np.full(3, R), np.full(3, R), v[i], v[j],
                            np.tile(Om, (3, 1)), np.tile(Om, (3, 1)), F, mu_r=0.002)
    for p in parts:
        assert np.abs(p).max() < 1e-15
    # a ball touching a wall (delta = 0), both spinning with the frame; pressed in by delta the
    # DEM's radius lever arm sees the slip -delta Omega x n (contact_power.py)
    b = _one([0.0, 0.0, R])
    parts = wall_power_loss(b, [R], _one([0, 0, 0]), _one([0, 0, 0]), _one(F[0]),
                            frame_spin=Om, mu_r=0.002)
    for p in parts:
        assert abs(p[0]) < 1e-15


def _lattice(a, nx, nz):
    x, z = np.meshgrid(np.arange(nx) * a, np.arange(nz) * a, indexing="ij")
    return np.stack([x.ravel(), np.zeros(x.size), z.ravel()], axis=1)


def test_coarse_grained_loss_integrates_to_the_contacts_total():
    a, nx, nz = 2 * R, 6, 6
    pos = _lattice(a, nx, nz)
    rng = np.random.default_rng(1)
    idx = np.arange(pos.shape[0]).reshape(nx, nz)
    i, j = idx[:, 1:].ravel(), idx[:, :-1].ravel()     # vertical neighbours
    vel = rng.normal(scale=0.1, size=pos.shape)
    F = rng.normal(size=(i.size, 3))
    g = ThermalBalanceGrainer(None, cell_size=0.002, depth=0.01, rho_s=7800.0,
                              diameter=2 * R, n_phases=1, n_batches=1,
                              extent=(-0.01, 0.04, -0.01, 0.04))
    total = g.add_snapshot(pos, vel, np.zeros_like(vel), R, 1e-3, 0, 0, contacts_i=i,
                           contacts_j=j, contact_force=F)
    ds = g.fields()
    parts = pair_power_loss(pos[i] - pos[j], np.full(i.size, R), np.full(i.size, R), vel[i],
                            vel[j], np.zeros((i.size, 3)), np.zeros((i.size, 3)), F)
    assert total == pytest.approx(sum(p.sum() for p in parts), rel=1e-12)
    integral = float(ds.dissipation_cycle_mean.sum()) * 0.002**2 * 0.01
    assert integral == pytest.approx(total, rel=1e-3)     # the grid sum of the kernel


def test_simple_shear_of_a_uniform_stress_produces_tau_gamma_dot():
    a, nx, nz, depth, gdot, f_x, f_z = 2 * R, 40, 40, 0.01, 5.0, -0.7, 2.0
    pos = _lattice(a, nx, nz)
    vel = np.zeros_like(pos)
    vel[:, 0] = gdot * pos[:, 2]                 # V_x = gamma_dot z
    idx = np.arange(pos.shape[0]).reshape(nx, nz)
    i, j = idx[:, 1:].ravel(), idx[:, :-1].ravel()
    F = np.tile([f_x, 0.0, f_z], (i.size, 1))    # on the upper ball by the lower
    g = ThermalBalanceGrainer(None, cell_size=a / 2, depth=depth, rho_s=7800.0,
                              diameter=2 * R, n_phases=1, n_batches=1, kernel="lucy", width=3 * a,
                              extent=(-0.06, nx * a + 0.06, -0.06, nz * a + 0.06))
    g.add_snapshot(pos, vel, np.zeros_like(vel), R, 1e-3, 0, 0, contacts_i=i, contacts_j=j,
                   contact_force=F)
    ds = g.fields()
    # P_xz = f_x a / (a^2 L_y) (one vertical contact per lattice site): Pi = -P_xz gamma_dot;
    # Lucy's kernel is smooth at its cut-off, so the lattice's sums are the integrals to 1e-5
    hand = -f_x / (a * depth) * gdot
    centre = ds.production_cycle_mean.sel(x=nx * a / 2, z=nz * a / 2, method="nearest")
    assert float(centre) == pytest.approx(hand, rel=1e-4)
    assert float(ds.production_contact_cycle_mean.sel(x=nx * a / 2, z=nz * a / 2,
                                                      method="nearest")) == \
        pytest.approx(hand, rel=1e-4)


def test_dense_dissipation_coefficient_closes_a_hand_made_balance():
    from vibroflow.calibration.shear_temperature import (dense_dissipation_coefficient,
                                                         kinetic_parameters)
    from vibroflow.continuum.kinetic_theory import dissipation_W_m3
    prm = kinetic_parameters(0.00635, 7800.0, 0.85)
    phi, T, p, k_f, gd = 0.59, 3e-3, 4500.0, 0.37, 12.0
    # tau gamma_dot = Lun's Gamma + k_f p sqrt(T) / d, written out by hand
    tau = (dissipation_W_m3(phi, T, gd, prm) + k_f * p * np.sqrt(T) / 0.00635) / gd
    assert dense_dissipation_coefficient(phi, gd, T, tau, p, prm) == pytest.approx(k_f,
                                                                                   rel=1e-12)
