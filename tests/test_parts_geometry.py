"""The parts' geometry (vibroflow/tub/parts.py, vibroflow/scenario/part_shapes.py) against
hand-computed distances, the shapes' analytic areas, an STL facetting's known error, each
other (the checks' numpy distance against the solvers' compiled one), and the scenario's
one-line checks of [[parts]]."""
from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

from vibroflow.errors import InputError
from vibroflow.scenario.io import load_scenario, parse_scenario
from vibroflow.scenario.part_shapes import signed_distance
from vibroflow.tub.parts import (SHAPE_BOX, pack, part_nearest, parts_of, patch_layout,
                                 patch_of)

BAR = dict(name="bar", shape="cylinder", center=[0.05, 0.0, 0.10], radius=0.0125)


def _packed(*parts):
    s = parse_scenario({"parts": list(parts)})
    return s, parts_of(s), pack(parts_of(s))


def _nearest(pk, k, p):
    return part_nearest(pk.shape, pk.prm, pk.tri, pk.tri_normal, pk.tri_start, k, *p)


def test_cylinder_distance_normal_and_sector_by_hand():
    _, _, pk = _packed(BAR)
    # 0.02 m above the axis: 0.0075 m outside, normal +z, the 90-100 degree sector
    gap, nx, ny, nz, cx, cy, cz, f = _nearest(pk, 0, (0.05, 0.03, 0.12))
    assert gap == pytest.approx(0.0075)
    assert (nx, ny, nz) == pytest.approx((0.0, 0.0, 1.0))
    assert (cx, cy, cz) == pytest.approx((0.05, 0.03, 0.1125))
    assert patch_of(pk.shape[0], pk.tri_group, nx, ny, nz, f) == 9
    # below and to the left at 45 degrees: the 220-230 degree sector
    gap, nx, _, nz, *_ = _nearest(pk, 0, (0.05 - 0.01, 0.0, 0.10 - 0.01))
    assert gap == pytest.approx(math.sqrt(2) * 0.01 - 0.0125)
    assert patch_of(pk.shape[0], pk.tri_group, nx, 0.0, nz, -1) == 22


def test_turned_box_face_edge_corner_by_hand():
    box = dict(name="block", shape="box", center=[0.0, 0.03, 0.10], size=[0.04, 0.02, 0.02],
               angle_y=math.pi / 2)  # turned a quarter: its x edge now runs along z
    _, _, pk = _packed(box)
    assert pk.shape[0] == SHAPE_BOX
    # above the top face: the box's -x face (x towards z turned by +90 degrees: x_box = z)
    gap, nx, ny, nz, cx, cy, cz, face = _nearest(pk, 0, (0.0, 0.03, 0.125))
    assert gap == pytest.approx(0.005)
    assert (nx, ny, nz) == pytest.approx((0.0, 0.0, 1.0), abs=1e-12)
    assert face == 1  # +x in the box's own axes
    # beyond an edge (x and y outside): distance to the edge line
    gap, *_ = _nearest(pk, 0, (0.013, 0.03 + 0.013, 0.10))
    assert gap == pytest.approx(math.hypot(0.003, 0.003))
    # beyond a corner
    gap, *_ = _nearest(pk, 0, (0.011, 0.03 + 0.012, 0.10 + 0.023))
    assert gap == pytest.approx(math.sqrt(0.001**2 + 0.002**2 + 0.003**2))
    # inside: negative, to the nearest face
    gap, *_ = _nearest(pk, 0, (0.0, 0.03, 0.118))
    assert gap == pytest.approx(-0.002)


