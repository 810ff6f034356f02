"""The coarse-grained fluctuation-energy flux (vibroflow.calibration.energy_flux) against known
answers.

1. Kinetic flux: balls on a fine lattice whose fluctuation velocities have a prescribed,
   skewed distribution with a temperature that grows linearly in sqrt: c = sigma(z) (xi_x,
   xi_y, eta), xi = +-1 and eta in {2, -1/2} with probabilities 1/5, 4/5 (mean 0, variance 1,
   third moment 3/2), each combination equally often, plus a uniform drift V0.  Then T =
   sigma^2, dT/dz = 2 sigma sigma', and q_z = rho <c_z |c|^2> / 2 = (3/4) rho sigma^3,
   q_x = q_y = 0, whatever V0.
2. Collisional flux: vertical pairs of touching balls, half with force F_A and both balls
   moving up at u relative to V0, half with F_B moving down at u: q_c,z = n_pairs (F_A - F_B)
   u b / 2, and the drift's work V0 . f (a tangential force included) is no flux.
3. The grainer's own coarse-grained fields are a CoarseGrainer's, bit for bit.
4. Solid-fraction gradient: a lattice whose balls' volume (and mass, rho_s V) grows linearly
   with height, V(z) = V0 (1 + SLOPE z): phi = V(z) / (a_x a_z L) and d phi / dz =
   V0 SLOPE / (a_x a_z L), d phi / dx = 0.
"""
from __future__ import annotations

import numpy as np

from vibroflow.calibration.coarse_grain import CoarseGrainer
from vibroflow.calibration.energy_flux import EnergyFluxGrainer

AX, AZ, DEPTH, MASS = 0.0002, 0.001, 0.05, 0.01
X_LEN, Z_LEN = 0.24, 0.2
V0 = np.array([0.3, 0.05, -0.2])
SIGMA0, SLOPE = 0.1, 2.5          # sigma(z) = SIGMA0 (1 + SLOPE z), m/s and 1/m


def _grainer(cls=EnergyFluxGrainer):
    return cls(extent=(0.0, X_LEN, 0.0, Z_LEN), depth=DEPTH, cell_size=0.01, width=0.008,
               rho_s=7800.0)


def _lattice():
    kx = np.arange(int(round(X_LEN / AX)))
    kz = np.arange(int(round(Z_LEN / AZ)))
    K, Kz = np.meshgrid(kx, kz, indexing="ij")
    K, Kz = K.ravel(), Kz.ravel()
    pos = np.stack([(K + 0.5) * AX, np.zeros(K.size), (Kz + 0.5) * AZ], axis=1)
    return K, pos


def _interior(ds, name):
    sel = dict(x=slice(0.06, 0.18), z=slice(0.05, 0.15))
    return ds[name].sel(**sel)


