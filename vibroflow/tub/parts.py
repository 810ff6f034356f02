"""Rigid parts in the bed (the scenario's [[parts]]), for every solver: one frozen record per part
(`Part`), one mapping from the scenario (`parts_of`), one packed form for the kernels
(`PackedParts`, `pack`), the nearest point of a part's surface (`part_nearest`, numba), and the
surface patches over which what a part receives is reported (`patch_of`, `patch_layout`).

A part is fixed in the tub frame (`FRAME_TUB`: it moves with the tub, tub/motion.py) or in the
lab (`FRAME_LAB`); the kernels take a point in the frame the part is fixed in (the tub frame and
the lab coincide at t = 0, where the scenario places the part).  Shapes and their coordinates
are those of vibroflow/scenario/part_shapes.py: a cylinder's axis runs along y and spans the
slice; a box is turned by angle_y about y; an STL surface is its placed triangles, outward
normals.

Patches (SI; the impact maps' bins):
- cylinder: CYLINDER_SECTORS sectors of the angle around its axis, measured in the x-z plane
  from +x towards +z (90 degrees is the top of a bar, 270 its underside);
- sphere: SPHERE_BANDS bands of the polar angle from +z (the top first);
- box: its six faces -x, +x, -y, +y, -z, +z in the box's own axes;
- STL: its triangles grouped by the axis their outward normal points along most (-x ... +z).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numba as nb
import numpy as np

from vibroflow.scenario.part_shapes import placed_triangles

SHAPES = ("cylinder", "box", "sphere", "stl")
SHAPE_CYLINDER, SHAPE_BOX, SHAPE_SPHERE, SHAPE_STL = range(4)
FRAMES = ("tub", "lab")
FRAME_TUB, FRAME_LAB = range(2)
# columns of PackedParts.prm
P_CX, P_CY, P_CZ, P_RADIUS, P_HX, P_HY, P_HZ, P_COS, P_SIN, P_FRAME = range(10)
N_PARAM = 10
CYLINDER_SECTORS = 36
SPHERE_BANDS = 18
FACE_NAMES = ("-x", "+x", "-y", "+y", "-z", "+z")


@dataclass(frozen=True)
class Part:
    """One rigid part (SI): name, shape (one of SHAPES), center (m), radius (m; cylinder and
    sphere), half_size (m, half edges; box), angle_y (rad; box), frame ("tub" or "lab"),
    material, and triangles (n, 3, 3), m, placed in the tub frame (stl)."""

    name: str
    shape: str
    center: tuple[float, float, float]
    material: str
    frame: str = "tub"
    radius: float = 0.0
    half_size: tuple[float, float, float] = (0.0, 0.0, 0.0)
    angle_y: float = 0.0
    triangles: np.ndarray | None = None

    def area_m2(self, slice_length_m: float) -> float:
        """Surface area (m^2) in contact with the media: a cylinder's over the slice's length."""
        return float(patch_layout(self, slice_length_m)[1].sum())


def parts_of(scenario) -> tuple[Part, ...]:
    """The scenario's parts as records, STL triangles read and placed (empty: no parts)."""
    out = []
    for p in scenario.parts or []:
        half = tuple(0.5 * v for v in p.size) if p.size is not None else (0.0, 0.0, 0.0)
        out.append(Part(name=p.name, shape=p.shape, center=tuple(p.center), material=p.material,
                        frame=p.frame, radius=p.radius or 0.0, half_size=half,
                        angle_y=p.angle_y,
                        triangles=placed_triangles(p) if p.shape == "stl" else None))
    return tuple(out)


@dataclass(frozen=True)
class PackedParts:
    """The parts as flat arrays for the kernels: shape codes (n,), parameters prm (n, N_PARAM),
    all triangles tri (m, 3, 3) with their unit outward normals tri_normal (m, 3) and patch
    groups tri_group (m,), part k's triangles being tri_start[k]:tri_start[k + 1]."""

    shape: np.ndarray
    prm: np.ndarray
    tri: np.ndarray
    tri_normal: np.ndarray
    tri_group: np.ndarray
    tri_start: np.ndarray

    @property
    def n(self) -> int:
        return int(self.shape.shape[0])


