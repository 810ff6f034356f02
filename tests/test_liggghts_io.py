"""The LIGGGHTS round trip (vibroflow.liggghts).

Known answers used here: the analytic U surface of tub47.md (every STL vertex on it, every facet
within the 0.05 mm chord tolerance of it, the facets' normals pointing into the tub); the contact
parameters of tub47.md and models.md (computed here independently of the package); the tub motion
s(a, phi, t) = a [sin(omega t + phi) - sin(phi)] of tub47.md; synthetic LIGGGHTS dumps (balls,
wall and pair contacts) whose numbers are known; and, with LIGGGHTS installed (slow), the
textbook restitution and contact time of the linear spring-dashpot, a tiny end-to-end run whose
balls must stay in the tub, and a bed at rest whose imported contact forces must balance
LIGGGHTS' own per-atom forces ball by ball (Newton's laws), push, and give a compressive
coarse-grained pressure.
"""
from __future__ import annotations

import json
import math
import re
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest

from vibroflow import liggghts as LG
from vibroflow.errors import InputError
from vibroflow.liggghts.stl import (arc_segments, facet_normals, partition_triangles, read_stl,
                                    u_profile, u_triangles, write_stl, write_tub_meshes)
from vibroflow.scenario.model import Scenario
from vibroflow.tub.geometry import TubGeometry, geometry_of

R_TUB, RIM = 0.15, 0.40
TOL = 5.0e-5  # m, the facets' allowed deviation from the circle

LIGGGHTS = LG.find_liggghts()
needs_liggghts = pytest.mark.skipif(LIGGGHTS is None or shutil.which("mpirun") is None,
                                    reason="LIGGGHTS (apt-get install liggghts) or mpirun "
                                           "not installed")


def quick(**run) -> Scenario:
    """tub47-quick (tub47.md "Smaller variant") built from the model, with run overrides."""
    s = Scenario()
    return s.model_copy(update={
        "case": "tub47-quick",
        "tub": s.tub.model_copy(update={"length": 0.01905}),
        "fill": s.fill.model_copy(update={"count": 4200}),
        "run": s.run.model_copy(update={"duration": 1.5, "average_last": 1.0, **run}),
    })


def signed_distance_to_u(p):
    """Distance of points (..., 3) to the analytic U surface (tub47.md), >= 0 inside."""
    x, z = p[..., 0], p[..., 2]
    circle = R_TUB - np.hypot(x, z - R_TUB)
    side = R_TUB - np.abs(x)
    return np.where(z <= R_TUB, circle, side)


# ----------------------------------------------------------------------------------------------
# STL

def test_arc_segments_is_the_smallest_count_within_the_sagitta():
    # brute force: the smallest n whose chord sagitta R (1 - cos(pi / 2n)) is below 0.05 mm
    n = 1
    while R_TUB * (1 - math.cos(math.pi / (2 * n))) >= TOL:
        n += 1
    assert arc_segments(R_TUB, TOL) == n
    assert R_TUB * (1 - math.cos(math.pi / (2 * (n - 1)))) >= TOL


@pytest.mark.parametrize("length", [0.01905, 0.0635])
def test_u_mesh_lies_on_the_analytic_surface(length):
    g = TubGeometry(radius=R_TUB, rim_height=RIM, length=length)
    tris = u_triangles(g)
    verts = tris.reshape(-1, 3)
    # every vertex on the surface (to round-off)
    assert np.abs(signed_distance_to_u(verts)).max() < 1e-12
    assert verts[:, 1].min() == 0.0 and np.isclose(verts[:, 1].max(), length)
    assert np.isclose(verts[:, 2].max(), RIM) and 0.0 <= verts[:, 2].min() < TOL
    # every point of every facet within 0.05 mm of the surface, and only ever inside it
    w = np.array([(a, b, 1 - a - b) for a in np.linspace(0, 1, 11) for b in np.linspace(0, 1, 11)
                  if a + b <= 1 + 1e-12])
    pts = np.einsum("kv,tvc->tkc", w, tris)
    d = signed_distance_to_u(pts)
    assert d.min() > -1e-12
    assert d.max() < TOL
    # fine enough to matter: the coarsest chord is close to the tolerance
    assert d.max() > 0.8 * TOL
    # the facets tile the surface: area = profile length x L (chords slightly shorter than arcs)
    area = 0.5 * np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]),
                                axis=1).sum()
    exact = (math.pi * R_TUB + 2 * (RIM - R_TUB)) * length
    assert abs(area - exact) / exact < 1e-3


def test_u_mesh_normals_point_into_the_tub_and_orientation_is_consistent():
    g = TubGeometry(radius=R_TUB, rim_height=RIM, length=0.01905)
    tris = u_triangles(g)
    n = facet_normals(tris)
    c = tris.mean(axis=1)
    # the inward normal of the analytic surface at the facet's centroid
    inward = np.where((c[:, 2] <= R_TUB)[:, None],
                      np.stack([-c[:, 0], np.zeros(len(c)), R_TUB - c[:, 2]], axis=1),
                      np.stack([-np.sign(c[:, 0]), np.zeros(len(c)), np.zeros(len(c))], axis=1))
    inward /= np.linalg.norm(inward, axis=1, keepdims=True)
    assert np.einsum("ij,ij->i", n, inward).min() > 0.99
    # consistent orientation: an edge shared by two facets is traversed once each way; edges used
    # once lie on the mesh's boundary (the rims and the ends y = 0, y = L)
    key = {tuple(v): i for i, v in enumerate(np.unique(np.round(tris.reshape(-1, 3), 12),
                                                       axis=0))}
    idx = np.array([[key[tuple(v)] for v in np.round(t, 12)] for t in tris])
    directed = {}
    for t in idx:
        for a, b in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0])):
            directed[(a, b)] = directed.get((a, b), 0) + 1
    assert max(directed.values()) == 1  # no edge twice in the same direction
    verts = np.array(sorted(key, key=key.get))
    for (a, b) in directed:
        if (b, a) not in directed:
            pa, pb = verts[a], verts[b]
            on_end = (abs(pa[1]) < 1e-12 and abs(pb[1]) < 1e-12) or \
                (abs(pa[1] - 0.01905) < 1e-12 and abs(pb[1] - 0.01905) < 1e-12)
            on_rim = abs(pa[2] - RIM) < 1e-12 and abs(pb[2] - RIM) < 1e-12
            assert on_end or on_rim, (pa, pb)
    # no needle: LIGGGHTS warns under 0.5 degree
    for t in tris:
        for k in range(3):
            u, v = t[(k + 1) % 3] - t[k], t[(k + 2) % 3] - t[k]
            ang = math.degrees(math.acos(np.dot(u, v) / np.linalg.norm(u) / np.linalg.norm(v)))
            assert ang > 2.0


