"""The granular column collapse: the Lagrangian continuum (material point method) against the
published scaling with aspect ratio and against vibroflow's own DEM of the same column; the
Eulerian continuum against the Lagrangian on the same grid and floor.

A column of width L0 and height H0 (a = H0/L0) against a wall, on a rough floor, released at
t = 0, spreads to a deposit of run-out L_inf and height H_inf (vibroflow.measure.column, which
measures every method alike and holds the published laws).

What is checked, and against what:

* the measurement itself, on deposits whose run-out and height are known by geometry;
* the continuum (vibroflow.continuum.column, tub47's media: d = 6.35 mm, the glass-bead mu(I) of
  `ContinuumMaterial()`) at the experiments' scale, L0 = 1 m = 157 d (the laws were fitted on
  columns of tens to hundreds of grains across): the published planar scaling of Lube et al.
  (2005) -- the height of a low column (H_inf = H0, its top never moves) and the run-out's
  growth (L_inf - L0)/L0 ~ a^(2/3) at large a -- each within 10 %.  Not met, and said so in the
  tests' docstrings with the numbers: the run-out's prefactor (the plane-strain continuum with
  tub47's glass-bead friction on a floor of mu_w = 0.40 runs out about 1.9 times as far as the
  channel experiments; the prefactor depends on the grains' and the floor's friction, and with
  the friction of the experiments' sand the continuum comes within 25 %), the tall columns'
  height (it hardly grows with a: 0.90 L0 at a = 3, 1.05 L0 at a = 6, 42 % and 49 % below
  a^(2/5)), and the low column's run-out, which is not grid-converged; and the time step:
  with the default APIC transfers the run-out depends on the number of steps (5.72 at cfl
  0.3, 3.84 at cfl 0.03), with the FLIP-APIC blend (flip = 0.99) it is converged to 10 % and
  35 - 50 % above the law (test_mpm_runout_is_time_step_converged_with_flip_not_with_apic);
* the continuum against the DEM of the same column of steel balls (a quasi-2D slab between
  frictionless walls, on a floor of glued balls), at the DEM's size (L0 of 10 to 13 balls,
  where the mu(I) continuum's rate dependence and the balls' size both matter, so neither can be
  judged by the large-scale laws).
"""
from __future__ import annotations

import functools
import math

import numpy as np
import pytest

from dem_helpers import one_thread
from vibroflow.measure.column import (LAJEUNESSE_2004, LAJEUNESSE_2005, LUBE_2004, LUBE_2005,
                                       measure_continuum_deposit, measure_deposit,
                                       quasistatic_runout, quasistatic_runout_axisymmetric,
                                       slab_areas)
from vibroflow.continuum.column import run_column
from vibroflow.continuum.constitutive import ContinuumMaterial
from vibroflow.dem import simulate as S
from vibroflow.dem.neighbours import transfer_history
from vibroflow.errors import InputError
from vibroflow.scenario.model import ContactPair, Material, ParticleSpec, Run, Scenario, WallSpec

D = 0.00635          # tub47's ball diameter (m)
R = 0.5 * D
RHO = 7800.0         # steel (kg/m^3)
G_ACC = 9.81


# ----------------------------------------------------------------------------------------------
# the measurement, on deposits whose run-out and height are known exactly

def lattice_points(top, x_end, spacing):
    """Points on a square lattice of `spacing` (m) under the surface z = top(x), 0 < x < x_end
    (m), each standing for spacing^2 of area."""
    xs = (np.arange(int(round(x_end / spacing))) + 0.5) * spacing
    pts = []
    for x in xs:
        nz = int(np.floor(top(x) / spacing + 0.5))
        pts += [(x, (k + 0.5) * spacing) for k in range(nz)]
    return np.array(pts)


def trapezoid(H0, x_top, slope):
    """z = H0 up to x_top, then falling at `slope` to the floor."""
    return lambda x: H0 if x < x_top else max(H0 - slope * (x - x_top), 0.0)


def test_rectangle_reads_its_own_width_and_height():
    """An undisturbed column is its own deposit: run-out L0, height H0, area L0 H0."""
    L0, H0, sp = 0.10, 0.05, 0.001
    pts = lattice_points(lambda x: H0, L0, sp)
    dep = measure_deposit(pts[:, 0], sp * sp, D, bin_width=5 * sp)
    assert dep.runout == pytest.approx(L0, abs=sp)
    assert dep.height == pytest.approx(H0, rel=1e-9)
    assert (dep.h * (dep.x[1] - dep.x[0])).sum() == pytest.approx(L0 * H0, rel=1e-9)
    assert dep.normalised(L0) == pytest.approx((0.0, 0.5), abs=0.01)
    # a continuum's settings (bins of whole point spacings, a front no thinner than a point)
    cont = measure_continuum_deposit(pts[:, 0], sp * sp, sp, D)
    assert (cont.runout, cont.height) == pytest.approx((L0, H0), abs=sp)


def test_trapezoid_front_where_it_thins_below_one_grain():
    """A deposit flat at H0 up to x_top, then sloping at tan(theta) to its toe: the thickness
    falls through one grain diameter at toe - d / tan(theta).  Two grains flung far ahead (each
    thinner than a grain on its own) are the farthest points but do not move the front."""
    H0, x_top, slope, sp = 0.05, 0.06, 0.4, 0.0005
    toe = x_top + H0 / slope
    pts = lattice_points(trapezoid(H0, x_top, slope), toe, sp)
    x = np.concatenate([pts[:, 0], [toe + 0.05, toe + 0.11]])
    area = np.concatenate([np.full(len(pts), sp * sp), np.full(2, 0.3 * D * D)])
    dep = measure_deposit(x, area, D, bin_width=4 * sp)
    assert dep.runout == pytest.approx(toe - D / slope, abs=2 * sp)
    assert dep.height == pytest.approx(H0, rel=0.01)
    assert x.max() > toe + 0.1 and dep.runout < toe
    # the mass-fraction front: 99 % of the area lies behind it, inside the trapezoid
    assert x_top < dep.runout_mass < toe


