"""The Lagrangian continuum (material point method) against known answers.

Constitutive law (Dunatunga & Kamrin 2015) in steady simple shear; elastic P waves at
sqrt((K + 4G/3)/rho); linear and angular momentum of the APIC transfers (Jiang et al. 2015); a
block on an accelerating plate that sticks or slips as Coulomb's law says; the steady inclined
layer (Bagnold profile of mu(I)) and its convergence with the grid.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from vibroflow.continuum.boundary import Plane
from vibroflow.continuum.constitutive import ContinuumMaterial
from vibroflow.continuum.rheology import mu_of_I
from vibroflow.continuum.stress_update import update_stress_points
from vibroflow.continuum.grid import Grid
from vibroflow.continuum.grid_update import LabFrame
from vibroflow.continuum.mpm.solver import MPMSystem, init_state, run_steps
from vibroflow.continuum.timestep import stable_dt
from vibroflow.errors import InputError

from continuum_helpers import G_ACC, lattice, spinning_compressed_disc


# ----------------------------------------------------------------------------------------------
# constitutive law


# ----------------------------------------------------------------------------------------------
# MPM


def bagnold_error(nz: int) -> float:
    """Steady flow down a rough incline (theta = 25 deg, layer H = 1 cm of d = 2 mm grains,
    periodic along the slope) from rest: max |u - u_analytic| / u_analytic(H) after 1 s, with
    the mu(I) solution u(z) = (2/3) (I/d) sqrt(phi g cos theta) (H^1.5 - (H - z)^1.5),
    tan theta = mu(I) (GDR MiDi 2004; Silbert et al. 2001), z from the base."""
    d, H, theta = 2e-3, 0.01, math.radians(25.0)
    mat = ContinuumMaterial(bulk_modulus=1e5, shear_modulus=5e4, diameter=d)
    dx = H / nz
    sp = dx / 2
    grid = Grid.periodic_strip(4 * dx, 0.0, 1.1 * H, dx)
    x = lattice(0.0, 4 * dx, 0.0, H, sp)
    rho_c = mat.critical_density
    p = rho_c * G_ACC * math.cos(theta) * (H - x[:, 1])
    rho = rho_c * np.exp(p / mat.bulk_modulus)
    stress = np.zeros((len(x), 4))
    stress[:, [0, 1, 3]] = -p[:, None]
    base = Plane((0.0, 0.0), (0.0, 1.0), (mat.bulk_modulus + 4 * mat.shear_modulus / 3) / sp,
                 friction=10.0)
    gravity = (G_ACC * math.sin(theta), -G_ACC * math.cos(theta))
    system = MPMSystem(grid, mat, stable_dt(mat, dx, sp, [base]), frame=LabFrame(gravity),
                       boundaries=[base])
    state = init_state(system, x, sp * sp * rho_c / rho, rho, stress=stress)
    run_steps(system, state, int(1.0 / system.dt))
    rows = np.floor(x[:, 1] / sp).astype(int)
    z = np.bincount(rows, state.x[:, 1]) / np.bincount(rows)
    u = np.bincount(rows, state.v[:, 0]) / np.bincount(rows)
    I = mat.I_0 * (math.tan(theta) - mat.mu_s) / (mat.mu_2 - math.tan(theta))
    phi = mat.critical_solid_fraction
    ua = (2 / 3) * (I / d) * math.sqrt(phi * G_ACC * math.cos(theta)) * (
        H**1.5 - np.clip(H - z, 0, None) ** 1.5)
    return float(np.max(np.abs(u - ua)) / ua.max())


def test_bagnold_inclined_layer_profile_and_convergence():
    """The steady mu(I) profile within 3% at 16 grid cells across the layer, and the error
    falls as the grid is refined (8 -> 16 cells)."""
    coarse, fine = bagnold_error(8), bagnold_error(16)
    assert fine < 0.03
    assert fine < 0.6 * coarse


@pytest.mark.slow
def test_bagnold_inclined_layer_fine_grid():
    """32 cells across the layer: within 1.5%."""
    assert bagnold_error(32) < 0.015


# ----------------------------------------------------------------------------------------------
# the tub run and its command


# ----------------------------------------------------------------------------------------------
# the tub frame


# ----------------------------------------------------------------------------------------------
# checkpoints, resume, blow-ups, grid fields


# ----------------------------------------------------------------------------------------------
# the FLIP fraction of the points' velocity update (MPMSystem.flip, ContinuumOptions.flip)


# ----------------------------------------------------------------------------------------------
# the bed viscosity (stress_update.damped_stress): a Kelvin-Voigt standing shear wave


