"""The thermal fluctuation (vibroflow.calibration.thermal_flux) against a known answer.

Two snapshots of one lattice at the same phase, each ball moving at the snapshot's uniform
velocity (V_A or V_B) plus a fixed pattern c = sigma (xi_x, xi_y, xi_z), xi = +-1 in equal
numbers (mean 0, variance sigma^2 per component).  About the phase's mean (energy_flux.py) the
temperature is sigma^2 + |V_A - V_B|^2 / 12: the two snapshots' collective difference counts as
agitation.  About each snapshot's own coarse-grained velocity it is sigma^2, and the flux of a
symmetric pattern is zero.
"""
from __future__ import annotations

import numpy as np

from vibroflow.calibration.coarse_grain import CoarseGrainer
from vibroflow.calibration.energy_flux import EnergyFluxGrainer
from vibroflow.calibration.thermal_flux import thermal_velocities

A, X_LEN, Z_LEN, DEPTH, MASS, SIGMA = 0.001, 0.2, 0.16, 0.05, 0.01, 0.05
V_A, V_B = np.array([0.1, 0.0, 0.4]), np.array([-0.05, 0.0, -0.2])
GRID = dict(extent=(0.0, X_LEN, 0.0, Z_LEN), depth=DEPTH, cell_size=0.01, rho_s=7800.0)


def _lattice():
    kx, kz = np.arange(int(round(X_LEN / A))), np.arange(int(round(Z_LEN / A)))
    Kx, Kz = (a.ravel() for a in np.meshgrid(kx, kz, indexing="ij"))
    pos = np.stack([(Kx + 0.5) * A, np.zeros(Kx.size), (Kz + 0.5) * A], axis=1)
    xi = np.stack([np.where(Kx % 2 == 0, 1.0, -1.0), np.where((Kx + Kz) % 2 == 0, 1.0, -1.0),
                   np.where(Kz % 2 == 0, 1.0, -1.0)], axis=1)
    return pos, SIGMA * xi


def _temperature(thermal):
    pos, c = _lattice()
    g = EnergyFluxGrainer(width=0.004, n_phases=1, **GRID)
    for V in (V_A, V_B):
        vel = V + c
        if thermal:
            vel = thermal_velocities(pos, vel, 2e-4, MASS, CoarseGrainer(width=0.016, **GRID))
        g.add_snapshot(pos, vel, 2e-4, MASS, phase_bin=0)
    ds = g.energy_flux_fields(phase_resolved=True).isel(phase=0)
    sel = dict(x=slice(0.06, 0.14), z=slice(0.05, 0.11))
    return ds["temperature"].sel(**sel).values, ds["energy_flux"].sel(**sel).values


def test_about_the_phase_mean_the_collective_difference_counts_as_temperature():
    T, _ = _temperature(thermal=False)
    dV = V_A - V_B
    np.testing.assert_allclose(T, SIGMA**2 + dV @ dV / 12.0, rtol=1e-3)


def test_about_each_snapshots_own_mean_only_the_agitation_counts():
    T, q = _temperature(thermal=True)
    np.testing.assert_allclose(T, SIGMA**2, rtol=1e-3)
    assert np.abs(q).max() < 1e-6 * MASS / (A * A * DEPTH) * SIGMA**3   # rho sigma^3
