"""The axisymmetric sections of both continuum formulations (the material points'
MPMSystem.axisymmetric, the Eulerian cells' EulerianSystem.axisymmetric) against known answers:
the divergence of a stress in cylindrical coordinates, the kinematics of a radial stretch, and
the cylindrical column collapse of Lube et al. (2004) and Lajeunesse et al. (2004).

In a section x = r >= 0 of a body of revolution the points' masses and volumes are per radian
(V = A r), the hoop stress sigma_theta is the stress's yy slot, the velocity gradient gains the
hoop rate v_r / r and the internal force the term -V sigma_theta w / r (Nairn & Guilkey 2015).
"""
from __future__ import annotations

import functools

import numpy as np
import pytest

from continuum_helpers import METHODS
from vibroflow.measure.column import (LAJEUNESSE_2004, LUBE_2004, LUBE_2005,
                                       quasistatic_runout_axisymmetric)
from vibroflow.continuum.boundary import Plane
from vibroflow.continuum.column import SAND_FRICTION_DEG, run_column, sand_material
from vibroflow.continuum.constitutive import ContinuumMaterial
from vibroflow.continuum.stress_update import update_stress_points
from vibroflow.continuum.g2p import g2p
from vibroflow.continuum.grid import Grid
from vibroflow.continuum.mpm.solver import MPMSystem, init_state
from vibroflow.continuum.p2g import p2g
from vibroflow.continuum.plasticity import update_volume
from vibroflow.errors import InputError

DX = 0.05
SP = 0.5 * DX


def ring_points(r0, r1, z1):
    """Points 2 x 2 a cell filling [r0, r1] x [0, z1] (m), and their volumes per radian."""
    rs = np.arange(r0 + 0.5 * SP, r1, SP)
    zs = np.arange(0.5 * SP, z1, SP)
    R, Z = np.meshgrid(rs, zs, indexing="ij")
    x = np.stack([R.ravel(), Z.ravel()], axis=1)
    return x, SP * SP * x[:, 0]


def _axi_system(r1=0.8, z1=0.5, dx=DX):
    from vibroflow.continuum.eulerian.mesh import EulerianMesh
    from vibroflow.continuum.eulerian.solver import EulerianSystem

    mesh = EulerianMesh.box(0.0, r1, 0.0, z1, dx, axis=True)
    return EulerianSystem(mesh, ContinuumMaterial(), 1e-4, axisymmetric=True)


def _points_ring_scatter(p0):
    """(forces on the inner nodes scattered with the hoop term, without it, the nodes' radii) of
    a thick ring of material points 2 x 2 a cell over [0.2, 0.8] x [0, 0.4] m under -p0 I
    (p2g: the plane-strain scatter of the same volumes without the hoop term)."""
    x, vol = ring_points(0.2, 0.8, 0.4)
    n = len(x)
    stress = np.zeros((n, 4))
    stress[:, [0, 1, 3]] = -p0
    g = Grid.covering(0.0, 1.0, -0.1, 0.5, DX)
    ri = g.x0 + np.arange(g.nx) * DX
    zk = g.z0 + np.arange(g.nz) * DX
    R, Z = np.meshgrid(ri, zk, indexing="ij")
    inner = (R >= 0.2 + 1.5 * DX) & (R <= 0.8 - 1.5 * DX) & (Z >= 1.5 * DX) & (Z <= 0.4 - 1.5 * DX)
    assert inner.sum() > 20
    out = {}
    for axi in (True, False):
        gm, gmv, gf, _ = g.zeros()
        p2g(x, np.zeros((n, 2)), np.zeros((n, 4)), 4680.0 * vol, vol, stress, np.zeros((n, 2)),
            g.x0, g.z0, DX, False, gm, gmv, gf, axi)
        out[axi] = gf[inner]
    return out[True], out[False], R[inner]