def test_partitions_cover_the_cross_section_with_inward_normals():
    L = 0.0635
    g = TubGeometry(radius=R_TUB, rim_height=RIM, length=L)
    tris = partition_triangles(g)
    n = facet_normals(tris)
    assert np.allclose(n[:2], [0, 1, 0]) and np.allclose(n[2:], [0, -1, 0])
    assert np.allclose(tris[:2, :, 1], 0.0) and np.allclose(tris[2:, :, 1], L)
    area = 0.5 * np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1)
    assert np.isclose(area[:2].sum(), 2 * R_TUB * RIM) and np.isclose(area[2:].sum(),
                                                                       2 * R_TUB * RIM)
    # the U profile fits inside the rectangles
    prof = u_profile(g)
    assert np.abs(prof[:, 0]).max() <= R_TUB + 1e-15 and prof[:, 1].max() <= RIM + 1e-15


@pytest.mark.parametrize("binary", [False, True])
def test_stl_files_round_trip(tmp_path, binary):
    g = TubGeometry(radius=R_TUB, rim_height=RIM, length=0.01905)
    tris = u_triangles(g)
    p = write_stl(tmp_path / "u.stl", tris, binary=binary)
    back, normals = read_stl(p)
    assert back.shape == tris.shape
    assert np.allclose(back, tris, atol=1e-6 if binary else 1e-14)
    assert np.allclose(normals, facet_normals(tris), atol=1e-6)
    paths = write_tub_meshes(g, tmp_path / "m")
    assert set(paths) == {"u", "partitions"}
    assert p.read_bytes()[:5] != b"solid" or not binary


# ----------------------------------------------------------------------------------------------
# The deck

def _fix_table(deck: str, name: str) -> np.ndarray:
    m = re.search(rf"^fix {name} all property/global {name} peratomtypepair 3 (.+)$", deck,
                  re.MULTILINE)
    assert m, f"no property/global {name} in the deck"
    return np.array([float(x) for x in m.group(1).split()]).reshape(3, 3)


def test_deck_holds_the_tub47_contact_parameters(tmp_path):
    s = quick()
    LG.export_deck(s, tmp_path)
    deck = (tmp_path / "in.tub").read_text()
    # independently of the package: tub47.md's table and models.md's damping
    d, rho = 6.35e-3, 7800.0
    m = 4.0 / 3.0 * math.pi * (d / 2) ** 3 * rho
    assert abs(m - 1.046e-3) < 1e-6  # tub47.md: mass 1.046 g

    def gamma(k, e, m_eff):
        zeta = -math.log(e) / math.sqrt(math.pi**2 + math.log(e) ** 2)
        return 2 * zeta * math.sqrt(m_eff * k)

    # types: 1 steel balls, 2 polyurethane tub wall, 3 glass partitions
    expect = {(0, 0): (1.0e5, 0.85, 0.20, m / 2), (0, 1): (5.0e4, 0.60, 0.40, m),
              (0, 2): (1.0e5, 0.85, 0.15, m)}
    kn, kt = _fix_table(deck, "kn"), _fix_table(deck, "kt")
    gn, gt = _fix_table(deck, "gamman_abs"), _fix_table(deck, "gammat_abs")
    mu = _fix_table(deck, "coefficientFriction")
    mur = _fix_table(deck, "coefficientRollingFriction")
    for (i, j), (k, e, f, m_eff) in expect.items():
        for a, b in ((i, j), (j, i)):
            assert kn[a, b] == pytest.approx(k, rel=1e-9)
            assert kt[a, b] == pytest.approx(2.0 / 7.0 * k, rel=1e-9)
            assert gn[a, b] == pytest.approx(gamma(k, e, m_eff), rel=1e-8)
            assert mu[a, b] == pytest.approx(f)
            assert mur[a, b] == pytest.approx(0.002)
    assert np.all(gt == 0.0)  # no tangential damping
    # the damping is absolute (N s/m), the tangential damping off, the rolling model CDT
    pair = re.search(r"^pair_style\s+gran (.+)$", deck, re.MULTILINE).group(1)
    wall = re.search(r"^fix walls all wall/gran (.+)$", deck, re.MULTILINE).group(1)
    for line in (pair, wall):
        assert "model hooke/stiffness" in line and "tangential history" in line
        assert "rolling_friction cdt" in line
        assert "absolute_damping on" in line and "tangential_damping off" in line
    assert "meshes tub parts" in wall
    assert re.search(r"^timestep\s+1e-05$", deck, re.MULTILINE)
    assert re.search(r"^fix gravi all gravity 9.81 vector 0 0 -1$", deck, re.MULTILINE)
    # the scenario travels with the deck
    assert (tmp_path / "scenario.toml").is_file() and (tmp_path / "README.txt").is_file()
    assert "mpirun -np 2 liggghts -in in.tub" in (tmp_path / "README.txt").read_text()


def test_deck_follows_the_scenario(tmp_path):
    s = quick()
    contacts = [c.model_copy(update={"k_n": 2.0e5}) if c.pair == ("steel", "steel") else c
                for c in s.contacts]
    s = s.model_copy(update={"contacts": contacts,
                             "run": s.run.model_copy(update={"dt": 5e-6, "seed": 7}),
                             "fill": s.fill.model_copy(update={"count": 1234})})
    info = LG.export_deck(s, tmp_path)
    deck = (tmp_path / "in.tub").read_text()
    assert _fix_table(deck, "kn")[0, 0] == pytest.approx(2.0e5)
    assert re.search(r"^timestep\s+5e-06$", deck, re.MULTILINE)
    assert "nparticles 1234 " in deck
    for p in info.seeds:
        assert p > 10000 and all(p % q for q in range(2, math.isqrt(p) + 1))
        assert str(p) in deck
    assert len(set(info.seeds)) == 3
    assert set(LG.seed_primes(7)) != set(LG.seed_primes(8))