def test_quasistatic_trapezoid_holds_the_column_area():
    """quasistatic_runout(a, tan theta) = a / (2 tan theta): the trapezoid of height H0 and
    slope tan(theta) that holds the column's area L0 H0 has its toe at L0 (1 + that)."""
    L0, a, slope, sp = 0.1, 0.5, 0.38, 0.0005
    H0 = a * L0
    x_top = L0 - H0 / (2 * slope)
    toe = x_top + H0 / slope
    pts = lattice_points(trapezoid(H0, x_top, slope), toe + sp, sp)
    assert len(pts) * sp * sp == pytest.approx(L0 * H0, rel=0.01)
    assert (toe - L0) / L0 == pytest.approx(quasistatic_runout(a, slope), rel=1e-12)
    dep = measure_deposit(pts[:, 0], sp * sp, D, bin_width=4 * sp, threshold=2 * sp)
    assert dep.runout == pytest.approx(toe - 2 * sp / slope, abs=2 * sp)


def test_slab_areas_add_up_to_the_column():
    """Balls of a slab W at solid fraction phi_0 filling L0 x H0 stand for L0 H0 in all."""
    W, phi0, L0, H0 = 3 * D, 0.58, 0.1, 0.05
    n = phi0 * L0 * H0 * W / (math.pi * D**3 / 6)
    assert slab_areas(np.full(1, R), W, phi0).sum() * n == pytest.approx(L0 * H0, rel=1e-12)


@pytest.mark.parametrize("a", [0.3, 0.5, 1.0, 3.0, 7.0])
def test_quasistatic_cone_holds_the_cylinder_volume(a):
    """quasistatic_runout_axisymmetric(a, s): the solid of revolution of slope s (a truncated
    cone of height H0 for low columns, a full cone for tall ones) holds the cylinder's volume
    pi R0^2 H0, integrated by the midpoint rule over its profile; its top is H0 while it is
    truncated and below H0 once it is a full cone."""
    s = math.tan(math.radians(29.5))
    runout, height = quasistatic_runout_axisymmetric(a, s)
    r_base = 1.0 + runout
    r = (np.arange(200_000) + 0.5) * r_base / 200_000
    h = np.minimum(height, s * (r_base - r))
    volume = 2.0 * math.pi * float(np.sum(h * r)) * r_base / 200_000
    assert volume == pytest.approx(math.pi * a, rel=1e-6)
    assert h[0] == pytest.approx(height, rel=1e-4)
    if a / s <= math.sqrt(3.0):
        assert height == pytest.approx(a)
    else:
        assert height < a and height == pytest.approx(s * r_base, rel=1e-12)


def test_published_laws():
    """The fits as published (module docstring of vibroflow.measure.column)."""
    assert LUBE_2005.runout(0.5) == pytest.approx(0.6)
    assert LUBE_2005.runout(3.0) == pytest.approx(1.9 * 3.0 ** (2 / 3))
    assert LUBE_2005.height(0.5) == 0.5
    assert LUBE_2005.height(3.0) == pytest.approx(3.0 ** 0.4)
    assert LAJEUNESSE_2005.runout(0.5) == pytest.approx(0.9)
    assert LUBE_2004.runout(4.0) == pytest.approx(3.2)
    assert LAJEUNESSE_2004.height(2.0) == pytest.approx(0.74)
    assert LUBE_2005.runout_length(0.1, 0.05) == pytest.approx(0.16)
    # the linear branch: lambda = 1 / (2 tan theta) of a low column's trapezoidal deposit
    assert quasistatic_runout(0.5, 1 / 2.4) == pytest.approx(LUBE_2005.runout(0.5))
    with pytest.raises(InputError, match="transition"):
        LUBE_2005.runout(2.0)
    with pytest.raises(InputError, match="aspect ratio"):
        LUBE_2005.runout(-1.0)
    with pytest.raises(InputError, match="no final-height law"):
        LUBE_2004.height(1.0)


def test_bad_input_is_one_line_naming_the_field():
    with pytest.raises(InputError, match="bin_width"):
        measure_deposit([0.0, 0.01], 1e-6, D, bin_width=0.0)
    with pytest.raises(InputError, match="grain_diameter"):
        measure_deposit([0.0, 0.01], 1e-6, -1.0)
    with pytest.raises(InputError, match="mass fraction"):
        measure_deposit([0.0, 0.01], 1e-6, D, mass_fraction=1.5)
    with pytest.raises(InputError, match="slab_thickness"):
        slab_areas([R], 0.0, 0.6)
    with pytest.raises(InputError, match="column L0"):
        run_column(0.1001, 0.05, 0.005)
    with pytest.raises(InputError, match="floor_friction"):
        run_column(0.1, 0.05, 0.005, floor_friction=-0.1)


# ----------------------------------------------------------------------------------------------
# the DEM column: steel balls in a quasi-2D slab
#
# The slab: W = 3 d between two frictionless plane walls (y = 0, y = W), so the collapse is
# planar without a side-wall friction that the plane-strain continuum does not have; three balls
# across keeps it cheap while not being a single layer of discs (a 2D packing).  A 5 d slab
# gave the same deposits within the seed-to-seed scatter (run-out 2.85, height 0.84 at a = 2.0
# against 2.96, 0.86 and 2.81, 0.94 at a = 2.1 for two seeds of the 3 d slab; 0.25, 0.41 at
# a = 0.46 against 0.48, 0.45 and 0.28, 0.47 at a = 0.52).  The
# floor: tub47's lining (steel-polyurethane k_n = 5e4 N/m, e = 0.6, mu = 0.40) under a layer of
# glued balls, three rows across the slab at random gaps of 0.02 to 0.14 d along x: the published
# experiments' rough floor, which a flat floor is not (on it the balls, with tub47's rolling
# resistance of 0.002, roll away one by one).  The glued balls are steel balls 1e4 times as dense
# (they do not move under the column; tub47's ball-ball law with them, a stiff contact with the
# floor).  The wall behind the column and the gate in front are frictionless: the wall stands
# for the symmetry plane of the continuum's whole column (vibroflow.continuum.column, released
# on both sides).  Every other contact is tub47's (ball-ball k_n = 1e5 N/m, e = 0.85,
# mu = 0.20, mu_r = 0.002, dt = 1e-5 s).
#
# Fill: balls on a loose lattice (spacing 1.06 d, jitter 0.45 of the gap) behind the gate, let
# settle until their kinetic energy is below 1e-8 J a ball; the column's solid fraction phi_0 is
# that of the balls whose centres lie from the glued balls' tops up to 1.5 d below the highest
# centre (the whole width: the wall layers are part of the column), and its height is
# H0 = N V_ball / (W L0 phi_0), the height of the same area at that fraction.  Release: the gate
# goes at once (a second scenario, identical but for the gate, started from the settled state
# with every contact history carried over).  At rest: the deposit's kinetic energy (the balls
# behind its front; a few balls roll on ahead over the glued layer for a long time and are not
# part of the deposit) below 1e-4 of the column's potential energy, after at least 3 sqrt(H0/g).

