"""The granular temperature of steady simple shear: the closure's balance of production and
dissipation against its algebraic value, and against the temperature the DEM shear cell
measures about the imposed profile.

Closure (vibroflow.continuum.kinetic_theory): with eta = E rho_s d sqrt(T) (Gidaspow 1994) and
Gamma = G rho_s T^(3/2) / (d L/d) (Lun et al. 1984, Jenkins' L/d = max(1, c_L d gamma_dot /
sqrt(T))), eta gamma_dot^2 = Gamma gives T / (d gamma_dot)^2 = max(E / G, (E c_L / G)^(2/3)),
written out below from the papers' formulas.

DEM: the Lees-Edwards shear cell of tub47's steel balls (frictional, e = 0.85, 300 balls,
diameters d (1 +- 0.1)) at its mid-depth pressure, T = <m |v - u(z)|^2> / (3 <m>) about
u_x = gamma_dot z over the steady window.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from vibroflow.calibration.shear_cell import run_shear_cell
from vibroflow.calibration.shear_temperature import (closure_temperature,
                                                     fit_correlation_coefficient,
                                                     kinetic_parameters, profile_shear_rate,
                                                     sliding_table)
from vibroflow.continuum.kinetic_stress import balance_temperature
from vibroflow.dem.periodic_box import PeriodicBox
from vibroflow.scenario.model import Scenario

D = 0.00635
RHO = 7800.0


def g0_paper(phi, phi_c=0.64):
    """Chialvo & Sundaresan (2013): Carnahan-Starling plus 1.1596 phi^2 / (phi_c - phi)^1.5."""
    return (2 - phi) / (2 * (1 - phi) ** 3) + 1.1596 * phi ** 2 / (phi_c - phi) ** 1.5


def algebraic_temperature(phi, shear_rate, e, c_L=0.0, d=D):
    """T (m^2/s^2) = max(E / G, (E c_L / G)^(2/3)) (d gamma_dot)^2 from the papers' formulas."""
    g0 = g0_paper(phi)
    E = (4 / 5 * phi ** 2 * g0 * (1 + e) / math.sqrt(math.pi)
         + 10 * math.sqrt(math.pi) / (96 * (1 + e) * g0) * (1 + 4 / 5 * phi * g0 * (1 + e)) ** 2)
    G = 12 * (1 - e ** 2) * phi ** 2 * g0 / math.sqrt(math.pi)
    return max(E / G, (E * c_L / G) ** (2 / 3)) * (d * shear_rate) ** 2


@pytest.mark.parametrize("phi", [0.1, 0.45, 0.6])
@pytest.mark.parametrize("e", [0.5, 0.85, 0.95])
@pytest.mark.parametrize("c_L", [0.0, 0.5, 3.0])
def test_closure_temperature_is_the_algebraic_balance(phi, e, c_L):
    prm = kinetic_parameters(D, RHO, e, correlation_coefficient=c_L)
    for shear_rate in (1.0, 30.0):
        assert closure_temperature(phi, shear_rate, prm) == pytest.approx(
            algebraic_temperature(phi, shear_rate, e, c_L), rel=1e-9)


def test_fitted_correlation_coefficient_gives_back_the_temperature():
    prm = kinetic_parameters(D, RHO, 0.85)
    phi, shear_rate = 0.6, 4.0
    plain = algebraic_temperature(phi, shear_rate, 0.85)
    c_L = fit_correlation_coefficient(phi, shear_rate, 1.5 * plain, prm)
    assert algebraic_temperature(phi, shear_rate, 0.85, c_L) == pytest.approx(1.5 * plain,
                                                                               rel=1e-9)
    assert fit_correlation_coefficient(phi, shear_rate, 0.5 * plain, prm) == 0.0


def test_profile_shear_rate_is_the_slope_of_a_linear_profile():
    rng = np.random.default_rng(3)
    n, L = 50, 0.05
    pos = rng.random((n, 3)) * L
    box = PeriodicBox(pos, np.full(n, 0.001), rng.uniform(1e-3, 2e-3, n), np.zeros(32),
                      (L, L, L), 1e-5, 0.001, 0.001)
    box.vel[:] = 0.0
    box.vel[:, 0] = 7.0 * (pos[:, 2] - 0.3 * L) + 0.4
    assert profile_shear_rate(box) == pytest.approx(7.0, rel=1e-12)


# the DEM shear cell against the closure
INERTIAL_NUMBERS = (0.03, 0.1, 0.3)
MISSES = {
    0.03: "measured miss: -31 % at I = 0.03 (phi = 0.598): in dense flow the grains' velocities "
          "are correlated and collisions dissipate less than Lun's uncorrelated estimate "
          "(Jenkins' c_L = 1.3 from this point closes it)",
    0.3: "measured miss: +74 % at I = 0.3 (phi = 0.564): the smooth-sphere dissipation omits "
         "the balls' sliding friction (0.2) and rolling resistance, which drain fluctuation "
         "energy in every collision of the sheared gas",
}