def test_deck_rejects_what_liggghts_cannot_do(tmp_path):
    s = quick()
    mixed = [s.contacts[0].model_copy(update={"model": "hertz"}), *s.contacts[1:]]
    with pytest.raises(InputError, match="contacts.model"):
        LG.export_deck(s.model_copy(update={"contacts": mixed}), tmp_path)
    missing = [c for c in s.contacts if c.pair != ("steel", "glass")]
    with pytest.raises(InputError, match="glass"):
        LG.export_deck(s.model_copy(update={"contacts": missing}), tmp_path)


def test_deck_for_hertz_contacts_uses_liggghts_hertz(tmp_path):
    s = quick()
    hertz = [c.model_copy(update={"model": "hertz"}) for c in s.contacts]
    LG.export_deck(s.model_copy(update={"contacts": hertz}), tmp_path)
    deck = (tmp_path / "in.tub").read_text()
    assert re.search(r"^pair_style\s+gran model hertz tangential history rolling_friction cdt "
                     r"tangential_damping off", deck, re.MULTILINE)
    assert "property/global kn " not in deck
    # Hertz takes E and nu per type (steel, polyurethane, glass) and e per pair
    assert "youngsModulus peratomtype 2e+11 25000000 6.3e+10" in deck
    assert _fix_table(deck, "coefficientRestitution")[0, 1] == pytest.approx(0.60)


def test_deck_for_a_periodic_length_has_no_partitions(tmp_path):
    s = quick()
    s = s.model_copy(update={"tub": s.tub.model_copy(update={"periodic": True})})
    LG.export_deck(s, tmp_path)
    deck = (tmp_path / "in.tub").read_text()
    assert re.search(r"^boundary\s+f p f$", deck, re.MULTILINE)
    assert "mesh n_meshes 1 meshes tub " in deck and "partitions.stl" not in deck
    assert not (tmp_path / "partitions.stl").exists()


def _variable(deck: str, name: str):
    """A `variable NAME equal A*cos(W*v_tmid+P)` of the deck as (A, W, P)."""
    m = re.search(rf"^variable {name} equal ([-0-9.e+]+)\*cos\(([-0-9.e+]+)\*v_tmid\+"
                  rf"([-0-9.e+]+)\)$", deck, re.MULTILINE)
    assert m, name
    return tuple(float(x) for x in m.groups())


@pytest.mark.parametrize("factor", [1.0, 1.5])
def test_deck_mesh_motion_reproduces_the_tub_motion(tmp_path, factor):
    """The deck's mesh velocities, integrated as LIGGGHTS does (one update a step, the step
    counter already advanced, so v_tmid = (step - n0 - 1/2) dt), give tub47.md's pose."""
    s = quick()
    s = s.model_copy(update={"motion": s.motion.model_copy(update={"amplitude_factor": factor})})
    LG.export_deck(s, tmp_path)
    deck = (tmp_path / "in.tub").read_text()
    dt = s.run.dt
    assert re.search(r"^variable tmid equal \(step-\$\{n0\}-0\.5\)\*1e-05$", deck, re.MULTILINE)
    n = 2 * int(round(1 / 47.0 / dt))  # two cycles
    tmid = (np.arange(1, n + 1) - 0.5) * dt
    w = 2 * math.pi * 47.0
    expected = {"vX": (1.0e-3, 0.0), "vZ": (1.5e-3, math.pi / 2), "wT": (4.0e-3, 0.0)}
    for name, (a, phi) in expected.items():
        A, W, P = _variable(deck, name)
        a *= factor
        x = np.cumsum(A * np.cos(W * tmid + P)) * dt
        t = np.arange(1, n + 1) * dt
        exact = a * (np.sin(w * t + phi) - np.sin(phi))
        assert np.abs(x - exact).max() < 1e-4 * a, name
    # the rotation is about the pivot (0, -0.10), x turning towards z (an axis along -y), and
    # rides on the translation (the linear mover comes first)
    lines = deck.splitlines()
    i_t = lines.index("fix move_tub_t all move/mesh mesh tub linear/variable v_vX v_vY v_vZ")
    i_r = [k for k, ln in enumerate(lines) if ln.startswith("fix move_tub_r")][0]
    assert i_t < i_r
    assert "rotate/variable origin 0 0. -0.1 axis 0. -1. 0. omega v_wT" in lines[i_r]
    assert any(ln.startswith("fix move_parts_r") for ln in lines)


def test_dump_steps_are_vibroflows_sampling_instants(tmp_path):
    s = quick()
    info = LG.export_deck(s, tmp_path)
    steps = np.loadtxt(tmp_path / "post" / "dump_steps.txt", dtype=np.int64)
    # 47 cycles x 8 phases over the last 1.0 s of 1.5 s, at the nearest step (tub47.md)
    f, dt = 47.0, 1e-5
    t0 = 1.5 - 47 / f
    want = np.round((t0 + np.arange(47 * 8) / (8 * f)) / dt).astype(np.int64)
    assert np.array_equal(steps[:-2], want)
    assert np.array_equal(info.dump_steps, want)
    assert steps[-2] > 150000 and steps[-1] > steps[-2]  # sentinels beyond the run


# ----------------------------------------------------------------------------------------------
# Import

def _write_dump(path: Path, snaps, header_cols):
    with open(path, "w") as f:
        for step, rows in snaps:
            f.write(f"ITEM: TIMESTEP\n{step}\nITEM: NUMBER OF ATOMS\n{len(rows)}\n")
            f.write("ITEM: BOX BOUNDS ff ff ff\n-1 1\n-1 1\n-1 1\n")
            f.write(f"ITEM: ATOMS {header_cols}\n")
            for r in rows:
                f.write(" ".join(repr(float(v)) if not isinstance(v, int) else str(v)
                                 for v in r) + "\n")