BASE_DENSITY_FACTOR = 1.0e4


def _column_contacts():
    r = 2.0 / 7.0
    steel = dict(k_n=1.0e5, k_t_over_k_n=r, restitution=0.85, friction=0.20,
                 rolling_friction=0.002)
    smooth = dict(k_n=1.0e5, k_t_over_k_n=r, restitution=0.85, friction=0.0,
                  rolling_friction=0.0, rolling_model="none")
    return [ContactPair(pair=("steel", "steel"), **steel),
            ContactPair(pair=("steel", "glued"), **steel),
            ContactPair(pair=("glued", "glued"), **steel),
            ContactPair(pair=("steel", "lining"), k_n=5.0e4, k_t_over_k_n=r, restitution=0.60,
                        friction=0.40, rolling_friction=0.002),
            ContactPair(pair=("glued", "lining"), k_n=1.0e9, k_t_over_k_n=r, restitution=0.5,
                        friction=1.0, rolling_friction=0.0, rolling_model="none"),
            ContactPair(pair=("steel", "smooth"), **smooth),
            ContactPair(pair=("glued", "smooth"), **smooth)]


def _column_scenario(balls, glued, W, gate_x, dt):
    materials = {"steel": Material(density=RHO),
                 "glued": Material(density=RHO * BASE_DENSITY_FACTOR),
                 "lining": Material(density=1200.0, youngs_modulus=2.5e7, poisson_ratio=0.45),
                 "smooth": Material(density=2500.0, youngs_modulus=6.3e10, poisson_ratio=0.23)}
    walls = [WallSpec(point=(0.0, 0.0, 0.0), normal=(0.0, 0.0, 1.0), material="lining"),
             WallSpec(point=(0.0, 0.0, 0.0), normal=(1.0, 0.0, 0.0), material="smooth"),
             WallSpec(point=(0.0, 0.0, 0.0), normal=(0.0, 1.0, 0.0), material="smooth"),
             WallSpec(point=(0.0, W, 0.0), normal=(0.0, -1.0, 0.0), material="smooth"),
             WallSpec(point=(gate_x, 0.0, 0.0), normal=(-1.0, 0.0, 0.0), material="smooth")]
    parts = [ParticleSpec(position=tuple(p), diameter=D, material="glued" if g else "steel")
             for p, g in zip(balls, glued)]
    return Scenario(case="column-collapse", gravity=(0.0, 0.0, -G_ACC), tub=None, fill=None,
                    particles=parts, walls=walls, contacts=_column_contacts(),
                    materials=materials, run=Run(dt=dt, duration=1.0, average_last=0.0))


def _column_state(system, balls, glued):
    n = len(balls)
    names = system.material_names
    mat = np.where(glued, names.index("glued"), names.index("steel")).astype(np.int64)
    zero = np.zeros((n, 3))
    return S.init_state(system, np.array(balls, dtype=float), zero, zero.copy(), np.full(n, R),
                        np.where(glued, RHO * BASE_DENSITY_FACTOR, RHO), mat)


def _glued_row(rng, x_end, y):
    out, x = [], R + rng.uniform(0.0, 0.1 * D)
    while x < x_end:
        out.append((x, y, R))
        x += D * (1.02 + rng.uniform(0.0, 0.12))
    return out