def _cells_ring_scatter(p0):
    """The same of the Eulerian cells filled over [0.2, 0.6] x [0, 0.3] m (column_scatter.
    scatter with inv_r = 1/r; the plane scatter with inv_r = 0), 2 x 2 cells an element, as the
    points are."""
    from vibroflow.continuum.eulerian.column_scatter import scatter, scatter_work
    from vibroflow.continuum.eulerian.transfer import WeightTables, node_row_columns

    system = _axi_system()
    mesh, g = system.mesh, system.mesh.grid
    c = system.x
    filled = (c[:, 0] > 0.2) & (c[:, 0] < 0.6) & (c[:, 1] < 0.3)
    n = mesh.n
    vol = np.where(filled, mesh.h**2 * c[:, 0], 0.0)
    stress = np.zeros((n, 4))
    stress[np.ix_(filled, [0, 1, 3])] = -p0
    t = WeightTables.of_mesh(mesh, c)
    ri = g.x0 + np.arange(g.nx) * DX
    zk = g.z0 + np.arange(g.nz) * DX
    R, Z = np.meshgrid(ri, zk, indexing="ij")
    inner = (R >= 0.2 + 1.5 * DX) & (R <= 0.6 - 1.5 * DX) & (Z >= 1.5 * DX) & \
        (Z <= 0.3 - 1.5 * DX)
    assert inner.sum() >= 8
    out = {}
    for name, inv_r in (("axi", system.inv_r), ("plane", np.zeros(n))):
        gm, gmv, gf, _ = g.zeros()
        scatter(mesh.ncz, t.cx, t.cz, g.dx, node_row_columns(t.cx, g.nx, g.periodic),
                4680.0 * vol, vol, np.zeros((n, 2)), np.zeros((n, 4)), stress, np.zeros((n, 2)),
                inv_r, scatter_work(mesh.ncx, g.nz), gm, gmv, gf)
        out[name] = gf[inner]
    return out["axi"], out["plane"], R[inner]


RING_SCATTER = {"lagrangian": _points_ring_scatter, "eulerian": _cells_ring_scatter}


@pytest.mark.parametrize("method", METHODS)
def test_uniform_stress_is_in_equilibrium_in_cylindrical_coordinates(method):
    """An isotropic stress -p0 I is divergence-free in any coordinates: in cylindrical ones
    d sigma_rr / dr + (sigma_rr - sigma_theta) / r = 0.  A thick ring of material under it
    scatters no force to the nodes whose support lies inside it: with the hoop term, zero to
    round-off (the quadratic B-spline's weights summed over 2 x 2 points, or cells, an element
    integrate d(r w)/dr exactly); without it (the plane-strain scatter of the same volumes)
    every such node keeps the radial force p0 dx^2 of the missing -V sigma_theta w / r."""
    p0 = 1.0e4
    axi, plane, r = RING_SCATTER[method](p0)
    scale = p0 * DX * r
    assert (np.abs(axi[:, 0]) / scale).max() < 1e-12
    assert (np.abs(axi[:, 1]) / scale).max() < 1e-12
    # the missing hoop term: p0 sum_p A_p w_ip = p0 dx^2 at every interior node
    np.testing.assert_allclose(np.abs(plane[:, 0]), p0 * DX * DX, rtol=1e-9)


# ----------------------------------------------------------------------------------------------
# the kinematics of a radial stretch: the points' compression, the cells' expansion

def test_hoop_rate_volume_and_stress_of_a_radial_compression():
    """The grid velocity v = (eps r, 0) (a uniform radial compression, eps < 0): every point
    gets L_rr = eps and the hoop rate L_theta = v_r / r = eps exactly (the B-spline reproduces
    a linear field), its volume per radian changes by (1 + dt eps)^2 (the radial and the hoop
    stretch), and the elastic predictor adds dt (2 lambda eps + 2 G eps) to sigma_rr and
    sigma_theta and dt 2 lambda eps to sigma_zz (Hooke's law with D = diag(eps, 0, eps))."""
    x, vol = ring_points(0.1, 0.6, 0.3)
    n = len(x)
    eps, dt = -0.5, 1.0e-4
    g = Grid.covering(0.0, 0.8, -0.1, 0.4, DX)
    gv = np.zeros((g.nx, g.nz, 2))
    gv[:, :, 0] = eps * (g.x0 + np.arange(g.nx) * DX)[:, None]
    L = np.zeros((n, 5))
    r_before = x[:, 0].copy()
    xx = x.copy()
    g2p(xx, np.zeros((n, 2)), np.zeros((n, 4)), L, gv, g.x0, g.z0, DX, dt, False,
        np.zeros((g.nx, g.nz)), np.zeros((g.nx, g.nz, 2)), 0.0)
    np.testing.assert_allclose(L[:, 0], eps, rtol=1e-12)
    np.testing.assert_allclose(L[:, 4], eps, rtol=1e-12)
    np.testing.assert_allclose(L[:, 1:4], 0.0, atol=1e-12)
    np.testing.assert_allclose(xx[:, 0], r_before * (1.0 + dt * eps), rtol=1e-12)

    mat = ContinuumMaterial()
    rho = np.full(n, 1.02 * mat.critical_density)
    mass = rho * vol
    volume = vol.copy()
    update_volume(L, mass, volume, rho, dt, 0.0)
    np.testing.assert_allclose(volume / vol, (1.0 + dt * eps) ** 2, rtol=1e-12)

    p0 = 5.0e3
    stress = np.zeros((n, 4))
    stress[:, [0, 1, 3]] = -p0
    gd = np.zeros(n)
    st = np.zeros(n, np.int8)
    update_stress_points(stress, L, rho, dt, mat.as_array(), gd, st)
    K, G = mat.bulk_modulus, mat.shear_modulus
    lam = K - 2.0 * G / 3.0
    assert np.all(st == 1)     # compressed isotropically: elastic
    np.testing.assert_allclose(stress[:, 0], -p0 + dt * (2 * lam * eps + 2 * G * eps), rtol=1e-12)
    np.testing.assert_allclose(stress[:, 3], -p0 + dt * (2 * lam * eps + 2 * G * eps), rtol=1e-12)
    np.testing.assert_allclose(stress[:, 1], -p0 + dt * 2 * lam * eps, rtol=1e-12)