def _write_local(path: Path, snaps):
    with open(path, "w") as f:
        for step, rows in snaps:
            f.write(f"ITEM: TIMESTEP\n{step}\nITEM: NUMBER OF ENTRIES\n{len(rows)}\n")
            f.write("ITEM: BOX BOUNDS ff ff ff\n-1 1\n-1 1\n-1 1\n")
            f.write("ITEM: ENTRIES " + " ".join(f"c_wallc[{k}]" for k in range(1, 10)) + "\n")
            for r in rows:
                f.write(" ".join(str(v) for v in r) + "\n")


def test_import_of_a_synthetic_dump(tmp_path):
    s = quick(duration=0.1, average_last=0.09, batches=2, seed=3)
    s = s.model_copy(update={"fill": s.fill.model_copy(update={"count": 3})})
    deck = tmp_path / "deck"
    info = LG.export_deck(s, deck)
    post = deck / "post"
    n0 = 123456
    (post / "vibration_start_step.txt").write_text(f"{n0}\n")
    rel = info.dump_steps  # vibration steps of the snapshots
    rng = np.random.default_rng(0)
    ids = np.array([17, 3, 9])  # LIGGGHTS ids, not in order
    data = {}
    snaps = []
    for k, r in enumerate(rel):
        # balls near the bottom of the tub (lab frame), arbitrary velocities
        pos = np.stack([rng.uniform(-0.05, 0.05, 3), rng.uniform(0.004, 0.015, 3),
                        rng.uniform(0.01, 0.03, 3)], axis=1)
        vel = rng.normal(0, 0.1, (3, 3))
        omg = rng.normal(0, 10.0, (3, 3))
        data[k] = (pos, vel, omg)
        rows = [[int(ids[i]), 1, *pos[i], *vel[i], *omg[i], 0.003175] for i in range(3)]
        order = rng.permutation(3)
        snaps.append((n0 + int(r), [rows[i] for i in order]))
    _write_dump(post / "balls.dump", snaps,
                "id type x y z vx vy vz omegax omegay omegaz radius")
    # one U contact in the first snapshot (ball id 9) and one partition contact (id 17, tri 3)
    t_first = rel[0] * s.run.dt
    w = 2 * math.pi * 47.0
    theta = 4e-3 * math.sin(w * t_first)
    c, sn = math.cos(theta), math.sin(theta)
    pos9 = data[0][0][2]
    # the analytic inward normal at ball 9 in tub frame, turned into the lab (x towards z)
    X, Z = 1e-3 * math.sin(w * t_first), 1.5e-3 * (math.sin(w * t_first + math.pi / 2) - 1)
    rx, rz = pos9[0] - X - 0.0, pos9[2] - Z + 0.10
    tx, tz = c * rx + sn * rz, -0.10 - sn * rx + c * rz
    u = np.array([tx, tz - R_TUB]) / math.hypot(tx, tz - R_TUB)
    n_tub = -u
    n_lab = np.array([c * n_tub[0] - sn * n_tub[1], 0.0, sn * n_tub[0] + c * n_tub[1]])
    fn9 = 0.8 * n_lab
    ft9 = 0.4 * 0.8 * np.array([n_lab[2], 0.0, -n_lab[0]])  # at the Coulomb limit (mu = 0.4)
    fn17 = np.array([0.0, -0.5, 0.0])  # partition at y = L pushes towards -y
    ft17 = np.array([0.01, 0.0, 0.0])
    _write_local(post / "wall.dump", [
        (n0 + int(rel[0]), [[0, 57, 9, *fn9, *ft9], [1, 3, 17, *fn17, *ft17]]),
        (n0 + int(rel[1]), []),
    ])
    (post / "series.txt").write_text("# t_vibration_s kinetic_energy_J\n0.0 1.5\n0.001 2.5\n")
    out = tmp_path / "out"
    summary = LG.import_run(post, None, out)  # the scenario from deck/scenario.toml

    with h5py.File(out / "dem.h5", "r") as f:
        assert f.attrs["source"] == "liggghts" and f.attrs["n_particles"] == 3
        assert f.attrs["dt"] == 1e-5 and f.attrs["frequency"] == 47.0
        assert "tub47-quick" in f.attrs["case"] and "[fill]" in f.attrs["scenario_toml"]
        assert np.allclose(f["particles/radius"][()], 0.003175)
        t = f["snapshots/time"][()]
        assert np.allclose(t, rel * 1e-5, rtol=0, atol=1e-12)
        assert np.array_equal(f["snapshots/step"][()], rel)
        assert np.allclose(f["snapshots/phase"][()], (rel * 1e-5 * 47.0) % 1.0)
        assert f["snapshots/phase"][()].max() < 1.0
        pose = f["snapshots/tub_pose"][()]
        want = np.stack([1e-3 * np.sin(w * t), 1.5e-3 * (np.sin(w * t + math.pi / 2) - 1),
                         4e-3 * np.sin(w * t), 1e-3 * w * np.cos(w * t),
                         1.5e-3 * w * np.cos(w * t + math.pi / 2), 4e-3 * w * np.cos(w * t)],
                        axis=1)
        assert np.allclose(pose, want, rtol=1e-12, atol=1e-15)
        # particles in LIGGGHTS id order 3, 9, 17
        sort = np.argsort(ids)
        for k in range(len(rel)):
            pos, vel, omg = data[k]
            assert np.allclose(f["snapshots/position"][k], pos[sort], atol=1e-7)
            assert np.allclose(f["snapshots/velocity"][k], vel[sort], rtol=1e-6, atol=1e-7)
            assert np.allclose(f["snapshots/angular_velocity"][k], omg[sort], rtol=1e-6,
                               atol=1e-6)
        assert f["snapshots/position"].dtype == np.float32
        wc = f["wall_contacts"]
        assert list(wc["snapshot"][()]) == [0, 0]
        assert list(wc["particle"][()]) == [1, 2]  # id 9 -> index 1, id 17 -> index 2
        assert list(wc["wall"][()]) == [0, 2]  # the U, the partition at y = L
        assert wc["fn"][0] == pytest.approx(0.8, rel=1e-6)
        assert wc["fn"][1] == pytest.approx(0.5, rel=1e-6)
        assert wc["ft"][0] == pytest.approx(0.32, rel=1e-6)
        assert list(wc["sliding"][()]) == [True, False]
        # the contact point: the U point nearest the ball (tub frame), on the circle
        p = wc["position_tub"][0]
        assert math.hypot(p[0], p[2] - R_TUB) == pytest.approx(R_TUB, rel=1e-6)
        assert wc["arc"][0] == pytest.approx(R_TUB * math.atan2(u[0], -u[1]), abs=1e-6)
        assert math.isnan(wc["arc"][1]) and wc["position_tub"][1][1] == pytest.approx(0.01905)
        for name in ("time", "kind", "position_tub", "normal_speed"):
            assert f[f"impacts/{name}"].shape[0] == 0
        assert np.allclose(f["series/time"][()], [0.0, 0.001])
        assert np.allclose(f["series/kinetic_energy"][()], [1.5, 2.5])
        assert np.all(np.isnan(f["series/max_overlap_ball"][()]))
    written = json.loads((out / "summary.json").read_text())
    assert written["source"] == "liggghts" and written["n_particles"] == 3
    assert written["dt"] == 1e-5 and written["simulated_time_s"] == pytest.approx(0.1)
    assert "circulation" in written and "probes" in written
    assert summary["case"] == written["case"]
    assert (out / "bulk_velocity.csv").is_file()
    assert not list(out.glob(".*"))  # no temporary left behind


