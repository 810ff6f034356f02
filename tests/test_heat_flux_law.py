"""Garzo & Dufty's heat flux (vibroflow.continuum.garzo_dufty) and its fit to coarse-grained
cells (vibroflow.calibration.heat_flux_law) against known answers.

1. Elastic grains (e = 1): kappa is Enskog's conductivity of elastic hard spheres, which is
   Gidaspow's at e = 1 (the continuum's closure, kinetic_theory.conductivity_kg_m_s), its dilute
   limit Chapman & Cowling's 75 sqrt(pi) rho_s d sqrt(T) / 384, and the density-gradient
   coefficient mu vanishes; for inelastic grains mu > 0 (heat flows down the density gradient,
   Brey et al. 1998) and, in the dilute limit, kappa* = (2/3)(1 + c*) / (nu* - 2 zeta*).
2. g0's slope is the derivative of g0 (both forms), against central differences.
3. Synthetic cells whose flux is a known A0 kappa grad T + B0 mu grad phi, plus independent noise
   in each batch: the fit returns A0 and B0 within three batch-means standard errors, overall
   and in every solid-fraction bin, with R^2 near 1; the same on the cycle means of a
   phase-resolved set.
"""
from __future__ import annotations

import math
import tomllib
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from vibroflow.calibration.heat_flux_law import (fit_cycle_mean, fit_heat_flux_law,
                                                 gd_coefficients, heat_flux_law_table)
from vibroflow.continuum.garzo_dufty import (gd_conductivity_kg_m_s, gd_density_coefficient_W_m,
                                             heat_flux_factors, radial_distribution_slope)
from vibroflow.continuum.kinetic_theory import (LUN_SAVAGE, KineticParameters,
                                                conductivity_kg_m_s, radial_distribution)
from vibroflow.errors import InputError
from vibroflow.io.calibration_file import Calibration, read_calibration, write_calibration

RHO_S, D, E, PHI_RCP = 7800.0, 0.00635, 0.85, 0.63


def test_elastic_grains_have_enskogs_conductivity_and_no_density_term():
    prm = KineticParameters(diameter_m=D, density_kg_m3=RHO_S, restitution=1.0, phi_rcp=PHI_RCP)
    for phi, T in ((1e-9, 0.01), (0.1, 0.004), (0.4, 0.02), (0.6, 0.01)):
        assert gd_conductivity_kg_m_s(phi, T, prm) == pytest.approx(
            conductivity_kg_m_s(phi, T, prm), rel=1e-12)
        assert gd_density_coefficient_W_m(phi, T, prm) == 0.0
    assert gd_conductivity_kg_m_s(1e-12, 0.01, prm) == pytest.approx(
        75 * math.sqrt(math.pi) * RHO_S * D * 0.1 / 384, rel=1e-9)


def test_inelastic_dilute_limit_and_sign():
    e = 0.7
    prm = KineticParameters(restitution=e, phi_rcp=PHI_RCP)
    c = 32 * (1 - e) * (1 - 2 * e * e) / (81 - 17 * e + 30 * e * e * (1 - e))
    zeta = 5 / 12 * (1 - e * e) * (1 + 3 * c / 32)
    nu = (1 + e) / 3 * (1 + 33 / 16 * (1 - e) + (19 - 3 * e) / 1024 * c)
    kappa, mu = heat_flux_factors(1e-12, prm)
    assert kappa == pytest.approx(2 / 3 * (1 + c) / (nu - 2 * zeta), rel=1e-9)
    assert mu == pytest.approx(2 * (zeta * kappa + c / 3) / (2 * nu - 3 * zeta), rel=1e-9)
    for phi in (0.05, 0.3, 0.55):
        assert heat_flux_factors(phi, prm)[1] > 0


@pytest.mark.parametrize("form", [0, LUN_SAVAGE])
def test_g0_slope_is_its_derivative(form):
    prm = KineticParameters(phi_rcp=PHI_RCP, g0_form=form)
    for phi in (0.05, 0.3, 0.55, 0.62):
        h = 1e-6
        fd = (radial_distribution(phi + h, prm) - radial_distribution(phi - h, prm)) / (2 * h)
        assert radial_distribution_slope(phi, prm) == pytest.approx(fd, rel=1e-6)