def test_eulerian_radial_expansion_hoop_rate_and_mass_per_radian():
    """A uniform radial expansion u = eps r (eps > 0) of a full annulus of uniform density:
    face_velocity.match_divergence gives every cell L_rr = eps (the finite-volume divergence of the
    section's own plane part) and the hoop rate (u_L + u_R) / (2 r) = eps exactly, and one
    remap with the section's face weights takes from every cell whose inner neighbour is full
    the mass 2 eps dt of its own, the volume change (1 + eps dt)^2 of the material to first
    order in dt, exactly (the fluxes are rho u dt h r at each face: (r_L^2 - r_R^2) = -2 r h);
    the total mass per radian is conserved to round-off once the flux reaches empty cells."""
    from vibroflow.continuum.eulerian.advection import remap
    from vibroflow.continuum.eulerian.face_velocity import match_divergence

    system = _axi_system()
    mesh = system.mesh
    ncx, ncz, h = mesh.ncx, mesh.ncz, mesh.h
    c = system.x
    full = c[:, 0] < 0.5
    rho = 1500.0
    mass = np.where(full, rho * h * h * c[:, 0], 0.0)
    eps, dt = 0.3, 1.0e-3
    r_faces = np.arange(ncx + 1) * h
    ux = np.where(mesh.open_x, eps * r_faces[:, None], 0.0)
    ux[0] = 0.0
    uz = np.zeros((ncx, ncz + 1))
    L = np.zeros((mesh.n, 5))
    L[:, 0] = eps              # what g2p gives from the nodes
    match_divergence(L, ux, uz, h, False, np.zeros((mesh.n, 2)), mesh.normal, mass,
                     mesh.open_x, mesh.open_z, system.inv_r)
    np.testing.assert_allclose(L[full, 0], eps, rtol=1e-12)
    np.testing.assert_allclose(L[full, 3], 0.0, atol=1e-12)
    np.testing.assert_allclose(L[full, 4], eps, rtol=1e-12)
    m2 = mass.reshape(ncx, ncz).copy()
    q = np.zeros((11, ncx, ncz))
    remap(m2, q, ux, uz, h, dt, False, system.remap_work)
    new = m2.ravel()
    inner = full & (c[:, 0] > h)    # the inner neighbour full (the axis cell has none)
    np.testing.assert_allclose(new[inner] / mass[inner], 1.0 - 2.0 * eps * dt, rtol=1e-12)
    assert new.sum() == pytest.approx(mass.sum(), rel=1e-14)


# ----------------------------------------------------------------------------------------------
# the cylinder against the planar column, tub47's glass-bead media