def test_import_refuses_incomplete_runs(tmp_path):
    s = quick(duration=0.1, average_last=0.09, batches=2)
    LG.export_deck(s, tmp_path)
    post = tmp_path / "post"
    with pytest.raises(InputError, match="balls.dump"):
        LG.import_run(post, s, tmp_path / "out")
    _write_dump(post / "balls.dump", [(1000, [[1, 1, 0, 0.01, 0.01, 0, 0, 0, 0, 0, 0, 0.003]]),
                                      (1266, [[2, 1, 0, 0.01, 0.01, 0, 0, 0, 0, 0, 0, 0.003]])],
                "id type x y z vx vy vz omegax omegay omegaz radius")
    with pytest.raises(InputError, match="vibration_start_step"):
        LG.import_run(post, s, tmp_path / "out")
    (post / "vibration_start_step.txt").write_text("0\n")
    with pytest.raises(InputError, match="balls lost"):
        LG.import_run(post, s, tmp_path / "out")
    assert not (tmp_path / "out" / "dem.h5").exists()


def _write_pairs(path: Path, snaps):
    """A pair/gran/local dump (id1 id2 periodic-flag fx fy fz) as LIGGGHTS writes it."""
    with open(path, "w") as f:
        for step, rows in snaps:
            f.write(f"ITEM: TIMESTEP\n{step}\nITEM: NUMBER OF ENTRIES\n{len(rows)}\n")
            f.write("ITEM: BOX BOUNDS ff pp ff\n-1 1\n-1 1\n-1 1\n")
            f.write("ITEM: ENTRIES " + " ".join(f"c_pairc[{k}]" for k in range(1, 7)) + " \n")
            for r in rows:
                f.write(" ".join(repr(float(v)) for v in r) + "\n")


def _pair_case(tmp_path, periodic: bool):
    """A deck folder with a ball dump of three balls at rest (LIGGGHTS ids 17, 3, 9, written
    out of order): 9 touches 3 along x; 17 touches 3 along z, or, in a periodic tub, along y
    across the periodic boundary (17 near y = L, 3 near y = 0).  Returns (post, scenario,
    steps, positions by id)."""
    s = quick(duration=0.1, average_last=0.09, batches=2, seed=3)
    s = s.model_copy(update={"fill": s.fill.model_copy(update={"count": 3}),
                             "tub": s.tub.model_copy(update={"periodic": periodic})})
    info = LG.export_deck(s, tmp_path / "deck")
    post = tmp_path / "deck" / "post"
    n0 = 5000
    (post / "vibration_start_step.txt").write_text(f"{n0}\n")
    L, gap = s.tub.length, 0.0063  # centre distance: 0.05 mm overlap for d = 6.35 mm
    pos = {3: np.array([0.0, 0.002, 0.02]), 9: np.array([gap, 0.002, 0.02]),
           17: (np.array([0.0, 0.002 - gap + L, 0.02]) if periodic
                else np.array([0.0, 0.002, 0.02 + gap]))}
    steps = [n0 + int(r) for r in info.dump_steps]
    rows = [[i, 1, *pos[i], 0, 0, 0, 0, 0, 0, 0.003175] for i in (17, 3, 9)]
    _write_dump(post / "balls.dump", [(st, rows) for st in steps],
                "id type x y z vx vy vz omegax omegay omegaz radius")
    return post, s, steps, pos


