"""DEM verification, parts in the bed (vibroflow.dem.parts): single balls on a cylinder, a box
(face, edge, corner) and an STL cylinder against the analytic linear spring-dashpot law, and the
momentum the balls lose to a fixed part against the force the part records.

Expected numbers (test_dem_collisions.py's module docstring has the law): a ball meeting a fixed
surface head-on with the linear law leaves with e times its speed, reversed along the contact
normal; without friction a contact whose normal n stays fixed (a flat face, a straight edge met
with a velocity along the edge) changes only the normal velocity, v' = v - (1 + e) (v . n) n.
The normal of a box's edge is the bisector of its faces' (the ball's centre lies in the edge's
Voronoi region), a corner's the diagonal.  A polygonal STL cylinder of `SECTIONS` facets turns
the contact normal by at most pi / SECTIONS from the round one's, so the rebound velocities of
the two agree within (1 + e) v sin(pi / SECTIONS).

Momentum: velocity Verlet changes the balls' momentum over a step by dt (F_k + F_k+1) / 2, so
over a run that starts and ends with the balls apart the balls' momentum change equals minus dt
times the sum of the loads the part recorded at each step, to round-off.

A tub-fixed part's contact is checked against the tub's rigid motion (a ball carried by it feels
the spring alone), a periodic tub's through the image; the fill against the part's signed
distance; short tub runs (slow) against their own impact records (parts.nc counts each once),
a resumed and an uninterrupted run, and one thread against two.
"""
from __future__ import annotations

import math
import signal
from types import SimpleNamespace

import h5py
import numba
import numpy as np
import pytest
import trimesh

from dem_helpers import (M_STEEL, R_STEEL, Sim, ball, contact, linear_contact_time, one_thread,
                         rel, scenario)
from tests.test_dem_run import _cli, _env, _same_h5, _sets
from vtk_reader import read_vtk
from vibroflow.dem import simulate as S
from vibroflow.dem.blowup import BlowUp
from vibroflow.dem.fill import lattice_fill
from vibroflow.dem.laws import pair_table
from vibroflow.dem.output import PART_UNITS
from vibroflow.dem.parts import EMPTY, SLOTS, ball_parts, parts_record
from vibroflow.dem.run import run_dem
from vibroflow.io.part_vtk import part_surface
from vibroflow.io.parts_file import read_parts as read_parts_nc
from vibroflow.scenario.io import load_scenario
from vibroflow.scenario.model import PartSpec
from vibroflow.scenario.part_shapes import placed_triangles, signed_distance
from vibroflow.tub.motion import lab_to_tub_np, rigid_velocity, tub_to_lab
from vibroflow.tub.parts import pack, parts_of, patch_layout


def parts_of_specs(specs):
    """The Part records of PartSpecs (vibroflow.tub.parts.parts_of reads a scenario's)."""
    return parts_of(SimpleNamespace(parts=specs))

E = 0.85
V = 0.5
SECTIONS = 64
BAR_R = 0.0125
DT = 2e-6


def _sim(part: PartSpec, balls, mu=0.0, e=E) -> Sim:
    sc = scenario(balls, [contact(e=e, mu=mu)], dt=DT, duration=0.05)
    return Sim(sc.model_copy(update={"parts": [part]}))


def _bounce(part: PartSpec, start, vel, mu=0.0, e=E, t=0.004) -> np.ndarray:
    """The ball's velocity (m/s) after it has hit the part and left it."""
    sim = _sim(part, [ball(start, vel=vel)], mu=mu, e=e)
    sim.run(int(round(t / DT)))
    assert not sim.state.part_key[0, 0].max() >= -1, "the ball is still touching the part"
    return sim.state.vel[0].copy()


def _bar(**kw) -> PartSpec:
    return PartSpec(name="bar", shape="cylinder", center=(0.0, 0.0, 0.0), radius=BAR_R,
                    frame="lab", **kw)


def _box() -> PartSpec:
    return PartSpec(name="block", shape="box", center=(0.0, 0.0, 0.0), size=(0.02, 0.02, 0.02),
                    frame="lab")


GAP = 1e-4  # m between the ball and the part at the start


def test_ball_on_cylinder_top_rebounds_with_restitution():
    v = _bounce(_bar(), (0.0, 0.0, BAR_R + R_STEEL + GAP), (0.0, 0.0, -V))
    assert rel(v[2], E * V) < 0.01
    assert abs(v[0]) < 1e-12 and abs(v[1]) < 1e-12