@pytest.mark.slow
def test_axisymmetric_low_column_keeps_its_top():
    """a = 0.5 < 0.74, R0 = 1 m, dx = R0/20, rough floor: the top of a low cylinder never
    moves, so H_inf = H0 (Lajeunesse et al. 2004's small-a branch, H_inf / R0 = a), within the
    mission's 10 %.  Measured 0.466 (-7 %; 0.488 with flip = 0.99, 0.474 on R0/40): the
    continuum's centre subsides, its top 0.453 at the axis and 0.41 at r = 0.3 R0, where the
    plane-strain column's sinks by 2.6 % only (0.487 at the symmetry plane, same grid and floor);
    a 15-degree cone stands (largest displacement 3 mm over 6 sqrt(H/g)), so this is the
    continuum's low-confinement creep, not a lost equilibrium.  The run-out is not
    grid-converged (0.45, 0.60, 0.73 on R0/10, /20, /40 against Lube et al. 2004's 1.24 a =
    0.62), as the planar low column's is not."""
    a = 0.5
    run = run_column(1.0, a, 1.0 / 20, rough_floor=True, axisymmetric=True)
    assert run.settled
    dep = run.deposit()
    runout, height = dep.normalised(1.0)
    print(f"\naxisymmetric a = {a}: run-out {runout:.3f} (Lube 2004 {LUBE_2004.runout(a):.3f}),"
          f" height {height:.3f} (Lajeunesse 2004 {LAJEUNESSE_2004.height(a):.3f})")
    assert height == pytest.approx(LAJEUNESSE_2004.height(a), rel=0.10)
    # the thickness profile h(r) of the meridian areas holds the cylinder's volume per radian,
    # int h r dr = R0^2 H0 / 2 (to the bins' midpoint rule)
    bw = dep.x[1] - dep.x[0]
    assert float(np.sum(dep.h * dep.x) * bw) == pytest.approx(0.5 * a, rel=0.01)


@pytest.mark.slow
def test_axisymmetric_column_spreads_less_than_the_planar_one():
    """a = 3, R0 = L0 = 1 m, dx = L0/20, rough floor, APIC: the cylinder's run-out is shorter
    than the plane-strain column's, as the experiments' are (Lube et al. 2004's 1.6 a^(1/2) =
    2.77 against Lube et al. 2005's 1.9 a^(2/3) = 3.95: 0.70), because its spreading layer
    thins as 1/r.  Measured: 3.46 against 5.65 (0.61).  With this default material (tub47's
    glass-bead mu_s = tan 20.9 deg) the cylinder runs out 25 % (APIC) to 37 % (flip 0.99,
    R0/40) past Lube et al. 2004's 2.77 and stands at 0.52 - 0.60 R0 against Lajeunesse et
    al. 2004's 0.74; with the friction of the experiments' sand it meets both within 10 %
    (test_tall_sand_cylinder_meets_lube_and_lajeunesse_2004)."""
    a = 3.0
    axi = run_column(1.0, a, 1.0 / 20, rough_floor=True, axisymmetric=True)
    plane = run_column(1.0, a, 1.0 / 20, rough_floor=True)
    assert axi.settled and plane.settled
    ra, ha = axi.deposit().normalised(1.0)
    rp, hp = plane.deposit().normalised(1.0)
    print(f"\na = {a}: axisymmetric run-out {ra:.3f} (Lube 2004 {LUBE_2004.runout(a):.3f}), "
          f"height {ha:.3f} (Lajeunesse 2004 {LAJEUNESSE_2004.height(a):.3f}); planar run-out "
          f"{rp:.3f} (Lube 2005 {LUBE_2005.runout(a):.3f}), height {hp:.3f}")
    assert ra < 0.75 * rp
    assert ha < hp


# ----------------------------------------------------------------------------------------------
# the experiments' columns: Lube et al. 2004 and Lajeunesse et al. 2004 are axisymmetric

#: the central height is the deposit's mean thickness within this fraction of R0 of the axis:
#: next to the axis a bin holds few points, and one bin's thickness swings by 5 - 15 % (a = 4
#: on R0/20 read 0.687 in the first bin, 0.774 within 0.1 R0, with 0.80 - 0.90 around it);
#: the summit of a tall cylinder's deposit is nearly flat over that distance
CENTRE = 0.1


@functools.cache
def sand_column(a, n, method="lagrangian", reach=None):
    """The deposit ((r_inf - R0)/R0, H_inf/R0) of a sand cylinder of R0 = 1 m (157 of tub47's
    grains across), aspect ratio a, on dx = R0/n, rough floor, APIC, by `method` (reach: where
    the grid or mesh is cut, R0; default run_column's); the height within CENTRE R0 of the
    axis; the mass per radian conserved to round-off."""
    run = run_column(1.0, a, 1.0 / n, material=sand_material(), rough_floor=True,
                     axisymmetric=True, reach=reach, method=method)
    assert run.settled
    assert abs(run.mass_error) < 1e-12
    runout, height = run.deposit(wall_window=CENTRE).normalised(1.0)
    print(f"\n{method} sand, a = {a}, R0/{n}: run-out {runout:.3f} (Lube 2004 "
          f"{LUBE_2004.runout(a):.3f}, {runout / LUBE_2004.runout(a) - 1:+.1%}), height "
          f"{height:.3f} (Lajeunesse 2004 {LAJEUNESSE_2004.height(a):.3f}, "
          f"{height / LAJEUNESSE_2004.height(a) - 1:+.1%})")
    return runout, height


