"""The checks of the scenario's parts ([[parts]]), run with the other cross-field checks
(checks.check_consistent): each shape has the fields it needs and no other, names are unique,
an STL file reads as a closed surface, a part lies inside the tub (a lab-fixed one clear of the
moving wall by the wall's excursion), parts do not overlap, and no ball of an explicit start
begins inside one.  Each failure is one line "FIELD = VALUE: what is allowed".  Materials and
contact laws are checked with the walls' (checks.wall_materials names each part).
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from vibroflow.scenario.part_shapes import (ShapeError, placed_triangles, signed_distance,
                                            surface_points)

Scenario = Any

#: the fields each shape takes (besides name, shape, center, material, frame)
SHAPE_FIELDS = {"cylinder": ("radius",), "sphere": ("radius",), "box": ("size", "angle_y"),
                "stl": ("file", "scale")}
_UNSET = {"radius": None, "size": None, "file": None, "angle_y": 0.0, "scale": 1.0}


def check_parts(s: Scenario, fail) -> None:
    """Every check of s.parts, in the order its errors are reported (`fail` raises the one-line
    scenario error)."""
    parts = s.parts or []
    seen: dict[str, int] = {}
    for i, p in enumerate(parts):
        _check_fields(i, p, fail)
        if p.name in seen:
            fail(f"parts.{i}.name = \"{p.name}\": the name of parts.{seen[p.name]} too; each "
                 "part needs its own name")
        seen[p.name] = i
        if s.explicit and p.frame == "tub":
            fail(f"parts.{i}.frame = \"tub\": explicit mode has no tub; use frame = \"lab\"")
    triangles = [_triangles(i, p, fail) for i, p in enumerate(parts)]
    if s.tub is not None:
        for i, p in enumerate(parts):
            _check_inside_tub(s, i, p, triangles[i], fail)
    for i, a in enumerate(parts):
        for j in range(i):
            _check_apart(s, j, parts[j], triangles[j], i, a, triangles[i], fail)
    if s.explicit:
        _check_balls_outside(s, parts, triangles, fail)


def _check_fields(i: int, p, fail) -> None:
    allowed = SHAPE_FIELDS[p.shape]
    for field in ("radius", "size", "file"):
        value = getattr(p, field)
        if field in allowed and value is None:
            fail(f"parts.{i}.{field}: required by shape = \"{p.shape}\"")
    for field, unset in _UNSET.items():
        if field not in allowed and getattr(p, field) != unset:
            takes = ", ".join(f"{k} ({' and '.join(v)})" for k, v in SHAPE_FIELDS.items()
                              if field in v)
            fail(f"parts.{i}.{field} = {getattr(p, field)!r}: not a field of shape = "
                 f"\"{p.shape}\" (it belongs to {takes})")
    if p.shape == "box" and min(p.size) <= 0.0:
        fail(f"parts.{i}.size = {list(p.size)}: every edge length must be greater than 0 m")


def _triangles(i: int, p, fail):
    if p.shape != "stl":
        return None
    try:
        return placed_triangles(p)
    except ShapeError as e:
        fail(f"parts.{i}.file = \"{p.file}\": {e}")


def _y_range(s: Scenario) -> tuple[float, float]:
    if s.tub is not None:
        return 0.0, s.tub.length
    return -1.0, 1.0


def _excursion(s: Scenario, pts: np.ndarray) -> float:
    """An upper bound (m) of how far the tub's wall moves at points pts: the translations'
    amplitudes plus the turn's about the pivot (tub47.md "Tub motion"; each s(a, phi, t)
    spans at most 2 a)."""
    m, f = s.motion, s.motion.amplitude_factor
    arm = np.hypot(pts[:, 0] - m.pivot[0], pts[:, 2] - m.pivot[1]).max()
    return 2.0 * f * (m.amplitude_x + m.amplitude_z + m.amplitude_theta * float(arm))


def _check_inside_tub(s: Scenario, i: int, p, tri, fail) -> None:
    tub = s.tub
    pts = surface_points(p, _y_range(s), tri)
    R = tub.radius
    # the U's signed distance (vibroflow/tub/geometry.py distance_to_wall_np), positive inside
    wall = np.where(pts[:, 2] <= R, R - np.hypot(pts[:, 0], pts[:, 2] - R), R - np.abs(pts[:, 0]))
    need = _excursion(s, pts) if p.frame == "lab" else 0.0
    k = int(np.argmin(wall))
    centre = "[" + ", ".join(f"{c:g}" for c in p.center) + "]"
    if wall[k] < need:
        if p.frame == "lab":
            fail(f"parts.{i}.center = {centre}: the lab-fixed part comes within "
                 f"{max(wall[k], 0.0):.3g} m of the tub wall, which moves up to {need:.3g} m; "
                 "it must stay clear of the moving wall")
        fail(f"parts.{i}.center = {centre}: the part reaches {-wall[k]:.3g} m through the tub "
             "wall; it must lie inside the tub")
    if pts[:, 2].max() > tub.rim_height:
        fail(f"parts.{i}.center = {centre}: the part reaches above the rim (tub.rim_height = "
             f"{tub.rim_height:g} m); it must lie inside the tub")
    if p.shape != "cylinder":
        lo, hi = float(pts[:, 1].min()), float(pts[:, 1].max())
        if lo < 0.0 or hi > tub.length:
            fail(f"parts.{i}.center = {centre}: the part spans y from {lo:.4g} to {hi:.4g} m; "
                 f"it must lie between the partitions, 0 and tub.length = {tub.length:g} m")


def _check_apart(s: Scenario, j: int, a, ta, i: int, b, tb, fail) -> None:
    pa = surface_points(a, _y_range(s), ta)
    pb = surface_points(b, _y_range(s), tb)
    if a.shape == "cylinder" and b.shape != "cylinder":
        pa = surface_points(a, (float(pb[:, 1].min()), float(pb[:, 1].max())), ta)
    if b.shape == "cylinder" and a.shape != "cylinder":
        pb = surface_points(b, (float(pa[:, 1].min()), float(pa[:, 1].max())), tb)
    if min(signed_distance(b, pa, tb).min(), signed_distance(a, pb, ta).min()) < 0.0:
        fail(f"parts.{i}.center = [{', '.join(f'{c:g}' for c in b.center)}]: the part overlaps "
             f"parts.{j} (\"{a.name}\"); parts must not overlap")


def _check_balls_outside(s: Scenario, parts, triangles, fail) -> None:
    x = np.array([q.position for q in s.particles], dtype=float)
    r = 0.5 * np.array([q.diameter for q in s.particles], dtype=float)
    for k, (p, tri) in enumerate(zip(parts, triangles)):
        over = (r - signed_distance(p, x, tri)) / (2.0 * r)
        bad = np.flatnonzero(over >= s.run.max_overlap)
        if bad.size:
            n = int(bad[0])
            where = "[" + ", ".join(f"{c:g}" for c in s.particles[n].position) + "]"
            inside = " (its centre is inside the part)" if over[n] > 0.5 else ""
            fail(f"particles.{n}.position = {where}: the ball overlaps parts.{k} (\"{p.name}\") "
                 f"by {over[n]:.3g} of its diameter{inside}; must be below run.max_overlap "
                 f"= {s.run.max_overlap:g}")


def parts_volume_m3(s: Scenario) -> float:
    """The parts' volume (m^3) inside the tub's slice, which the fill cannot use."""
    total = 0.0
    L = s.tub.length if s.tub is not None else 1.0
    for p in s.parts or []:
        if p.shape == "cylinder":
            total += math.pi * p.radius**2 * L
        elif p.shape == "sphere":
            total += 4.0 / 3.0 * math.pi * p.radius**3
        elif p.shape == "box":
            total += float(np.prod(p.size))
        else:
            tri = placed_triangles(p)
            total += abs(float(np.einsum("ij,ij->i", tri[:, 0],
                                         np.cross(tri[:, 1], tri[:, 2])).sum())) / 6.0
    return total