def test_ball_on_cylinder_off_centre_leaves_along_the_mirrored_normal():
    # frictionless: only the normal velocity changes; the normal at the contact is radial
    a = math.radians(60.0)
    n = np.array([math.cos(a), 0.0, math.sin(a)])
    start = (BAR_R + R_STEEL + GAP) * n + np.array([0.0, 0.0, 0.0])
    vel = np.array([0.0, 0.0, -V])
    expect = vel - (1.0 + E) * (vel @ n) * n
    v = _bounce(_bar(), start, vel)
    # the ball slides along the curved surface while in contact, so the normal turns by
    # dphi = v_t t_c / (R + r); the impulse (1 + e) |v_n| m is off the fixed-normal answer by
    # about its size times dphi (twice that allowed)
    vn, vt = abs(vel @ n), math.sqrt(V * V - (vel @ n) ** 2)
    t_c = linear_contact_time(1.0e5, M_STEEL, E)
    dphi = vt * t_c / (BAR_R + R_STEEL)
    assert np.linalg.norm(v - expect) < 2.0 * (1.0 + E) * vn * dphi
    assert rel(v @ n, E * vn) < 0.02


def test_a_ball_pressing_on_a_cylinder_off_its_centre_line_gives_the_hand_torque():
    """A ball at rest overlapping the bar by delta = 10 um at 30 deg around its axis and
    y0 = 5 mm along it, frictionless: the part feels F = -k_n delta n at the surface point
    y0 e_y + R n, so its torque about its centre is y0 e_y x F = y0 k_n delta (-n_z, 0, n_x)
    (the radial part R n x F vanishes); one step of 2 us moves the ball by nanometres, and its
    damping force (c v ~ 2 mN against 1 N) is inside the 1 % allowed."""
    a, y0, delta, k_n = math.radians(30.0), 0.005, 1.0e-5, 1.0e5
    n = np.array([math.cos(a), 0.0, math.sin(a)])
    start = (BAR_R + R_STEEL - delta) * n + np.array([0.0, y0, 0.0])
    sim = _sim(_bar(), [ball(start)])
    sim.run(1)
    load = S.part_loads_now(sim.system, sim.state)[0]
    force = -k_n * delta * n
    torque = y0 * k_n * delta * np.array([-n[2], 0.0, n[0]])
    assert np.allclose(load[:3], force, rtol=0.0, atol=0.01 * k_n * delta)
    assert np.allclose(load[3:], torque, rtol=0.0, atol=0.01 * y0 * k_n * delta)
    assert abs(load[4]) < 1e-12


@pytest.mark.parametrize("where", ["face", "edge", "corner"])
def test_ball_on_box_rebounds_along_the_feature_normal(where):
    h = 0.01
    feature = {"face": np.array([0.0, 0.0, h]), "edge": np.array([h, 0.0, h]),
               "corner": np.array([h, h, h])}[where]
    n = {"face": np.array([0.0, 0.0, 1.0]), "edge": np.array([1.0, 0.0, 1.0]) / math.sqrt(2),
         "corner": np.ones(3) / math.sqrt(3)}[where]
    start = feature + (R_STEEL + GAP) * n
    v = _bounce(_box(), start, -V * n)
    assert rel(v @ n, E * V) < 0.01
    assert np.linalg.norm(v - (v @ n) * n) < 1e-9


def test_ball_sliding_along_a_box_edge_keeps_its_edge_velocity():
    h = 0.01
    n = np.array([1.0, 0.0, 1.0]) / math.sqrt(2)
    start = np.array([h, 0.0, h]) + (R_STEEL + GAP) * n
    vel = -V * n + np.array([0.0, 0.3, 0.0])
    v = _bounce(_box(), start, vel)
    expect = vel - (1.0 + E) * (vel @ n) * n
    assert np.linalg.norm(v - expect) < 0.01 * V


def _stl_cylinder(tmp_path) -> PartSpec:
    mesh = trimesh.creation.cylinder(radius=BAR_R, height=0.05, sections=SECTIONS)
    mesh.apply_transform(trimesh.transformations.rotation_matrix(math.pi / 2, [1, 0, 0]))
    path = tmp_path / "bar.stl"
    mesh.export(path)
    return PartSpec(name="bar", shape="stl", file=str(path), center=(0.0, 0.0, 0.0),
                    frame="lab")