@pytest.mark.parametrize("periodic", [False, True])
def test_import_of_a_synthetic_pair_dump(tmp_path, periodic):
    """Known answer: LIGGGHTS dumps each contact once, as (id1, id2, flag, force on id1), in
    either id order.  The import maps the ids to the sorted snapshot (3 -> 0, 9 -> 1,
    17 -> 2), orders each pair i < j with the force on i (negated when swapped: Newton's third
    law), drops zero-force rows, and takes the branch as the minimum image."""
    post, s, steps, pos = _pair_case(tmp_path, periodic)
    f93 = np.array([0.50, 0.01, -0.02])     # on 9 by 3: pushes 9 towards +x, away from 3
    f317 = np.array([0.0, 0.3, 0.0]) if periodic else np.array([0.01, 0.0, -0.4])
    # (on 3 by 17: 17 sits on 3, or, periodic, lies at -y of 3 through the boundary)
    rows = [[9, 3, 0, *f93], [3, 17, 1 if periodic else 0, *f317], [17, 9, 0, 0, 0, 0]]
    _write_pairs(post / "pairs.dump", [(st, rows[k % 2:] + rows[:k % 2])
                                       for k, st in enumerate(steps)])
    out = tmp_path / "out"
    summary = LG.import_run(post, s, out)
    n = len(steps)
    with h5py.File(out / "dem.h5", "r") as f:
        bc = f["ball_contacts"]
        assert np.array_equal(bc["snapshot"][()], np.repeat(np.arange(n), 2))
        assert np.array_equal(bc["i"][()], np.tile([0, 0], n))
        assert np.array_equal(bc["j"][()], np.tile([1, 2], n))
        force = bc["force_lab"][()]
        assert force.dtype == np.float32
        assert np.allclose(force[0::2], -f93, rtol=1e-6)   # swapped: the force on 3 by 9
        assert np.allclose(force[1::2], f317, rtol=1e-6)   # kept: the force on 3 by 17
    assert summary["ball_contacts_available"] and summary["ball_contacts"] == 2 * n
    assert summary["ball_contacts_repulsive_fraction"] == 1.0
    from vibroflow.calibration.dem_result import DEMResult
    with DEMResult.open(out) as res:
        assert res.has_ball_contacts
        _, snap = next(res.iter_snapshots([0]))
        # the calibration's branch r_i - r_j: along the line of centres, |b| = 6.3 mm
        assert np.allclose(np.linalg.norm(snap["contact_branch"], axis=1), 0.0063, rtol=1e-5)
        assert np.all(np.einsum("ij,ij->i", snap["contact_force"], snap["contact_branch"]) > 0)


def test_import_refuses_inconsistent_pair_dumps(tmp_path):
    post, s, steps, pos = _pair_case(tmp_path, False)
    f93 = [0.5, 0.0, 0.0]
    cases = {
        # the force taken on the second id: every contact would pull
        "pull": [[9, 3, 0, *(-np.array(f93))], [3, 17, 0, 0.0, 0.0, 0.4]],
        "not two balls": [[9, 42, 0, *f93]],
        "twice": [[9, 3, 0, *f93], [3, 9, 0, *(-np.array(f93))]],
        "apart": [[9, 17, 0, *f93]],
    }
    for message, rows in cases.items():
        _write_pairs(post / "pairs.dump", [(st, rows) for st in steps])
        with pytest.raises(InputError, match=message):
            LG.import_run(post, s, tmp_path / "out")
    _write_pairs(post / "pairs.dump", [(st, [[9, 3, 0, *f93]]) for st in steps[:-1]])
    with pytest.raises(InputError, match=f"no entry for step {steps[-1]}"):
        LG.import_run(post, s, tmp_path / "out")
    assert not (tmp_path / "out" / "dem.h5").exists()
    assert not list((tmp_path / "out").glob(".*"))


def test_import_without_a_pair_dump_has_no_ball_contacts(tmp_path):
    """A deck written before the pair dump: dem.h5 is complete, its ball_contacts group
    empty, and the calibration sees no ball contacts (contact stress: walls only)."""
    post, s, steps, pos = _pair_case(tmp_path, False)
    out = tmp_path / "out"
    summary = LG.import_run(post, s, out)
    assert summary["ball_contacts_available"] is False
    with h5py.File(out / "dem.h5", "r") as f:
        for name in ("snapshot", "i", "j", "force_lab"):
            assert f[f"ball_contacts/{name}"].shape[0] == 0
        assert f["snapshots/position"].shape == (len(steps), 3, 3)
    from vibroflow.calibration.dem_result import DEMResult
    with DEMResult.open(out) as res:
        assert not res.has_ball_contacts
        _, snap = next(res.iter_snapshots([0]))
        assert "contacts_i" not in snap


def test_deck_dumps_the_ball_contacts_at_the_snapshot_steps(tmp_path):
    s = quick()
    LG.export_deck(s, tmp_path)
    deck = (tmp_path / "in.tub").read_text()
    lines = deck.splitlines()
    # the compute before the first run (LIGGGHTS wants it so), next to the wall compute
    i_compute = lines.index("compute pairc all pair/gran/local id force")
    assert i_compute < min(k for k, ln in enumerate(lines) if ln.startswith("run "))
    assert "variable pfile file post/dump_steps.txt" in lines
    assert "variable pnext equal ${n0}+next(pfile)" in lines
    assert ("dump dpairs all local 1 post/pairs.dump c_pairc[1] c_pairc[2] c_pairc[3] "
            "c_pairc[4] c_pairc[5] c_pairc[6]") in lines
    assert any(ln.startswith("dump_modify dpairs every v_pnext format") for ln in lines)
    assert "post/pairs.dump" in (tmp_path / "README.txt").read_text()
    LG.export_deck(s, tmp_path / "no", pair_contacts=False)
    assert "pair/gran/local" not in (tmp_path / "no" / "in.tub").read_text()


def test_loop_time_parsing(tmp_path):
    log = tmp_path / "log.liggghts"
    log.write_text("Loop time of 12.156 on 2 procs for 5000 steps with 4200 atoms, finish ...\n"
                   "Loop time of 1.5 on 1 procs for 100 steps with 30 atoms\n")
    lt = LG.loop_times(log)
    assert [x.steps for x in lt] == [5000, 100]
    assert lt[0].particle_steps_per_s == pytest.approx(4200 * 5000 / 12.156)


def test_mpirun_command_runs_two_ranks():
    cmd = LG.mpirun_command(2, binary="/usr/bin/liggghts") if shutil.which("mpirun") else None
    if cmd is None:
        pytest.skip("mpirun not installed")
    assert cmd[-3:] == ["/usr/bin/liggghts", "-in", "in.tub"]
    assert "-np" in cmd and cmd[cmd.index("-np") + 1] == "2"


# ----------------------------------------------------------------------------------------------
# With LIGGGHTS (slow)