def test_kinetic_flux_of_a_skewed_distribution_with_a_temperature_gradient():
    K, pos = _lattice()
    eta = np.where(K % 5 == 0, 2.0, -0.5)
    xi_x = np.where((K // 5) % 2 == 0, 1.0, -1.0)
    xi_y = np.where((K // 10) % 2 == 0, 1.0, -1.0)
    sig = SIGMA0 * (1.0 + SLOPE * pos[:, 2])
    vel = V0 + sig[:, None] * np.stack([xi_x, xi_y, eta], axis=1)
    g = _grainer()
    g.add_snapshot(pos, vel, 1e-4, MASS)
    ds = g.energy_flux_fields(phase_resolved=False)
    rho = MASS / (AX * AZ * DEPTH)
    z = _interior(ds, "temperature")["z"].values
    s = SIGMA0 * (1.0 + SLOPE * z)
    T = _interior(ds, "temperature").values
    np.testing.assert_allclose(T, np.broadcast_to(s**2, T.shape), rtol=2e-3)
    gT = _interior(ds, "temperature_gradient").values
    np.testing.assert_allclose(gT[..., 1], np.broadcast_to(2 * s * SIGMA0 * SLOPE, T.shape),
                               rtol=5e-3)
    # the cut-off kernel leaves a trace of the lattice pattern: 1e-3 of the gradient
    assert np.abs(gT[..., 0]).max() < 2e-3 * np.abs(gT[..., 1]).max()
    q = _interior(ds, "kinetic_energy_flux").values
    q_exact = 0.75 * rho * s**3
    np.testing.assert_allclose(q[..., 2], np.broadcast_to(q_exact, T.shape), rtol=5e-3)
    assert np.abs(q[..., :2]).max() < 1e-4 * q_exact.max()
    assert np.abs(_interior(ds, "collisional_energy_flux").values).max() == 0.0


def test_collisional_flux_of_a_synthetic_contact_set():
    b, u, F_A, F_B, F_T = 0.004, 0.07, 3.0, 1.0, 0.5
    kx = np.arange(int(round(X_LEN / 0.0005)))
    kz = np.arange(int(round(Z_LEN / 0.005)))
    Kx, Kz = (a.ravel() for a in np.meshgrid(kx, kz, indexing="ij"))
    centre = np.stack([(Kx + 0.5) * 0.0005, np.zeros(Kx.size), (Kz + 0.5) * 0.005], axis=1)
    up = Kx % 2 == 0
    half = np.array([0.0, 0.0, 0.5 * b])
    pos = np.concatenate([centre + half, centre - half])
    c = np.where(up, u, -u)[:, None] * np.array([0.0, 0.0, 1.0])
    vel = V0 + np.concatenate([c, c])
    n = Kx.size
    force = np.zeros((n, 3))
    force[:, 2] = np.where(up, F_A, F_B)
    force[:, 0] = F_T
    g = _grainer()
    g.add_snapshot(pos, vel, 1e-4, MASS, contacts_i=np.arange(n), contacts_j=np.arange(n, 2 * n),
                   contact_force=force, contact_branch=np.tile([0.0, 0.0, b], (n, 1)))
    ds = g.energy_flux_fields(phase_resolved=False)
    n_pairs = 1.0 / (0.0005 * 0.005 * DEPTH)
    qc = _interior(ds, "collisional_energy_flux").values
    np.testing.assert_allclose(qc[..., 2], n_pairs * 0.5 * (F_A - F_B) * u * b, rtol=2e-4)
    assert np.abs(qc[..., :2]).max() < 1e-4 * np.abs(qc[..., 2]).max()
    # each ball's c_z^3 cancels between the up and down pairs: no kinetic flux
    assert np.abs(_interior(ds, "kinetic_energy_flux").values).max() < 1e-6 * np.abs(qc).max()


def test_the_grainers_fields_are_a_coarse_grainers():
    rng = np.random.default_rng(3)
    pos = rng.uniform([0.0, 0.0, 0.0], [X_LEN, 0.0, Z_LEN], size=(500, 3))
    vel = rng.normal(size=(500, 3))
    i, j = np.arange(0, 100), np.arange(100, 200)
    f = rng.normal(size=(100, 3))
    a, b = _grainer(), _grainer(CoarseGrainer)
    for gr in (a, b):
        gr.add_snapshot(pos, vel, 1e-3, MASS, contacts_i=i, contacts_j=j, contact_force=f,
                        wall_particle=np.array([5]), wall_force=np.array([[0.0, 0.0, 2.0]]),
                        wall_point=np.array([[pos[5, 0], 0.0, pos[5, 2] - 0.002]]))
    fa, fb = a.fields(), b.fields()
    for name in fb.data_vars:
        np.testing.assert_array_equal(fa[name].values, fb[name].values)


def test_solid_fraction_gradient_of_a_graded_lattice():
    ax, az = 0.001, 0.002
    kx = np.arange(int(round(X_LEN / ax)))
    kz = np.arange(int(round(Z_LEN / az)))
    Kx, Kz = (a.ravel() for a in np.meshgrid(kx, kz, indexing="ij"))
    pos = np.stack([(Kx + 0.5) * ax, np.zeros(Kx.size), (Kz + 0.5) * az], axis=1)
    rho_s, v0 = 7800.0, 4.0e-8
    vol = v0 * (1.0 + SLOPE * pos[:, 2])
    radius = np.cbrt(3.0 * vol / (4.0 * np.pi))
    g = _grainer()
    g.add_snapshot(pos, np.zeros_like(pos), radius, rho_s * vol)
    ds = g.energy_flux_fields(phase_resolved=False)
    z = _interior(ds, "solid_fraction")["z"].values
    cell = ax * az * DEPTH
    phi = _interior(ds, "solid_fraction").values
    np.testing.assert_allclose(phi, np.broadcast_to(v0 * (1 + SLOPE * z) / cell, phi.shape),
                               rtol=1e-3)
    gp = _interior(ds, "solid_fraction_gradient").values
    # the kernel's sampling of the 2 mm lattice: 3e-3 of the gradient, as for grad T above
    np.testing.assert_allclose(gp[..., 1], v0 * SLOPE / cell, rtol=5e-3)
    assert np.abs(gp[..., 0]).max() < 1e-3 * v0 * SLOPE / cell
