"""calibration/mu_temperature.py against known answers: cells generated from a known mu(I)
give that curve back; cells from mu(r I) with a known T collapse exactly on r I (and not on
I); the DEM-dissipation r_D equals Lun's r where the measured dissipation is Lun's Gamma;
Kim & Kamrin's exponent comes back from cells built with it."""
import numpy as np
import pytest
import xarray as xr

from vibroflow.calibration import mu_temperature as mt
from vibroflow.continuum.kinetic_stress import balance_temperature
from vibroflow.continuum.kinetic_theory import KineticParameters, dissipation_W_m3
from vibroflow.continuum.rheology import mu_of_I
from vibroflow.errors import InputError

PRM = KineticParameters(diameter_m=0.00635, density_kg_m3=7800.0, restitution=0.85,
                        phi_rcp=0.635)
LAW = {"mu_s": 0.28, "mu_2": 0.55, "I_0": 0.036}


def _cells(n=300, seed=0):
    rng = np.random.default_rng(seed)
    I = np.exp(rng.uniform(np.log(0.003), np.log(0.3), n))
    p = rng.uniform(500.0, 5000.0, n)
    phi = rng.uniform(0.52, 0.6, n)
    gd = I * np.sqrt(p / PRM.density_kg_m3) / PRM.diameter_m
    return I, p, phi, gd


def _dataset(mu, I, p, phi, gd):
    shape = (1, 1, mu.size)
    v = {"friction_coefficient": mu, "inertial_number": I, "pressure": p, "shear_rate": gd,
         "solid_fraction": phi, "friction_coefficient_stderr": 0.01 * np.ones(mu.size),
         "shear_rate_stderr": 0.01 * gd}
    return xr.Dataset({k: (("phase", "x", "z"), a.reshape(shape)) for k, a in v.items()})


def test_known_mu_of_I_comes_back():
    I, p, phi, gd = _cells()
    mu = mu_of_I(I, LAW["mu_s"], LAW["mu_2"], LAW["I_0"])
    fit = mt.fit_collapse(I, mu)
    assert fit["mu_s"] == pytest.approx(LAW["mu_s"], rel=1e-5)
    assert fit["mu_2"] == pytest.approx(LAW["mu_2"], rel=1e-5)
    assert fit["x_0"] == pytest.approx(LAW["I_0"], rel=1e-4)
    assert fit["rms_log_residual"] < 1e-6


def test_cells_from_mu_of_rI_collapse_on_rI_only():
    """mu = mu(X) at X = r I: for each cell pick r, invert for T = T_bal / r^2 with T_bal the
    continuum's balance at the cell's own tau gamma_dot; the pipeline's r I is X exactly."""
    I, p, phi, gd = _cells(seed=1)
    r = np.exp(np.random.default_rng(2).uniform(np.log(0.3), np.log(3.0), I.size))
    X = r * I
    mu = mu_of_I(X, LAW["mu_s"], LAW["mu_2"], LAW["I_0"])
    T_bal = np.array([balance_temperature(f, m * q, g, PRM)
                      for f, m, q, g in zip(phi, mu, p, gd)])
    T = T_bal / r ** 2
    D = np.array([dissipation_W_m3(f, t, g, PRM) for f, t, g in zip(phi, T, gd)])
    pts = mt.cell_points(_dataset(mu, I, p, phi, gd), T[None, None, :], PRM, D[None, None, :])
    assert pts["rI"] == pytest.approx(X, rel=1e-9)
    assert pts["rI_dem"] == pytest.approx(X, rel=1e-9)       # D = Lun's Gamma: r_D = r
    assert pts["Theta"] == pytest.approx(PRM.density_kg_m3 * T / p, rel=1e-12)
    tab = mt.collapse_table(pts, LAW)
    assert tab["rI"]["rms_log_residual"] < 1e-6
    assert tab["rI"]["calibrated_rms_log_residual"] < 1e-12
    assert tab["I"]["rms_log_residual"] > 0.05
    assert tab["noise"] == pytest.approx(np.sqrt(np.mean((0.01 / mu) ** 2)), rel=1e-12)


def test_kim_kamrin_exponent_comes_back():
    I, p, phi, gd = _cells(seed=3)
    theta = np.exp(np.random.default_rng(4).uniform(np.log(1e-3), np.log(5e-2), I.size))
    mu = theta ** 0.2 * mu_of_I(I, LAW["mu_s"], LAW["mu_2"], LAW["I_0"])
    fit = mt.fit_collapse(I, mu, theta)
    assert fit["a"] == pytest.approx(0.2, abs=1e-5)
    assert fit["rms_log_residual"] < 1e-6
    assert mt.fit_collapse(I, mu)["rms_log_residual"] > 0.1


