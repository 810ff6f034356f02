"""The settled bed a continuum starts from, the same for every formulation and the column
checks: the DEM's solid volume at the critical solid fraction fills the U to the height h that
holds it (`bed_area`, `bed_height`), at rest under the lithostatic stress sigma_zz = -rho_c g
(h - z), sigma_xx = sigma_yy = K0 sigma_zz with Jaky's K0 = 1 - sin(atan mu_s), at the density
rho_c exp(p / K) the elastic law gives that pressure (`lithostatic`), so its weight is carried
from the start.  Each formulation places it on its own points or cells
(Formulation.initial_state)."""
from __future__ import annotations

import math

import numpy as np

from vibroflow.errors import InputError
from vibroflow.tub.geometry import cross_section_area, geometry_of

from .constitutive import ContinuumMaterial


def bed_height(radius: float, area: float, rim: float) -> float:
    """Height h (m) whose U cross-section below it has the given area (m^2)."""
    if area >= cross_section_area(radius, rim):
        raise InputError(f"bed area = {area:.4g} m^2: more than the tub holds below its rim")
    lo, hi = 0.0, rim
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        if cross_section_area(radius, mid) < area:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def bed_area(scenario, material: ContinuumMaterial) -> float:
    """Cross-section (m^2) of the settled bed: the DEM's solid volume (fill.count balls of
    fill.diameter) over the slice L_y, at the critical solid fraction (or the material's
    initial_solid_fraction)."""
    fill = scenario.fill
    solid = fill.count * math.pi * fill.diameter**3 / 6.0 / geometry_of(scenario).length
    return solid * material.solid_density / material.initial_density


def lithostatic(rho_c: float, g: float, depth: np.ndarray, mu_s: float, bulk_modulus: float,
                mask: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Stresses (N, 4) Pa [xx, zz, xz, yy] and densities (N,) kg/m^3 of material of critical density
    rho_c (kg/m^3) at `depth` (N,) m below a free surface under gravity g (m/s^2): sigma_zz = -rho_c
    g depth (times `mask`, where given: the places that hold material), sigma_xx = sigma_yy = K0
    sigma_zz with Jaky's K0 = 1 - sin(atan mu_s), and the density rho_c exp(p / K) of the pressure p
    (module docstring)."""
    szz = -rho_c * g * depth
    if mask is not None:
        szz = szz * mask
    k0 = 1.0 - math.sin(math.atan(mu_s))
    stress = np.zeros((szz.shape[0], 4))
    stress[:, 1] = szz
    stress[:, 0] = stress[:, 3] = k0 * szz
    p = -(stress[:, 0] + stress[:, 1] + stress[:, 3]) / 3.0
    return stress, rho_c * np.exp(p / bulk_modulus)