# both run in the slow suite (30 s and more each on the 2-core machine from a cold cache); the
# default suite keeps the axisymmetric kernels' analytic checks above
@pytest.mark.slow
@pytest.mark.parametrize("a", [3.0, 4.0])
def test_tall_sand_cylinder_meets_lube_and_lajeunesse_2004(a):
    """The check on the power-law branch (the linear one needs finer grids:
    test_low_sand_cylinders_reach_the_law_on_fine_grids): a cylinder of the experiments' sand
    (SAND_FRICTION_DEG), a > 1.7, R0 = 1 m, dx = R0/20 (about 25 s for both): the run-out
    within 10 % of Lube et al. 2004's 1.6 a^(1/2) and the height within 10 % of Lajeunesse et
    al. 2004's 0.74 R0.  Measured: a = 3, 2.70 (-2.7 %) and 0.78 (+5.8 %); a = 4, 3.36
    (+5.0 %) and 0.77 (+4.6 %).  On R0/40 (test_sand_cylinder_runouts_meet_lube_2004) the
    run-outs hold and the heights do not: the height grows with the refinement (a = 3: 0.89,
    +20 %, on R0/80), mostly because one transfer a step damps eight times less on each
    halved grid.  With this grid's damping held (8 transfers a step on R0/40,
    benchmarks/column_convergence.py --hold-damping) a = 3 reads 2.62 and 0.81 (+9.6 %), a = 4
    3.29 and 0.83 (+11.6 %): the pass on the height holds at a = 3, not at a = 4
    (docs/validation.md).  With tub47's glass-bead friction (mu_s = tan 20.9
    deg) the same cylinder runs 25 % too far and stands 20 - 30 % too low
    (test_axisymmetric_column_spreads_less_than_the_planar_one): the continuum's deposit
    depends on the grains' friction, where the experiments' hardly did.  Lajeunesse et al.'s
    own grains were glass beads, whose height law they found insensitive to the bead size and
    the floor; the continuum meets their 0.74 with the sand's friction, not with a glass
    bead's: it reproduces the laws with one material, not their independence of it."""
    runout, height = sand_column(a, 20)
    assert runout == pytest.approx(LUBE_2004.runout(a), rel=0.10)
    assert height == pytest.approx(LAJEUNESSE_2004.height(a), rel=0.10)


@pytest.mark.slow
def test_eulerian_sand_cylinder_agrees_with_the_lagrangian():
    """a = 3, R0 = 1 m, dx = R0/10, the sand of the Lagrangian checks above, in the Eulerian
    formulation's axisymmetric section (about 30 s): the mass per radian is conserved to
    round-off and the deposit agrees with the material point method's on the same grid
    (another code: the Lagrangian formulation of the same continuum) within 10 % (measured
    run-out 2.39 against 2.35, height 0.815 against 0.770)."""
    r_e, h_e = sand_column(3.0, 10, "eulerian")
    r_l, h_l = sand_column(3.0, 10)
    assert r_e == pytest.approx(r_l, rel=0.10)
    assert h_e == pytest.approx(h_l, rel=0.10)


#: the tall cylinders of the finer grid, R0/40 (about 2 minutes together)
FINE_ASPECTS = (2.0, 3.0, 4.0, 5.0)


#: the tall cylinders (a, R0/dx) each formulation is held to past R0/20: the material points'
#: a = 2 to 5 on R0/40 (about 2 minutes together), the Eulerian cells' a = 3 on R0/20 (about
#: 80 s), where it stands as the material points' do one refinement later
TALL = {"lagrangian": tuple((a, 40) for a in FINE_ASPECTS), "eulerian": ((3.0, 20),)}