@pytest.fixture(scope="module")
def sheared():
    sc = Scenario()
    pair = next(c for c in sc.contacts if tuple(c.pair) == ("steel", "steel"))
    recs = run_shear_cell(sc, inertial_numbers=INERTIAL_NUMBERS, n_balls=300, seed=1,
                          strain=4.0, transient_strain=1.0, batches=8)
    prm = kinetic_parameters(sc.fill.diameter, sc.materials["steel"].density, pair.restitution)
    return {I: (r, closure_temperature(r["phi"], r["shear_rate"], prm))
            for I, r in zip(INERTIAL_NUMBERS, recs)}


@pytest.mark.slow
def test_shear_cell_measures_the_fluctuation_about_a_steady_imposed_profile(sheared):
    for I, (r, _) in sheared.items():
        assert r["steady"], r["reason"]
        # the balls follow the imposed profile, so T about it is the fluctuation
        assert r["shear_rate_measured"] == pytest.approx(r["shear_rate"], rel=0.05)
        # enough samples: the batch-means error is a small part of T
        assert r["granular_temperature_stderr"] < 0.05 * r["granular_temperature"]


@pytest.mark.slow
@pytest.mark.parametrize("I", [pytest.param(I, marks=pytest.mark.xfail(strict=True,
                                                                       reason=MISSES[I]))
                               if I in MISSES else I for I in INERTIAL_NUMBERS])
def test_sheared_temperature_matches_the_closure_within_ten_percent(sheared, I):
    r, T_closure = sheared[I]
    assert T_closure == pytest.approx(r["granular_temperature"], rel=0.10)


@pytest.mark.slow
def test_the_closures_misses_lie_where_its_physics_says(sheared):
    """Where the closure misses, it misses the way its missing physics says (MISSES): in dense
    flow (I = 0.03) the correlated grains dissipate less than Lun's estimate, so the closure's
    T is below the DEM's by more than the 10 % target; in the sheared gas (I = 0.3) the balls'
    sliding and rolling losses it omits put its T above the DEM's by more than 10 %; between
    them its T over the DEM's rises with I (docs/validation.md section 21)."""
    ratio = {I: T_closure / r["granular_temperature"] for I, (r, T_closure) in sheared.items()}
    assert ratio[0.03] < 0.9
    assert ratio[0.3] > 1.1
    assert ratio[0.03] < ratio[0.1] < ratio[0.3]


@pytest.mark.slow
@pytest.mark.xfail(strict=True, raises=AssertionError,
                   reason="measured miss: the continuum's dense balance, the DEM "
                   "cell's own plastic work mu p gamma_dot against Lun's dissipation, puts T at "
                   "5.4, 2.2 and 1.5 times the measured T at I = 0.03, 0.1, 0.3: the balls spend "
                   "their shear work in sliding and rolling, which the smooth-sphere Gamma "
                   "omits (docs/validation.md section 21)")
def test_plastic_work_balance_matches_the_sheared_temperature_within_ten_percent(sheared):
    # kinetic_stress.balance_temperature: tau gamma_dot = Gamma(phi, T); the DEM's tau = mu p
    prm = kinetic_parameters(D, RHO, 0.85)
    for I, (r, _) in sheared.items():
        T_bal = balance_temperature(r["phi"], r["mu"] * r["pressure"], r["shear_rate"], prm)
        assert T_bal == pytest.approx(r["granular_temperature"], rel=0.10), I


@pytest.fixture(scope="module")
def sliding_coefficient():
    """k_f of the dense sliding loss as `vibroflow calibrate --shear-cell` measures it
    (shear_temperature.sliding_table), from one steady point, I = 0.1, of a cell filled with
    another seed: none of the points it predicts below."""
    recs = run_shear_cell(Scenario(), inertial_numbers=(0.1,), n_balls=300, seed=2,
                          strain=4.0, transient_strain=1.0, batches=8)
    return sliding_table(recs, D, RHO, 0.85)["sliding_coefficient"]


@pytest.mark.slow
def test_the_dense_balance_with_the_sliding_loss_gives_the_sheared_temperature(
        sheared, sliding_coefficient):
    # the continuum's dense balance, tau gamma_dot = Gamma_Lun + k_f p sqrt(T) / d at the
    # cell's own equivalent shear stress and mean pressure (the invariants the continuum's
    # stress gives balance_temperature), with one k_f from another draw at one I, gives T
    # over a decade of I
    prm = kinetic_parameters(D, RHO, 0.85)._replace(sliding_coefficient=sliding_coefficient)
    for I, (r, _) in sheared.items():
        p = r["mean_pressure"]
        T_bal = balance_temperature(r["phi"], r["mu_eq"] * p, r["shear_rate"], prm, p)
        assert T_bal == pytest.approx(r["granular_temperature"], rel=0.10), I