def _collision_deck(s: Scenario, dt: float, steps: int) -> str:
    """Four balls without gravity: one falls on the U's flat bottom facet, two collide head-on,
    one hits the partition at y = 0; each at 0.5 m/s."""
    g = geometry_of(s)
    args, kw = LG.model_arguments(LG.pair_tables(s))
    r = 0.5 * s.fill.diameter
    L = g.length
    return "\n".join([
        "atom_style granular", "atom_modify map array sort 0 0", "boundary f f f", "newton off",
        "communicate single vel yes", "units si", "hard_particles yes",
        f"region domain block -0.2 0.2 -0.03 {L + 0.03} -0.05 0.45 units box",
        "create_box 3 domain", f"neighbor {0.6 * r} bin", "neigh_modify delay 0",
        *LG.contact_law_lines(s), f"timestep {dt}", "fix integr all nve/sphere",
        "fix tub all mesh/surface file tub_u.stl type 2",
        "fix parts all mesh/surface file partitions.stl type 3",
        f"fix walls all wall/gran {args} mesh n_meshes 2 meshes tub parts {kw}",
        f"create_atoms 1 single 0 {L / 2} 0.006 units box",
        f"create_atoms 1 single 0.05 {L / 2} 0.1 units box",
        f"create_atoms 1 single {0.05 + 3 * r} {L / 2} 0.1 units box",
        f"create_atoms 1 single -0.05 {2 * r} 0.1 units box",
        f"set atom * diameter {2 * r} density {s.materials['steel'].density}",
        "group b1 id 1", "group b2 id 2", "group b3 id 3", "group b4 id 4",
        "velocity b1 set 0 0 -0.5 units box", "velocity b2 set 0.5 0 0 units box",
        "velocity b3 set -0.5 0 0 units box", "velocity b4 set 0 -0.5 0 units box",
        "variable a equal vz[1]", "variable b equal vx[2]", "variable c equal vx[3]",
        "variable d equal vy[4]",
        'fix pr all print 1 "${a} ${b} ${c} ${d}" file vel.txt screen no',
        "thermo 100000", f"run {steps}", ""])


@pytest.mark.slow
@needs_liggghts
def test_liggghts_collisions_have_the_tub47_restitution_and_contact_time(tmp_path):
    """Head-on collisions in LIGGGHTS with the deck's contact law: restitution e (tub47.md) and
    contact time t_c = pi / sqrt(k/m_eff - (gamma/2 m_eff)^2) (models.md).  At dt = 1e-6 s the
    time discretisation is negligible, so this checks the parameters themselves (that LIGGGHTS
    reads gamman_abs in N s/m with the m_eff we assumed)."""
    s = Scenario().model_copy(update={"gravity": (0.0, 0.0, 0.0)})
    write_tub_meshes(geometry_of(s), tmp_path)
    dt = 1.0e-6
    (tmp_path / "in.tub").write_text(_collision_deck(s, dt, 30000))
    LG.run_deck(tmp_path, nprocs=1, timeout=300)
    v = np.loadtxt(tmp_path / "vel.txt", comments="#")
    m = 4.0 / 3.0 * math.pi * (6.35e-3 / 2) ** 3 * 7800.0
    cases = {  # column: (relative speed after / before, k, e, m_eff)
        "wall": (v[:, 0] / 0.5, 5.0e4, 0.60, m),
        "ball-ball": ((v[:, 2] - v[:, 1]) / 1.0, 1.0e5, 0.85, m / 2),
        "partition": (v[:, 3] / 0.5, 1.0e5, 0.85, m),
    }
    for name, (rel, k, e, m_eff) in cases.items():
        assert rel[-1] == pytest.approx(e, rel=3e-3), name
        zeta = -math.log(e) / math.sqrt(math.pi**2 + math.log(e) ** 2)
        gam = 2 * zeta * math.sqrt(m_eff * k)
        tc = math.pi / math.sqrt(k / m_eff - (gam / (2 * m_eff)) ** 2)
        changing = np.nonzero(np.abs(np.diff(rel)) > 1e-12)[0]
        duration = (changing[-1] - changing[0] + 1) * dt
        assert duration == pytest.approx(tc, rel=0.02), name


@pytest.mark.slow
@needs_liggghts
def test_liggghts_end_to_end_tiny_tub(tmp_path):
    """Export, run on 2 MPI ranks, import: 150 balls, a short settle and 0.1 s of vibration.
    The balls must stay in the tub (tub frame, within the facets' sagitta plus a small
    overlap) and the import must produce a complete dem.h5 and summary."""
    s = quick(duration=0.1, average_last=0.09, batches=2, seed=5)
    s = s.model_copy(update={"fill": s.fill.model_copy(update={
        "count": 150, "settle_time": 0.15, "max_settle_time": 0.15})})
    deck = tmp_path / "deck"
    info = LG.export_deck(s, deck)
    LG.run_deck(deck, nprocs=2, timeout=600)
    out = tmp_path / "out"
    summary = LG.import_run(deck / "post", s, out)
    assert summary["n_particles"] == 150 and summary["balls_lost"] == 0
    assert summary["mpi_ranks"] == 2 and summary["particle_steps_per_s"] > 0
    with h5py.File(out / "dem.h5", "r") as f:
        pos = f["snapshots/position"][()]
        pose = f["snapshots/tub_pose"][()]
        assert pos.shape == (len(info.dump_steps), 150, 3)
        for k in range(pos.shape[0]):
            X, Z, th = pose[k, :3]
            c, sn = math.cos(th), math.sin(th)
            rx, rz = pos[k, :, 0] - X, pos[k, :, 2] - Z + 0.10
            tub = np.stack([c * rx + sn * rz, pos[k, :, 1], -0.10 - sn * rx + c * rz], axis=-1)
            gap = signed_distance_to_u(tub) - 0.003175
            assert gap.min() > -2.0e-4
            assert tub[:, 1].min() > 0.003175 - 2e-4 and tub[:, 1].max() < 0.01905 - 0.003175 + 2e-4
        # wall contacts obey Coulomb's law with tub47's friction (0.40 tub, 0.15 partitions),
        # many at its limit, and push on the whole (the damping may pull at the end of a contact)
        fn, ft = f["wall_contacts/fn"][()], f["wall_contacts/ft"][()]
        wall, sliding = f["wall_contacts/wall"][()], f["wall_contacts/sliding"][()]
        assert fn.size > 20 and np.median(fn) > 0
        for w, mu in ((0, 0.40), (1, 0.15), (2, 0.15)):
            on = wall == w
            assert on.sum() > 0
            assert np.all(ft[on] <= mu * np.abs(fn[on]) * (1 + 1e-4) + 1e-9)
            assert np.all(ft[on & sliding] >= mu * np.abs(fn[on & sliding]) * (1 - 1e-4))
        assert sliding.sum() > 0
        # ball-ball contacts at every snapshot, each pair once with i < j, which push on the
        # whole even in the agitated bed (the damping pulls only at the end of a contact)
        bs, bi, bj = (f[f"ball_contacts/{k}"][()] for k in ("snapshot", "i", "j"))
        assert bs.size > 0 and np.all(bi < bj)
        pairs = bs.astype(np.int64) * 150**2 + bi.astype(np.int64) * 150 + bj
        assert np.unique(pairs).size == pairs.size
    assert summary["ball_contacts_available"]
    assert summary["ball_contacts_repulsive_fraction"] > 0.9
    assert json.loads((out / "summary.json").read_text())["source"] == "liggghts"