@pytest.mark.parametrize("angle_deg", [90.0, 73.0, 40.0])
def test_stl_cylinder_agrees_with_the_round_one_within_its_facets(tmp_path, angle_deg):
    a = math.radians(angle_deg)
    n = np.array([math.cos(a), 0.0, math.sin(a)])
    start = (BAR_R + R_STEEL + GAP) * n
    vel = (0.0, 0.0, -V)
    round_v = _bounce(_bar(), start, vel)
    stl_v = _bounce(_stl_cylinder(tmp_path), start, vel)
    bound = (1.0 + E) * V * math.sin(math.pi / SECTIONS)
    assert np.linalg.norm(stl_v - round_v) < bound
    assert rel(np.linalg.norm(stl_v), np.linalg.norm(round_v)) < 0.02


def test_stl_edge_gives_one_contact_not_one_per_triangle(tmp_path):
    # a ball dropped onto a facet edge of the polygonal cylinder (its top edge at 90 degrees
    # when SECTIONS is a multiple of 4 with a vertex there, or the face next to it): whatever
    # it meets, a head-on drop on the top rebounds with e, not (1 + e) more from a double contact
    part = _stl_cylinder(tmp_path)
    top = placed_triangles(part).reshape(-1, 3)
    z_top = float(top[:, 2].max())
    x_at = float(top[np.argmax(top[:, 2]), 0])  # an edge along y at the very top
    v = _bounce(part, (x_at, 0.0, z_top + R_STEEL + GAP), (0.0, 0.0, -V))
    assert rel(np.linalg.norm(v), E * V) < 0.01


def test_force_on_a_fixed_part_equals_the_momentum_the_balls_lose():
    # six balls from all sides onto the box's faces, edges and corners, with friction
    rng = np.random.default_rng(4)
    balls = []
    for n in rng.normal(size=(6, 3)):
        n /= np.linalg.norm(n)
        balls.append(ball(0.022 * n, vel=tuple(-1.0 * n + 0.2 * rng.normal(size=3))))
    sim = _sim(_box(), balls, mu=0.3)
    system, state = sim.system, sim.state
    assert np.all(np.abs(S.part_loads_now(system, state)) == 0.0)
    p0 = sim.momentum()
    impulse = np.zeros(3)
    touched = 0
    with one_thread():
        for _ in range(int(round(0.01 / DT))):
            S.run_steps(system, state, 1)
            load = S.part_loads_now(system, state)
            impulse += load[0, :3] * DT
            touched += bool(np.any(load[0] != 0.0))
    assert touched > 20  # balls did hit the box
    assert not np.any(state.part_key >= -1)  # and have left it
    dp = sim.momentum() - p0
    assert np.linalg.norm(dp) > 1e-4  # a real change of momentum, ...
    assert np.allclose(dp, -impulse, rtol=1e-9, atol=1e-15)  # ... all of it the part's


# ---------------------------------------------------------------------------------------------
# A tub run with a part: the fill keeps clear of it, and parts.nc counts every recorded impact

BAR_SET = ["fill.count=400", "tub.length=0.01905", "parts.0.center=[0.0, 0.0, 0.03]",
           "run.duration=0.2", "run.average_last=0.1", "fill.settle_time=0.05",
           "fill.max_settle_time=0.05", "run.series_every=200"]


def test_explicit_run_counts_the_balls_dropped_on_each_face_of_a_box(tmp_path):
    """Explicit mode (no tub, no gravity), a lab-fixed 20 mm box: three balls sent at its +z
    face, two at +x, one at -x, one past it; each hits once and leaves, so parts.nc's impact
    count per face (rate x area x window) is 1, 2, 0, 0, 0, 3 (faces -x, +x, -y, +y, -z, +z)
    and dem.h5 keeps no ball-ball or wall impacts (an explicit run records its parts' alone)."""
    top = 0.01 + R_STEEL + 0.001
    balls = [ball((-0.005, -0.005, top), vel=(0.0, 0.0, -0.5)),
             ball((0.005, 0.005, top), vel=(0.0, 0.0, -0.5)),
             ball((0.005, -0.005, top), vel=(0.0, 0.0, -0.5)),
             ball((top, 0.0, -0.005), vel=(-0.5, 0.0, 0.0)),
             ball((top, 0.0, 0.005), vel=(-0.5, 0.0, 0.0)),
             ball((-top, 0.0, 0.0), vel=(0.5, 0.0, 0.0)),
             ball((0.03, 0.03, 0.0), vel=(-0.5, 0.0, 0.0))]
    sc = scenario(balls, [contact()], dt=DT, duration=0.01)
    sc = sc.model_copy(update={"parts": [_box()]})
    summary = run_dem(sc, tmp_path / "run", progress=False)
    ds = read_parts_nc(tmp_path / "run" / "parts.nc")
    window = ds.attrs["window_s"]
    assert window == pytest.approx(0.01)
    counts = (ds["impact_rate_per_area"][0] * ds["patch_area_m2"][0]).values[:6] * window
    assert counts == pytest.approx([1, 2, 0, 0, 0, 3], abs=1e-9)
    assert summary["parts"][0]["impacts_per_s"] == pytest.approx(6 / window)
    vn = ds["normal_speed_mean"][0].values
    assert vn[[0, 1, 5]] == pytest.approx([0.5, 0.5, 0.5], rel=1e-6)
    with h5py.File(tmp_path / "run" / "dem.h5", "r") as f:
        assert f["part_impacts/time"].shape[0] == 6
        assert "impacts" not in f or f["impacts/time"].shape[0] == 0