def test_patch_areas_are_the_shapes_areas():
    s, parts, _ = _packed(BAR, dict(name="ball", shape="sphere", center=[-0.06, 0.03, 0.1],
                                    radius=0.01),
                          dict(name="block", shape="box", center=[0.0, 0.03, 0.2],
                               size=[0.04, 0.02, 0.03]))
    L = s.tub.length
    assert patch_layout(parts[0], L)[1].sum() == pytest.approx(2 * math.pi * 0.0125 * L)
    assert patch_layout(parts[1], L)[1].sum() == pytest.approx(4 * math.pi * 0.01**2)
    assert patch_layout(parts[2], L)[1].sum() == pytest.approx(
        2 * (0.04 * 0.02 + 0.04 * 0.03 + 0.02 * 0.03))


@pytest.fixture
def stl_cylinder(tmp_path):
    """A closed 64-sided cylinder along y of radius 12.5 mm through (0, 0), in mm."""
    mesh = trimesh.creation.cylinder(radius=12.5, height=20.0, sections=64)
    mesh.apply_transform(trimesh.transformations.rotation_matrix(math.pi / 2, [1, 0, 0]))
    path = tmp_path / "bar.stl"
    mesh.export(path)
    return path


def test_stl_cylinder_agrees_with_the_analytic_one_within_its_facet_error(stl_cylinder, tmp_path):
    toml = tmp_path / "case.toml"
    toml.write_text(
        '[[parts]]\nname = "mesh"\nshape = "stl"\nfile = "bar.stl"\nscale = 0.001\n'
        'center = [0.05, 0.03, 0.10]\n[[parts]]\nname = "far"\nshape = "sphere"\n'
        'center = [-0.08, 0.03, 0.15]\nradius = 0.005\n')
    s = load_scenario(toml)  # the file is found beside the scenario
    pk = pack(parts_of(s))
    sagitta = 0.0125 * (1 - math.cos(math.pi / 64))
    rng = np.random.default_rng(1)
    for _ in range(200):
        a, rho = rng.uniform(0, 2 * math.pi), rng.uniform(0.013, 0.03)
        p = (0.05 + rho * math.cos(a), 0.03 + rng.uniform(-0.008, 0.008),
             0.10 + rho * math.sin(a))
        gap, nx, ny, nz, *_ = _nearest(pk, 0, p)
        assert rho - 0.0125 - 1e-9 <= gap <= rho - 0.0125 + sagitta + 1e-9
        assert abs(ny) < 1e-9 and nx * math.cos(a) + nz * math.sin(a) > math.cos(math.pi / 32)
    # on the axis: inside, nearer the end caps (10 mm) than the side (12.5 mm)
    assert _nearest(pk, 0, (0.05, 0.03, 0.10))[0] == pytest.approx(-0.010)


@pytest.mark.parametrize("part, message", [
    (dict(BAR, radius=None), "parts.0.radius: required by shape"),
    (dict(BAR, size=[0.01, 0.01, 0.01]), "parts.0.size = (0.01, 0.01, 0.01): not a field"),
    (dict(BAR, center=[0.14, 0.0, 0.1]), "through the tub wall; it must lie inside the tub"),
    (dict(BAR, center=[0.0, 0.0, 0.395]), "above the rim"),
    (dict(BAR, center=[0.133, 0.0, 0.2], frame="lab"), "clear of the moving wall"),
    (dict(BAR, material="brass"), 'parts.0.material = "brass": no such material'),
    (dict(BAR, name="a b"), "must be a name"),
    (dict(name="s", shape="sphere", center=[0.0, 0.005, 0.1], radius=0.01),
     "it must lie between the partitions"),
    (dict(name="s", shape="stl", center=[0.0, 0.03, 0.1], file="/nonexistent.stl"),
     "no such file"),
    (dict(name="b", shape="box", center=[0.0, 0.03, 0.1], size=[0.01, 0.0, 0.01]),
     "every edge length must be greater than 0 m"),
])
def test_a_bad_part_is_one_line_naming_the_field(part, message):
    with pytest.raises(InputError) as e:
        parse_scenario({"parts": [part]})
    assert message in str(e.value) and "\n" not in str(e.value)


