"""The parts of [[parts]] in the LIGGGHTS round trip (vibroflow.liggghts.part_meshes, part_deck,
part_contacts): the meshes lie on the parts with outward normals, the deck carries each part
(its mesh, atom type, contact law, motion), a name that could change the deck is refused, and
the import turns a hand-made dump of a known contact into the known impact and load, on the
deck's own mesh, with LIGGGHTS' CDT rolling moment in the load.
"""
from __future__ import annotations

import math
import re
import subprocess
import sys

import h5py
import numpy as np
import pytest

from tests.cli_helpers import one_line_error

from vibroflow import liggghts as LG
from vibroflow.errors import InputError
from vibroflow.io.parts_file import read_parts
from vibroflow.liggghts.dumps import DumpSnapshot
from vibroflow.liggghts.part_contacts import PartGeometry, part_load_rows, part_rolling
from vibroflow.liggghts.part_deck import PART_DUMP
from vibroflow.liggghts.part_meshes import part_triangles
from vibroflow.liggghts.stl import facet_normals, write_stl
from vibroflow.scenario.io import load_scenario
from vibroflow.tub.parts import Part, closest_on_triangle, parts_of

R_BAR = 0.0125        # m, tub47-bar's bar
R_BALL = 0.003175     # m
BAR = (0.05, 0.0, 0.10)
N0 = 7000             # the step at which the vibration starts


def bar_case(*sets: str):
    """tub47-bar 19 mm long with 2 balls, 0.1 s of vibration (window from step 1000)."""
    return load_scenario("tub47-bar", ["tub.length=0.01905", "fill.count=2", "run.duration=0.1",
                                       "run.average_last=0.09", "run.batches=2", *sets])


# ----------------------------------------------------------------------------------------------
# Meshes

def test_the_bar_mesh_lies_on_the_bar_with_outward_normals():
    part = Part("bar", "cylinder", BAR, "steel", radius=R_BAR)
    tri = part_triangles(part, 0.01905)
    v = tri.reshape(-1, 3)
    assert np.allclose(np.hypot(v[:, 0] - BAR[0], v[:, 2] - BAR[2]), R_BAR, rtol=0, atol=1e-15)
    assert v[:, 1].min() == 0.0 and v[:, 1].max() == 0.01905
    centroid = tri.mean(axis=1)
    out = centroid - np.array(BAR)
    out[:, 1] = 0.0
    assert np.all(np.einsum("ij,ij->i", facet_normals(tri), out) > 0)
    # the U's sagitta rule on the whole circle: 36 chords, r (1 - cos 5 deg) = 0.0476 mm
    angles = np.unique(np.round(np.degrees(np.arctan2(v[:, 2] - BAR[2], v[:, 0] - BAR[0])), 9))
    assert angles.size == 36 and np.allclose(np.diff(angles), 10.0)
    assert R_BAR * (1 - math.cos(math.radians(5))) < 5e-5


def test_box_and_sphere_meshes_enclose_their_volume_with_outward_normals():
    box = Part("b", "box", (0.0, 0.01, 0.1), "steel", half_size=(0.02, 0.01, 0.005),
               angle_y=0.3)
    sphere = Part("s", "sphere", (0.0, 0.01, 0.1), "steel", radius=0.01)
    # the sphere's vertices lie on it, its facets within two chord sagittas (0.1 mm) of it: its
    # volume between that of the sphere 0.1 mm smaller and its own
    inner = 4 / 3 * math.pi * (0.01 - 1e-4) ** 3
    full = 4 / 3 * math.pi * 0.01**3
    for part, volume, tol in ((box, 0.04 * 0.02 * 0.01, 1e-12),
                              (sphere, 0.5 * (inner + full), 0.5 * (full - inner) / full)):
        tri = part_triangles(part, 0.02)
        # divergence theorem: sum over facets of (centroid . n) area / 3 is the enclosed volume,
        # positive only when every normal points out
        n = facet_normals(tri)
        area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]),
                                    axis=1)
        c = tri.mean(axis=1) - np.array(part.center)
        enclosed = float(np.sum(np.einsum("ij,ij->i", c, n) * area) / 3.0)
        assert enclosed == pytest.approx(volume, rel=tol)
        assert np.all(np.einsum("ij,ij->i", c, n) > 0)
    v = part_triangles(sphere, 0.02).reshape(-1, 3) - np.array(sphere.center)
    assert np.allclose(np.linalg.norm(v, axis=1), 0.01, rtol=0, atol=1e-15)