@pytest.mark.slow
@needs_liggghts
@pytest.mark.parametrize("periodic", [False, True])
def test_liggghts_ball_contacts_of_a_bed_at_rest(tmp_path, periodic):
    """300 balls settled in a small tub (R = 5 cm) that stays at rest (amplitude factor 0),
    2 MPI ranks.  Known answers: Newton's laws, ball by ball: the imported ball contact forces
    (+F on i, -F on j) plus the wall forces and the weight add up to LIGGGHTS' own per-atom
    total force (dumped beside, fx fy fz); contact forces at rest are repulsive,
    F_on_i . (r_i - r_j) > 0; and the coarse-grained pressure of the bed is compressive."""
    s = quick(duration=0.06, average_last=0.05, batches=2, seed=5)
    s = s.model_copy(update={
        "tub": s.tub.model_copy(update={"radius": 0.05, "rim_height": 0.15,
                                        "periodic": periodic}),
        "motion": s.motion.model_copy(update={"amplitude_factor": 0.0}),
        "fill": s.fill.model_copy(update={"count": 300, "settle_time": 0.2,
                                          "max_settle_time": 0.2})})
    deck = tmp_path / "deck"
    LG.export_deck(s, deck)
    # LIGGGHTS' per-atom total force (pair + wall + gravity) in the ball dump, for the balance
    text = (deck / "in.tub").read_text()
    text, n1 = re.subn(r"(dump dballs .* radius)$", r"\1 fx fy fz", text, flags=re.MULTILINE)
    text, n2 = re.subn(r'(dump_modify dballs .*format "[^"]*)"', r'\1 %.10g %.10g %.10g"', text)
    assert n1 == n2 == 1
    (deck / "in.tub").write_text(text)
    LG.run_deck(deck, nprocs=2, timeout=600)
    out = tmp_path / "out"
    summary = LG.import_run(deck / "post", s, out)
    assert summary["balls_lost"] == 0 and summary["ball_contacts_available"]
    f_liggghts = []
    for step, cols, data in LG.iter_dump(deck / "post" / "balls.dump"):
        c = {name: k for k, name in enumerate(cols)}
        data = data[np.argsort(data[:, c["id"]])]
        f_liggghts.append(data[:, [c["fx"], c["fy"], c["fz"]]])
    if periodic:  # some contacts across the periodic boundary, which the import must handle
        flags = np.concatenate([d[:, 2] for _, _, d in LG.iter_dump(deck / "post" /
                                                                     "pairs.dump")])
        assert np.count_nonzero(flags == 1) > 0
    L = s.tub.length
    with h5py.File(out / "dem.h5", "r") as f:
        radius = f["particles/radius"][()]
        mass = 4.0 / 3.0 * math.pi * radius**3 * 7800.0
        weight = mass[:, None] * np.array([0.0, 0.0, -9.81])
        pos = f["snapshots/position"][()].astype(np.float64)
        bs, bi, bj = (f[f"ball_contacts/{k}"][()] for k in ("snapshot", "i", "j"))
        bf = f["ball_contacts/force_lab"][()].astype(np.float64)
        ws, wp = f["wall_contacts/snapshot"][()], f["wall_contacts/particle"][()]
        wf = f["wall_contacts/force_lab"][()].astype(np.float64)
    n_snap = pos.shape[0]
    assert len(f_liggghts) == n_snap
    assert np.all(bi < bj)
    # a settled bed: a few contacts per ball at every snapshot
    assert np.all(np.bincount(bs, minlength=n_snap) > 300)
    errors = []
    for k in range(n_snap):
        net = weight.copy()
        on = bs == k
        np.add.at(net, bi[on], bf[on])
        np.add.at(net, bj[on], -bf[on])
        on = ws == k
        np.add.at(net, wp[on], wf[on])
        errors.append(np.linalg.norm(net - f_liggghts[k], axis=1) / (mass * 9.81))
    errors = np.concatenate(errors)
    # measured: median 1e-3 m g, 99 % below 0.015 m g (the computes re-evaluate the contacts
    # at output time, and the forces are stored in float32); a force on the wrong ball of a
    # swapped pair would leave errors of several m g
    assert np.median(errors) < 0.01
    assert np.mean(errors < 0.1) > 0.99
    branch = pos[bs, bi] - pos[bs, bj]
    if periodic:
        branch[:, 1] -= L * np.round(branch[:, 1] / L)
    assert np.allclose(np.linalg.norm(branch, axis=1), 2 * radius[bi], rtol=2e-3)
    push = np.einsum("ij,ij->i", bf, branch) > 0
    assert push.mean() > 0.99
    from vibroflow.calibration.run_fields import coarse_grain_run
    avg, _, info = coarse_grain_run(out)
    assert info["contact_stress"] == "ball and wall"
    bed = avg["solid_fraction"].values > 0.5
    assert bed.sum() > 10
    assert np.all(avg["pressure"].values[bed] > 0)
