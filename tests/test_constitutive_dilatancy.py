"""The dilatancy option of the shared constitutive law (vibroflow.continuum.constitutive) against
the Pailha & Pouliquen (2009, J. Fluid Mech. 633, 115-135) law integrated independently:

    mu = mu(I) + K_dil (phi - phi_eq(I)),  phi_eq(I) = phi_c - a I,  d phi / d gamma = -phi tan psi,

for a homogeneous simple shear at constant pressure; and its fit on a DEM-like transient
(vibroflow.calibration.dilatancy.fit_dilatancy) against a transient of known K_dil.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from vibroflow.calibration.dilatancy import fit_dilatancy
from vibroflow.continuum.constitutive import ContinuumMaterial
from vibroflow.continuum.rheology import mu_of_I
from vibroflow.continuum.stress_update import update_stress_points
from vibroflow.errors import InputError

# a material whose steady phi_eq(I) stays connected (phi_eq > phi_c exp(-p/K)) at the test's I
MAT = dict(bulk_modulus=2.0e6, shear_modulus=1.0e6, phi_max=0.60, phi_min=0.50,
           critical_solid_fraction=0.60)
P0 = 5.0e3      # Pa
RATE = 1.0      # 1/s
DT = 1.0e-5     # s (the dilation's pressure change lags the yield by K dt tan(psi) gp: first order)


def barostat_step(stress, rho, rate, p0, K, dt, params, gd, st):
    """One constitutive step of a point (stress (1, 4), density rho (1,)) in simple shear
    L_xz = rate with an in-plane isotropic strain rate e that brings the trial pressure back to
    p0 (a perfect barostat: p - K dt tr(D) = p0, tr(D) = 2 e); the density follows det F.
    Returns e (1/s)."""
    p = -(stress[0, 0] + stress[0, 1] + stress[0, 3]) / 3.0
    e = 0.5 * (p - p0) / (K * dt)
    rho[0] /= (1.0 + dt * e) ** 2   # det F of the step (plane strain)
    update_stress_points(stress, np.array([[e, rate, 0.0, e]]), rho, dt, params, gd, st)
    return e


def barostat_point(mat, phi0, p0):
    """One point under the isotropic stress -p0 (Pa) at the unloaded packing phi0: (bulk
    modulus K, stress (1, 4), density (1,) = phi0 exp(p0 / K) rho_s, gamma_dot and state work
    arrays, the material's packed parameters), for barostat_step."""
    K = mat.bulk_modulus
    stress = np.array([[-p0, -p0, 0.0, -p0]])
    rho = np.array([phi0 * math.exp(p0 / K) * mat.solid_density])
    return K, stress, rho, np.zeros(1), np.zeros(1, np.int8), mat.as_array()


def pressure_controlled_shear(mat, phi0, strain, p0=P0, rate=RATE, dt=DT):
    """One point in simple shear L_xz = rate from the isotropic stress -p0 at the unloaded
    packing phi0, with an in-plane isotropic strain rate that brings the trial pressure back to
    p0 every step (a perfect barostat): returns plastic strain, stress ratio tau/p and unloaded
    packing phi rho exp(-p/K) / rho_s per step."""
    K, stress, rho, gd, st, params = barostat_point(mat, phi0, p0)
    n = int(round(strain / (rate * dt)))
    out = np.zeros((n, 3))
    gp_sum = 0.0
    for k in range(n):
        barostat_step(stress, rho, rate, p0, K, dt, params, gd, st)
        s = stress[0]
        pr = -(s[0] + s[1] + s[3]) / 3.0
        dev = np.array([s[0] + pr, s[1] + pr, s[3] + pr])
        tau = math.sqrt(0.5 * (dev @ dev) + s[2] ** 2)
        gp_sum += gd[0] * dt
        out[k] = gp_sum, tau / pr, rho[0] * math.exp(-pr / K) / mat.solid_density
    assert st[0] == 2  # flowing at the end
    return out


def pailha_pouliquen(mat, K_dil, phi0, strain, p0=P0, rate=RATE):
    """The law integrated with scipy over the shear strain: phi(gamma) and mu(gamma)."""
    I = rate * mat.diameter / math.sqrt(p0 / mat.solid_density)
    phi_eq = mat.critical_solid_fraction - (mat.phi_max - mat.phi_min) * I
    mu_I = float(mu_of_I(I, mat.mu_s, mat.mu_2, mat.I_0))
    sol = solve_ivp(lambda g, y: [-y[0] * K_dil * (y[0] - phi_eq)], (0.0, strain), [phi0],
                    dense_output=True, rtol=1e-10, atol=1e-12)

    def at(g):
        phi = sol.sol(np.asarray(g, float))[0]
        return phi, mu_I + K_dil * (phi - phi_eq)

    return at, mu_I, phi_eq


def test_dense_bed_peaks_and_relaxes_to_mu_of_I():
    """A bed 0.03 denser than critical: its stress ratio peaks at mu(I) + K_dil (phi0 -
    phi_eq(I)) and relaxes to mu(I) as it dilates to phi_eq(I), along the Pailha & Pouliquen
    curve (solved with scipy)."""
    K_dil, phi0 = 4.0, 0.63
    mat = ContinuumMaterial(**MAT, dilatancy=K_dil)
    run = pressure_controlled_shear(mat, phi0, strain=3.0)
    law, mu_I, phi_eq = pailha_pouliquen(mat, K_dil, phi0, 3.0)
    g, mu, phi = run[:, 0], run[:, 1], run[:, 2]
    peak = mu_I + K_dil * (phi0 - phi_eq)
    assert mu.max() == pytest.approx(peak, rel=2e-3)
    # along the whole transient (past the elastic loading, a strain mu p / G ~ 2e-3)
    sel = g > 0.01
    phi_law, mu_law = law(g[sel])
    assert np.max(np.abs(mu[sel] - mu_law)) < 2e-3 * peak
    assert np.max(np.abs(phi[sel] - phi_law)) < 2e-4
    # relaxed: the steady mu(I), phi_eq(I)
    assert mu[-1] == pytest.approx(mu_I, abs=2e-3)
    assert phi[-1] == pytest.approx(phi_eq, abs=2e-4)


def test_bed_at_phi_eq_flows_at_mu_of_I_without_volume_change():
    """At phi = phi_eq(I) the law is the plain mu(I): no dilatancy, no peak."""
    mat = ContinuumMaterial(**MAT, dilatancy=4.0)
    _, mu_I, phi_eq = pailha_pouliquen(mat, 4.0, 0.6, 0.1)
    run = pressure_controlled_shear(mat, phi_eq, strain=0.3)
    assert run[-1, 1] == pytest.approx(mu_I, rel=1e-3)
    assert run[-1, 2] == pytest.approx(phi_eq, abs=1e-6)


def test_off_is_the_plain_law_bit_for_bit():
    """K_dil = 0 gives the plain mu(I) return map, bit for bit."""
    rng = np.random.default_rng(3)
    n = 50
    stress = -np.abs(rng.normal(3e3, 1e3, (n, 4)))
    stress[:, 2] = rng.normal(0, 2e3, n)
    L = rng.normal(0, 30.0, (n, 4))
    base = ContinuumMaterial()
    rho = np.full(n, base.critical_density * 1.02)
    out = []
    for mat in (base, ContinuumMaterial(dilatancy=0.0)):
        s = stress.copy()
        gd, st = np.zeros(n), np.zeros(n, np.int8)
        update_stress_points(s, L, rho, 1e-5, mat.as_array(), gd, st)
        out.append((s, gd, st))
    assert np.array_equal(out[0][0], out[1][0]) and np.array_equal(out[0][1], out[1][1])


def test_confined_dense_bed_builds_pressure():
    """Reynolds dilatancy: a dense bed sheared at constant volume cannot dilate, so its plastic
    dilation tr D^p = tan(psi) gamma_dot_p turns into pressure, dp = K tan(psi) d gamma_p."""
    K_dil, phi0 = 4.0, 0.63
    mat = ContinuumMaterial(**MAT, dilatancy=K_dil)
    stress = np.array([[-P0, -P0, 0.0, -P0]])
    rho = np.array([phi0 * math.exp(P0 / mat.bulk_modulus) * mat.solid_density])
    gd, st = np.zeros(1), np.zeros(1, np.int8)
    L = np.array([[0.0, RATE, 0.0, 0.0]])
    for _ in range(2000):
        update_stress_points(stress, L, rho, DT, mat.as_array(), gd, st)
    p = -(stress[0, 0] + stress[0, 1] + stress[0, 3]) / 3.0
    assert p > P0 * 1.01
    plain = ContinuumMaterial(**MAT)
    stress2 = np.array([[-P0, -P0, 0.0, -P0]])
    for _ in range(2000):
        update_stress_points(stress2, L, rho, DT, plain.as_array(), gd, st)
    assert -(stress2[0, 0] + stress2[0, 1] + stress2[0, 3]) / 3.0 == pytest.approx(P0, rel=1e-9)


def test_fit_recovers_a_known_dilatancy_constant():
    """fit_dilatancy on a Pailha & Pouliquen transient with noise: K_dil within its error."""
    mat = ContinuumMaterial(**MAT)
    K_dil, phi0 = 3.0, 0.64
    law, mu_I, phi_eq = pailha_pouliquen(mat, K_dil, phi0, 3.0)
    g = np.arange(0.005, 3.0, 0.01)
    phi, mu = law(g)
    rng = np.random.default_rng(1)
    # an elastic rise to the peak over the first 0.05 of strain, then the law, with noise
    mu = np.where(g < 0.05, mu * g / 0.05, mu) + rng.normal(0, 0.01, g.size)
    fit = fit_dilatancy(g, mu, phi, steady_fraction=0.3, segment_strain=0.01)
    assert abs(fit["K_dil"] - K_dil) < 3 * fit["K_dil_stderr"] + 0.1
    assert fit["phi_ss"] == pytest.approx(phi_eq, abs=1e-3)
    assert fit["mu_ss"] == pytest.approx(mu_I, abs=0.01)


def test_bad_dilatancy_input():
    with pytest.raises(InputError, match="dilatancy"):
        ContinuumMaterial(dilatancy=-1.0)
    with pytest.raises(InputError, match="dilatancy"):
        ContinuumMaterial(model="drucker_prager", dilatancy=2.0)


def test_run_option_takes_k_dil_from_the_calibration():
    """`dilatancy = true` (run options) switches the option on with the calibration's measured
    [dilatancy] K_dil, and is refused without one; an initial excess packing is carried to the
    bed without changing its solid volume (the DEM's balls)."""
    from vibroflow.continuum.bed import bed_area
    from vibroflow.continuum.formulation import formulation
    from vibroflow.continuum.material import material_of
    from vibroflow.io.calibration_file import Calibration
    from vibroflow.scenario.io import load_scenario

    sc = load_scenario("tub47-quick", [])
    tables = {"rheology": {"mu_s": 0.3, "mu_2": 0.55, "I_0": 0.04, "phi_max": 0.57,
                           "phi_min": 0.36},
              "elastic": {"bulk_modulus_Pa": 1.0e6, "shear_modulus_Pa": 1.0e5},
              "wall": {"friction": 0.19},
              "media": {"diameter_m": 0.00635, "solid_density_kg_m3": 7800.0}}
    cal = Calibration.from_dict(tables)
    assert material_of(sc, cal, "mu_i", False).dilatancy == 0.0
    with pytest.raises(InputError, match="dilatancy"):
        material_of(sc, cal, "mu_i", True)
    tables["dilatancy"] = {"K_dil": 6.0}
    mat = material_of(sc, Calibration.from_dict(tables), "mu_i", True)
    assert mat.dilatancy == 6.0 and mat.initial_solid_fraction is None
    tables["dilatancy"]["initial_excess_solid_fraction"] = 0.03
    dense = material_of(sc, Calibration.from_dict(tables), "mu_i", True)
    assert dense.initial_solid_fraction == pytest.approx(0.60)
    solid = sc.fill.count * math.pi * sc.fill.diameter**3 / 6.0 / sc.tub.length
    for m in (mat, dense):
        assert bed_area(sc, m) * m.initial_density == pytest.approx(solid * 7800.0, rel=1e-12)
    with pytest.raises(InputError, match="dilatancy"):
        formulation("lagrangian").options(dilatancy="yes")


@pytest.mark.slow
def test_dem_dense_packing_peaks_dilates_and_gives_k_dil_of_published_order():
    """The DEM measurement (vibroflow.calibration.dilatancy) on tub47's balls: a dense packing
    sheared at constant pressure peaks above its steady friction and dilates to its steady
    solid fraction (Reynolds; Pailha & Pouliquen 2009 figs. 4-5), and the post-peak slope
    K_dil is positive and of the order of Pailha & Pouliquen's 4.09 (glass beads)."""
    from vibroflow.calibration.dilatancy import run_dilatancy
    from vibroflow.scenario.io import load_scenario

    sc = load_scenario("tub47-quick", [])
    r = run_dilatancy(sc, pressure=3370.0, inertial_number=0.02, seeds=(1, 2), strain=1.2)
    for peak, ss, f0, fss in zip(r["mu_peak"], r["mu_ss"], r["phi_start"], r["phi_ss"]):
        assert peak > ss + 0.05
        assert f0 > fss + 0.01
    assert 4.09 / 3 < r["K_dil"] < 4.09 * 3