# ----------------------------------------------------------------------------------------------
# The deck

def test_the_deck_carries_the_bar_with_its_type_law_and_motion(tmp_path):
    info = LG.export_deck(bar_case(), tmp_path / "deck")
    deck = (tmp_path / "deck" / "in.tub").read_text()
    assert (tmp_path / "deck" / "part_bar.stl").is_file()
    assert "create_box      4 domain" in deck
    # LIGGGHTS' default curvature: the convex bar's creases are active edges (part_deck.py)
    assert "fix pmesh1 all mesh/surface file part_bar.stl type 4\n" in deck
    assert re.search(r"fix walls all wall/gran .* mesh n_meshes 3 meshes tub parts pmesh1 ", deck)
    assert "fix move_pmesh1_t all move/mesh mesh pmesh1 linear/variable v_vX v_vY v_vZ" in deck
    assert "fix move_pmesh1_r all move/mesh mesh pmesh1 rotate/variable origin 0 0. -0.1" in deck
    # type 4 is steel: Young's modulus, and the ball-bar pair is tub47-bar's steel-steel law
    # with a wall's m_eff = m: gamma_n = 2 zeta sqrt(m k_n), zeta = -ln e / sqrt(pi^2 + ln^2 e)
    assert "peratomtype 2e+11 25000000 6.3e+10 2e+11\n" in deck
    m = 7800.0 * 4.0 / 3.0 * math.pi * R_BALL**3
    zeta = -math.log(0.85) / math.sqrt(math.pi**2 + math.log(0.85) ** 2)
    gn = 2.0 * zeta * math.sqrt(m * 1.0e5)
    kn = re.search(r"fix kn all property/global kn peratomtypepair 4 (.*)\n", deck).group(1)
    g = re.search(r"gamman_abs peratomtypepair 4 (.*)\n", deck).group(1)
    kn, g = (np.array(x.split(), float).reshape(4, 4) for x in (kn, g))
    assert kn[0, 3] == kn[3, 0] == 1.0e5
    assert g[0, 3] == pytest.approx(gn, rel=1e-9) and g[3, 0] == g[0, 3]
    assert info.tables.friction[0, 3] == 0.2
    # the balls near the bar every step from the step before the window (1000 - 1)
    # the fill leaves the bar out: its circle widened by r + skin/2
    margin = R_BALL + 0.5 * 0.3 * 2 * R_BALL
    assert (f"region pout1 cylinder y 0.05 0.1 {R_BAR + margin:.10g} INF INF side out units box"
            in deck)
    assert "region ins intersect 3 uin zcut pout1\n" in deck
    assert "variable pfirst equal ${n0}+999\n" in deck
    assert "dump_modify dpart every v_pstep region pnear sort id" in deck


def test_a_lab_fixed_part_does_not_move(tmp_path):
    LG.export_deck(bar_case("parts.0.frame=lab"), tmp_path / "deck")
    deck = (tmp_path / "deck" / "in.tub").read_text()
    assert "fix pmesh1 all mesh/surface" in deck and "move_pmesh1" not in deck
    assert "fix move_tub_t all move/mesh" in deck


@pytest.mark.parametrize("field", ["name", "material"])
def test_a_part_name_that_could_change_the_deck_is_refused(tmp_path, field):
    s = bar_case()
    bad = s.model_copy(update={"parts": [s.parts[0].model_copy(
        update={field: "bar\nshell rm -rf /"})]})  # model_copy does not validate
    with pytest.raises(InputError) as err:
        LG.export_deck(bad, tmp_path / "deck")
    assert err.value.message.startswith(f"parts.0.{field} = 'bar\\nshell rm -rf /': must be 1 to "
                                        "64 characters")
    assert not (tmp_path / "deck").exists()