def test_the_fill_keeps_clear_of_the_parts():
    sc = load_scenario("tub47-bar", BAR_SET)
    pos = lattice_fill(sc, np.random.default_rng(sc.run.seed))
    r = 0.5 * sc.fill.diameter
    gap = signed_distance(sc.parts[0], pos)
    assert pos.shape[0] == sc.fill.count
    assert gap.min() >= r  # no ball inside or overlapping the bar
    assert gap.min() < 3.0 * r  # and the bed reaches it (the bar is in the bed)


@pytest.mark.slow
def test_tub_run_with_a_bar_writes_parts_nc(tmp_path, monkeypatch):
    monkeypatch.setenv("VIBROFLOW_CACHE", str(tmp_path / "cache"))
    sc = load_scenario("tub47-bar", BAR_SET)
    out = tmp_path / "run"
    summary = run_dem(sc, out, vtk=True, progress=False)
    ds = read_parts_nc(out / "parts.nc")
    with h5py.File(out / "dem.h5", "r") as f:
        for key, (units, _) in PART_UNITS.items():
            assert f[key].attrs["units"] == units
        t = f["part_impacts/time"][()]
        part = f["part_impacts/part"][()]
        vn = f["part_impacts/normal_speed"][()]
    t0 = sc.run.duration - sc.run.average_last
    window = ds.attrs["window_s"]
    in_window = (t >= t0 - 1e-12) & (t < t0 + window) & (part == 0)
    assert in_window.sum() > 50  # the bar is hit
    counted = float(np.nansum(ds["impact_rate_per_area"][0] * ds["patch_area_m2"][0]) * window)
    assert counted == pytest.approx(in_window.sum(), rel=1e-9)
    assert float(np.nanmax(ds["normal_speed_p95"][0])) <= float(vn[in_window].max())
    assert ds.attrs["method"] == "dem" and ds.attrs["batches"] == sc.run.batches
    assert np.isfinite(ds["force"][0]).all() and np.isfinite(ds["force_stderr"][0]).all()
    assert np.isfinite(ds["torque"][0]).all() and ds["torque"].attrs["units"] == "N m"
    assert summary["parts"][0]["name"] == "bar"
    assert summary["parts"][0]["impacts_per_s"] == pytest.approx(in_window.sum() / window)
    with h5py.File(out / "dem.h5", "r") as f:
        last = f["snapshots/position"][-1]
        X, Z, theta = f["snapshots/tub_pose"][-1][:3]
    # no ball's centre near the inside of the bar at the end (it moves with the tub: the
    # snapshot's lab positions taken to the tub frame); contact overlaps are below 10 % of r
    tub = lab_to_tub_np(last.astype(float), X, Z, theta, tuple(sc.motion.pivot))
    r = 0.5 * sc.fill.diameter
    assert signed_distance(sc.parts[0], tub).min() > 0.9 * r
    # ParaView: the bar's surface carries parts.nc's map, patch by patch
    surface = read_vtk(out / "vtk" / "part_bar.vtu")["CellData"]
    rate = ds["impact_rate_per_area"][0].values
    assert np.array_equal(surface["impact_rate_per_area_1_per_m2_s"], rate[surface["patch"]],
                          equal_nan=True)


