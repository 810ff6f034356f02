"""Coarse-graining (vibroflow.calibration.coarse_grain) against known answers.

1. A bed at rest on a floor (a small explicit DEM: 400 steel balls settled in a box of plane
   walls whose four side walls are frictionless, so the floor carries the whole weight).  The
   momentum balance of a static packing, d sigma_zb / d x_b = -rho g (compression positive),
   integrated across the box, says that the box-averaged vertical stress at height z is the
   weight of the material above z per unit area.  "Material above" is measured two ways: the CG
   density integrated from z up (the exact statement for the smoothed fields), and the mass of
   the balls whose centres lie above z (the discrete count, which differs by the smoothing of
   the layering).  The floor's load must be the whole weight.
2. Uniform translation: every ball with the same velocity gives exactly that velocity, zero
   velocity gradient (shear rate) and zero granular temperature.
3. The integral of the contact stress over the plane times the depth is the contact virial
   sum_c f_c (x) b_c (the kernel and the line-integral quadrature both have unit weight).
4. Simple shear v_x = gamma_dot z on random positions: the CG shear rate is gamma_dot in the
   interior, and the granular temperature is the kernel's own smearing of the mean velocity
   profile, gamma_dot^2 <dz^2>_W / 3 (a known artefact of coarse-graining a gradient).
5. Phase-resolved averages of a velocity that depends on the phase: each phase bin recovers its
   velocity, the time average the mean, and the time-averaged temperature the spread of the
   phase velocities about their mean (the definition: averaged sums, then derived).
"""
from __future__ import annotations

import numpy as np
import pytest

from dem_helpers import D_STEEL, G, M_STEEL, R_STEEL, Sim, ball, contact, one_thread, plane, \
    scenario
from vibroflow.calibration.coarse_grain import CoarseGrainer, snapshot_from_state
from vibroflow.calibration.coarse_grain_kernel import kernel_value
from vibroflow.errors import InputError
from vibroflow.scenario.model import Material
from vibroflow.tub.geometry import TubGeometry

D = D_STEEL


# ----------------------------------------------------------------------------------------------
# 1. a bed at rest

NX, NY, NLAYERS = 5, 4, 20           # 400 balls, started on a loose, jittered lattice
SPACING = 1.1 * D
HALF_X = 0.5 * NX * SPACING          # box x in [-HALF_X, HALF_X]
DEPTH_Y = NY * SPACING               # box y in [0, DEPTH_Y]
DT = 2.0e-5                          # <= 1/10 of the contact time (the validator checks)
SETTLE_STEPS = 15000                 # 0.3 s: kinetic energy ~1e-8 J (from 1e-2 J in the fall)
N_SNAPSHOTS, SNAPSHOT_EVERY = 20, 250  # then 0.1 s of snapshots (the bed's slow creep averages)


@pytest.fixture(scope="module")
def bed():
    rng = np.random.default_rng(3)
    balls = []
    for layer in range(NLAYERS):
        for i in range(NX):
            for j in range(NY):
                p = (-HALF_X + (i + 0.5) * SPACING + rng.uniform(-0.04, 0.04) * D,
                     (j + 0.5) * SPACING + rng.uniform(-0.04, 0.04) * D,
                     0.52 * D + layer * SPACING)
                balls.append(ball(p, vel=tuple(rng.normal(0.0, 0.05, 3))))
    materials = {"steel": Material(density=7800.0), "slick": Material(density=7800.0)}
    laws = [contact("steel", "steel", e=0.3, mu=0.3),
            contact("steel", "slick", e=0.3, mu=0.0)]   # frictionless side walls
    walls = [plane((0, 0, 0), (0, 0, 1), "steel"),           # the floor (frictional)
             plane((-HALF_X, 0, 0), (1, 0, 0), "slick"), plane((HALF_X, 0, 0), (-1, 0, 0), "slick"),
             plane((0, 0, 0), (0, 1, 0), "slick"), plane((0, DEPTH_Y, 0), (0, -1, 0), "slick")]
    sim = Sim(scenario(balls, laws, walls=walls, dt=DT, gravity=(0.0, 0.0, -G),
                       materials=materials))
    sim.run(SETTLE_STEPS)
    snaps, floor_load = [], []
    for _ in range(N_SNAPSHOTS):
        with one_thread():
            snaps.append(snapshot_from_state(sim.system, sim.state))
        floor_load.append(sim.state.wall_force[:, 3, 2].sum())
        sim.run(SNAPSHOT_EVERY)
    st = sim.state
    return {"snaps": snaps, "floor_load": np.array(floor_load), "mass": st.mass.copy(),
            "z_top": float(st.pos[:, 2].max()),
            "kinetic_energy": 0.5 * float((st.mass * (st.vel**2).sum(axis=1)).sum())}


