"""The parts of [[parts]] as triangle meshes for LIGGGHTS (SI: m, the tub frame at rest, like the
U's meshes in vibroflow.liggghts.stl), one STL file per part, outward normals (from the part
into the media), every vertex on the part's analytic surface.

* cylinder (axis along y, spanning the slice from y = 0 to L_y): its circle cut into the
  smallest even number of equal chords whose sagitta r (1 - cos(pi / n)) is below
  `max_sagitta`, the U's rule (vibroflow.liggghts.stl.arc_segments on the half circle; n = 36
  for r = 12.5 mm and 0.05 mm, so each facet spans one of the 36 patches of
  vibroflow.tub.parts), the vertices at angles 2 pi k / n from +x towards +z; the length in
  strips no longer than two chords; open ends (they lie on the partitions, or on the periodic
  boundary).
* box: its six faces, two triangles each, turned by angle_y about y.
* sphere: n_lon = the circle's chord count by the same rule, n_lon / 2 bands of latitude,
  the poles' bands as fans.
* STL: the part's own placed triangles (vibroflow.scenario.part_shapes.placed_triangles).
"""
from __future__ import annotations

import math

import numpy as np

from vibroflow.liggghts.stl import DEFAULT_MAX_SAGITTA, arc_segments
from vibroflow.tub.parts import Part


def circle_chords(radius: float, max_sagitta: float = DEFAULT_MAX_SAGITTA) -> int:
    """Number n of equal chords on a whole circle of `radius` (m): twice the U's count for the
    half circle, so the sagitta r (1 - cos(pi / n)) is below `max_sagitta` (m)."""
    return 2 * arc_segments(radius, max_sagitta)


def _quad(a, b, c, d) -> list:
    """Two triangles of the quadrilateral a b c d (counterclockwise about its normal)."""
    return [(a, b, c), (a, c, d)]


def cylinder_triangles(part: Part, length: float,
                       max_sagitta: float = DEFAULT_MAX_SAGITTA) -> np.ndarray:
    """Triangles (T, 3, 3) of a cylinder part from y = 0 to `length` (m), outward normals."""
    r = part.radius
    cx, _, cz = part.center
    n = circle_chords(r, max_sagitta)
    a = 2.0 * math.pi * np.arange(n + 1) / n
    xs, zs = cx + r * np.cos(a), cz + r * np.sin(a)
    chord = 2.0 * r * math.sin(math.pi / n)
    ny = max(1, math.ceil(length / (2.0 * chord)))
    ys = np.linspace(0.0, length, ny + 1)
    tris = []
    for k in range(n):
        for j in range(ny):
            # the angle runs from +x towards +z, which is a turn about -y: with the tangent
            # t (k -> k + 1) and e_y, the outward normal is e_y x t, so p(k, j) -> p(k, j + 1)
            # -> p(k + 1, j + 1) turns counterclockwise about it
            p00 = (xs[k], ys[j], zs[k])
            p01 = (xs[k], ys[j + 1], zs[k])
            p11 = (xs[k + 1], ys[j + 1], zs[k + 1])
            p10 = (xs[k + 1], ys[j], zs[k + 1])
            tris += _quad(p00, p01, p11, p10)
    return np.asarray(tris, dtype=float)


def box_triangles(part: Part) -> np.ndarray:
    """Triangles (12, 3, 3) of a box part, outward normals, turned by angle_y about y."""
    hx, hy, hz = part.half_size
    c, s = math.cos(part.angle_y), math.sin(part.angle_y)
    corners = {}
    for ix in (-1, 1):
        for iy in (-1, 1):
            for iz in (-1, 1):
                q0, q1, q2 = ix * hx, iy * hy, iz * hz
                corners[ix, iy, iz] = (part.center[0] + c * q0 - s * q2, part.center[1] + q1,
                                       part.center[2] + s * q0 + c * q2)
    tris = []
    for axis in range(3):
        for sign in (-1, 1):
            # the face's corners counterclockwise about its outward normal sign e_axis
            u, v = (axis + 1) % 3, (axis + 2) % 3
            ring = [(-1, -1), (1, -1), (1, 1), (-1, 1)]
            if sign < 0:
                ring = ring[::-1]
            pts = []
            for a_u, a_v in ring:
                idx = [0, 0, 0]
                idx[axis], idx[u], idx[v] = sign, a_u, a_v
                pts.append(corners[tuple(idx)])
            tris += _quad(*pts)
    return np.asarray(tris, dtype=float)


def sphere_triangles(part: Part, max_sagitta: float = DEFAULT_MAX_SAGITTA) -> np.ndarray:
    """Triangles of a sphere part (latitude-longitude, outward normals)."""
    r = part.radius
    c = np.asarray(part.center, dtype=float)
    n_lon = circle_chords(r, max_sagitta)
    n_lat = n_lon // 2
    polar = np.pi * np.arange(n_lat + 1) / n_lat
    azim = 2.0 * np.pi * np.arange(n_lon + 1) / n_lon

    def at(i, j):
        return tuple(c + r * np.array([math.sin(polar[i]) * math.cos(azim[j]),
                                       math.sin(polar[i]) * math.sin(azim[j]),
                                       math.cos(polar[i])]))

    tris = []
    for i in range(n_lat):
        for j in range(n_lon):
            # from the top (+z) down, azimuth counterclockwise about +z: outward is
            # (down) x (around) ... (a, b, c) = (p(i, j), p(i + 1, j), p(i + 1, j + 1))
            if i == 0:
                tris.append((at(0, j), at(1, j), at(1, j + 1)))
            elif i == n_lat - 1:
                tris.append((at(i, j), at(i + 1, j), at(i, j + 1)))
            else:
                tris += _quad(at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1))
    return np.asarray(tris, dtype=float)


def part_triangles(part: Part, length: float,
                   max_sagitta: float = DEFAULT_MAX_SAGITTA) -> np.ndarray:
    """The mesh (T, 3, 3) of one part (module docstring), m, tub frame at rest."""
    if part.shape == "cylinder":
        return cylinder_triangles(part, length, max_sagitta)
    if part.shape == "box":
        return box_triangles(part)
    if part.shape == "sphere":
        return sphere_triangles(part, max_sagitta)
    return np.asarray(part.triangles, dtype=float)
