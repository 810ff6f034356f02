"""The steady inclined layer in both continuum formulations: the Bagnold profile of mu(I).

Steady flow down a rough incline (theta = 25 deg, layer H = 1 cm of d = 2 mm grains, periodic
along the slope) from rest: max |u - u_analytic| / u_analytic(H) after 1 s, with the mu(I)
solution u(z) = (2/3) (I/d) sqrt(phi g cos theta) (H^1.5 - (H - z)^1.5), tan theta = mu(I)
(GDR MiDi 2004; Silbert et al. 2001), z from the base.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from continuum_helpers import G_ACC, lattice
from vibroflow.continuum.constitutive import ContinuumMaterial
from vibroflow.continuum.grid_update import LabFrame
from vibroflow.continuum.timestep import stable_dt

D, H, THETA = 2e-3, 0.01, math.radians(25.0)


def _material() -> ContinuumMaterial:
    return ContinuumMaterial(bulk_modulus=1e5, shear_modulus=5e4, diameter=D)


def _bagnold_speed(mat: ContinuumMaterial, z):
    """The mu(I) solution u(z) (m/s) at heights z (m) from the base."""
    I = mat.I_0 * (math.tan(THETA) - mat.mu_s) / (mat.mu_2 - math.tan(THETA))
    phi = mat.critical_solid_fraction
    return (2 / 3) * (I / D) * math.sqrt(phi * G_ACC * math.cos(THETA)) * (
        H**1.5 - np.clip(H - z, 0, None) ** 1.5)


def lagrangian_bagnold_error(nz: int) -> float:
    """The error of the material points (grid spacing H / nz, 2 x 2 points a cell) on a plane
    base of friction 10, the points' mean speed in each row of points."""
    from vibroflow.continuum.boundary import Plane
    from vibroflow.continuum.grid import Grid
    from vibroflow.continuum.mpm.solver import MPMSystem, init_state, run_steps

    mat = _material()
    dx = H / nz
    sp = dx / 2
    grid = Grid.periodic_strip(4 * dx, 0.0, 1.1 * H, dx)
    x = lattice(0.0, 4 * dx, 0.0, H, sp)
    rho_c = mat.critical_density
    p = rho_c * G_ACC * math.cos(THETA) * (H - x[:, 1])
    rho = rho_c * np.exp(p / mat.bulk_modulus)
    stress = np.zeros((len(x), 4))
    stress[:, [0, 1, 3]] = -p[:, None]
    base = Plane((0.0, 0.0), (0.0, 1.0), (mat.bulk_modulus + 4 * mat.shear_modulus / 3) / sp,
                 friction=10.0)
    gravity = (G_ACC * math.sin(THETA), -G_ACC * math.cos(THETA))
    system = MPMSystem(grid, mat, stable_dt(mat, dx, sp, [base]), frame=LabFrame(gravity),
                       boundaries=[base])
    state = init_state(system, x, sp * sp * rho_c / rho, rho, stress=stress)
    run_steps(system, state, int(1.0 / system.dt))
    rows = np.floor(x[:, 1] / sp).astype(int)
    z = np.bincount(rows, state.x[:, 1]) / np.bincount(rows)
    u = np.bincount(rows, state.v[:, 0]) / np.bincount(rows)
    ua = _bagnold_speed(mat, z)
    return float(np.max(np.abs(u - ua)) / ua.max())


def eulerian_bagnold_error(nz: int) -> float:
    """The error on the Eulerian mesh (node spacing H / nz, cells of half that) on a floor wall
    of friction 10, the mass-weighted speed of each row of cells; the mass conserved to
    round-off."""
    from vibroflow.continuum.eulerian.mesh import EulerianMesh
    from vibroflow.continuum.eulerian.solver import EulerianSystem, init_state, run_steps
    from vibroflow.continuum.eulerian.wall import MeshWall

    mat = _material()
    dx = H / nz
    h = dx / 2
    mesh = EulerianMesh.box(0.0, 4 * dx, 0.0, 1.5 * H, dx, periodic=True)
    kn = (mat.bulk_modulus + 4 * mat.shear_modulus / 3) / h
    wall = MeshWall(kn, friction=10.0, damping_ratio=0.5)
    gravity = (G_ACC * math.sin(THETA), -G_ACC * math.cos(THETA))
    system = EulerianSystem(mesh, mat, stable_dt(mat, dx, h, [wall]), frame=LabFrame(gravity),
                            wall=wall)
    c = system.x
    rho_c = mat.critical_density
    filled = c[:, 1] < H
    p = rho_c * G_ACC * math.cos(THETA) * np.clip(H - c[:, 1], 0.0, None) * filled
    rho = rho_c * np.exp(p / mat.bulk_modulus)
    stress = np.zeros((mesh.n, 4))
    stress[:, [0, 1, 3]] = -p[:, None]
    state = init_state(system, np.where(filled, rho * h * h, 0.0), rho, stress=stress)
    run_steps(system, state, int(1.0 / system.dt))
    rows = int(round(H / h))
    u2 = (state.mass * state.v[:, 0]).reshape(mesh.ncx, mesh.ncz).sum(axis=0)
    m2 = state.mass.reshape(mesh.ncx, mesh.ncz).sum(axis=0)
    z = (np.arange(rows) + 0.5) * h
    u = u2[:rows] / m2[:rows]
    ua = _bagnold_speed(mat, z)
    assert abs(state.mass_error()) < 1e-12
    return float(np.max(np.abs(u - ua)) / ua.max())


BAGNOLD_ERROR = {"lagrangian": lagrangian_bagnold_error, "eulerian": eulerian_bagnold_error}


@pytest.mark.parametrize("method", [
    "lagrangian",
    # about 40 s: the per-step cost of this small mesh is the kernels' call overhead
    pytest.param("eulerian", marks=pytest.mark.slow),
])
def test_bagnold_inclined_layer_profile_and_convergence(method):
    """The steady mu(I) profile within 3 % at 16 node spacings across the layer, and the error
    falls as the grid is refined (8 -> 16)."""
    coarse, fine = BAGNOLD_ERROR[method](8), BAGNOLD_ERROR[method](16)
    assert fine < 0.03
    assert fine < 0.6 * coarse


@pytest.mark.slow
def test_bagnold_inclined_layer_fine_grid():
    """The material points, 32 grid spacings across the layer: within 1.5 %."""
    assert lagrangian_bagnold_error(32) < 0.015