def bed_fields(bed, kernel="gaussian", h=D / 4):
    cg = CoarseGrainer(None, h, kernel=kernel, extent=(-HALF_X, HALF_X, 0.0, 0.11),
                       depth=DEPTH_Y, rho_s=7800.0)
    for s in bed["snaps"]:
        cg.add_snapshot(**s)
    return cg, cg.fields()


@pytest.mark.parametrize("kernel", ["gaussian", "lucy"])
def test_bed_at_rest_vertical_stress_is_the_weight_above(bed, kernel):
    area = 2 * HALF_X * DEPTH_Y
    weight = bed["mass"].sum() * G
    assert bed["kinetic_energy"] < 1e-6 * weight * D      # at rest
    # frictionless side walls: the floor carries the whole weight (time average)
    assert bed["floor_load"].mean() == pytest.approx(weight, rel=0.005)

    h = D / 4
    cg, ds = bed_fields(bed, kernel, h)
    z = ds.z.values
    # box-averaged vertical stress and density (the grid covers the kernel's whole support)
    szz = ds.stress.sel(i="z", j="z").sum("x").values * h / (2 * HALF_X)
    rho = ds.density.sum("x").values * h / (2 * HALF_X)
    above = np.zeros_like(rho)             # int_z^top rho dz, trapezoid from the top down
    above[:-1] = np.cumsum((0.5 * (rho[1:] + rho[:-1]) * h)[::-1])[::-1]
    away = (z > 2 * D) & (z < bed["z_top"] - 3 * D)
    assert away.sum() > 30
    np.testing.assert_allclose(szz[away], G * above[away], rtol=0.02)
    # against the discrete count: mass of the balls whose centres are above z
    count = np.array([bed["mass"][s_z > zz].sum() for zz in z
                      for s_z in [bed["snaps"][-1]["positions_tub"][:, 2]]]) * G / area
    mid = (z > 2 * D) & (z < bed["z_top"] - 6 * D)   # 150 balls or more above
    np.testing.assert_allclose(szz[mid], count[mid], rtol=0.02)
    # all the CG mass (the grid reaches below the floor by the kernel's cut-off) is the weight
    assert G * above[0] == pytest.approx(weight / area, rel=0.002)
    # the kinetic part is negligible at rest; the stress is compressive (positive) in the bed
    kzz = ds.kinetic_stress.sel(i="z", j="z").sum("x").values * h / (2 * HALF_X)
    assert np.all(np.abs(kzz[away]) < 1e-4 * szz[away])
    assert np.all(ds.pressure.sum("x").values[away] > 0)


def test_contact_stress_integral_is_the_virial_of_a_settled_bed(bed):
    h = D / 4
    s = bed["snaps"][-1]
    cg = CoarseGrainer(None, h, extent=(-HALF_X, HALF_X, 0.0, 0.11), depth=DEPTH_Y)
    cg.add_snapshot(**s)
    ds = cg.fields()
    integral = ds.contact_stress.sum(("x", "z")).values * h * h * DEPTH_Y
    pos = s["positions_tub"]
    virial = np.einsum("ca,cb->ab", s["contact_force"], s["contact_branch"])
    virial += np.einsum("ca,cb->ab", s["wall_force"], pos[s["wall_particle"]] - s["wall_point"])
    np.testing.assert_allclose(integral, virial, rtol=0.01, atol=0.01 * np.abs(virial).max())


