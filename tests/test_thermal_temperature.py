"""The DEM's thermal temperature (calibration.thermal_temperature, measure.thermal) against known
answers.

* A uniform flow that changes from snapshot to snapshot plus Maxwellian noise of temperature
  T0: about each snapshot's own mean the temperature is T0 (1 - 3 / N_eff), N_eff = 4 pi w^2 n
  the balls under the local mean's Gaussian (module notes of measure.thermal); about the phase's
  mean over the snapshots (the phase-resolved T) it is T0 + the flows' variance / 3.
* A rigid rotation v = Omega x (r - r0) about y: a linear field, which a symmetric kernel
  reproduces exactly, so in the interior the local mean's curvature term is zero and the
  thermal T is ~0; the phase-resolved T there is the rotation's spread under its own kernel
  (width w_f), (Omega^2 w_f^2 + Omega^2 w_f^2) / 3 by hand.
"""
from __future__ import annotations

import math

import numpy as np

from vibroflow.calibration.coarse_grain import CoarseGrainer
from vibroflow.calibration.thermal_temperature import ThermalTemperatureGrainer
from vibroflow.measure.thermal import thermal_velocities

D = 0.004                               # ball diameter, m: fields' kernel d/2, local mean 2d
X_LEN, Z_LEN, DEPTH, MASS = 0.2, 0.16, 0.05, 1e-3
GRID = dict(geometry=None, extent=(0.0, X_LEN, 0.0, Z_LEN), cell_size=0.002, depth=DEPTH,
            rho_s=7800.0, diameter=D)
INTERIOR = dict(x=slice(0.05, 0.15), z=slice(0.05, 0.11))


def test_maxwellian_noise_about_changing_uniform_flows():
    rng = np.random.default_rng(7)
    n_balls, T0, n_snap = 16000, 0.01, 8
    g = ThermalTemperatureGrainer(n_phases=1, n_batches=4, **GRID)
    plain = CoarseGrainer(kernel="gaussian", width=0.5 * D, n_phases=1, n_batches=4, **GRID)
    flows = rng.normal(0.0, 0.3, (n_snap, 3))
    for k in range(n_snap):
        pos = np.stack([rng.uniform(0, X_LEN, n_balls), np.zeros(n_balls),
                        rng.uniform(0, Z_LEN, n_balls)], axis=1)
        vel = flows[k] + rng.normal(0.0, math.sqrt(T0), (n_balls, 3))
        g.add_snapshot(pos, vel, 1e-4, MASS, phase_bin=0, batch=k % 4)
        plain.add_snapshot(pos, vel, 1e-4, MASS, phase_bin=0, batch=k % 4)
    phase, cycle = g.fields()
    n_eff = 4.0 * math.pi * (2.0 * D) ** 2 * n_balls / (X_LEN * Z_LEN)
    T = phase["thermal_temperature"].isel(phase=0).sel(**INTERIOR)
    expected = T0 * (1.0 - 3.0 / n_eff)
    assert abs(float(T.mean()) / expected - 1.0) < 0.01
    se = phase["thermal_temperature_stderr"].isel(phase=0).sel(**INTERIOR)
    assert 0.0 < float(se.median()) < 0.1 * T0
    assert phase["thermal_temperature"].attrs["units"] == "m2 s-2"
    # one phase: the cycle mean is that phase's field
    np.testing.assert_allclose(cycle["thermal_temperature_cycle_mean"].sel(**INTERIOR), T,
                               rtol=1e-12)
    # about the phase's mean over the snapshots the flows' scatter counts as temperature
    T_phase = plain.fields(phase_resolved=True)["temperature"].isel(phase=0).sel(**INTERIOR)
    spread = float(np.sum(np.var(flows, axis=0))) / 3.0
    assert abs(float(T_phase.mean()) / (T0 + spread) - 1.0) < 0.02
    assert spread > 5.0 * T0


def test_rigid_rotation_has_no_thermal_temperature():
    omega, spacing = 10.0, 1e-3
    kx, kz = np.meshgrid(np.arange(int(X_LEN / spacing)), np.arange(int(Z_LEN / spacing)),
                         indexing="ij")
    pos = np.stack([(kx.ravel() + 0.5) * spacing, np.zeros(kx.size),
                    (kz.ravel() + 0.5) * spacing], axis=1)
    r0 = np.array([0.5 * X_LEN, 0.0, 0.5 * Z_LEN])
    rel = pos - r0
    vel = omega * np.stack([rel[:, 2], np.zeros(len(rel)), -rel[:, 0]], axis=1)
    g = ThermalTemperatureGrainer(n_phases=1, n_batches=1, **GRID)
    g.add_snapshot(pos, vel, 1e-4, MASS, phase_bin=0, batch=0)
    T_th = g.fields()[0]["thermal_temperature"].isel(phase=0).sel(**INTERIOR).values
    # the phase-resolved T of the same snapshot: the rotation's spread under the d/2 kernel
    w_f = 0.5 * D
    T_phase = 2.0 * omega**2 * w_f**2 / 3.0
    assert np.abs(T_th).max() < 1e-3 * T_phase
    # and the grains' local mean (measure.thermal) likewise: c = 0 away from the edges
    near = (np.abs(rel[:, 0]) < 0.04) & (np.abs(rel[:, 2]) < 0.04)
    c = thermal_velocities(pos[near], vel[near], MASS, 2.0 * D)
    inner = (np.abs(rel[near, 0]) < 0.015) & (np.abs(rel[near, 2]) < 0.015)
    # (up to the round-off of which lattice points at exactly the cutoff count)
    assert np.abs(c[inner]).max() < 1e-4 * omega * 2.0 * D


def test_grains_local_mean_leaves_maxwellian_noise():
    rng = np.random.default_rng(3)
    n_balls, T0 = 6000, 0.02
    pos = np.stack([rng.uniform(0, 0.1, n_balls), np.zeros(n_balls),
                    rng.uniform(0, 0.1, n_balls)], axis=1)
    vel = np.array([0.2, 0.0, -0.5]) + rng.normal(0.0, math.sqrt(T0), (n_balls, 3))
    c = thermal_velocities(pos, vel, MASS, 2.0 * D)
    inner = (np.abs(pos[:, 0] - 0.05) < 0.025) & (np.abs(pos[:, 2] - 0.05) < 0.025)
    n_eff = 4.0 * math.pi * (2.0 * D) ** 2 * n_balls / 0.01
    T = float(np.mean(c[inner] ** 2))
    se = T * math.sqrt(2.0 / (3 * inner.sum()))
    assert abs(T - T0 * (1.0 - 3.0 / n_eff)) < 3.0 * se