def pack(parts: tuple[Part, ...]) -> PackedParts:
    """The packed form of `parts` (valid, with zero parts too)."""
    n = len(parts)
    shape = np.array([SHAPES.index(p.shape) for p in parts], dtype=np.int64)
    prm = np.zeros((n, N_PARAM))
    tris, start = [], [0]
    for k, p in enumerate(parts):
        prm[k, P_CX:P_CZ + 1] = p.center
        prm[k, P_RADIUS] = p.radius
        prm[k, P_HX:P_HZ + 1] = p.half_size
        prm[k, P_COS], prm[k, P_SIN] = math.cos(p.angle_y), math.sin(p.angle_y)
        prm[k, P_FRAME] = FRAMES.index(p.frame)
        if p.triangles is not None:
            tris.append(p.triangles)
        start.append(start[-1] + (0 if p.triangles is None else len(p.triangles)))
    tri = np.concatenate(tris) if tris else np.zeros((0, 3, 3))
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    length = np.linalg.norm(normal, axis=1, keepdims=True)
    normal = normal / np.where(length > 0.0, length, 1.0)
    axis = np.argmax(np.abs(normal), axis=1) if len(tri) else np.zeros(0, np.int64)
    group = 2 * axis + (normal[np.arange(len(tri)), axis] > 0.0) if len(tri) else axis
    return PackedParts(shape=shape, prm=prm, tri=np.ascontiguousarray(tri),
                       tri_normal=np.ascontiguousarray(normal),
                       tri_group=np.asarray(group, dtype=np.int64),
                       tri_start=np.asarray(start, dtype=np.int64))


@nb.njit(cache=True, inline="always")
def closest_on_triangle(px, py, pz, tri, t):
    """Nearest point (cx, cy, cz) of triangle t of tri to the point, and its region: 0 the
    face, 1-3 a vertex (a, b, c), 4-6 an edge (ab, bc, ca) (Ericson 2005, 5.1.5)."""
    ax, ay, az = tri[t, 0, 0], tri[t, 0, 1], tri[t, 0, 2]
    bx, by, bz = tri[t, 1, 0], tri[t, 1, 1], tri[t, 1, 2]
    cx, cy, cz = tri[t, 2, 0], tri[t, 2, 1], tri[t, 2, 2]
    abx, aby, abz = bx - ax, by - ay, bz - az
    acx, acy, acz = cx - ax, cy - ay, cz - az
    apx, apy, apz = px - ax, py - ay, pz - az
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    if d1 <= 0.0 and d2 <= 0.0:
        return ax, ay, az, 1
    bpx, bpy, bpz = px - bx, py - by, pz - bz
    d3 = abx * bpx + aby * bpy + abz * bpz
    d4 = acx * bpx + acy * bpy + acz * bpz
    if d3 >= 0.0 and d4 <= d3:
        return bx, by, bz, 2
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        return ax + v * abx, ay + v * aby, az + v * abz, 4
    cpx, cpy, cpz = px - cx, py - cy, pz - cz
    d5 = abx * cpx + aby * cpy + abz * cpz
    d6 = acx * cpx + acy * cpy + acz * cpz
    if d6 >= 0.0 and d5 <= d6:
        return cx, cy, cz, 3
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        return ax + w * acx, ay + w * acy, az + w * acz, 6
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return bx + w * (cx - bx), by + w * (cy - by), bz + w * (cz - bz), 5
    den = 1.0 / (va + vb + vc)
    v = vb * den
    w = vc * den
    return (ax + abx * v + acx * w, ay + aby * v + acy * w, az + abz * v + acz * w, 0)