# ----------------------------------------------------------------------------------------------
# synthetic snapshots

def random_bed(rng, n, box):
    lo, hi = np.array(box[0]), np.array(box[1])
    return lo + (hi - lo) * rng.uniform(size=(n, 3))


@pytest.mark.parametrize("kernel", ["gaussian", "lucy"])
def test_uniform_translation(kernel):
    rng = np.random.default_rng(11)
    geo = TubGeometry()
    v0 = np.array([0.31, -0.07, -0.22])
    cg = CoarseGrainer(geo, 0.015, kernel=kernel, n_batches=2)
    for b in range(4):
        pos = random_bed(rng, 3000, ((-0.14, 0.0, 0.01), (0.14, geo.length, 0.2)))
        cg.add_snapshot(pos, np.broadcast_to(v0, pos.shape), R_STEEL, M_STEEL, batch=b // 2)
    ds = cg.fields()
    full = ds.density.values > 0.05 * ds.density.values.max()
    assert full.sum() > 100
    np.testing.assert_allclose(ds.velocity.values[full], np.broadcast_to(v0, (full.sum(), 3)),
                               rtol=1e-12, atol=1e-12)
    vscale = np.linalg.norm(v0) / cg.width     # a gradient's natural size here (1/s)
    assert np.abs(ds.velocity_gradient.values[full]).max() < 1e-9 * vscale
    assert ds.shear_rate.values[full].max() < 1e-9 * vscale
    assert np.abs(ds.temperature.values[full]).max() < 1e-12 * (v0 @ v0)
    rho_max = ds.density.values.max()
    assert np.abs(ds.kinetic_stress.values[full]).max() < 1e-12 * rho_max * (v0 @ v0)
    # identical velocities in both batches: no scatter
    assert np.nanmax(ds.velocity_stderr.values[full]) < 1e-12


def test_contact_stress_integral_is_the_virial_synthetic():
    rng = np.random.default_rng(7)
    geo = TubGeometry(radius=0.05, rim_height=0.1, length=0.02)
    n, c, w = 300, 600, 40
    pos = random_bed(rng, n, ((-0.04, 0.0, 0.01), (0.04, geo.length, 0.09)))
    i, j = rng.integers(0, n, c), rng.integers(0, n, c)
    u = rng.normal(size=(c, 3))
    branch = D * u / np.linalg.norm(u, axis=1)[:, None]
    force = rng.normal(size=(c, 3))
    wi = rng.integers(0, n, w)
    wpoint = pos[wi] - R_STEEL * u[:w] / np.linalg.norm(u[:w], axis=1)[:, None]
    wforce = rng.normal(size=(w, 3))
    virial = force.T @ branch + wforce.T @ (pos[wi] - wpoint)
    # a grid fine against the kernel (h = w / 2), so that the grid sum is the integral
    for kernel, h in (("gaussian", D / 4), ("lucy", D / 4)):
        cg = CoarseGrainer(geo, h, kernel=kernel)
        cg.add_snapshot(pos, np.zeros((n, 3)), R_STEEL, M_STEEL, i, j, force, branch, wi, wforce,
                        wpoint)
        ds = cg.fields()
        integral = ds.contact_stress.sum(("x", "z")).values * h * h * geo.length
        np.testing.assert_allclose(integral, virial, rtol=0.01,
                                   atol=0.01 * np.abs(virial).max())


@pytest.mark.parametrize("kernel", ["gaussian", "lucy"])
def test_simple_shear_rate_and_smearing_temperature(kernel):
    rng = np.random.default_rng(5)
    gamma = 20.0                       # 1/s
    side, depth = 0.12, 4.0            # a deep slab: many balls under each kernel
    n = int(0.6 * side * side * depth / (np.pi / 6 * D**3))
    cg = CoarseGrainer(None, 0.015, kernel=kernel, extent=(-side / 2, side / 2, 0.0, side),
                       depth=depth)
    for _ in range(25):
        pos = random_bed(rng, n, ((-side / 2, 0.0, 0.0), (side / 2, depth, side)))
        vel = np.zeros((n, 3))
        vel[:, 0] = gamma * (pos[:, 2] - 0.05)
        cg.add_snapshot(pos, vel, R_STEEL, M_STEEL)
    ds = cg.fields()
    rc = cg.cutoff_radius + 1e-9
    inner = ds.sel(x=slice(-side / 2 + rc, side / 2 - rc), z=slice(rc, side - rc))
    assert inner.shear_rate.size >= 25
    np.testing.assert_allclose(inner.shear_rate.values, gamma, rtol=0.02)
    assert abs(float(inner.shear_rate.mean()) / gamma - 1) < 0.005
    np.testing.assert_allclose(inner.strain_rate.sel(i="x", j="z").values, gamma / 2, rtol=0.02)
    assert np.abs(inner.velocity.sel(i="z").values).max() == 0.0
    np.testing.assert_allclose(inner.solid_fraction.values, 0.6, rtol=0.05)
    # temperature from the kernel smearing the mean velocity: gamma^2 <dz^2>_W / 3
    x = np.linspace(-0.012, 0.012, 481)
    X, Z = np.meshgrid(x, x, indexing="ij")
    wk = kernel_value(kernel, cg.width, None, X, Z)
    var_z = float((wk * Z * Z).sum() / wk.sum())
    np.testing.assert_allclose(inner.temperature.values, gamma**2 * var_z / 3, rtol=0.05)


def test_phase_resolved_and_time_averaged_velocity_and_temperature():
    rng = np.random.default_rng(2)
    geo = TubGeometry(radius=0.05, rim_height=0.1, length=0.02)
    n_ph = 4
    v_of_phase = np.array([[0.2, 0, 0.1], [0.0, 0, -0.3], [-0.1, 0, 0.2], [0.3, 0, 0.4]])
    cg = CoarseGrainer(geo, 0.01, n_phases=n_ph, n_batches=2)
    pos = random_bed(rng, 2000, ((-0.045, 0.0, 0.005), (0.045, geo.length, 0.09)))
    for cycle in range(4):
        for k in range(n_ph):
            cg.add_snapshot(pos, np.broadcast_to(v_of_phase[k], pos.shape), R_STEEL, M_STEEL,
                            phase_bin=k, batch=cycle // 2)
    ds = cg.fields()
    dp = cg.fields(phase_resolved=True)
    full = ds.density.values > 0.05 * ds.density.values.max()
    np.testing.assert_allclose(ds.velocity.values[full],
                               np.broadcast_to(v_of_phase.mean(0), (full.sum(), 3)), atol=1e-12)
    spread = ((v_of_phase - v_of_phase.mean(0)) ** 2).sum(axis=1).mean() / 3
    np.testing.assert_allclose(ds.temperature.values[full], spread, rtol=1e-10)
    assert dp.velocity.dims[:3] == ("phase", "x", "z")
    np.testing.assert_allclose(dp.phase.values, 2 * np.pi * np.arange(n_ph) / n_ph)
    for k in range(n_ph):
        np.testing.assert_allclose(dp.velocity.values[k][full],
                                   np.broadcast_to(v_of_phase[k], (full.sum(), 3)), atol=1e-12)
        assert np.abs(dp.temperature.values[k][full]).max() < 1e-12
    assert ds.velocity.attrs["units"] == "m s-1" and ds.stress.attrs["units"] == "Pa"


def test_bad_parameters_are_one_line_errors():
    geo = TubGeometry()
    for kwargs, field in (({"kernel": "box"}, "kernel"), ({"cell_size": -1.0}, "cell_size"),
                          ({"kernel": "lucy", "cutoff": 2.0}, "cutoff"),
                          ({"width": 0.0}, "width")):
        with pytest.raises(InputError) as err:
            CoarseGrainer(geo, **{"cell_size": 0.015, **kwargs})
        assert err.value.message.startswith(field + " = ") and "\n" not in err.value.message


def test_snapshot_from_a_vibrating_tub_state_is_in_tub_frame_and_axes():
    """Three balls in a strongly turned, fast-moving tub (theta = 0.29 rad): one on the U wall
    touching a second ball, one on the partition y = 0.  The snapshot's positions, contact
    points, branches and forces must all be in the tub frame / tub axes: a wall force's
    component along (centre - contact point) is the contact's normal force, the partition's
    contact point lies on y = 0 under the ball, the branch is the tub-frame difference."""
    from vibroflow.dem import simulate as S
    from vibroflow.scenario.model import Motion, Scenario
    from vibroflow.tub.motion import pose_np, tub_to_lab

    sc = Scenario(motion=Motion(amplitude_theta=0.3, amplitude_x=0.01, amplitude_z=0.01))
    system = S.make_system(sc)
    step = int(round(0.3 / 47.0 / system.dt))
    pz = {k: float(v) for k, v in pose_np(system.motion, step * system.dt).items()}
    assert abs(pz["theta"]) > 0.25
    R, ang = 0.15, np.radians(40.0)
    p1 = np.array([R * np.sin(ang), 0.03, R - R * np.cos(ang)])
    p1 += (R_STEEL - 2e-5) * np.array([-np.sin(ang), 0.0, np.cos(ang)])   # on the U wall
    p2 = p1 + (D - 3e-5) * np.array([-0.6, 0.0, 0.8])                     # touching ball 0
    p3 = np.array([-0.05, R_STEEL - 1e-5, 0.1])                            # on the partition
    tub = np.array([p1, p2, p3])
    lab, vel = tub.copy(), np.zeros((3, 3))
    for k in range(3):
        lab[k, 0], lab[k, 2] = tub_to_lab(tub[k, 0], tub[k, 2], pz["X"], pz["Z"], pz["theta"],
                                          0.0, -0.10)
    # moving with the tub (its rigid velocity at each centre), so the contacts stay made
    rx, rz = lab[:, 0] - pz["X"], lab[:, 2] - pz["Z"] + 0.10
    vel[:, 0] = pz["Xdot"] - pz["thetadot"] * rz
    vel[:, 2] = pz["Zdot"] + pz["thetadot"] * rx
    with one_thread():
        st = S.init_state(system, lab, vel, np.zeros((3, 3)), np.full(3, R_STEEL),
                          np.full(3, 7800.0), [system.material_names.index("steel")] * 3)
        st.vibrating, st.step = True, step
        S.run_steps(system, st, 1)
        snap = snapshot_from_state(system, st)
    pos = snap["positions_tub"]
    np.testing.assert_allclose(pos, tub, atol=1e-6)
    assert np.abs(snap["velocities_rel_tub"]).max() < 0.1      # the tub moves at ~3 m/s
    assert list(snap["wall_particle"]) == [0, 2]
    n0 = pos[0] - snap["wall_point"][0]
    n0 /= np.linalg.norm(n0)
    assert snap["wall_force"][0] @ n0 == pytest.approx(st.wall_fn[0, 0], rel=1e-9)
    np.testing.assert_allclose(snap["wall_point"][1], [pos[2, 0], 0.0, pos[2, 2]], atol=1e-9)
    assert snap["wall_force"][1][1] > 0                       # the partition pushes towards +y
    assert list(snap["contacts_i"]) == [0] and list(snap["contacts_j"]) == [1]
    np.testing.assert_allclose(snap["contact_branch"][0], pos[0] - pos[1], atol=1e-12)
    assert snap["contact_force"][0] @ snap["contact_branch"][0] > 0   # repulsive


def _batched_bed(rng, n_batches):
    """A grainer of 2 phase bins fed one snapshot a (batch, phase): 2 000 balls all moving at
    (1 + b) v_k; returns it, v, the positions and the cells well inside the bed."""
    geo = TubGeometry(radius=0.05, rim_height=0.1, length=0.02)
    v = np.array([[0.2, 0, 0.1], [0.0, 0, -0.3]])
    cg = CoarseGrainer(geo, 0.01, n_phases=2, n_batches=n_batches)
    pos = random_bed(rng, 2000, ((-0.045, 0.0, 0.005), (0.045, geo.length, 0.09)))
    for b in range(n_batches):
        for k in range(2):
            cg.add_snapshot(pos, np.broadcast_to((1 + b) * v[k], pos.shape), R_STEEL, M_STEEL,
                            phase_bin=k, batch=b)
    full = cg.fields().density.values > 0.05 * cg.fields().density.values.max()
    return cg, v, pos, full


def test_each_batch_keeps_its_own_phase_fields_and_follows_every_snapshot_added():
    """batch_phase_arrays: batch b, phase k holds the velocity its snapshots carry (here
    (1 + b) v_k), and a snapshot added afterwards shows in the next call and in the standard
    errors of fields(phase_resolved=True)."""
    cg, v, pos, full = _batched_bed(np.random.default_rng(5), 2)
    first = cg.batch_phase_arrays(("velocity",))["velocity"]
    for b in range(2):
        for k in range(2):
            np.testing.assert_allclose(first[b, k][full], np.broadcast_to((1 + b) * v[k],
                                                                          (full.sum(), 3)),
                                       atol=1e-12)
    se = cg.fields(phase_resolved=True).velocity_stderr.values
    # two batches a and b: the batch-means error is |a - b| / 2
    np.testing.assert_allclose(se[0][full], np.broadcast_to(np.abs(v[0]) / 2, (full.sum(), 3)),
                               atol=1e-12)
    # batch 1, phase 0 gets an equal-weight snapshot at 5 v_0: its mean becomes (2 + 5) / 2 v_0
    cg.add_snapshot(pos, np.broadcast_to(5 * v[0], pos.shape), R_STEEL, M_STEEL, phase_bin=0,
                    batch=1)
    after = cg.batch_phase_arrays(("velocity",))["velocity"]
    np.testing.assert_allclose(after[1, 0][full], np.broadcast_to(3.5 * v[0], (full.sum(), 3)),
                               atol=1e-12)
    se = cg.fields(phase_resolved=True).velocity_stderr.values
    np.testing.assert_allclose(se[0][full],
                               np.broadcast_to(np.abs(2.5 * v[0]) / 2, (full.sum(), 3)),
                               atol=1e-12)


def test_the_fields_without_one_batch_are_the_other_batches_pooled():
    """leave_one_out_phase_arrays: three batches whose balls all move at (1 + b) v_k in phase
    k. Without batch b the velocity is the mean of the other two's, and the temperature is the
    spread between them, |u_a - u_c|^2 / 12 (T = tr(sigma_k) / (3 rho) of two equal halves at
    u_a and u_c), where each batch alone has none."""
    cg, v, pos, full = _batched_bed(np.random.default_rng(11), 3)
    loo = cg.leave_one_out_phase_arrays(("velocity", "temperature"))
    assert loo["velocity"].shape == (3, 2) + full.shape + (3,)
    for b in range(3):
        a, c = [1 + o for o in range(3) if o != b]
        for k in range(2):
            np.testing.assert_allclose(loo["velocity"][b, k][full],
                                       np.broadcast_to(0.5 * (a + c) * v[k], (full.sum(), 3)),
                                       atol=1e-12)
            T = (c - a) ** 2 * float(v[k] @ v[k]) / 12.0
            np.testing.assert_allclose(loo["temperature"][b, k][full], T, rtol=1e-9)