def dem_column(L0, a, slab=3, seed=1, dt=1.0e-5, ke_fraction=1.0e-4, t_max_tau=15.0):
    """Fill, settle and release a DEM column of width L0 (m) and aspect ratio about a (block
    comment above); returns a dict: L0, H0 (m), a, phi0, W (m), n, x (n,) final ball x (m),
    radius (n,), settled, t (s of collapse), tau = sqrt(H0/g) (s)."""
    W = slab * D
    rng = np.random.default_rng(seed)
    vball = math.pi * D**3 / 6
    n = int(round(0.57 * a * L0 * L0 * W / vball))
    s = 1.06 * D
    nx, ny = int((L0 - D) // s) + 1, int((W - D) // s) + 1
    xs = R + 0.5 * (L0 - D - (nx - 1) * s) + np.arange(nx) * s
    ys = R + 0.5 * (W - D - (ny - 1) * s) + np.arange(ny) * s
    zs = D + R + 0.001 + np.arange(math.ceil(n / (nx * ny))) * s
    col = np.array([(x, y, z) for z in zs for x in xs for y in ys])[:n]
    col += rng.uniform(-0.45 * (s - D), 0.45 * (s - D), col.shape)
    rows = [_glued_row(rng, L0 * (2.0 + 3.0 * a), y) for y in (R, 0.5 * W, W - R)]
    under = [p for row in rows for p in row if p[0] < L0 - R]
    beyond = [p for row in rows for p in row if p[0] >= L0 + R]   # none under the gate
    chunk = int(round(0.01 / dt))
    with one_thread():
        # 1. fill behind the gate and settle
        balls = [tuple(p) for p in col] + under
        glued = np.arange(len(balls)) >= n
        system = S.make_system(_column_scenario(balls, glued, W, L0, dt))
        st = _column_state(system, balls, glued)
        while True:
            S.run_steps(system, st, chunk)
            ke = 0.5 * float((st.mass[:n] * (st.vel[:n] ** 2).sum(axis=1)).sum())
            if (st.step * dt > 0.1 and ke / n < 1e-8) or st.step * dt > 0.6:
                break
        z = st.pos[:n, 2] - D    # heights above the glued balls' tops
        cut = z.max() - 1.5 * D  # below the rough top surface
        phi0 = (z < cut).sum() * vball / (cut * L0 * W)
        H0 = n * vball / (W * L0 * phi0)
        # 2. release: the gate gone, the rest of the glued floor laid, the histories kept
        balls2 = [tuple(p) for p in st.pos] + beyond
        glued2 = np.concatenate([glued, np.ones(len(beyond), bool)])
        system2 = S.make_system(_column_scenario(balls2, glued2, W, 1.0e3, dt))
        st2 = _column_state(system2, balls2, glued2)
        k = len(balls)
        st2.vel[:k], st2.omg[:k] = st.vel, st.omg
        old_start = np.concatenate([st.nl.start, np.full(len(beyond), st.nl.start[-1])])
        st2.nl.hist, st2.nl.flag = transfer_history(old_start, st.nl.nbr, st.nl.hist,
                                                    st.nl.flag, st2.nl.start, st2.nl.nbr)
        st2.wall_hist[:k], st2.wall_flag[:k] = st.wall_hist, st.wall_flag
        st2.wall_hist[:, 4], st2.wall_flag[:, 4] = 0.0, 0    # the gate's slot, now far away
        tau = math.sqrt(H0 / G_ACC)
        pe0 = float((st2.mass[:n] * G_ACC * (st2.pos[:n, 2] - D)).sum())
        areas = slab_areas(np.full(n, R), W, phi0)
        settled = False
        while st2.step * dt < t_max_tau * tau:
            S.run_steps(system2, st2, chunk)
            front = measure_deposit(st2.pos[:n, 0], areas, D).runout
            behind = st2.pos[:n, 0] < front + 2 * D
            ke = 0.5 * float((st2.mass[:n][behind] * (st2.vel[:n][behind] ** 2).sum(axis=1)).sum())
            if st2.step * dt >= 3 * tau and ke < ke_fraction * pe0:
                settled = True
                break
    return dict(L0=L0, H0=H0, a=H0 / L0, phi0=phi0, W=W, n=n, x=st2.pos[:n, 0].copy(),
                radius=st2.radius[:n].copy(), settled=settled, t=st2.step * dt, tau=tau,
                areas=areas)


# ----------------------------------------------------------------------------------------------
# the continuum against the published scaling, at the experiments' scale

L_BIG = 1.0   # m: 157 of tub47's balls across, as the experiments' columns are tens to hundreds


def mpm_deposit(run):
    """The deposit of a finished MPM column run (vibroflow.continuum.column.ColumnRun; its
    material's grains are tub47's balls, d = D)."""
    assert run.material.diameter == D
    return run.deposit()


def test_mpm_low_column_keeps_its_top_and_runs_past_the_experiments():
    """a = 0.5, L0 = 1 m, dx = L0/20 (tub47's media): the top of a low column never moves, so
    H_inf = H0 (H_inf/L0 = a, the small-a branch of every planar law) within 2 %; the run-out
    is past Lube et al. 2005's 1.2 a, the shortest of the planar fits (the plane-strain
    continuum has no channel side walls to brake it; its run-out at this a also grows with the
    grid refinement, see test_mpm_grid_refinement)."""
    a = 0.5
    run = run_column(L_BIG, a * L_BIG, L_BIG / 20)
    assert run.settled
    runout, height = mpm_deposit(run).normalised(L_BIG)
    assert height == pytest.approx(LUBE_2005.height(a), rel=0.02)
    assert height == pytest.approx(a, rel=0.02)
    assert runout > LUBE_2005.runout(a)


@functools.cache
def friction_runout(name: str) -> float:
    """The run-out (r_inf - L0)/L0 of a = 3 on L0/10 for one material of the test below:
    "glass" (tub47's glass beads), "sand" (Lube's sand), "rough" (the glass beads on a floor
    that never slides); each run once a session, and only where a test asks for it (the
    default suite needs glass and sand)."""

    a = 3.0
    mu_s = math.tan(math.radians(29.5))
    base = ContinuumMaterial()
    sand = ContinuumMaterial(mu_s=mu_s, mu_2=mu_s + base.mu_2 - base.mu_s)
    kw = {"glass": {}, "sand": {"material": sand}, "rough": {"floor_friction": 1.0}}[name]
    return mpm_deposit(run_column(L_BIG, a * L_BIG, L_BIG / 10, **kw)).normalised(L_BIG)[0]


@pytest.mark.slow
def test_mpm_runout_prefactor_falls_with_the_grain_friction():
    """a = 3 (the power-law branch, a > 2.8), L0 = 1 m, dx = L0/10.  The run-out's prefactor
    depends on the grains' friction: the tub47 material (glass-bead mu(I), mu_s = tan 20.9 deg)
    runs out 1.8 times Lube et al.'s 1.9 a^(2/3) (7.17 against 3.95); given the friction of
    Lube et al.'s quartz sand (its angle of repose 29.5 deg as mu_s, the same mu_2 - mu_s and
    I_0), 4.65, within 25 % of it (on L0/20, 5.01); Lube's value would need mu_s ~ 0.63.  Part
    of the rest may be their channel's side-wall friction, which a plane-strain continuum does
    not feel.  It depends on the floor's friction too: the default mu_w = 0.40 (tub47's
    ball-lining friction, as the brief asks) is below the flowing material's mu(I), so the base
    slides; a floor that never slides (mu_w = 1) shortens the run-out to 4.52 (but 5.78 on
    L0/20: not converged)."""
    assert friction_runout("sand") < friction_runout("glass")
    assert friction_runout("rough") < friction_runout("glass")


@pytest.mark.xfail(strict=True, reason=(
    "the plane-strain continuum of Lube's sand runs out 4.65 on L0/10 against Lube et al. "
    "2005's 3.95 at a = 3 (+18 %; 5.01 on L0/20); their channel's side walls, which it lacks, "
    "may brake the rest"))
def test_mpm_sand_column_runout_meets_lube_2005():
    """The target: a = 3, the sand's run-out within 10 % of Lube et al. 2005's 1.9 a^(2/3)."""
    assert friction_runout("sand") == pytest.approx(LUBE_2005.runout(3.0), rel=0.10)


def test_mpm_column_runouts_regression_guard():
    """Regression guard of the state reached (the target is the strict xfail above): a = 3 on
    L0/10, the sand within 25 % of Lube et al. 2005 (measured +18 %) and tub47's glass beads
    beyond 1.5 times it (measured 1.8 times)."""
    law = LUBE_2005.runout(3.0)
    assert friction_runout("sand") == pytest.approx(law, rel=0.25)
    assert friction_runout("glass") > 1.5 * law


@pytest.mark.slow
def test_mpm_runout_grows_as_a_to_two_thirds():
    """a = 3 and a = 6 (both on the power-law branch, a > 2.8), L0 = 1 m, dx = L0/20: the
    run-out grows as Lube et al.'s (L_inf - L0)/L0 ~ a^(2/3), the ratio within 10 % of
    2^(2/3) = 1.587 (measured 7.66 and 12.21: 1.594; on the coarser L0/10, 1.76).  Neither
    the prefactor (1.9 times Lube's, test_mpm_runout_prefactor_falls_with_the_grain_friction)
    nor the tall columns' heights (H_inf/L0 = 0.90 at a = 3, 1.05 at a = 6 against
    a^(2/5) = 1.55, 2.05: the continuum's final height hardly grows with a) are met."""
    out = {}
    for a in (3.0, 6.0):
        run = run_column(L_BIG, a * L_BIG, L_BIG / 20)
        assert run.settled
        out[a] = mpm_deposit(run).normalised(L_BIG)
        print(f"\na = {a}: MPM run-out {out[a][0]:.3f} (Lube 2005 {LUBE_2005.runout(a):.3f}, "
              f"Lajeunesse 2005 {LAJEUNESSE_2005.runout(a):.3f}), height {out[a][1]:.3f} "
              f"(Lube 2005 {LUBE_2005.height(a):.3f})")
    ratio = out[6.0][0] / out[3.0][0]
    assert ratio == pytest.approx(LUBE_2005.runout(6.0) / LUBE_2005.runout(3.0), rel=0.10)
    assert ratio == pytest.approx(2.0 ** (2.0 / 3.0), rel=0.10)


@pytest.mark.slow
def test_mpm_grid_refinement():
    """Grid dependence at L0 = 1 m.  a = 3: the run-out is grid-converged (L0/10 -> L0/20: the
    99 % mass front within 2 %, the one-grain front within 10 %).  a = 0.5: the top stays at H0
    on every grid, but the run-out is not converged (one-grain front 0.65, 0.99, 1.20 at
    L0/20, L0/40, L0/80; the 99 % mass front 0.56, 0.78, 0.87): the low column fails along a
    shear band as wide as a cell, and the thin front keeps spreading as the cells shrink."""
    fronts = {}
    for a, cells in ((3.0, (10, 20)), (0.5, (20, 40))):
        for n in cells:
            run = run_column(L_BIG, a * L_BIG, L_BIG / n)
            assert run.settled
            dep = mpm_deposit(run)
            fronts[a, n] = (dep.normalised(L_BIG)[0], (dep.runout_mass - L_BIG) / L_BIG)
            print(f"\na = {a}, dx = L0/{n}: run-out {fronts[a, n][0]:.3f}, 99 % mass front "
                  f"{fronts[a, n][1]:.3f}, height {dep.height / L_BIG:.3f}")
            if a == 0.5:
                assert dep.height / L_BIG == pytest.approx(a, rel=0.02)
    assert fronts[3.0, 20][1] == pytest.approx(fronts[3.0, 10][1], rel=0.02)
    assert fronts[3.0, 20][0] == pytest.approx(fronts[3.0, 10][0], rel=0.10)


def test_mpm_rough_floor_does_not_slip():
    """The rough floor (rough_floor=True, the no-slip grid condition of MPMSystem.no_slip_below)
    holds the material at the floor: a low column (a = 0.5, L0 = 1 m, dx = L0/10) collapses
    over it, and the points that stood on the floor at the start (the bottom row, a quarter
    cell above the held node row z = 0, so moving with a quarter of the next row's velocity
    in the quadratic B-spline interpolation) have moved along it by less than 15 % of a cell
    (measured 9 %), a seventh of what the same row slides on the penalty floor alone
    (mu_w = 0.40 < mu(I): 69 %), while the material above them has run out."""
    a, n = 0.5, 10
    dx = L_BIG / n

    def base_slip(**kw):
        from vibroflow.continuum.mpm.column import column_state, column_system

        system = column_system(L_BIG, a * L_BIG, dx, **kw)
        x0 = column_state(system, L_BIG, a * L_BIG).x
        run = run_column(L_BIG, a * L_BIG, dx, **kw)
        assert run.settled
        bottom = x0[:, 1] < run.point_side   # the row centred at half a side up
        return float(np.abs(run.state.x[bottom, 0] - x0[bottom, 0]).max()), run

    slip_rough, run = base_slip(rough_floor=True)
    slip_plain, _ = base_slip()
    print(f"\nbase slip: rough {slip_rough:.4f} m, penalty floor {slip_plain:.4f} m")
    assert slip_rough < 0.15 * dx
    assert slip_plain > 5.0 * slip_rough
    assert mpm_deposit(run).runout > 1.2 * L_BIG     # the column did run out


@pytest.mark.slow
def test_mpm_rough_floor_runout_is_grid_converged_but_long():
    """a = 3, L0 = 1 m, on the rough (no-slip grid) floor: the run-out is grid-converged
    (L0/10 -> L0/20 within 5 %; measured 5.72 and 5.65), where the penalty floor of a friction
    above mu_2 is not (4.53 -> 5.80 with mu_w = 1).  It is not the published law: 40 % above Lube
    et al. 2005's 1.9 a^(2/3) = 3.95 and 18 % above Lajeunesse et al. 2005's glass-bead 2.3
    a^(2/3) = 4.78; the height at the symmetry plane stays 0.90 L0 against a^(2/5) = 1.55."""
    a = 3.0
    out = {}
    for n in (10, 20):
        run = run_column(L_BIG, a * L_BIG, L_BIG / n, rough_floor=True)
        assert run.settled
        out[n] = mpm_deposit(run).normalised(L_BIG)
        print(f"\na = {a}, L0/{n}, rough floor: run-out {out[n][0]:.3f}, height {out[n][1]:.3f}")
    assert out[20][0] == pytest.approx(out[10][0], rel=0.05)


# ----------------------------------------------------------------------------------------------
# the continuum against the DEM of the same column

L_DEM = 0.064   # m: 10 balls across


_DEM_COLUMNS: dict = {}


def dem_column_once(a):
    """dem_column(L_DEM, a), run once a session: the Lagrangian's and the Eulerian's checks
    against the DEM read the same column (one DEM sample, the same for both formulations)."""
    if a not in _DEM_COLUMNS:
        _DEM_COLUMNS[a] = dem_column(L_DEM, a)
    return _DEM_COLUMNS[a]


def dem_and_mpm(a, dx_cells=32, method="lagrangian"):
    """The DEM column of aspect ratio about a (width L_DEM), and the continuum column of the same
    width and the DEM's measured height (rounded to a point spacing, the Eulerian mesh's cell side
    being the same dx/2), on dx = L_DEM/dx_cells, with the same floor (the glued balls' roughness:
    mu_w = 0.40, above the continuum's mu_s), released on both sides (the DEM's frictionless wall
    stands for that symmetry plane); `method` "lagrangian" (the material point method) or "eulerian"
    (vibroflow.continuum.eulerian.column, the same set-up on the fixed mesh; both run by
    vibroflow.continuum.column.run_column). Returns ((L-L0)/L0, H/L0) of each and the DEM record."""
    dem = dem_column_once(a)
    assert dem["settled"]
    dem_dep = measure_deposit(dem["x"], dem["areas"], D)
    dx = L_DEM / dx_cells
    sp = 0.5 * dx
    H0 = sp * round(dem["H0"] / sp)
    run = run_column(L_DEM, H0, dx, method=method)
    assert run.settled
    if method == "eulerian":
        assert abs(run.mass_error) < 1e-12
        return dem_dep.normalised(L_DEM), run.deposit().normalised(L_DEM), dem
    return dem_dep.normalised(L_DEM), mpm_deposit(run).normalised(L_DEM), dem


def mpm_dem_tolerance(value_dem, seed_spread=0.0):
    """How far the continuum's (L-L0)/L0 or H/L0 may be from the DEM's: 25 % of the DEM's, or
    two grain diameters over L0, whichever is larger, plus the DEM's own seed_spread (the
    difference between two DEM columns that differ only in their fill or summation order,
    SEED_SPREAD), since the DEM column it is compared with is one sample of that scatter.  Why: (1) both deposits are read to about
    a grain, at either end of the front and at the top (2 d / L0 = 0.2 here); (2) the continuum
    is tub47's glass-bead mu(I) (mu_s = 0.38), not a calibration on these balls (the shear cell
    puts their mu_s anywhere in 0.15 - 0.45), and a change of 0.1 in mu_s moves the continuum's
    run-out by 25 % (test_mpm_runout_prefactor_falls_with_the_grain_friction: 0.38 -> 0.57
    shortens it by 35 %); (3) one DEM column of a few hundred balls is one sample: two fill
    seeds gave run-outs 2.96 and 2.81, heights 0.86 and 0.94 at a = 2.1, and run-outs 0.48 and
    0.28, heights 0.45 and 0.47 at a = 0.52, where one grain is 0.1 L0: the low column's
    seed-to-seed scatter is itself two grains."""
    return max(0.25 * abs(value_dem), 2.0 * D / L_DEM) + seed_spread


#: the DEM column's own scatter, (run-out, height) over L0: the difference between two columns of
#: one aspect ratio that differ only in their fill seed (a = 2.1: run-outs 2.96 and 2.81, heights
#: 0.86 and 0.94; a = 0.52: 0.48 and 0.28, 0.45 and 0.47; mpm_dem_tolerance's docstring).  The
#: pair-force summation order alone moves the tall column's height as much (0.863 and 0.829).
SEED_SPREAD = {"tall": (0.15, 0.08), "low": (0.20, 0.02)}


@pytest.mark.slow
def test_mpm_against_dem_low_column():
    """a ~ 0.5, L0 = 10 balls (166 balls, 8 s of DEM): the DEM of tub47's balls (block
    comment above the DEM helpers) and the MPM column of the same size agree on the run-out and
    the height within `mpm_dem_tolerance` (measured: run-out 0.48 and 0.44, height 0.45 and
    0.53 at a = 0.525); the DEM's top stays near H0 too (within two grains)."""
    (ro_dem, h_dem), (ro_mpm, h_mpm), dem = dem_and_mpm(0.5)
    print(f"\na = {dem['a']:.3f}: DEM run-out {ro_dem:.3f} height {h_dem:.3f}; "
          f"MPM run-out {ro_mpm:.3f} height {h_mpm:.3f}")
    assert abs(ro_mpm - ro_dem) <= mpm_dem_tolerance(ro_dem, SEED_SPREAD["low"][0])
    assert abs(h_mpm - h_dem) <= mpm_dem_tolerance(h_dem, SEED_SPREAD["low"][1])
    assert h_dem == pytest.approx(dem["a"], abs=2 * D / L_DEM)


@pytest.mark.slow
def test_mpm_against_dem_tall_column():
    """a ~ 2.1, L0 = 10 balls (about 660 balls and 220 glued ones; a minute of DEM): run-out
    and height of the continuum and the DEM agree within `mpm_dem_tolerance` (measured: DEM
    run-out 2.96 and height 0.86, the continuum 2.85 and 1.03 at a = 2.09-2.10: the continuum
    stands 20 % taller, its run-out 4 % shorter).  The one-grain front of a column this small
    is sensitive where the deposit's tail is about a grain thick: a continuum column 1.5 %
    taller (a = 2.125) read 3.33."""
    # L0/16 suffices at this a: the run-out and height change by < 1 % on L0/32
    (ro_dem, h_dem), (ro_mpm, h_mpm), dem = dem_and_mpm(2.0, dx_cells=16)
    print(f"\na = {dem['a']:.3f}: DEM run-out {ro_dem:.3f} height {h_dem:.3f}; "
          f"MPM run-out {ro_mpm:.3f} height {h_mpm:.3f}")
    assert abs(ro_mpm - ro_dem) <= mpm_dem_tolerance(ro_dem, SEED_SPREAD["tall"][0])
    assert abs(h_mpm - h_dem) <= mpm_dem_tolerance(h_dem, SEED_SPREAD["tall"][1])


@pytest.mark.slow
def test_eulerian_against_dem_low_column():
    """The low DEM column of test_mpm_against_dem_low_column (the same run, dem_column_once)
    against the Eulerian formulation on the same L0/32 (the column collapse as for the
    Lagrangian formulation, against vibroflow's own DEM of the same column; about 2 minutes, the
    fixed mesh covering the whole reach at the 1 mm cell): run-out and height within
    `mpm_dem_tolerance`, the mass conserved to round-off (measured: DEM run-out 0.483 and
    height 0.446, the fixed mesh 0.408 and 0.528 at a = 0.525; the material point method's
    0.435 and 0.527)."""
    (ro_dem, h_dem), (ro_e, h_e), dem = dem_and_mpm(0.5, method="eulerian")
    print(f"\na = {dem['a']:.3f}: DEM run-out {ro_dem:.3f} height {h_dem:.3f}; "
          f"Eulerian run-out {ro_e:.3f} height {h_e:.3f}")
    assert abs(ro_e - ro_dem) <= mpm_dem_tolerance(ro_dem, SEED_SPREAD["low"][0])
    assert abs(h_e - h_dem) <= mpm_dem_tolerance(h_dem, SEED_SPREAD["low"][1])


@pytest.mark.slow
def test_eulerian_against_dem_tall_column():
    """The tall DEM column of test_mpm_against_dem_tall_column (the same run) against the
    Eulerian formulation on the same L0/16 (about 4.5 minutes): run-out and height within
    `mpm_dem_tolerance` (measured: DEM height 0.829 (0.863 with the previous summation order of
    its pair forces), the fixed mesh's run-out 2.719 and height 1.037 at a = 2.103, the material
    point method's 2.847 and 1.035: both formulations stand 20 - 25 % above this DEM, as tall as
    each other)."""
    (ro_dem, h_dem), (ro_e, h_e), dem = dem_and_mpm(2.0, dx_cells=16, method="eulerian")
    print(f"\na = {dem['a']:.3f}: DEM run-out {ro_dem:.3f} height {h_dem:.3f}; "
          f"Eulerian run-out {ro_e:.3f} height {h_e:.3f}")
    assert abs(ro_e - ro_dem) <= mpm_dem_tolerance(ro_dem, SEED_SPREAD["tall"][0])
    assert abs(h_e - h_dem) <= mpm_dem_tolerance(h_dem, SEED_SPREAD["tall"][1])


@pytest.mark.slow
def test_mpm_runout_is_time_step_converged_with_flip_not_with_apic():
    """a = 3, L0 = 1 m, dx = L0/10, rough floor: the run-out against the Courant number.  APIC
    (flip = 0) damps the flow at every step (tests/test_continuum_conservation.py, the free
    grains), so its run-out falls as the steps multiply (measured: 5.72 at cfl 0.3, 3.84 at
    cfl 0.03, -33 %); the FLIP-APIC blend (flip = 0.99,
    vibroflow.continuum.mpm.solver.MPMSystem.flip) moves by less
    than a third of that (measured 5.35 and 5.88, +10 %).  With it, the continuum's own
    run-out (5.4 - 5.9) is 35 - 50 % above Lube et al. 2005's 3.95, and its height (0.90 -
    0.93 L0) 40 % below their a^(2/5) = 1.55: the planar laws are missed by the model, not by
    APIC's damping, which happened to shorten the run-out toward them."""
    a = 3.0
    out = {}
    for flip in (0.0, 0.99):
        for cfl in (0.3, 0.03):
            run = run_column(L_BIG, a * L_BIG, L_BIG / 10, rough_floor=True, flip=flip, cfl=cfl)
            assert run.settled
            out[flip, cfl] = mpm_deposit(run).normalised(L_BIG)
            print(f"\nflip {flip}, cfl {cfl}: run-out {out[flip, cfl][0]:.3f}, height "
                  f"{out[flip, cfl][1]:.3f}")
    apic = abs(out[0.0, 0.03][0] - out[0.0, 0.3][0])
    flip = abs(out[0.99, 0.03][0] - out[0.99, 0.3][0])
    assert apic > 0.25 * out[0.0, 0.3][0]
    assert flip < apic / 3.0
    assert flip < 0.12 * out[0.99, 0.3][0]


# ----------------------------------------------------------------------------------------------
# the Eulerian formulation's column against the Lagrangian's, and the experiments

def _formulation_deposit(L0, H0, dx, method):
    """Run-out (L_inf - L0)/L0 and height H_inf/L0 of a column collapse by `method`
    ("eulerian" or "lagrangian"; both symmetric, folded about x = 0, floor friction 0.40),
    measured by the shared vibroflow.measure.column.measure_continuum_deposit; and the
    relative mass error of the Eulerian run (0 for the Lagrangian's, whose points keep their
    masses)."""
    from vibroflow.continuum.column import run_column

    run = run_column(L0, H0, dx, method=method)
    err = run.mass_error
    assert run.settled
    dep = run.deposit()
    return (dep.runout - L0) / L0, dep.height / L0, err


@pytest.mark.slow
def test_column_collapse_conserves_mass_and_agrees_with_the_lagrangian():
    """A square column (a = 1, half-width 5 cm, 10 node spacings across, released both ways)
    collapses on the fixed mesh with its free surface: the mass is conserved to round-off (far
    inside the 0.5 % asked), and the deposit agrees within 10 % with the material point
    method's on the same grid (another code: the Lagrangian formulation of the same continuum;
    measured run-out 0.700 against 0.664 L0, height 0.809 against 0.850 L0)."""
    r_e, h_e, err = _formulation_deposit(0.05, 0.05, 0.01, "eulerian")
    r_l, h_l, _ = _formulation_deposit(0.05, 0.05, 0.01, "lagrangian")
    assert abs(err) < 1e-12
    assert h_e == pytest.approx(h_l, rel=0.10)
    assert r_e == pytest.approx(r_l, rel=0.10)



def _big_deposit(a: float, n: int, method: str):
    """(run-out (L_inf - L0)/L0, height H_inf/L0) of a column of L0 = 1 m and aspect ratio a on
    node spacing L0/n by `method`, measured by _formulation_deposit; the mass conserved to
    round-off."""
    r, h, err = _formulation_deposit(L_BIG, a * L_BIG, L_BIG / n, method)
    assert abs(err) < 1e-12
    return r, h


@pytest.mark.slow
def test_eulerian_low_column_keeps_its_top_at_the_experiments_scale():
    """a = 0.5, L0 = 1 m, dx = L0/20 (about 25 s): the top of a low column never moves, so
    H_inf = H0 (H_inf/L0 = a, the small-a branch of Lube et al. 2005's planar law) within 2 %;
    the run-out is past Lube et al.'s 1.2 a (0.75 against 0.60; the Lagrangian formulation on
    the same grid gives 0.65 and its run-out grows with the refinement,
    tests/test_column_collapse.py: the plane-strain continuum has no channel side walls)."""
    from vibroflow.measure.column import LUBE_2005

    a = 0.5
    runout, height = _big_deposit(a, 20, "eulerian")
    assert height == pytest.approx(LUBE_2005.height(a), rel=0.02)
    assert runout > LUBE_2005.runout(a)


@pytest.mark.slow
def test_eulerian_tall_column_runs_out_as_the_lagrangian():
    """a = 3 (the power-law branch of Lube et al. 2005, a > 2.8), L0 = 1 m, dx = L0/10: the
    run-out agrees with the material point method's on the same grid within 10 %
    (measured 7.22 against 7.17), and, as there, runs past Lube et al.'s 1.9 a^(2/3) = 3.95 by
    more than half (tests/test_column_collapse.py: the tub47 glass-bead friction and no
    channel side walls); the height at the symmetry plane is not compared (1.13 against 0.90,
    Lube's a^(2/5) = 1.55: neither formulation meets it)."""
    from vibroflow.measure.column import LUBE_2005

    a = 3.0  # (about 2 minutes)
    r_e, _ = _big_deposit(a, 10, "eulerian")
    r_l, _ = _big_deposit(a, 10, "lagrangian")
    assert r_e == pytest.approx(r_l, rel=0.10)
    assert r_e > 1.5 * LUBE_2005.runout(a)



def _rough_deposit(a: float, n: int, method: str):
    """(run-out (L_inf - L0)/L0, height H_inf/L0) of the column of L0 = 1 m, aspect ratio a,
    node spacing L0/n, on the rough floor (both formulations' no-slip grid floor, APIC)."""
    from vibroflow.continuum.column import run_column

    run = run_column(L_BIG, a * L_BIG, L_BIG / n, rough_floor=True, method=method)
    assert abs(run.mass_error) < 1e-12
    assert run.settled
    dep = run.deposit()
    return (dep.runout - L_BIG) / L_BIG, dep.height / L_BIG


@pytest.mark.slow
def test_rough_floor_low_column_agrees_with_the_lagrangian():
    """a = 0.5, L0 = 1 m, dx = L0/20, both formulations on the same rough floor (about 10 s):
    the top never moves (H_inf = H0 within 1 %, the small-a branch of every experiment) and
    the run-outs agree within 10 % (measured 0.554 Eulerian, 0.589 Lagrangian; Lube et al.
    2005's 1.2 a = 0.60).  The agreement with Lube et al. on this grid is not a claim: neither
    run-out is grid-converged (L0/10: 0.304 and 0.381; L0/40: 0.769 and 0.782), since the front
    is read where the deposit is one cell thick and a mu(I) continuum has no h_stop to stop a
    thinner tail (docs/validation.md); the two formulations move together."""
    r_e, h_e = _rough_deposit(0.5, 20, "eulerian")
    r_l, h_l = _rough_deposit(0.5, 20, "lagrangian")
    print(f"\nrough floor a = 0.5: Eulerian {r_e:.3f} / {h_e:.3f}, Lagrangian {r_l:.3f} / "
          f"{h_l:.3f}")
    assert h_e == pytest.approx(0.5, rel=0.01) and h_l == pytest.approx(0.5, rel=0.01)
    assert r_e == pytest.approx(r_l, rel=0.10)


@pytest.mark.slow
def test_rough_floor_tall_column_runs_out_as_the_lagrangian():
    """a = 3, L0 = 1 m, dx = L0/10, both formulations on the rough floor (about 1 minute): the
    run-outs agree within 10 % (measured 5.41 Eulerian, 5.72 Lagrangian) and both run past
    Lube et al. 2005's 1.9 a^(2/3) = 3.95 by more than a third: the continuum's excess mobility
    (docs/validation.md) is the model's, the same on the fixed mesh."""
    from vibroflow.measure.column import LUBE_2005

    r_e, h_e = _rough_deposit(3.0, 10, "eulerian")
    r_l, h_l = _rough_deposit(3.0, 10, "lagrangian")
    print(f"\nrough floor a = 3: Eulerian {r_e:.3f} / {h_e:.3f}, Lagrangian {r_l:.3f} / {h_l:.3f}")
    assert r_e == pytest.approx(r_l, rel=0.10)
    assert min(r_e, r_l) > 1.33 * LUBE_2005.runout(3.0)