@nb.njit(cache=True)
def part_nearest(shape, prm, tri, tri_normal, tri_start, k, px, py, pz):
    """Nearest surface point of part k to the point (px, py, pz) (m, in the part's frame).

    Returns (gap, nx, ny, nz, cx, cy, cz, feature): gap the signed distance (m, positive
    outside the part), (nx, ny, nz) the unit normal from the surface towards the point (the
    part's outward normal where the point is outside), (cx, cy, cz) the surface point, and
    feature: the box face (0-5, FACE_NAMES) or the STL triangle (global index) it lies on; -1
    for a cylinder and a sphere (patch_of reads their angle from the normal)."""
    s = shape[k]
    x0, y0, z0 = prm[k, P_CX], prm[k, P_CY], prm[k, P_CZ]
    if s == SHAPE_CYLINDER or s == SHAPE_SPHERE:
        dx, dz = px - x0, pz - z0
        dy = py - y0 if s == SHAPE_SPHERE else 0.0
        d = math.sqrt(dx * dx + dy * dy + dz * dz)
        r = prm[k, P_RADIUS]
        if d < 1e-300:
            nx, ny, nz = 0.0, 0.0, 1.0
        else:
            nx, ny, nz = dx / d, dy / d, dz / d
        cy = y0 + r * ny if s == SHAPE_SPHERE else py
        return d - r, nx, ny, nz, x0 + r * nx, cy, z0 + r * nz, -1
    if s == SHAPE_BOX:
        c, sn = prm[k, P_COS], prm[k, P_SIN]
        dx, dy, dz = px - x0, py - y0, pz - z0
        q0, q1, q2 = c * dx + sn * dz, dy, -sn * dx + c * dz
        h0, h1, h2 = prm[k, P_HX], prm[k, P_HY], prm[k, P_HZ]
        e0, e1, e2 = abs(q0) - h0, abs(q1) - h1, abs(q2) - h2
        # the face: the axis the point lies furthest beyond (outside) or nearest to (inside)
        axis = 0
        if e1 > e0 and e1 >= e2:
            axis = 1
        elif e2 > e0 and e2 > e1:
            axis = 2
        if e0 > 0.0 or e1 > 0.0 or e2 > 0.0:
            k0, k1, k2 = min(max(q0, -h0), h0), min(max(q1, -h1), h1), min(max(q2, -h2), h2)
            m0, m1, m2 = q0 - k0, q1 - k1, q2 - k2
            gap = math.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
            m0, m1, m2 = m0 / gap, m1 / gap, m2 / gap
        else:
            k0, k1, k2 = q0, q1, q2
            m0, m1, m2 = 0.0, 0.0, 0.0
            if axis == 0:
                k0 = h0 if q0 >= 0.0 else -h0
                m0 = 1.0 if q0 >= 0.0 else -1.0
                gap = e0
            elif axis == 1:
                k1 = h1 if q1 >= 0.0 else -h1
                m1 = 1.0 if q1 >= 0.0 else -1.0
                gap = e1
            else:
                k2 = h2 if q2 >= 0.0 else -h2
                m2 = 1.0 if q2 >= 0.0 else -1.0
                gap = e2
        qa = (q0, q1, q2)[axis]
        face = 2 * axis + (1 if qa >= 0.0 else 0)
        return (gap, c * m0 - sn * m2, m1, sn * m0 + c * m2,
                x0 + c * k0 - sn * k2, y0 + k1, z0 + sn * k0 + c * k2, face)
    best, bt = np.inf, -1
    bx, by, bz = 0.0, 0.0, 0.0
    for t in range(tri_start[k], tri_start[k + 1]):
        cx, cy, cz, _ = closest_on_triangle(px, py, pz, tri, t)
        d2 = (px - cx) ** 2 + (py - cy) ** 2 + (pz - cz) ** 2
        if d2 < best:
            best, bt, bx, by, bz = d2, t, cx, cy, cz
    d = math.sqrt(best)
    sign = 1.0
    if (px - bx) * tri_normal[bt, 0] + (py - by) * tri_normal[bt, 1] + \
            (pz - bz) * tri_normal[bt, 2] < 0.0:
        sign = -1.0
    if d < 1e-300:
        nx, ny, nz = tri_normal[bt, 0], tri_normal[bt, 1], tri_normal[bt, 2]
    else:
        nx, ny, nz = sign * (px - bx) / d, sign * (py - by) / d, sign * (pz - bz) / d
    return sign * d, nx, ny, nz, bx, by, bz, bt


@nb.njit(cache=True)
def patch_of(shape, tri_group, nx, ny, nz, feature):
    """The patch (index within its part; patch_layout names them) of a surface point with
    outward normal (nx, ny, nz) and part_nearest's feature."""
    if shape == SHAPE_CYLINDER:
        a = math.atan2(nz, nx)
        if a < 0.0:
            a += 2.0 * math.pi
        return min(int(a / (2.0 * math.pi) * CYLINDER_SECTORS), CYLINDER_SECTORS - 1)
    if shape == SHAPE_SPHERE:
        polar = math.acos(min(max(nz, -1.0), 1.0))
        return min(int(polar / math.pi * SPHERE_BANDS), SPHERE_BANDS - 1)
    if shape == SHAPE_BOX:
        return feature
    return tri_group[feature]


def patch_layout(part: Part, slice_length_m: float) -> tuple[list[str], np.ndarray]:
    """Names and areas (m^2) of a part's patches, in patch_of's order (a cylinder's sectors
    over the slice's length)."""
    if part.shape == "cylinder":
        step = 360.0 / CYLINDER_SECTORS
        names = [f"{k * step:g}-{(k + 1) * step:g} deg" for k in range(CYLINDER_SECTORS)]
        area = np.full(CYLINDER_SECTORS,
                       2.0 * math.pi * part.radius / CYLINDER_SECTORS * slice_length_m)
        return names, area
    if part.shape == "sphere":
        edges = np.linspace(0.0, math.pi, SPHERE_BANDS + 1)
        names = [f"polar {math.degrees(a):g}-{math.degrees(b):g} deg"
                 for a, b in zip(edges[:-1], edges[1:])]
        return names, 2.0 * math.pi * part.radius**2 * (np.cos(edges[:-1]) - np.cos(edges[1:]))
    if part.shape == "box":
        hx, hy, hz = part.half_size
        face = np.array([hy * hz, hy * hz, hx * hz, hx * hz, hx * hy, hx * hy]) * 4.0
        return [f"face {f}" for f in FACE_NAMES], face
    packed = pack((part,))
    tri = packed.tri
    a = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    area = np.bincount(packed.tri_group, weights=a, minlength=6)
    return [f"normal {f}" for f in FACE_NAMES], area