@pytest.mark.parametrize("method", [pytest.param(m, marks=pytest.mark.slow) for m in METHODS])
def test_sand_cylinder_runouts_meet_lube_2004(method):
    """Every run-out of TALL within 10 % of Lube et al. 2004.

    Lagrangian, R0/40, a = 2 to 5: measured -7.3, -2.3, +2.7, +4.1 %.  Its run-out grows
    faster with a than a^(1/2): from a = 2 to 5 by 1.77 against 1.58.  A friction angle of
    27.5 deg puts a = 1 to 3 within 10 % on both run-out and height (run-outs -5.8, -1.0,
    +3.1 %; heights -8.8, +1.5, +6.7 %) and a = 4, 5 just outside (+10.1, +10.2 %); it is not
    the default of this test because it was chosen to fit.

    Eulerian, a = 3, R0/20: measured 2.88, +4.0 %; its height is not within 10 % of
    Lajeunesse et al. 2004 (0.84, +13.7 %; the Lagrangian's 0.78, +5.8 %, on this grid, 0.85
    on R0/40).  a = 4 on R0/20 (about 3.5 minutes, not run here): run-out 3.55 (+10.8 %),
    height 0.87 (+17.8 %).  Neither formulation's tall run-out is grid-converged: a = 3 reads
    2.39, 2.88, 3.12 on R0/10, /20, /40 in the Eulerian (R0/40: +12.6 %, height 0.878, 14
    minutes), and the Lagrangian's 2.35, 2.70, 2.71, 2.86 on R0/10 to /80 (height 0.77, 0.78,
    0.85, 0.89), the plateau from R0/20 to R0/40 a coincidence (benchmarks/column_convergence.py;
    docs/validation.md).  Both rises are mostly the transfers' damping, which one transfer a
    step divides by eight on each halved grid: with R0/20's damping held (8 transfers a step on
    R0/40, 23 minutes) the Eulerian's R0/40 reads 2.684 (-3.1 %) and 0.831, the Lagrangian's
    2.619 and 0.811."""
    for a, n in TALL[method]:
        runout, _ = sand_column(a, n, method)
        assert runout == pytest.approx(LUBE_2004.runout(a), rel=0.10)


@pytest.mark.parametrize("method", [
    pytest.param("lagrangian", marks=[pytest.mark.slow, pytest.mark.xfail(strict=True, reason=(
        "the continuum's tall cylinders stand too high on R0/40: 0.807, 0.847, 0.842, 0.864 for "
        "a = 2 to 5 (+9.1, +14.5, +13.8, +16.8 % of Lajeunesse et al. 2004's 0.74; "
        "docs/validation.md)"))]),
    pytest.param("eulerian", marks=[pytest.mark.slow, pytest.mark.xfail(strict=True, reason=(
        "the Eulerian tall cylinder stands too high on R0/20: 0.84 against Lajeunesse et al. "
        "2004's 0.74 (+13.7 %); docs/validation.md"))]),
])
def test_sand_cylinder_heights_meet_lajeunesse_2004(method):
    """The target: every central height of TALL within 10 % of Lajeunesse et al. 2004's
    0.74 R0.  The height is the deposit's least converged figure (Lagrangian a = 3: 0.77, 0.78,
    0.85, 0.89 on R0/10 to /80), and much of its rise is the transfers' damping, which one
    transfer a step divides by eight on each halved grid: held fixed, R0/40 to R0/80 moves the
    height by 2 % where one transfer a step moves it by 5 % (a = 3; a = 4 still by 7 %).  The
    continuum's tall cylinders (a = 3 to 5) stand 9.6 - 12.9 % above the experiments' at the
    damping of R0/20's one transfer a step and about 20 % with next to none
    (docs/validation.md)."""
    for a, n in TALL[method]:
        _, height = sand_column(a, n, method)
        assert height == pytest.approx(LAJEUNESSE_2004.height(a), rel=0.10)


@pytest.mark.parametrize("method", [pytest.param(m, marks=pytest.mark.slow) for m in METHODS])
def test_sand_cylinder_heights_regression_guard(method):
    """Regression guard of the state reached (not a physics target: that is the strict xfail
    above): the central heights of TALL stay within 20 % of Lajeunesse et al. 2004 (measured
    +9.1 to +16.8 %, Lagrangian on R0/40; +13.7 %, Eulerian on R0/20)."""
    for a, n in TALL[method]:
        _, height = sand_column(a, n, method)
        assert height == pytest.approx(LAJEUNESSE_2004.height(a), rel=0.20)


def test_low_sand_cylinder_stops_between_the_static_cone_and_the_experiments():
    """The linear branch (a < 1.7), a = 0.5, R0 = 1 m, dx = R0/20: on this grid the low
    cylinder comes to rest at the quasi-static cone of its own friction
    (analysis.column.quasistatic_runout_axisymmetric: the truncated cone of slope mu_s holding
    the cylinder's volume, run-out 0.409; measured 0.405), 35 % short of Lube et al. 2004's
    1.24 a = 0.62, a deposit sloping at 19.5 deg, 10 degrees below the sand's friction angle:
    the experiments' low columns flow well past the static cone.  So does the continuum once
    the grid resolves its failure, a shear band a cell wide that on a coarse grid is too thick
    to let the sliding wedge gather speed: 0.405, 0.478, 0.537, 0.574 on R0/20, /40, /80, /160
    (the steps shrink by 0.63 each halving, so the limit is about 0.64, +3 % from the law;
    test_low_sand_cylinders_reach_the_law_on_fine_grids).  The top never moves: the height is a
    within 2 %."""
    a = 0.5
    mu_s = float(np.tan(np.radians(SAND_FRICTION_DEG)))
    static, _ = quasistatic_runout_axisymmetric(a, mu_s)
    runout, height = sand_column(a, 20)
    assert height == pytest.approx(a, rel=0.02)
    assert static * 0.97 < runout < LUBE_2004.runout(a)