def _cells(A0, B0, n_batches=8, noise=0.2, seed=2, shape=(4, 30, 20)):
    rng = np.random.default_rng(seed)
    phi = rng.uniform(0.06, 0.59, shape)
    T = rng.uniform(0.002, 0.02, shape)
    gT = rng.normal(0.0, 0.5, shape + (2,))
    gp = rng.normal(0.0, 5.0, shape + (2,))
    kappa, mu = gd_coefficients(phi, T, RHO_S, D, E, PHI_RCP)
    q_true = np.zeros(shape + (3,))
    q_true[..., (0, 2)] = -A0 * kappa[..., None] * gT - B0 * mu[..., None] * gp
    scale = np.abs(q_true).mean()
    qb = q_true + noise * scale * rng.normal(size=(n_batches,) + q_true.shape)
    dims = ("phase", "x", "z")
    bd = ("batch",) + dims

    def rep(a):
        return np.broadcast_to(a, (n_batches,) + a.shape)

    return xr.Dataset({
        "solid_fraction": (dims, phi), "temperature": (dims, T),
        "temperature_gradient": (dims + ("k",), gT),
        "solid_fraction_gradient": (dims + ("k",), gp),
        "energy_flux": (dims + ("i",), qb.mean(0)),
        "solid_fraction_batches": (bd, rep(phi)), "temperature_batches": (bd, rep(T)),
        "temperature_gradient_batches": (bd + ("k",), rep(gT)),
        "solid_fraction_gradient_batches": (bd + ("k",), rep(gp)),
        "energy_flux_batches": (bd + ("i",), qb),
        "energy_flux_stderr": (dims + ("i",), qb.std(0, ddof=1) / math.sqrt(n_batches)),
    })


@pytest.mark.parametrize("A0, B0", [(1.0, 1.0), (0.3, -2.0), (2.5, 0.5)])
def test_fit_recovers_known_multipliers(A0, B0):
    fit = fit_heat_flux_law(_cells(A0, B0), RHO_S, D, E, PHI_RCP)
    for key, v in (("conductivity_multiplier", A0), ("density_multiplier", B0)):
        assert abs(fit[key] - v) < 3 * fit[key + "_stderr"]
        assert fit[key + "_stderr"] < 0.05 * abs(v)
    assert fit["r2"] > 0.9 and fit["direction_fraction"] > 0.9
    by = fit["by_solid_fraction"]
    for a, sa, b, sb in zip(by["conductivity_multiplier"], by["conductivity_multiplier_stderr"],
                            by["density_multiplier"], by["density_multiplier_stderr"]):
        assert abs(a - A0) < 4 * sa and abs(b - B0) < 4 * sb
    if A0 == B0 == 1.0:
        assert fit["r2_as_is"] == pytest.approx(fit["r2"], abs=0.01)
    flat = fit_heat_flux_law(_cells(A0, B0), RHO_S, D, E, PHI_RCP, weighted=False)
    for key, v in (("conductivity_multiplier", A0), ("density_multiplier", B0)):
        assert abs(flat[key] - v) < 3 * flat[key + "_stderr"]
    table = heat_flux_law_table(fit, unweighted=flat)
    assert table["gd_status"] == "measured"
    assert table["gd_unweighted_r2"] == flat["r2"]


def test_cycle_mean_fit_recovers_known_multipliers():
    A0, B0 = 0.7, 1.8
    fit = fit_cycle_mean(_cells(A0, B0, noise=0.05), RHO_S, D, E, PHI_RCP)
    assert abs(fit["conductivity_multiplier"] - A0) < 3 * fit["conductivity_multiplier_stderr"]
    assert abs(fit["density_multiplier"] - B0) < 3 * fit["density_multiplier_stderr"]
    assert fit["r2"] > 0.9


def test_too_few_cells_is_one_line():
    with pytest.raises(InputError, match="cells = 0"):
        fit_heat_flux_law(_cells(1.0, 1.0), RHO_S, D, E, PHI_RCP, phi_range=(0.595, 0.599))
    with pytest.raises(InputError, match="solid_fraction_gradient"):
        fit_heat_flux_law(_cells(1.0, 1.0).drop_vars("solid_fraction_gradient"), RHO_S, D, E,
                          PHI_RCP)


def test_the_table_round_trips_through_calibration_toml(tmp_path):
    fit = fit_heat_flux_law(_cells(1.0, 1.0), RHO_S, D, E, PHI_RCP, min_cells=300)
    table = heat_flux_law_table(fit, fit_cycle_mean(_cells(1.0, 1.0), RHO_S, D, E, PHI_RCP))
    assert math.isnan(table["gd_r2_by_solid_fraction"][-1])   # a bin with too few cells
    src = Path(__file__).parent / "data" / "tub47-quick-dem" / "calibration.toml"
    tables = {**tomllib.loads(src.read_text()),
              "kinetic": {"phi_rcp": PHI_RCP, "conductivity": {"multiplier": 0.1, **table}}}
    write_calibration(tmp_path / "a.toml", Calibration.from_dict(tables))
    again = read_calibration(tmp_path / "a.toml")
    write_calibration(tmp_path / "b.toml", again)
    assert (tmp_path / "a.toml").read_bytes() == (tmp_path / "b.toml").read_bytes()
    assert again.kinetic.conductivity.gd_density_multiplier == table["gd_density_multiplier"]