@pytest.mark.parametrize("damage, words", [
    ("truncated", "neither a binary STL (84 + 50 x its 256 triangles = 12884 bytes"),
    ("garbage", "neither a binary STL"),
    ("empty", "0 bytes, neither a binary STL"),
])
def test_a_damaged_stl_file_is_one_line_saying_why(stl_cylinder, tmp_path, damage, words):
    data = stl_cylinder.read_bytes()
    bad = tmp_path / "bad.stl"
    bad.write_bytes({"truncated": data[:len(data) // 2], "garbage": b"\x00\x01 not a mesh " * 9,
                     "empty": b""}[damage])
    part = dict(name="s", shape="stl", center=[0.0, 0.03, 0.1], file=str(bad))
    with pytest.raises(InputError) as e:
        parse_scenario({"parts": [part]})
    assert words in str(e.value) and "\n" not in str(e.value), str(e.value)


def test_overlapping_parts_and_a_part_without_a_contact_law_are_refused():
    box = dict(name="b", shape="box", center=[0.06, 0.03, 0.10], size=[0.02, 0.02, 0.02])
    with pytest.raises(InputError, match='parts.1.center .* overlaps parts.0 \\("bar"\\)'):
        parse_scenario({"parts": [BAR, box]})
    materials = {"steel": {}, "polyurethane": {}, "glass": {}, "brass": {"density": 8500.0}}
    with pytest.raises(InputError, match="no contact law for the pair steel-brass \\(ball-part\\)"):
        parse_scenario({"parts": [dict(BAR, material="brass")], "materials": materials})


def test_an_explicit_ball_inside_a_part_is_refused():
    raw = {"particles": [{"position": [0.0, 0.0, 0.001]}],
           "parts": [dict(name="b", shape="box", center=[0, 0, 0], size=[0.1, 0.1, 0.01],
                          frame="lab")]}
    with pytest.raises(InputError, match="particles.0.position .* overlaps parts.0"):
        parse_scenario(raw)
    raw["parts"][0]["frame"] = "tub"
    with pytest.raises(InputError, match='parts.0.frame = "tub": explicit mode has no tub'):
        parse_scenario(raw)


def test_the_checks_and_the_solvers_measure_the_same_distance(stl_cylinder, tmp_path):
    """Two implementations of a part's signed distance agree: the scenario checks' numpy one
    (part_shapes.signed_distance; an STL's sign from its winding number) and the solvers'
    compiled one (tub.parts.part_nearest; an STL's sign from its nearest feature's normal), on
    random points in and around a cylinder, a turned box, a sphere and an STL cylinder."""
    toml = tmp_path / "case.toml"
    toml.write_text(
        '[[parts]]\nname = "bar"\nshape = "cylinder"\ncenter = [-0.07, 0.0, 0.10]\n'
        'radius = 0.0125\n'
        '[[parts]]\nname = "block"\nshape = "box"\ncenter = [0.0, 0.03, 0.25]\n'
        'size = [0.04, 0.02, 0.03]\nangle_y = 0.4\n'
        '[[parts]]\nname = "ball"\nshape = "sphere"\ncenter = [-0.06, 0.03, 0.25]\n'
        'radius = 0.01\n'
        '[[parts]]\nname = "mesh"\nshape = "stl"\nfile = "bar.stl"\nscale = 0.001\n'
        'center = [0.05, 0.03, 0.10]\n')
    s = load_scenario(toml)
    parts = parts_of(s)
    pk = pack(parts)
    rng = np.random.default_rng(7)
    for k, (spec, part) in enumerate(zip(s.parts, parts)):
        p = np.array(part.center) + rng.uniform(-0.03, 0.03, size=(300, 3))
        numpy_gap = signed_distance(spec, p, part.triangles)
        compiled_gap = np.array([_nearest(pk, k, q)[0] for q in p])
        assert compiled_gap == pytest.approx(numpy_gap, abs=1e-12), spec.name