@pytest.mark.xfail(strict=True, reason=(
    "on R0/20 the low cylinder stops at its static cone: run-out 0.405 against Lube et al. "
    "2004's 0.62 (-35 %); the law is reached on R0/160 "
    "(test_low_sand_cylinders_reach_the_law_on_fine_grids)"))
def test_low_sand_cylinder_on_the_coarse_grid_meets_lube_2004():
    """The target on R0/20: a = 0.5, the run-out within 10 % of Lube et al. 2004's 1.24 a."""
    runout, _ = sand_column(0.5, 20)
    assert runout == pytest.approx(LUBE_2004.runout(0.5), rel=0.10)


#: the low cylinders (a, R0/dx, reach) on the grids that resolve their failure: the material
#: points' (about 3 minutes), the Eulerian cells' (about 2 minutes, the mesh cut at 2.6 and
#: 1.8 R0, past the run-outs)
LOW_FINE = {"lagrangian": ((1.0, 80, None), (0.5, 160, None)),
            "eulerian": ((1.0, 40, 2.6), (0.5, 80, 1.8))}


@pytest.mark.parametrize("method", [pytest.param(m, marks=pytest.mark.slow) for m in METHODS])
def test_low_sand_cylinders_reach_the_law_on_fine_grids(method):
    """The linear branch resolved: run-out within 10 % of Lube et al. 2004's 1.24 a and height
    within 10 % of Lajeunesse et al. 2004's.  Lagrangian, a = 1 on R0/80 and a = 0.5 on
    R0/160: measured 1.169 (-5.7 %) and 0.730 (-1.4 %); 0.574 (-7.4 %) and 0.499.  On R0/20
    they read 0.947 (-24 %) and 0.405 (-35 %)
    (test_low_sand_cylinder_stops_between_the_static_cone_and_the_experiments).  Eulerian,
    a = 1 on R0/40 and a = 0.5 on R0/80: measured 1.152, -7.1 %, and 0.706, -4.6 %; 0.574,
    -7.4 %, and 0.499.  On R0/20 a = 1 reads 0.954 (-23 %), the Lagrangian's 0.947: the same
    continuum, the same need of a grid that resolves the failure's shear band, which the fixed
    mesh meets one refinement earlier (the Lagrangian's a = 1 on R0/40: 1.072; a = 0.5 reaches
    0.574 on R0/160)."""
    for a, n, reach in LOW_FINE[method]:
        runout, height = sand_column(a, n, method, reach=reach)
        assert runout == pytest.approx(LUBE_2004.runout(a), rel=0.10)
        assert height == pytest.approx(LAJEUNESSE_2004.height(a), rel=0.10)


# ----------------------------------------------------------------------------------------------
# set-ups a section of revolution cannot have

def _mpm_system(grid, **kw):
    return MPMSystem(grid, ContinuumMaterial(), 1e-4, axisymmetric=True, **kw)


def _eulerian_system(mesh):
    from vibroflow.continuum.eulerian.solver import EulerianSystem

    return EulerianSystem(mesh, ContinuumMaterial(), 1e-4, axisymmetric=True)


def _mesh(*args, **kw):
    from vibroflow.continuum.eulerian.mesh import EulerianMesh

    return EulerianMesh.box(*args, **kw)


