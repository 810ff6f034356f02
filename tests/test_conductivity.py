"""The conductivity fit (vibroflow.calibration.conductivity) against known answers.

1. Gidaspow's factor K(phi) is the closure's kappa / (rho_s d sqrt(T)); its dilute limit is the
   elastic hard-sphere gas's 150 sqrt(pi) / (384 (1 + e)) (g0 -> 1, phi -> 0).
2. Synthetic cells whose flux is C0 times the closure's, plus independent noise in each batch:
   the fit returns C0 within its batch-means standard error (three of them), in every bin of
   solid fraction, and an R^2 near 1; a flux up the gradient gives a negative multiplier.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
import xarray as xr

from vibroflow.calibration.conductivity import conductivity_factor, fit_conductivity
from vibroflow.continuum.kinetic_theory import KineticParameters, conductivity_kg_m_s
from vibroflow.errors import InputError

RHO_S, D, E, PHI_RCP = 7800.0, 0.00635, 0.85, 0.63


def test_factor_is_the_closures_conductivity():
    prm = KineticParameters(diameter_m=D, density_kg_m3=RHO_S, restitution=E, phi_rcp=PHI_RCP)
    for phi, T in ((0.1, 0.01), (0.45, 0.004), (0.6, 0.02)):
        k = conductivity_kg_m_s(phi, T, prm)
        assert conductivity_factor(phi, E, PHI_RCP) * RHO_S * D * math.sqrt(T) == \
            pytest.approx(k, rel=1e-12)
    assert conductivity_factor(1e-9, E, PHI_RCP) == pytest.approx(
        150 * math.sqrt(math.pi) / (384 * (1 + E)), rel=1e-6)


def _cells(C0, n_batches=8, noise=0.2, seed=1):
    rng = np.random.default_rng(seed)
    shape = (4, 30, 20)
    phi = rng.uniform(0.06, 0.59, shape)
    T = rng.uniform(0.002, 0.02, shape)
    gT = rng.normal(0.0, 0.5, shape + (2,))
    kappa = conductivity_factor(phi, E, PHI_RCP) * RHO_S * D * np.sqrt(T)
    q_true = np.zeros(shape + (3,))
    q_true[..., (0, 2)] = -C0 * kappa[..., None] * gT
    scale = np.abs(q_true).mean()
    qb = q_true + noise * scale * rng.normal(size=(n_batches,) + q_true.shape)
    dims = ("phase", "x", "z")
    ds = xr.Dataset({
        "solid_fraction": (dims, phi), "temperature": (dims, T),
        "temperature_gradient": (dims + ("k",), gT),
        "energy_flux": (dims + ("i",), qb.mean(0)),
        "solid_fraction_batches": (("batch",) + dims, np.broadcast_to(phi, (n_batches,) + shape)),
        "temperature_batches": (("batch",) + dims, np.broadcast_to(T, (n_batches,) + shape)),
        "temperature_gradient_batches": (("batch",) + dims + ("k",),
                                         np.broadcast_to(gT, (n_batches,) + gT.shape)),
        "energy_flux_batches": (("batch",) + dims + ("i",), qb),
        "energy_flux_stderr": (dims + ("i",), qb.std(0, ddof=1) / math.sqrt(n_batches)),
    })
    return ds


@pytest.mark.parametrize("C0", [0.35, 1.0, 2.7])
def test_fit_recovers_a_known_multiplier(C0):
    fit = fit_conductivity(_cells(C0), RHO_S, D, E, PHI_RCP)
    assert abs(fit["multiplier"] - C0) < 3 * fit["multiplier_stderr"]
    assert fit["multiplier_stderr"] < 0.02 * C0
    assert fit["r2"] > 0.9
    assert fit["down_gradient_fraction"] > 0.9
    assert fit["cell_ratio_p16"] < C0 < fit["cell_ratio_p84"]
    by = fit["by_solid_fraction"]
    for m, se in zip(by["multiplier"], by["multiplier_stderr"]):
        assert abs(m - C0) < 4 * se


def test_flux_up_the_gradient_is_a_negative_multiplier():
    fit = fit_conductivity(_cells(-0.5), RHO_S, D, E, PHI_RCP)
    assert fit["multiplier"] == pytest.approx(-0.5, abs=3 * fit["multiplier_stderr"])
    assert fit["down_gradient_fraction"] < 0.1


def test_too_few_cells_is_one_line():
    with pytest.raises(InputError, match="cells = 0"):
        fit_conductivity(_cells(1.0), RHO_S, D, E, PHI_RCP, phi_range=(0.595, 0.599))
