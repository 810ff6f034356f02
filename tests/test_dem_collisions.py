"""DEM verification, single collisions: the contact laws against known answers.

Every expected number here comes from an analytic solution of the contact law (or from rigid-body
mechanics with Coulomb friction), never from the engine itself.

Head-on collisions (models.md, "DEM contact laws")
--------------------------------------------------
Linear spring-dashpot: m x'' = -k x - gamma x' during the contact (x the overlap), a damped
oscillator started at x = 0, x' = v: x(t) = (v / w_d) exp(-zeta w0 t) sin(w_d t), so the contact
lasts t_c = pi / w_d = pi / sqrt(k/m - (gamma / 2m)^2) and the restitution is
e = exp(-zeta w0 t_c) = exp(-pi zeta / sqrt(1 - zeta^2)) (the damping may pull at the end, as in
LAMMPS/LIGGGHTS; that is what makes these formulas exact).

Hertz, undamped (e = 1): m x'' = -k x^(3/2) with k = (4/3) E* sqrt(R_eff).  In units of length
L = (m v^2 / k)^(2/5) and time T = L / v = (m / k)^(2/5) v^(-1/5) this is X'' = -X^(3/2),
X(0) = 0, X'(0) = 1.  Energy: X'^2 / 2 + (2/5) X^(5/2) = 1/2, so the largest overlap is
X_m = (5/4)^(2/5), and the time to reach it is
    integral_0^X_m dX / sqrt(1 - (4/5) X^(5/2)) = X_m integral_0^1 du / sqrt(1 - u^(5/2))
                                                = X_m (2/5) B(2/5, 1/2)
(substitute s = u^(5/2)).  The contact is symmetric, so
    t_c = TAU_HERTZ (m_eff / k)^(2/5) v^(-1/5),  TAU_HERTZ = 2 (5/4)^(2/5) (2/5) B(2/5, 1/2)
                                                          = 3.21807...
In Johnson's form, (m/k)^(2/5) = (3/4)^(2/5) (m^2 / (R E*^2))^(1/5), so
t_c = 2.8683 (m_eff^2 / (R_eff E*^2 v))^(1/5), Johnson's (Contact Mechanics, sec. 11.4) "2.87".
(A constant 2.9432 is TAU_HERTZ / (5/4)^(2/5): it goes with the time to the largest overlap
doubled, measured in units of X_m; it is not the contact time in these units.)  For ball-ball
collisions v is the relative normal speed.

With the damping c delta^(1/4) v_n of Tsuji et al. (1992) the Hertz restitution does not depend
on the impact speed (the dimensionless equation above gains -eta X^(1/4) X', free of v).

Oblique impacts (Chung & Ooi 2011, Granular Matter 13:643-656)
---------------------------------------------------------------
Their test 4: an alumina sphere (R = 2.5 mm, E = 380 GPa, nu = 0.23, rho = 4000 kg/m^3,
mu = 0.092) hits a flat wall (E 1000 times larger) at |v| = 3.9 m/s, at angles theta from the
normal; the later tests vary the tangential speed at a fixed normal speed.

Analytic answers.  A sphere (radius R, mass m, I = 2/5 m R^2) hits a wall with normal speed
v_n and tangential speed v_t, no spin.  Every contact force acts at the contact point, so the
tangential impulse J_t changes v_t by -J_t / m and R omega by +(5/2) J_t / m; the
contact-point slip speed u = v_t - R omega changes by -(7/2) J_t / m.  If the contact slides
throughout (Coulomb), J_t = mu J_n = mu (1 + e) m v_n and
    v_t' = v_t - mu (1 + e) v_n,   omega' = 5 mu (1 + e) v_n / (2 R),
whatever the stiffness; it does slide throughout when the slip does not stop,
u' = v_t - (7/2) mu (1 + e) v_n > 0, i.e. tan(theta) > (7/2) mu (1 + e) (Maw, Barber &
Fawcett 1976; Wu, Thornton & Li 2009).  Ball-ball (equal spheres, one at rest): J_n = (m/2)
(1 + e) v_n, each ball's v_t changes by mu J_n / m and each spins up by 5 mu J_n / (2 m R); the
slip changes by -7 mu J_n / m, so the same boundary applies.

Linear law with k_t = (2/7) k_n and e = 1 (tangential regimes at fixed contact law): the slip
displacement xi obeys xi'' = -(7/2) (k_t / m) xi = -(k_n / m) xi, the same frequency as the normal
oscillation, and F_t / F_n = (2/7) v_t / v_n is constant during the contact.  So for
tan(theta) < (7/2) mu the contact sticks throughout and, after exactly half a period, the slip
velocity is reversed: u' = -u (tangential restitution -1 at the contact point).

With damping the normal force pulls at the end of a linear-law contact, and the engine (like
LAMMPS and LIGGGHTS) limits friction by mu |F_n|; in gross sliding the tangential impulse is then
mu integral |F_n| dt, which the closed-form x(t) gives: integral |F_n| dt / m
= v (1 - e) - 2 x'(t*), with t* the instant x'' = 0 (the force changes sign).
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.special import beta

from dem_helpers import (D_STEEL, M_STEEL, R_STEEL, Sim, ball, contact, linear_contact_time,
                         plane, rel, scenario, sphere_mass, zeta_of)
from vibroflow.scenario.model import Material

TAU_HERTZ = 2.0 * (5.0 / 4.0) ** 0.4 * 0.4 * beta(0.4, 0.5)
STEEL_E, STEEL_NU = 2.0e11, 0.3
K_N = 1.0e5
STEPS_PER_CONTACT = 200


def test_hertz_time_constant_matches_johnson():
    # the closed form above against Johnson's published constant 2.87
    assert TAU_HERTZ == pytest.approx(3.2181, abs=1e-4)
    assert TAU_HERTZ * 0.75**0.4 == pytest.approx(2.87, abs=0.005)


def e_star(e1, nu1, e2, nu2):
    return 1.0 / ((1 - nu1**2) / e1 + (1 - nu2**2) / e2)


def hertz_contact_time(m_eff, r_eff, estar, v):
    k = 4.0 / 3.0 * estar * math.sqrt(r_eff)
    return TAU_HERTZ * (m_eff / k) ** 0.4 * v ** (-0.2)


def head_on(model: str, target: str, e: float, v: float):
    """One head-on collision of steel balls (d = 6.35 mm), ball-ball (+-v) or ball-wall (v).

    Returns (restitution, contact time, its analytic value, kinetic-energy ratio, momentum
    change / (m v)).  The contact time is measured from the overlap: the first and last steps
    with overlap bracket the contact, and the gap, linear in time outside it, is interpolated
    to zero on either side."""
    ball_ball = target == "ball"
    m_eff = M_STEEL / 2 if ball_ball else M_STEEL
    r_eff = R_STEEL / 2 if ball_ball else R_STEEL
    v_rel = 2 * v if ball_ball else v
    if model == "linear":
        t_c = linear_contact_time(K_N, m_eff, e)
        law = contact(model="linear", k_n=K_N, e=e)
    else:
        es = e_star(STEEL_E, STEEL_NU, STEEL_E, STEEL_NU)
        t_c = hertz_contact_time(m_eff, r_eff, es, v_rel)  # undamped: an estimate when e < 1
        law = contact(model="hertz", e=e)
    dt = t_c / STEPS_PER_CONTACT
    gap0 = 5.5 * v_rel * dt
    if ball_ball:
        sc = scenario([ball((0, 0, 0), (v, 0, 0)), ball((D_STEEL + gap0, 0, 0), (-v, 0, 0))],
                      [law], dt=dt)
    else:
        sc = scenario([ball((0, 0, R_STEEL + gap0), (0, 0, -v))], [law], walls=[plane()], dt=dt)
    sim = Sim(sc)
    ke0, p0 = sim.state.kinetic_energy(), sim.momentum()
    tr = sim.trace(int((gap0 / v_rel + 1.5 * t_c) / dt))
    if ball_ball:
        gap = tr["pos"][:, 1, 0] - tr["pos"][:, 0, 0] - D_STEEL
        v_out = sim.state.vel[1, 0] - sim.state.vel[0, 0]
    else:
        gap = tr["pos"][:, 0, 2] - R_STEEL
        v_out = sim.state.vel[0, 2]
    assert gap[-1] > 0, "still in contact at the end"
    t = tr["t"]
    inside = np.nonzero(gap < 0)[0]
    i0, i1 = inside[0], inside[-1]
    assert np.all(gap[i0:i1 + 1] < 0), "contact broken and made again"
    t_in = t[i0 - 1] + (t[i0] - t[i0 - 1]) * gap[i0 - 1] / (gap[i0 - 1] - gap[i0])
    t_out = t[i1] + (t[i1 + 1] - t[i1]) * gap[i1] / (gap[i1] - gap[i1 + 1])
    dp = np.abs(sim.momentum() - p0).max() / (M_STEEL * v)
    return v_out / v_rel, t_out - t_in, t_c, sim.state.kinetic_energy() / ke0, dp


@pytest.mark.parametrize("target", ["ball", "wall"])
@pytest.mark.parametrize("e", [0.85, 0.5])
def test_linear_head_on_restitution_and_contact_time(target, e):
    e_meas, t_meas, t_c, _, dp = head_on("linear", target, e, 0.5)
    assert rel(e_meas, e) < 0.01
    assert rel(t_meas, t_c) < 0.01
    if target == "ball":
        assert dp < 1e-12


@pytest.mark.parametrize("target", ["ball", "wall"])
@pytest.mark.parametrize("e,v", [(0.85, 0.2), (0.85, 2.0), (0.6, 0.5)])
def test_hertz_head_on_restitution_independent_of_speed(target, e, v):
    e_meas, *_ = head_on("hertz", target, e, v)
    assert rel(e_meas, e) < 0.01


@pytest.mark.parametrize("model", ["linear", "hertz"])
@pytest.mark.parametrize("target", ["ball", "wall"])
def test_elastic_head_on_contact_time_and_energy(model, target):
    e_meas, t_meas, t_c, ke_ratio, dp = head_on(model, target, 1.0, 0.5)
    assert rel(t_meas, t_c) < 0.01
    assert abs(ke_ratio - 1.0) < 1e-4
    assert abs(e_meas - 1.0) < 1e-4
    if target == "ball":
        assert dp < 1e-12


@pytest.mark.parametrize("model", ["linear", "hertz"])
@pytest.mark.parametrize("rolling", ["none", "cdt", "epsd"])
def test_oblique_ball_ball_conserves_momentum(model, rolling):
    # unequal balls, oblique, spinning, with friction and rolling resistance: pair forces are
    # equal and opposite, so the total momentum changes only by round-off
    d1, d2 = D_STEEL, 0.005
    r1, r2 = d1 / 2, d2 / 2
    m2 = sphere_mass(r2, 7800.0)
    m_eff, r_eff = M_STEEL * m2 / (M_STEEL + m2), r1 * r2 / (r1 + r2)
    v = 0.8
    if model == "linear":
        t_c = linear_contact_time(K_N, m_eff, 0.85)
        law = contact(model="linear", k_n=K_N, e=0.85, mu=0.3, mu_r=0.05, rolling=rolling)
    else:
        t_c = hertz_contact_time(m_eff, r_eff, e_star(STEEL_E, STEEL_NU, STEEL_E, STEEL_NU), v)
        law = contact(model="hertz", e=0.85, mu=0.3, mu_r=0.05, rolling=rolling)
    dt = t_c / 100
    sep = 0.6 * (r1 + r2)  # centres' offset across the line of approach (z)
    dx = math.sqrt((r1 + r2) ** 2 - sep**2) + 4 * v * dt
    sc = scenario([ball((0, 0, 0), (v, 0.1, 0.05), (30.0, -50.0, 80.0), d=d1),
                   ball((dx, 0.0, sep), (-0.2, 0.0, 0.1), (-40.0, 20.0, 10.0), d=d2)],
                  [law], dt=dt)
    sim = Sim(sc)
    p0 = sim.momentum()
    scale = float(np.sum(sim.state.mass * np.linalg.norm(sim.state.vel, axis=1)))
    touched = False
    for _ in range(int(3 * t_c / dt) // 10):
        sim.run(10)
        d = np.linalg.norm(sim.state.pos[1] - sim.state.pos[0])
        touched |= d < r1 + r2
    assert touched
    assert np.abs(sim.momentum() - p0).max() / scale < 1e-12


# ---------------------------------------------------------------------------------------------
# Oblique impacts

# Chung & Ooi (2011) test 4: alumina sphere on a flat wall (1000 times stiffer), |v| = 3.9 m/s
ALUMINA = {"alumina": Material(density=4000.0, youngs_modulus=3.8e11, poisson_ratio=0.23),
           "rigid": Material(density=4000.0, youngs_modulus=3.8e14, poisson_ratio=0.23)}
R_AL, MU_AL, V_AL = 0.0025, 0.092, 3.9


def oblique_wall(theta_deg, model="hertz", e=1.0, mu=MU_AL, speed=V_AL, k_n=1.0e7,
                 steps_per_contact=300):
    """An alumina sphere hits the rigid wall z = 0 at `theta_deg` from the normal, moving in +x.
    Returns (v_n, v_t, v_n'/v_n, v_t', omega_y')."""
    th = math.radians(theta_deg)
    vn, vt = speed * math.cos(th), speed * math.sin(th)
    m = sphere_mass(R_AL, 4000.0)
    if model == "hertz":
        es = e_star(3.8e11, 0.23, 3.8e14, 0.23)
        t_c = hertz_contact_time(m, R_AL, es, vn)
        law = contact("alumina", "rigid", model="hertz", e=e, mu=mu)
    else:
        t_c = linear_contact_time(k_n, m, e)
        law = contact("alumina", "rigid", model="linear", k_n=k_n, e=e, mu=mu)
    dt = t_c / steps_per_contact
    gap0 = 2.5 * vn * dt
    sc = scenario([ball((0, 0, R_AL + gap0), (vt, 0, -vn), d=2 * R_AL, material="alumina")],
                  [law], walls=[plane(material="rigid")], dt=dt, materials=ALUMINA)
    sim = Sim(sc)
    sim.run(int((gap0 / vn + 1.3 * t_c) / dt))
    st = sim.state
    assert st.pos[0, 2] > R_AL and not sim.wall_touching()
    return vn, vt, st.vel[0, 2] / vn, st.vel[0, 0], st.omg[0, 1]


@pytest.mark.parametrize("theta", [45.0, 60.0, 80.0])
def test_chung_ooi_oblique_wall_gross_sliding(theta):
    # tan(theta) > (7/2) mu (1 + e) = 0.644 (theta > 32.8 deg): rigid-body Coulomb answer
    assert math.tan(math.radians(theta)) > 3.5 * MU_AL * 2
    vn, vt, en, vt1, om1 = oblique_wall(theta)
    assert en == pytest.approx(1.0, abs=1e-4)
    assert rel(vt1, vt - MU_AL * 2 * vn) < 0.01
    assert rel(om1, 5 * MU_AL * 2 * vn / (2 * R_AL)) < 0.01


@pytest.mark.parametrize("theta", [5.0, 10.0])
def test_chung_ooi_oblique_wall_small_angles_stick(theta):
    # below the gross-sliding range the friction impulse stays under its Coulomb bound
    # mu (1 + e) m v_n, and the impulse's two effects keep their rigid-body ratio
    # R d(omega) = -(5/2) d(v_t)
    vn, vt, en, vt1, om1 = oblique_wall(theta)
    assert en == pytest.approx(1.0, abs=1e-4)
    jt = vt - vt1  # J_t / m
    assert 0 < jt < 0.95 * MU_AL * 2 * vn
    assert rel(R_AL * om1, 2.5 * jt) < 1e-6


@pytest.mark.parametrize("ratio", [0.3, 0.8])
def test_linear_law_stick_regime_reverses_slip(ratio):
    # k_t = 2/7 k_n, e = 1, tan(theta) = ratio * (7/2) mu < (7/2) mu: sticks throughout, the
    # slip velocity of the contact point comes back reversed
    mu = 0.2
    theta = math.degrees(math.atan(ratio * 3.5 * mu))
    vn, vt, en, vt1, om1 = oblique_wall(theta, model="linear", e=1.0, mu=mu, speed=1.0)
    u1 = vt1 - R_AL * om1
    assert en == pytest.approx(1.0, abs=1e-4)
    assert rel(u1, -vt) < 0.01
    assert rel(vt1, vt * 3 / 7) < 0.01  # J_t = (4/7) m u


@pytest.mark.parametrize("theta", [40.0, 70.0])
def test_linear_law_gross_sliding(theta):
    mu, e = 0.092, 1.0
    assert math.tan(math.radians(theta)) > 3.5 * mu * (1 + e)
    vn, vt, en, vt1, om1 = oblique_wall(theta, model="linear", e=e, mu=mu, speed=1.0)
    assert rel(vt1, vt - mu * (1 + e) * vn) < 0.01
    assert rel(om1, 5 * mu * (1 + e) * vn / (2 * R_AL)) < 0.01


def abs_normal_impulse_linear(e, vn):
    """integral |F_n| dt / m of a linear-law collision (module docstring)."""
    z = zeta_of(e)
    wd, a = math.sqrt(1 - z * z), z  # in units of w0 (the answer is a speed: no units left)
    t_star = (math.pi - math.atan2(2 * a * wd, wd * wd - a * a)) / wd
    xd = vn * math.exp(-a * t_star) * (math.cos(wd * t_star) - a / wd * math.sin(wd * t_star))
    return vn * (1 - e) - 2 * xd


@pytest.mark.parametrize("e,theta", [(0.85, 60.0), (0.85, 80.0), (0.5, 80.0)])
def test_damped_linear_gross_sliding_impulse(e, theta):
    mu = 0.092
    vn, vt, en, vt1, om1 = oblique_wall(theta, model="linear", e=e, mu=mu, speed=1.0)
    jt = mu * abs_normal_impulse_linear(e, vn)
    assert rel(en, e) < 0.01
    assert rel(vt1, vt - jt) < 0.01
    assert rel(om1, 2.5 * jt / R_AL) < 0.01


@pytest.mark.parametrize("model", ["linear", "hertz"])
def test_ball_ball_oblique_gross_sliding(model):
    # ball 0 hits ball 1 (at rest) along x, sliding along z: tan(theta) = 2.75 > 3.5 mu (1+e).
    # The balls slide past each other by v_t t_c during the contact, which turns the normal;
    # a stiff linear spring keeps that turn (and its effect on the answer) below 0.2%
    mu, e, v, k_n = 0.2, 1.0, 0.5, 1.0e7
    th = math.radians(70.0)
    vn, vt = v * math.cos(th), v * math.sin(th)
    m_eff, r_eff = M_STEEL / 2, R_STEEL / 2
    if model == "linear":
        t_c = linear_contact_time(k_n, m_eff, e)
        law = contact(model="linear", k_n=k_n, e=e, mu=mu)
    else:
        t_c = hertz_contact_time(m_eff, r_eff, e_star(STEEL_E, STEEL_NU, STEEL_E, STEEL_NU), vn)
        law = contact(model="hertz", e=e, mu=mu)
    dt = t_c / STEPS_PER_CONTACT
    gap0 = 3 * vn * dt
    sim = Sim(scenario([ball((0, 0, 0), (vn, 0, vt)), ball((D_STEEL + gap0, 0, 0))], [law],
                       dt=dt))
    sim.run(int((gap0 / vn + 1.5 * t_c) / dt))
    st = sim.state
    assert np.linalg.norm(st.pos[1] - st.pos[0]) > D_STEEL
    jn = (1 + e) * vn / 2  # J_n / m
    assert abs(st.vel[0, 0] - (vn - jn)) < 0.01 * vn  # e = 1: ball 0 stops along the normal
    assert rel(st.vel[1, 0], jn) < 0.01
    assert rel(st.vel[0, 2], vt - mu * jn) < 0.01
    assert rel(st.vel[1, 2], mu * jn) < 0.01
    for i in (0, 1):
        assert rel(st.omg[i, 1], 2.5 * mu * jn / R_STEEL) < 0.01


# ---------------------------------------------------------------------------------------------
# The whole run path once: explicit scenario -> run_dem -> summary.json

def test_run_dem_head_on_final_state(tmp_path):
    from vibroflow.dem.run import run_dem

    e, v = 0.85, 0.5
    t_c = linear_contact_time(K_N, M_STEEL / 2, e)
    dt = t_c / STEPS_PER_CONTACT
    gap0 = 0.2 * D_STEEL
    sc = scenario([ball((0, 0, 0), (v, 0, 0)), ball((D_STEEL + gap0, 0, 0), (-v, 0, 0))],
                  [contact(model="linear", k_n=K_N, e=e)], dt=dt,
                  duration=gap0 / (2 * v) + 3 * t_c)
    run_dem(sc, tmp_path / "out", progress=False)
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    final = summary["final_state"]
    v0, v1 = np.array(final[0]["velocity"]), np.array(final[1]["velocity"])
    x0, x1 = np.array(final[0]["position"]), np.array(final[1]["position"])
    # equal masses, head-on: each comes back at e v; the centre of mass does not move
    assert rel(v0[0], -e * v) < 0.01 and rel(v1[0], e * v) < 0.01
    assert np.abs(v0[1:]).max() == 0.0 and np.abs(v1[1:]).max() == 0.0
    assert abs(v0[0] + v1[0]) < 1e-12 * v
    assert abs(0.5 * (x0[0] + x1[0]) - 0.5 * (D_STEEL + gap0)) < 1e-12
    assert x1[0] - x0[0] > D_STEEL
    for b in final:
        assert np.abs(b["angular_velocity"]).max() == 0.0