@pytest.mark.parametrize("shape", ["cylinder", "box", "sphere"])
def test_part_surface_covers_each_patch_with_its_area(shape):
    # the ParaView triangulation: every patch's triangles add up to the patch's area (a
    # cylinder's and a sphere's to within the polygon's chord error)
    kw = {"cylinder": dict(radius=0.0125), "sphere": dict(radius=0.02),
          "box": dict(size=(0.02, 0.03, 0.04), angle_y=0.3)}[shape]
    spec = PartSpec(name="p", shape=shape, center=(0.05, 0.01, 0.1), frame="tub", **kw)
    part = parts_of_specs([spec])[0]
    tri, patch = part_surface(part, 0.02)
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    by_patch = np.bincount(patch, weights=area)
    _, expect = patch_layout(part, 0.02)
    assert by_patch == pytest.approx(expect, rel=0.01)


@pytest.mark.slow
def test_a_tub_fixed_part_moves_with_the_tub():
    # a ball carried rigidly by the moving, turning tub, pressed delta into a tub-fixed bar:
    # no relative velocity at the contact, so the force is the spring's alone, k_n delta along
    # the bar's normal turned by the tub's angle; a lab-fixed bar at the same place feels the
    # tub's velocity as an approach and damps it
    k_n, delta = 1.0e5, 2e-5
    X, Z, th, Xd, Zd, thd, pvx, pvz = 1e-3, 1.5e-3, 4e-3, 0.3, -0.2, 1.5, 0.0, -0.1
    pose = np.array([X, Z, th, Xd, Zd, thd, pvx, pvz])
    a = math.radians(70.0)
    n_tub = np.array([math.cos(a), 0.0, math.sin(a)])
    centre = np.array([0.05, 0.0, 0.1])
    p_tub = centre + (BAR_R + R_STEEL - delta) * n_tub
    lx, lz = tub_to_lab(p_tub[0], p_tub[2], X, Z, th, pvx, pvz)
    vx, vz = rigid_velocity(lx, lz, X, Z, Xd, Zd, thd, pvx, pvz)
    n_lab = np.array([math.cos(th) * n_tub[0] - math.sin(th) * n_tub[2], 0.0,
                      math.sin(th) * n_tub[0] + math.cos(th) * n_tub[2]])
    vel = np.array([[vx, 0.0, vz]])
    omg = np.array([[0.0, -thd, 0.0]])
    table = pair_table(scenario([ball((0, 0, 0))], [contact(k_n=k_n, e=E, mu=0.3)]))
    for frame in ("tub", "lab"):
        spec = PartSpec(name="bar", shape="cylinder", center=tuple(centre), radius=BAR_R,
                        frame=frame)
        packed = pack(parts_of_specs([spec]))
        rec = parts_record(packed, np.zeros(1, np.int64), np.zeros((1, 1, SLOTS, 6)),
                           np.full((1, 1, SLOTS), EMPTY, np.int64), 1)
        # dt_hist 0: the tangential spring is not advanced (the ball's contact point is taken
        # at r from its centre, as at the walls, which leaves a slip theta' delta)
        out = ball_parts(0, 0, 0.0, 0.0, False, lx, 0.0, lz, R_STEEL, M_STEEL, vel, omg, 0,
                         table, pose, math.cos(th), math.sin(th), 0.0, rec)
        force = np.array(out[:3])
        if frame == "tub":
            assert force == pytest.approx(k_n * delta * n_lab, rel=1e-9, abs=1e-12)
            assert out[6] == pytest.approx(delta, rel=1e-9)
            # the part's load: the opposite force, in tub axes
            assert rec.ncontrib[0, 0] == 1
            assert rec.contrib[0, 0, 0, :3] == pytest.approx(-k_n * delta * n_tub, rel=1e-9,
                                                       abs=1e-12)
        else:
            assert np.linalg.norm(force - k_n * delta * n_lab) > 1e-3 * k_n * delta


def test_a_blow_up_on_a_part_names_it():
    # a ball at 25 m/s into a soft box: the overlap passes run.max_overlap (0.25 d)
    h = 0.01
    sc = scenario([ball((0.0, 0.0, h + R_STEEL + GAP), vel=(0.0, 0.0, -25.0))],
                  [contact(e=E)], dt=DT, duration=0.01)
    sim = Sim(sc.model_copy(update={"parts": [_box()]}))
    with pytest.raises(BlowUp, match="part 'block'"):
        sim.run(2000)