@pytest.mark.slow  # a fresh interpreter imports vibroflow: about 10 s
def test_cli_refuses_a_part_name_with_a_space(tmp_path):
    """The scenario's own check refuses it first: one line, exit 2, nothing written."""
    r = subprocess.run([sys.executable, "-m", "vibroflow.cli", "export", "liggghts", "tub47-bar",
                        tmp_path / "deck", "--set", "parts.0.name=bar x"],
                       capture_output=True, text=True, timeout=120)
    line = one_line_error(r)
    assert re.match(r"error: parts(\.0)?\.name = 'bar x': must be", line), line
    assert not (tmp_path / "deck").exists()


# ----------------------------------------------------------------------------------------------
# The import: a known contact -> a known impact and load

def _dump(steps, rows_of, cols) -> str:
    out = []
    for k, step in enumerate(steps):
        rows = rows_of(k, step)
        out += ["ITEM: TIMESTEP", str(step), "ITEM: NUMBER OF ATOMS", str(len(rows)),
                "ITEM: BOX BOUNDS ff ff ff", "-0.3 0.3", "-0.03 0.05", "-0.1 0.6",
                f"ITEM: ATOMS {cols}", *rows]
    return "\n".join(out) + "\n"


def _ball(i, pos, vel=(0.0, 0.0, 0.0), omg=(0.0, 0.0, 0.0)) -> str:
    return f"{i} " + " ".join(f"{v:.10g}" for v in (*pos, *vel, *omg, R_BALL))


def _still_bar_deck(tmp_path):
    """The bar case held still in the lab (the relative velocity is the ball's), its deck
    exported under tmp_path/deck with the vibration starting at step N0: (scenario, the
    deck's post folder, the steps of its snapshots)."""
    s = bar_case("parts.0.frame=lab")
    info = LG.export_deck(s, tmp_path / "deck")
    post = tmp_path / "deck" / "post"
    (post / LG.START_FILE).write_text(f"{N0}\n")
    return s, post, [N0 + int(k) for k in info.dump_steps]


def _on_bar(angle_deg: float, gap: float, y: float = 0.01):
    """A ball centre at `angle_deg` around the bar (from +x towards +z), its surface `gap` (m)
    from the bar's analytic surface."""
    a = math.radians(angle_deg)
    d = R_BAR + R_BALL + gap
    return (BAR[0] + d * math.cos(a), y, BAR[2] + d * math.sin(a))