def test_cell_selection_and_binned_errors():
    I, p, phi, gd = _cells(n=4, seed=5)
    phi = np.array([0.3, 0.55, 0.55, 0.55])
    gd_unresolved = gd.copy()
    mu = np.full(4, 0.4)
    ds = _dataset(mu, I, p, phi, gd)
    ds["shear_rate_stderr"][0, 0, 2] = gd_unresolved[2]      # 1 error: not resolved
    pts = mt.cell_points(ds, np.full((1, 1, 4), 1e-3), PRM)
    assert pts["mu"].size == 2                               # dilute and unresolved left out
    rows = mt.binned_medians(np.array([1.0, 1.5, 2.0, 2.5]), np.array([0.1, 0.2, 0.3, 0.4]),
                             np.full(4, 0.02), [0.0, 10.0])
    assert rows[0]["mu"] == pytest.approx(0.25)
    assert rows[0]["mu_stderr"] == pytest.approx(mt.MEDIAN_ERROR * 0.02 * 2.0 / 4.0)
    with pytest.raises(InputError):
        mt.fit_collapse(I[:3], mu[:3])
    with pytest.raises(InputError, match="dissipation: 3 values"):
        mt.cell_points(ds, np.full((1, 1, 4), 1e-3), PRM, np.ones(3))


def test_pailha_pouliquen_dilatancy_comes_back_with_b_one():
    """Cells from mu = F(I) + tan psi (a dilating cell shears at more than mu(I), a compacting
    one at less): b = 1 fits them exactly and the fitted b is 1; cells from mu(I) alone, their
    tan psi unrelated, fit b = 0, and the law with b = 1 misses them."""
    I, p, phi, gd = _cells(seed=6)
    tp = np.random.default_rng(7).uniform(-0.15, 0.15, I.size)
    mu = mu_of_I(I, LAW["mu_s"], LAW["mu_2"], LAW["I_0"]) + tp
    fixed = mt.fit_dilatancy(I, mu, tp, b=1.0)
    assert fixed["rms_log_residual"] < 1e-6
    assert fixed["mu_s"] == pytest.approx(LAW["mu_s"], rel=1e-5)
    assert fixed["floored"] == 0.0
    assert mt.fit_dilatancy(I, mu, tp)["b"] == pytest.approx(1.0, abs=1e-5)
    plain = mu_of_I(I, LAW["mu_s"], LAW["mu_2"], LAW["I_0"])
    assert mt.fit_dilatancy(I, plain, tp)["b"] == pytest.approx(0.0, abs=1e-5)
    assert mt.fit_dilatancy(I, plain, tp, b=1.0)["rms_log_residual"] > 0.1


def test_a_law_that_makes_the_friction_negative_counts_it_at_the_floor():
    """tan psi = -1 with F(I) about 0.3 predicts a negative friction: the residual is
    ln(mu / MU_FLOOR), by hand."""
    I = np.full(5, 0.01)
    mu = np.full(5, 0.3)
    fit = mt.fit_dilatancy(I, mu, np.full(5, -1.0), b=1.0)
    assert fit["floored"] == 1.0
    assert fit["rms_log_residual"] == pytest.approx(np.log(0.3 / mt.MU_FLOOR), rel=1e-9)


def test_zhang_kamrin_fluidity_comes_back():
    """Cells whose fluidity gamma_dot / mu is (sqrt(T) / d) F(phi), ln F quadratic in phi, give
    a = 1 and F back exactly; built through cell_points, whose fluidity number is gamma_dot d /
    sqrt(T) and whose tan psi is the velocity gradient's trace over the shear rate."""
    I, p, phi, gd = _cells(seed=8)
    T = np.exp(np.random.default_rng(9).uniform(np.log(1e-4), np.log(1e-2), I.size))
    c = (2.0, -3.0, 1.5)
    F = np.exp(c[0] + c[1] * phi + c[2] * phi ** 2)
    mu = gd * PRM.diameter_m / np.sqrt(T) / F
    ds = _dataset(mu, I, p, phi, gd)
    L = np.zeros((1, 1, I.size, 3, 3))
    L[..., 0, 0], L[..., 2, 2], L[..., 0, 2] = 0.3 * gd, -0.1 * gd, gd
    ds["velocity_gradient"] = (("phase", "x", "z", "i", "j"), L)
    ds = ds.assign_coords(z=np.arange(I.size) * 0.005)
    pts = mt.cell_points(ds, T[None, None, :], PRM)
    assert pts["fluidity_number"] == pytest.approx(gd * PRM.diameter_m / np.sqrt(T), rel=1e-12)
    assert pts["tan_psi"] == pytest.approx(np.full(I.size, 0.2), rel=1e-12)
    assert pts["z_m"] == pytest.approx(np.arange(I.size) * 0.005)
    assert np.isnan(pts["x_m"]).all()
    fit = mt.fit_fluidity(pts["fluidity_number"], pts["phi"], pts["mu"], a=1.0)
    assert fit["rms_log_residual"] < 1e-9
    assert fit["c"] == pytest.approx(list(c), rel=1e-6)
    assert mt.fit_fluidity(pts["fluidity_number"], pts["phi"], pts["mu"])["a"] == \
        pytest.approx(1.0, abs=1e-9)
    tab = mt.collapse_table(pts)
    assert tab["fluidity"]["rms_log_residual"] < 1e-9
    assert tab["dilatancy_b"]["points"] == I.size