@pytest.mark.slow
def test_killed_and_resumed_run_with_a_part_equals_uninterrupted(tmp_path):
    env = _env(tmp_path)
    small = BAR_SET[:2] + ["parts.0.center=[0.0,0.0,0.03]"] + BAR_SET[3:]
    ref = tmp_path / "ref"
    r = _cli("dem", "tub47-bar", "--out", str(ref), *_sets(small), env=env)
    assert r.returncode == 0, r.stderr
    assert "part bar (cylinder, tub frame):" in r.stdout
    out = tmp_path / "killed"
    sets = _sets(small + ["run.checkpoint_every=0.05"])
    r = _cli("dem", "tub47-bar", "--out", str(out), *sets,
             env=dict(env, VIBROFLOW_FAULT_KILL_AFTER_CHECKPOINT="1"))
    assert r.returncode == -signal.SIGKILL, (r.returncode, r.stderr)
    r = _cli("dem", "tub47-bar", "--out", str(out), "--resume", *sets, env=env)
    assert r.returncode == 0, r.stderr
    _same_h5(ref / "dem.h5", out / "dem.h5")
    a, b = read_parts_nc(ref / "parts.nc"), read_parts_nc(out / "parts.nc")
    assert a.equals(b)


def test_a_periodic_tub_touches_a_part_through_its_image():
    # a box spanning y in [0, 0.01] in a periodic tub of length L: a ball at y = L - 0.001 lies
    # 0.001 m beyond the box's y = 0 face through the periodic boundary, and overlaps it by
    # r - 0.001 (the same as a ball at y = -0.001)
    length = 0.03
    spec = PartSpec(name="block", shape="box", center=(0.0, 0.005, 0.05),
                    size=(0.02, 0.01, 0.02), frame="lab")
    packed = pack(parts_of_specs([spec]))
    table = pair_table(scenario([ball((0, 0, 0))], [contact(e=E)]))
    pose = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -0.1])
    forces = []
    for y, periodic in ((length - 0.001, length), (-0.001, 0.0), (length - 0.001, 0.0)):
        rec = parts_record(packed, np.zeros(1, np.int64), np.zeros((1, 1, SLOTS, 6)),
                           np.full((1, 1, SLOTS), EMPTY, np.int64), 1)
        out = ball_parts(0, 0, 0.0, 0.0, False, 0.0, y, 0.05, R_STEEL, M_STEEL,
                         np.zeros((1, 3)), np.zeros((1, 3)), 0, table, pose, 1.0, 0.0,
                         periodic, rec)
        forces.append(np.array(out[:3]))
    k_n = 1.0e5
    assert forces[1] == pytest.approx([0.0, -k_n * (R_STEEL - 0.001), 0.0], abs=1e-12)
    assert forces[0] == pytest.approx(forces[1], rel=1e-9)
    assert not np.any(forces[2])  # without the periodic length: far from the box


def test_a_ball_over_the_diagonal_of_a_flat_stl_face_feels_one_contact(tmp_path):
    # a box's STL (trimesh: each face two triangles); a ball dropped head-on onto the top
    # face's diagonal, where both triangles' nearest points coincide, rebounds with e as on
    # the analytic box's face, not from two contacts
    mesh = trimesh.creation.box(extents=(0.02, 0.02, 0.02))
    path = tmp_path / "box.stl"
    mesh.export(path)
    spec = PartSpec(name="block", shape="stl", file=str(path), center=(0.0, 0.0, 0.0),
                    frame="lab")
    v = _bounce(spec, (0.0, 0.0, 0.01 + R_STEEL + GAP), (0.0, 0.0, -V))
    assert rel(v[2], E * V) < 0.01 and abs(v[0]) < 1e-12 and abs(v[1]) < 1e-12


@pytest.mark.slow
def test_same_part_numbers_on_one_thread_and_on_two(tmp_path):
    # the part loads are summed per block of the balls by id, ball by id, the blocks in block
    # order: the same bits whatever the threads (1600 balls: above the one-thread size)
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("numba has a single thread here")
    sets = ["fill.count=1600", "tub.length=0.01905", "parts.0.center=[0.0,0.0,0.05]",
            "fill.settle_time=0.05", "fill.max_settle_time=0.05", "run.duration=0.15",
            "run.average_last=0.1"]
    outs = []
    for threads in (1, 2):
        out = tmp_path / f"threads{threads}"
        r = _cli("dem", "tub47-bar", "--out", str(out), *_sets(sets),
                 env=dict(_env(tmp_path), NUMBA_NUM_THREADS=str(threads)))
        assert r.returncode == 0, r.stderr
        outs.append(out)
    _same_h5(outs[0] / "dem.h5", outs[1] / "dem.h5")
    assert read_parts_nc(outs[0] / "parts.nc").equals(read_parts_nc(outs[1] / "parts.nc"))