def test_a_known_contact_is_a_known_impact_and_load(tmp_path):
    s, post, snaps = _still_bar_deck(tmp_path)
    cols = "id type x y z vx vy vz omegax omegay omegaz radius"
    (post / LG.BALL_DUMP).write_text(_dump(snaps, lambda k, st: [
        _ball(5, (0.0, 0.01, 0.02)).replace("5 ", "5 1 ", 1),
        _ball(8, _on_bar(90.0, -1e-6)).replace("8 ", "8 1 ", 1)], cols))
    # ball 5 comes down onto the bar at 95 degrees (mid-facet: the mesh lies r (1 - cos 5 deg) =
    # 0.048 mm inside the circle) with 0.5 m/s along -n and 0.2 m/s along the surface; ball 8
    # rests on the top from before the window (no impact)
    a = math.radians(95.0)
    n = np.array([math.cos(a), 0.0, math.sin(a)])
    tangent = np.array([-math.sin(a), 0.0, math.cos(a)])
    v = -0.5 * n + 0.2 * tangent
    omega = (0.0, 30.0, 0.0)   # r omega x n adds r * 30 along +x: its tangential part counts

    def part_rows(k, step):
        gap = 1e-4 if step < N0 + 1001 else -1e-4
        return [_ball(5, _on_bar(95.0, gap), v, omega), _ball(8, _on_bar(90.0, -1e-6))]

    part_steps = list(range(N0 + 999, N0 + 1004))
    (post / PART_DUMP).write_text(_dump(part_steps, part_rows, cols.replace(" type", "")))
    # the wall dump at the first snapshot: the bar (mesh 2) pushes ball 8 with F_n (0, 0, 2) N
    # and F_t (0.1, 0, 0) N
    wall = ["ITEM: TIMESTEP", str(snaps[0]), "ITEM: NUMBER OF ENTRIES", "1",
            "ITEM: ENTRIES c_wallc[1] c_wallc[2] c_wallc[3] c_wallc[4] c_wallc[5] c_wallc[6] "
            "c_wallc[7] c_wallc[8] c_wallc[9]", "2 7 8 0 0 2 0.1 0 0"]
    (post / LG.WALL_DUMP).write_text("\n".join(wall) + "\n")
    summary = LG.import_run(post, None, tmp_path / "out")

    with h5py.File(tmp_path / "out" / "dem.h5") as f:
        imp = {k: f["part_impacts"][k][()] for k in f["part_impacts"]}
        load = {k: f["part_loads"][k][()] for k in f["part_loads"]}
    assert imp["ball"].tolist() == [0]            # id 5 is the first of the sorted ids
    assert imp["time"][0] == pytest.approx(1001 * 1e-5, abs=1e-12)
    assert imp["patch"][0] == 9                   # the sector 90 - 100 degrees
    assert imp["normal_speed"][0] == pytest.approx(0.5, abs=1e-6)
    slip = 0.2 * tangent - R_BALL * np.cross(omega, n)
    assert imp["tangential_speed"][0] == pytest.approx(np.linalg.norm(slip), abs=1e-6)
    m = 7800.0 * 4.0 / 3.0 * math.pi * R_BALL**3
    assert imp["energy"][0] == pytest.approx(0.5 * m * 0.25, rel=1e-6)
    assert np.allclose(imp["position_part"][0], (R_BAR * n[0], 0.01, R_BAR * n[2]), atol=1e-7)
    # the load at the first snapshot: minus the force on the ball, its torque at the bar's top
    g = np.array([-0.1, 0.0, -2.0])
    arm = np.array([0.0, 0.01, R_BAR])
    assert np.allclose(load["force"][0], g) and np.allclose(load["torque"][0],
                                                            np.cross(arm, g))
    assert np.all(load["force"][1:] == 0.0) and load["part"].tolist() == [0] * len(snaps)
    ds = read_parts(tmp_path / "out" / "parts.nc")
    assert ds.attrs["method"] == "dem" and summary["parts"][0]["name"] == "bar"
    assert float(ds["impact_rate_per_area"].sel(part="bar")[9]) > 0
    # a ball inside the bar (a fill that did not leave it out) is refused
    good = (post / LG.BALL_DUMP).read_text()
    (post / LG.BALL_DUMP).write_text(_dump(snaps, lambda k, st: [
        _ball(5, (BAR[0], 0.01, BAR[2] + 0.005)).replace("5 ", "5 1 ", 1),
        _ball(8, _on_bar(90.0, -1e-6)).replace("8 ", "8 1 ", 1)], cols))
    with pytest.raises(InputError, match=r"balls.dump: ball id 5 \(and 0 more\) lies inside "
                                         r"part 'bar' at the first snapshot"):
        LG.import_run(post, None, tmp_path / "out2")
    (post / LG.BALL_DUMP).write_text(good)
    # a part dump that skips a step is refused
    (post / PART_DUMP).write_text(_dump([N0 + 999, N0 + 1001], part_rows,
                                        cols.replace(" type", "")))
    with pytest.raises(InputError, match=r"part_contacts.dump: line \d+: step 8001 after step "
                                         r"7999: the part dump must hold every step"):
        LG.import_run(post, None, tmp_path / "out2")