@pytest.mark.parametrize("make, what", [
    pytest.param(lambda: _mpm_system(Grid.covering(0.0, 1.0, 0.0, 1.0, DX),
                                     boundaries=[Plane((0.0, 0.0), (0.0, 1.0), 1e6)]),
                 "boundaries", id="lagrangian-plane-boundary"),
    pytest.param(lambda: _mpm_system(Grid.periodic_strip(1.0, 0.0, 1.0, DX)), "periodic",
                 id="lagrangian-periodic"),
    pytest.param(lambda: _mpm_system(Grid(0.1, 0.0, DX, 20, 20)), "x0",
                 id="lagrangian-grid-off-the-axis"),
    pytest.param(lambda: init_state(_mpm_system(Grid.covering(0.0, 1.0, 0.0, 1.0, DX)),
                                    [[0.0, 0.5]], 1e-4, ContinuumMaterial().critical_density),
                 "r > 0", id="lagrangian-point-on-the-axis"),
    pytest.param(lambda: run_column(1.0, 1.0, 0.1, axisymmetric=True), "rough_floor",
                 id="lagrangian-column-without-rough-floor"),
    pytest.param(lambda: _eulerian_system(_mesh(0.0, 1.0, 0.0, 1.0, DX)), "wall along the axis",
                 id="eulerian-wall-along-the-axis"),
    pytest.param(lambda: _eulerian_system(_mesh(0.1, 1.0, 0.0, 1.0, DX, axis=True)), "xmin",
                 id="eulerian-mesh-off-the-axis"),
    pytest.param(lambda: _eulerian_system(_mesh(0.0, 1.0, 0.0, 1.0, DX, periodic=True)),
                 "periodic", id="eulerian-periodic"),
])
def test_bad_axisymmetric_set_ups_are_one_line_errors(make, what):
    """What a section of revolution cannot have (a plane boundary, periodic sides, a grid or
    mesh off the axis, a point on it, a column without the rough floor): a one-line error
    naming it."""
    with pytest.raises(InputError, match=what) as err:
        make()
    assert "\n" not in str(err.value)


# ----------------------------------------------------------------------------------------------
# the static strength: a pile below and above the friction angle

def _pile(theta_deg, axisymmetric, n=10, duration_tau=6.0):
    """A pile of half-width (or radius) W = 2 m and slope theta (deg) of the default material on
    the rough floor, lithostatic with Jaky's K_0, run for `duration_tau` sqrt(H/g).  Returns
    (top at the centre, initial height H, front, largest displacement), m."""
    from vibroflow.continuum.column_setup import G_ACC
    from vibroflow.continuum.mpm.column import column_points, column_system, lithostatic_state
    from vibroflow.continuum.mpm.solver import run_steps

    mat = ContinuumMaterial()
    W = 2.0
    H = W * np.tan(np.radians(theta_deg))
    dx = 1.0 / n
    sp = 0.5 * dx
    Hc = np.ceil(H / sp) * sp
    system = column_system(W, Hc, dx, mat, rough_floor=True, reach=3.0 * W,
                           axisymmetric=axisymmetric)
    x = column_points(0.0 if axisymmetric else -W, W, Hc, sp)
    x = x[x[:, 1] < H * (1.0 - np.abs(x[:, 0]) / W)]
    state = lithostatic_state(system, x, H * (1.0 - np.abs(x[:, 0]) / W))
    x0 = state.x.copy()
    run_steps(system, state, int(duration_tau * np.sqrt(H / G_ACC) / system.dt))
    top = float(state.x[np.abs(state.x[:, 0]) < 0.1, 1].max())
    moved = float(np.linalg.norm(state.x - x0, axis=1).max())
    return top, H, float(np.abs(state.x[:, 0]).max()), moved


@pytest.mark.parametrize("axisymmetric", [False, True])
def test_pile_stands_below_the_friction_angle_and_slumps_to_it_above(axisymmetric):
    """The static strength of the continuum, plane strain and axisymmetric: a pile (a wedge,
    or a cone) of 15 degrees, below the default material's friction angle (atan mu_s = 20.9
    degrees; asin mu_s = 22.5 in plane-strain flow), stands: its largest displacement over
    6 sqrt(H/g) is below 1 % of its height (measured 1.2 and 2.7 mm of 0.54 m); one of 30
    degrees slumps to a mean slope top / front within 4 degrees of that angle (measured 24.8
    and 19.7 degrees).  So the material is not too weak at rest: the column collapse's much
    flatter deposits (mean slope about 8 degrees at a = 3, vibroflow.continuum.column) come
    from the dynamics of the collapse, not from the yield condition."""
    top, H, _, moved = _pile(15.0, axisymmetric)
    assert moved < 0.01 * H
    top, H, front, moved = _pile(30.0, axisymmetric)
    slope = np.degrees(np.arctan(top / front))
    print(f"\n{'axisymmetric' if axisymmetric else 'plane'}: 30-degree pile slumped to "
          f"{slope:.1f} degrees (top {top:.3f} m, front {front:.3f} m)")
    assert moved > 0.1 * H
    assert 20.9 - 4.0 < slope < 22.5 + 4.0
