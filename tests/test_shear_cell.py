"""The media's rheology from DEM: Lees-Edwards periodic box, shear cell, elastic moduli and the
mu(I) fit, checked against known answers (never against numbers the code produced itself).

Lees-Edwards kinematics (Lees & Edwards 1972): the image of a ball one box above sits at
r + (Delta, 0, L_z) with the offset Delta = gamma_dot L_z t and moves at v + gamma_dot L_z x.
A free ball leaving through the top therefore re-enters at the bottom at
x = x_0 + v_x t - Delta(t) (mod L_x) with v_x - gamma_dot L_z, exactly; and a collision with
an image is the collision of two balls with the relative velocity of the images, so a head-on
collision across the boundary gives the restitution of the law, e = exp(-pi zeta /
sqrt(1 - zeta^2)) (tests/test_dem_collisions.py), whatever the shear rate.  Pair forces are
equal and opposite, so the momentum of the unwrapped balls, sum m (v_x + k gamma_dot L_z) with
k the net number of upward crossings, is conserved exactly.

Published rheology:
* frictionless spheres in steady simple shear have a quasi-static friction mu* = 0.10 and
  dilate little, phi_c = 0.64 (Peyneau & Roux 2008, PRE 78:011307, mu* = 0.100 +- 0.01 and
  phi_c = 0.637 for I -> 0; mu rises slowly with I, by about 0.02 at I = 0.01);
* frictional spheres: mu increases and phi decreases with I (GDR MiDi 2004; da Cruz et al.
  2005).

Elastic moduli: see `test_bulk_modulus_matches_the_affine_prediction`.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from vibroflow.errors import InputError
from vibroflow.scenario.model import ContactPair, Scenario

D = 0.00635
R = D / 2
RHO = 7800.0
M = RHO * math.pi * D**3 / 6


def scenario(friction=0.20, rolling=0.002, restitution=0.85, k_n=1.0e5):
    """tub47 with the ball-ball law changed."""
    base = Scenario()
    contacts = [c if tuple(c.pair) != ("steel", "steel") else
                ContactPair(pair=("steel", "steel"), k_n=k_n, restitution=restitution,
                            friction=friction, rolling_friction=rolling)
                for c in base.contacts]
    return Scenario(contacts=contacts)


def ball_row(sc):
    from vibroflow.dem.laws import material_index, pair_table
    i = material_index(sc)["steel"]
    return pair_table(sc)[i, i]


def make_box(pos, vel, lengths, sc=None, dt=1e-5):
    from vibroflow.dem.periodic_box import PeriodicBox
    sc = sc or scenario()
    n = len(pos)
    box = PeriodicBox(np.array(pos, float), np.full(n, R), np.full(n, M), ball_row(sc),
                      lengths, dt, 0.3 * D, 0.25 * D)
    box.vel[:] = np.array(vel, float)
    return box


# ----------------------------------------------------------------------------------------------
# Lees-Edwards kinematics

def test_free_ball_crossing_gets_the_exact_shift_and_velocity_jump():
    """Two balls far from anything cross the z boundary, up and down; after n steps each is
    where free flight plus the LE map puts it, to round-off."""
    from vibroflow.dem.periodic_step import MODE_FIXED
    L = (0.05, 0.04, 0.05)
    gd = 20.0
    x0 = np.array([[0.010, 0.020, 0.049], [0.030, 0.010, 0.001], [0.025, 0.030, 0.025]])
    v0 = np.array([[0.30, 0.10, 2.0], [-0.20, 0.05, -1.5], [0.0, 0.0, 0.0]])
    box = make_box(x0, v0, L)
    box.rates[0] = gd  # impose the shear without re-profiling: the balls keep v0
    p0 = box.unwrapped_momentum()
    n = 200
    box.run(n, MODE_FIXED, sample_every=n)
    t = n * box.dt
    offset = gd * L[2] * t
    for i, k in ((0, 1), (1, -1)):
        z = x0[i, 2] + v0[i, 2] * t - k * L[2]
        x = (x0[i, 0] + v0[i, 0] * t - k * offset) % L[0]
        y = (x0[i, 1] + v0[i, 1] * t) % L[1]
        assert box.pos[i] == pytest.approx([x, y, z], abs=1e-12)
        assert box.vel[i, 0] == pytest.approx(v0[i, 0] - k * gd * L[2], abs=1e-12)
        assert box.vel[i, 1:] == pytest.approx(v0[i, 1:], abs=1e-12)
        assert box.image[i, 2] == k
    assert box.box[3] == pytest.approx(offset % L[0], abs=1e-12)
    assert box.unwrapped_momentum() == pytest.approx(p0, abs=1e-15)


def test_head_on_collision_across_the_boundary_has_the_laws_restitution():
    """Ball A below the top moving up and ball B above the bottom moving down, B's image above
    the box exactly in line with A and moving with it in x (v_Ax = v_Bx + gamma_dot L_z): the
    images collide head-on with relative speed 2w and leave with 2 e w; x velocities keep
    their values, the relative normal velocity is reversed with e (1%, the time step), and
    the unwrapped momentum is conserved.  A wrong image shift or velocity jump would make
    the contact oblique by gamma_dot L_z = 1 m/s beside w = 0.1 m/s."""
    from vibroflow.dem.periodic_step import MODE_FIXED
    from vibroflow.scenario.laws import damping_ratio
    L = (0.05, 0.05, 0.05)
    gd = 20.0
    w = 0.1
    gap = 2e-5  # m: ten steps of approach
    # A's top at L_z - gap/2, the bottom of B's image (z_B + L_z) at L_z + gap/2
    pos = [[0.02, 0.025, L[2] - R - gap / 2], [0.02, 0.025, R + gap / 2]]
    # B's image sits at x_B + Delta, z_B + L_z: in line with A at t = 0 (Delta = 0), and
    # they keep in line since Delta grows at gamma_dot L_z = v_Ax - v_Bx
    vel = [[gd * L[2] / 2, 0.0, w], [-gd * L[2] / 2, 0.0, -w]]
    box = make_box(pos, vel, L)
    box.rates[0] = gd
    p0 = box.unwrapped_momentum()
    box.run(400, MODE_FIXED, sample_every=400)
    zeta = damping_ratio(0.85)
    e = math.exp(-math.pi * zeta / math.sqrt(1 - zeta**2))
    k = box.image[:, 2]
    vx = box.vel[:, 0] + k * gd * L[2]
    assert vx == pytest.approx([gd * L[2] / 2, -gd * L[2] / 2], abs=1e-9)
    v_rel = box.vel[1, 2] - box.vel[0, 2]
    assert v_rel / (2 * w) == pytest.approx(e, rel=0.01)
    assert np.abs(box.omg).max() < 1e-9
    assert box.unwrapped_momentum() == pytest.approx(p0, abs=1e-14)


def test_sheared_gas_conserves_unwrapped_momentum_and_is_reproducible():
    """A gas of 150 balls at phi = 0.3 sheared at a high rate, with many collisions across the
    LE boundary: the unwrapped momentum is conserved to round-off (pair forces are equal and
    opposite, every crossing accounted), and the same seed gives the same state bit for bit."""
    from vibroflow.dem.periodic_box import random_fill
    from vibroflow.dem.periodic_step import MODE_FIXED, Q_Z

    def run():
        rng = np.random.default_rng(7)
        n = 150
        side = (n * math.pi * D**3 / 6 / 0.3) ** (1 / 3)
        pos = random_fill(n, np.full(n, R), (side,) * 3, rng)
        box = make_box(pos, rng.normal(0.0, 0.5, (n, 3)), (side,) * 3)
        box.set_shear_rate(50.0)
        p0 = box.unwrapped_momentum()
        s = box.run(3000, MODE_FIXED, sample_every=100)
        return box, p0, s

    box, p0, s = run()
    assert np.abs(box.image[:, 2]).sum() > 10  # the test means something
    assert s[:, Q_Z].mean() > 0.02  # contacts per ball: collisions happen
    assert box.unwrapped_momentum() == pytest.approx(p0, abs=1e-14)
    box2, _, _ = run()
    assert np.array_equal(box.pos, box2.pos) and np.array_equal(box.vel, box2.vel)


# ----------------------------------------------------------------------------------------------
# shear cell

@pytest.fixture(scope="module")
def frictional_cell():
    """tub47's ball-ball law at I = 0.02 and 0.3: a short sweep (p = 20 kPa, k_n/(p d) = 790:
    still rigid, overlaps ~ 0.1% of d)."""
    from vibroflow.calibration.shear_cell import run_shear_cell
    return run_shear_cell(scenario(), inertial_numbers=(0.02, 0.3), pressure=2.0e4,
                          n_balls=200, seed=3, strain=2.0, transient_strain=0.6)


def test_barostat_holds_the_imposed_normal_stress():
    """Over 5 strain units of steady shear the measured sigma_zz is the imposed pressure: the
    control law has no steady-state error, so only the box's remaining breathing over the
    window shows, within 3% and within 3 standard errors; the measured I is the target one
    accordingly (I ~ sigma_zz^(-1/2))."""
    from vibroflow.calibration.shear_cell import run_shear_cell
    rows = run_shear_cell(scenario(), inertial_numbers=(0.1, 0.3), pressure=2.0e4,
                          n_balls=200, seed=4, strain=6.0, transient_strain=1.0)
    for r in rows:
        assert r["steady"], r["reason"]
        err = abs(r["pressure"] - 2.0e4)
        assert err < 0.03 * 2.0e4 and err < 3 * r["pressure_stderr"] + 1e-9, r
        assert r["I"] == pytest.approx(r["I_target"], rel=0.02)


def test_mu_increases_and_phi_decreases_with_I(frictional_cell):
    """GDR MiDi (2004): mu(I) rises and phi(I) falls, both well beyond their errors."""
    lo, hi = frictional_cell
    assert lo["steady"] and hi["steady"], (lo["reason"], hi["reason"])
    assert hi["mu"] - lo["mu"] > 3 * math.hypot(hi["mu_stderr"], lo["mu_stderr"])
    assert lo["phi"] - hi["phi"] > 3 * math.hypot(hi["phi_stderr"], lo["phi_stderr"])
    # and in the range of weakly frictional spheres (between frictionless, 0.1, and rough)
    assert 0.2 < lo["mu"] < 0.45 and 0.55 < lo["phi"] < 0.64
    for r in (lo, hi):
        assert r["pressure"] == pytest.approx(2.0e4, rel=0.1)


@pytest.mark.slow
def test_frictionless_spheres_have_peyneau_roux_friction():
    """Frictionless spheres (friction = 0, rolling = 0) at I = 0.01.  Peyneau & Roux (2008):
    mu* = 0.10 in the quasi-static limit, rising as a power of I (mu - mu* ~ I^0.35 or so in
    frictionless inertial flows, DeGiuli et al. 2015 PRE 91:062206), by some 0.02 to 0.05 at
    I = 0.01; so 0.10 <= mu < 0.16, a third of the frictional value.  phi stays near
    phi_c = 0.637 ("no dilatancy"): 0.625 to 0.645."""
    from vibroflow.calibration.shear_cell import run_shear_cell
    sc = scenario(friction=0.0, rolling=0.0)
    (r,) = run_shear_cell(sc, inertial_numbers=(0.01,), pressure=2.0e4, n_balls=200, seed=5,
                          strain=1.5, transient_strain=0.5)
    assert r["steady"], r["reason"]
    assert 0.10 - 2 * r["mu_stderr"] <= r["mu"] < 0.16, r
    assert 0.625 < r["phi"] < 0.645, r


def test_shear_cell_input_errors_are_one_line():
    from vibroflow.calibration.shear_cell import run_shear_cell
    sc = scenario()
    for kwargs, field in (({"n_balls": 10}, "n_balls"), ({"pressure": -1.0}, "pressure"),
                          ({"inertial_numbers": (0.1, 2.0)}, "inertial_numbers"),
                          ({"strain": 1.0, "transient_strain": 1.0}, "transient_strain")):
        with pytest.raises(InputError) as e:
            run_shear_cell(sc, pressure=kwargs.pop("pressure", 5e3), **kwargs)
        assert field in str(e.value) and "\n" not in str(e.value)


# ----------------------------------------------------------------------------------------------
# elastic moduli

def test_bulk_modulus_matches_the_affine_prediction():
    """Bulk modulus of a packing of linear springs against the affine (effective-medium, Voigt)
    prediction K_aff = phi Z k_n / (3 pi d) (Walton 1987; Makse et al. 1999 for Hertz).

    Derivation: the contact stress is sigma = (1/V) sum_c f_c (x) l_c, l_c = d n_c for equal
    spheres.  An affine isotropic compression eps (per axis) closes every contact by d eps and
    moves no contact point sideways, so each normal force grows by k_n d eps along n and sigma
    by (k_n d^2 eps / V) sum_c n (x) n, whose trace / 3 is dp = N_c k_n d^2 eps / (3 V).  With
    eps_v = 3 eps and the contact density N_c / V = (N Z / 2) / V = 3 phi Z / (pi d^3):
    K_aff = dp / deps_v = phi Z k_n / (3 pi d), Z = 2 C / N counting every ball.

    The affine field is kinematically admissible, so by the principle of minimum potential
    energy the relaxed (non-affine) response is softer: K <= K_aff, up to the O(p / K) terms
    of the pre-stress.  For compression the balls have little to rearrange along and, in
    packings well above the isostatic coordination, the relaxation takes off some 10-25%
    (Agnolin & Roux 2007, PRE 76:061304, elastic moduli against the Voigt bound), so
    0.7 K_aff < K <= K_aff.  The shear modulus relaxes much more (Makse et al. 1999: the
    effective-medium G is far too high): positive, below G_aff = phi Z (2 k_n + 3 k_t) /
    (10 pi d), the same bound for simple shear."""
    from vibroflow.calibration.elastic import elastic_moduli
    el = elastic_moduli(scenario(), pressure=2.0e4, n_balls=200, seed=2)
    assert el["converged"]
    assert el["pressure"] == pytest.approx(2.0e4, rel=0.02)
    k_aff = el["solid_fraction"] * el["coordination_number"] * 1.0e5 / (3 * math.pi * D)
    assert 0.7 * k_aff < el["bulk_modulus"] <= 1.01 * k_aff, el
    assert el["bulk_modulus"] > 10 * el["bulk_modulus_stderr"], el
    g_aff = el["solid_fraction"] * el["coordination_number"] * (2 + 3 * 2 / 7) * 1.0e5 / (
        10 * math.pi * D)
    assert 0 < el["shear_modulus"] < g_aff, el
    assert el["shear_modulus"] > 3 * el["shear_modulus_stderr"], el


# ----------------------------------------------------------------------------------------------
# fits and the Drucker-Prager equivalent

def test_mu_i_fit_recovers_known_parameters_from_noisy_data():
    """Synthetic points from the glass-bead mu(I) (mu_s = tan 20.9 deg, mu_2 = tan 32.8 deg,
    I_0 = 0.279, GDR MiDi / Jop et al. 2006) with Gaussian noise of known standard error: the
    fit must find each parameter within 3 of its own standard errors, in 20 noise draws at
    least 18 times, and chi2/dof near 1; phi(I) likewise."""
    from vibroflow.calibration.rheology_fit import fit_mu_i, fit_phi_i
    from vibroflow.continuum.rheology import mu_of_I, phi_of_I
    true = (math.tan(math.radians(20.9)), math.tan(math.radians(32.8)), 0.279)
    I = np.geomspace(0.003, 1.0, 9)
    se = np.full(I.size, 0.008)
    rng = np.random.default_rng(11)
    hits, chi = 0, []
    for _ in range(20):
        mu = mu_of_I(I, *true) + rng.normal(0, se)
        f = fit_mu_i(I, mu, se)
        ok = all(abs(f[k] - v) <= 3 * f[k + "_stderr"] for k, v in zip(("mu_s", "mu_2", "I_0"),
                                                                       true))
        hits += ok
        chi.append(f["chi2_per_dof"])
    assert hits >= 18
    assert 0.6 < np.mean(chi) < 1.5
    phi = phi_of_I(I, 0.60, 0.52) + rng.normal(0, 0.002, I.size)
    p = fit_phi_i(I, phi, np.full(I.size, 0.002))
    assert abs(p["phi_max"] - 0.60) < 3 * p["phi_max_stderr"]
    assert abs(p["phi_min"] - 0.52) < 3 * p["phi_min_stderr"]


def test_fits_refuse_too_few_points():
    from vibroflow.calibration.rheology_fit import fit_mu_i, fit_phi_i
    with pytest.raises(InputError, match="at least 3"):
        fit_mu_i([0.01, 0.1], [0.3, 0.4])
    with pytest.raises(InputError, match="at least 2"):
        fit_phi_i([0.01], [0.6])


@pytest.mark.parametrize("phi_deg", [10.0, 25.0, 40.0])
def test_plane_strain_drucker_prager_reproduces_mohr_coulomb(phi_deg):
    """The Drucker-Prager cone sqrt(J_2) = alpha I_1 (tan beta = 3 sqrt(3) alpha) with the
    returned tan beta, in plane strain with associated flow: the flow rule makes the plastic
    strain rate along y vanish, which fixes sigma_yy; the in-plane Mohr circle of the yield
    stress must then touch the Mohr-Coulomb line of phi_f = atan(mu_s): (s1 - s3)/(s1 + s3) =
    sin phi_f.  (Centre c, radius r, sigma_yy = c + e: J_2 = r^2 + e^2/3, s_yy = 2e/3; flow
    rule s_yy / (2 sqrt J_2) = alpha and yield sqrt J_2 = alpha (3c + e) give
    e = 9 alpha^2 c / (1 - 3 alpha^2), r^2 = alpha^2 (3c + e)^2 - e^2/3.)"""
    from vibroflow.calibration.rheology_fit import drucker_prager_equivalent
    mu_s = math.tan(math.radians(phi_deg))
    dp = drucker_prager_equivalent(mu_s, mu_s + 0.2, 0.3, 0.6, 0.5, 5000.0, D, RHO, 10.0)
    assert dp["friction_angle_deg"] == pytest.approx(phi_deg)
    alpha = dp["tan_beta"] / (3 * math.sqrt(3))
    c = 1.0
    e = 9 * alpha**2 * c / (1 - 3 * alpha**2)
    r = math.sqrt(alpha**2 * (3 * c + e) ** 2 - e**2 / 3)
    assert r / c == pytest.approx(math.sin(math.radians(phi_deg)), rel=1e-12)


def test_equivalent_viscosity_gives_the_mu_i_stress():
    """mu_s p + eta gamma_dot must be the mu(I) shear stress at that shear rate."""
    from vibroflow.calibration.rheology_fit import drucker_prager_equivalent
    from vibroflow.continuum.rheology import mu_of_I
    p, gd = 5000.0, 30.0
    dp = drucker_prager_equivalent(0.38, 0.64, 0.279, 0.6, 0.5, p, D, RHO, gd)
    I = gd * D / math.sqrt(p / RHO)
    assert dp["inertial_number"] == pytest.approx(I)
    assert 0.38 * p + dp["viscosity_Pa_s"] * gd == pytest.approx(mu_of_I(I, 0.38, 0.64, 0.279)
                                                                 * p)
    assert 0 < dp["dilation_angle_deg"] < 90


# ----------------------------------------------------------------------------------------------
# slow: the tub47 calibration sweep

@pytest.mark.slow
def test_tub47_shear_cell_sweep_is_monotonic_and_fits():
    """The default sweep on tub47 at its bed pressure: every point steady, mu never falling and
    phi never rising with I beyond their errors, both changing well beyond their errors over
    the range (GDR MiDi 2004), and the mu(I) fit in the range of frictional spheres
    (mu_s between the frictionless 0.1 and the glass beads' tan 20.9 deg = 0.38 plus margin)."""
    from vibroflow.calibration.rheology_fit import fit_mu_i
    from vibroflow.calibration.shear_cell import run_shear_cell
    rows = run_shear_cell(Scenario())
    assert all(r["steady"] for r in rows), [r["reason"] for r in rows]
    mu = np.array([r["mu"] for r in rows])
    phi = np.array([r["phi"] for r in rows])
    smu = np.array([r["mu_stderr"] for r in rows])
    sphi = np.array([r["phi_stderr"] for r in rows])
    assert np.all(np.diff(mu) > -3 * np.hypot(smu[1:], smu[:-1]))
    assert np.all(np.diff(phi) < 3 * np.hypot(sphi[1:], sphi[:-1]))
    assert mu[-1] - mu[0] > 3 * math.hypot(smu[-1], smu[0])
    assert phi[0] - phi[-1] > 3 * math.hypot(sphi[-1], sphi[0])
    f = fit_mu_i([r["I"] for r in rows], mu, smu)
    assert 0.15 < f["mu_s"] < 0.45 and f["mu_2"] > f["mu_s"]