def test_the_import_finds_contacts_on_the_decks_own_mesh(tmp_path):
    """A ball pressed 20 um into the bar at 95 degrees touches a mesh of 1 um chords (250 around
    the bar, the --fill-from deck's) but not the default 36 chords, whose facet lies
    r (1 - cos 5 deg) = 48 um inside the circle there: the import counts its impact, at the
    dumped 0.3 m/s, exactly when the deck's part_bar.stl is the fine mesh."""
    s, post, snaps = _still_bar_deck(tmp_path)
    cols = "id type x y z vx vy vz omegax omegay omegaz radius"
    (post / LG.BALL_DUMP).write_text(_dump(snaps, lambda k, st: [
        _ball(5, (0.0, 0.01, 0.02)).replace("5 ", "5 1 ", 1)], cols))
    a = math.radians(95.0)
    v = (-0.3 * math.cos(a), 0.0, -0.3 * math.sin(a))

    def part_rows(k, step):
        return [_ball(5, _on_bar(95.0, 1e-4 if step < N0 + 1001 else -2e-5), v)]

    (post / PART_DUMP).write_text(_dump(list(range(N0 + 999, N0 + 1003)), part_rows,
                                        cols.replace(" type", "")))
    (post / LG.WALL_DUMP).write_text("")

    def impacts(out):
        LG.import_run(post, None, tmp_path / out)
        with h5py.File(tmp_path / out / "dem.h5") as f:
            return f["part_impacts/normal_speed"][()], f["part_impacts/time"][()]

    assert impacts("coarse")[0].size == 0
    fine = part_triangles(Part("bar", "cylinder", BAR, "steel", radius=R_BAR), 0.01905, 1e-6)
    assert len(fine) > 36 * 2
    write_stl(tmp_path / "deck" / "part_bar.stl", fine, "part_bar")
    speed, time = impacts("fine")
    assert speed.tolist() == pytest.approx([0.3], abs=1e-6)
    assert time.tolist() == pytest.approx([1001 * 1e-5], abs=1e-12)
    # a deck without the part's mesh is refused in one line naming the file
    (tmp_path / "deck" / "part_bar.stl").unlink()
    with pytest.raises(InputError, match=r"part_bar.stl: no such file; the import finds the "
                                         r"contacts with part 'bar' on the mesh LIGGGHTS used"):
        LG.import_run(post, None, tmp_path / "gone")


def test_the_load_holds_liggghts_cdt_rolling_moment(tmp_path):
    """A ball 20 um into the bar's facet at 95 degrees, spinning at 30 rad/s about y and
    40 rad/s about the normal n: LIGGGHTS' CDT moment on the bar is mu_r k_n delta (r - delta/2)
    times the unit spin's tangential part, (0, 30, 0) / 50 (rolling_model_cdt.h: the whole spin
    normalised, then its normal part removed): 0.002 1e5 N/m 2e-5 m (r - 1e-5 m) 0.6 along +y,
    added to the contact force's moment; none without the rolling law."""
    s = bar_case("parts.0.frame=lab")
    parts = parts_of(s)
    geom = PartGeometry(parts, 0.01905, False)
    a = math.radians(95.0)
    n = np.array([math.cos(a), 0.0, math.sin(a)])
    delta = 2e-5
    centre = np.array(BAR) + (R_BAR * math.cos(math.radians(5.0)) + R_BALL - delta) * n
    centre[1] = 0.01
    tri = geom.meshes[0]
    near = [closest_on_triangle(*centre, tri, t) for t in range(len(tri))]
    t_hit = min((t for t in range(len(tri)) if near[t][3] == 0),
                key=lambda t: np.linalg.norm(centre - near[t][:3]))
    omega = np.array([0.0, 30.0, 0.0]) + 40.0 * n
    f_ball = 2.0 * n                                       # F_n on the ball, F_t = 0
    cols = [f"c_wallc[{i}]" for i in range(1, 10)]
    snap = DumpSnapshot(N0, cols, np.array([[2, t_hit, 5, *f_ball, 0, 0, 0]], float), 1, 9)
    pose = (0.0, 0.0, 0.0, 0.0, -0.1)
    ids = np.array([5])
    with_roll = part_load_rows(snap, 0, ids, centre[None], pose, geom, 2, "wall.dump",
                               omega[None], np.array([R_BALL]), part_rolling(s))
    plain = part_load_rows(snap, 0, ids, centre[None], pose, geom, 2, "wall.dump")
    arm = R_BAR * n + np.array([0.0, 0.01, 0.0])
    assert np.allclose(plain["torque"][0], np.cross(arm, -f_ball), atol=1e-12)
    moment = 0.002 * 1e5 * delta * (R_BALL - 0.5 * delta) * np.array([0.0, 0.6, 0.0])
    assert np.allclose(with_roll["torque"][0] - plain["torque"][0], moment, rtol=1e-6,
                       atol=1e-13)
    assert np.array_equal(with_roll["force"], plain["force"])
