"""The scenario's parts (vibroflow.tub.parts) as rigid obstacles of the 2D continuum.

The continuum is the slice's x-z section, averaged over its depth L_y; a part is an obstacle
there when it spans the slice: a cylinder (its axis runs along y from partition to partition),
a box whose y extent covers 0 .. L_y, an STL surface whose triangles reach both partitions (a
prism across the slice).  Its section is taken at the slice's middle y = L_y / 2
(tub.parts.part_nearest there).  A part shorter than the slice (a sphere, a shorter box or STL)
would block only part of the depth the continuum averages over; weighting its wall law by its
share of the depth would make it a porous obstacle that the depth-averaged material partly
passes through, a model of its own, so such a part is refused with a one-line error naming it
(`continuum_parts`).  A part held still in the lab (frame = "lab") moves through the tub-fixed
grid and mesh of both formulations every cycle; it is refused as well.

Both formulations give the part the U wall's law and numbers (stiffness, friction, damping):
the material point method as a penalty wall (boundary.PartWall), the Eulerian mesh as cells
outside its domain with a wall layer along the part (eulerian/mesh.py).  A packed box is
extended far along y (its section is what counts; a point deep inside a wide box then never
finds a y face nearer than its x or z faces).
"""
from __future__ import annotations

import math

import numpy as np

from vibroflow.errors import InputError
from vibroflow.tub.parts import P_CX, P_CZ, P_HY, Part, pack, parts_of

from .boundary import part_gaps, part_section_nearest_np

#: a box's or STL's y extent may miss a partition by this much (m) and still span the slice
SPAN_TOLERANCE_M = 1.0e-9
#: a packed box's half extent along y (m): far beyond any slice
FAR_Y_M = 1.0e3


def continuum_parts(scenario) -> tuple[Part, ...]:
    """The scenario's parts as the continuum takes them (module docstring): each spans the
    slice and is fixed in the tub frame, else InputError (one line naming the part)."""
    parts = parts_of(scenario)
    if not parts:
        return parts
    L = scenario.tub.length
    for i, p in enumerate(parts):
        where = f"parts.{i} (\"{p.name}\")"
        if p.frame != "tub":
            raise InputError(f"{where}.frame = \"{p.frame}\": the continuum takes only parts "
                             "fixed in the tub (frame = \"tub\"); its grid and mesh are fixed in "
                             "the tub frame, through which a lab-fixed part would move")
        if p.shape == "sphere":
            raise InputError(f"{where}.shape = \"sphere\": the 2D continuum averages over the "
                             f"slice's depth {L:g} m and takes only parts spanning it (a "
                             "cylinder, or a box or STL from y = 0 to the slice's length)")
        if p.shape == "box":
            lo, hi = p.center[1] - p.half_size[1], p.center[1] + p.half_size[1]
        elif p.shape == "stl":
            lo, hi = float(p.triangles[:, :, 1].min()), float(p.triangles[:, :, 1].max())
        else:
            continue
        if lo > SPAN_TOLERANCE_M or hi < L - SPAN_TOLERANCE_M:
            raise InputError(f"{where}: spans y = {lo:.4g} .. {hi:.4g} m; the 2D continuum "
                             f"averages over the slice's depth and takes only parts spanning it, "
                             f"y = 0 .. {L:g} m")
    return parts


def packed_section(parts: tuple[Part, ...]) -> tuple:
    """The parts packed for the kernels (boundary.NO_PARTS' layout: shape, prm, tri,
    tri_normal, tri_start), a box's y extent made far (module docstring)."""
    packed = pack(parts)
    prm = packed.prm.copy()
    for k, p in enumerate(parts):
        if p.shape == "box":
            prm[k, P_HY] = FAR_Y_M
    return (packed.shape, prm, packed.tri, packed.tri_normal, packed.tri_start)


def torque_on_part(packed: tuple, k: int, y: float, x: np.ndarray,
                   f_on_material: np.ndarray) -> float:
    """The y component (N m per metre of slice) of the torque on part k about its centre of
    the forces f_on_material (M, 2) (N/m, x and z) that its wall law applies to the material
    at the points or wall cells x (M, 2) (m, tub frame): their reactions -f, each acting at
    the nearest surface point of the part's section at y (the contact point), summed as
    (r x F)_y = r_z F_x - r_x F_z with r from the centre (the DEM's convention, dem/parts.py).
    The x and z components vanish: the depth-averaged forces spread evenly along the part's
    span on either side of its centre."""
    if x.shape[0] == 0:
        return 0.0
    g, nx, nz = part_section_nearest_np(packed, k, y, x[:, 0], x[:, 1])
    prm = packed[1]
    rx = x[:, 0] - g * nx - prm[k, P_CX]
    rz = x[:, 1] - g * nz - prm[k, P_CZ]
    return float(np.sum(rz * -f_on_material[:, 0] - rx * -f_on_material[:, 1]))


def section_bounds(part: Part) -> tuple[float, float, float, float]:
    """(xmin, xmax, zmin, zmax) (m) bounding the part's x-z section."""
    cx, _, cz = part.center
    if part.shape == "cylinder":
        r = part.radius
        return cx - r, cx + r, cz - r, cz + r
    if part.shape == "box":
        hx, _, hz = part.half_size
        c, s = math.cos(part.angle_y), math.sin(part.angle_y)
        ex, ez = abs(c) * hx + abs(s) * hz, abs(s) * hx + abs(c) * hz
        return cx - ex, cx + ex, cz - ez, cz + ez
    t = part.triangles
    return (float(t[:, :, 0].min()), float(t[:, :, 0].max()), float(t[:, :, 2].min()),
            float(t[:, :, 2].max()))


def section_segments(part: Part, y: float, n_arc: int = 72) -> np.ndarray:
    """The outline of the part's section at y as line segments (M, 2, 2) ((start, end), (x, z)
    m): a cylinder's circle as n_arc chords, a box's four edges, an STL's triangles cut by the
    plane y (each triangle crossing it gives one segment)."""
    cx, _, cz = part.center
    if part.shape == "cylinder":
        a = np.linspace(0.0, 2.0 * math.pi, n_arc + 1)
        pts = np.stack([cx + part.radius * np.cos(a), cz + part.radius * np.sin(a)], axis=1)
        return np.stack([pts[:-1], pts[1:]], axis=1)
    if part.shape == "box":
        hx, _, hz = part.half_size
        c, s = math.cos(part.angle_y), math.sin(part.angle_y)
        q = np.array([[-hx, -hz], [hx, -hz], [hx, hz], [-hx, hz], [-hx, -hz]])
        # the box's axes turned by angle_y about y (x towards z), as tub.parts.part_nearest
        pts = np.stack([cx + c * q[:, 0] - s * q[:, 1], cz + s * q[:, 0] + c * q[:, 1]], axis=1)
        return np.stack([pts[:-1], pts[1:]], axis=1)
    segs = []
    for tri in part.triangles:
        d = tri[:, 1] - y
        cut = []
        for i in range(3):
            a, b = tri[i], tri[(i + 1) % 3]
            da, db = d[i], d[(i + 1) % 3]
            if (da < 0.0) != (db < 0.0):
                w = da / (da - db)
                cut.append([a[0] + w * (b[0] - a[0]), a[2] + w * (b[2] - a[2])])
        if len(cut) == 2:
            segs.append(cut)
    return np.array(segs, dtype=float).reshape(-1, 2, 2)


def section_gaps(parts: tuple[Part, ...], packed: tuple, y: float, x: np.ndarray,
                 z: np.ndarray) -> np.ndarray:
    """The least gap (m; negative inside) of the points (x, z) from any part's section at y;
    +inf without parts."""
    pts = np.ascontiguousarray(np.stack([np.ravel(x), np.ravel(z)], axis=1), dtype=float)
    out = np.full(pts.shape[0], np.inf)
    g = np.zeros(pts.shape[0])
    for k in range(len(parts)):
        part_gaps(packed, k, float(y), pts, g)
        np.minimum(out, g, out=out)
    return out.reshape(np.shape(x))


def section_area_below(parts: tuple[Part, ...], packed: tuple, y: float, h: float,
                       cells: int = 400) -> float:
    """Area (m^2) of the parts' sections below the height h (m), counted on a lattice of
    `cells` x `cells` squares over each section's bounding box (the error is about a square's
    side times the section's perimeter)."""
    area = 0.0
    for k, p in enumerate(parts):
        x0, x1, z0, z1 = section_bounds(p)
        if h <= z0:
            continue
        sx, sz = (x1 - x0) / cells, (z1 - z0) / cells
        X, Z = np.meshgrid(x0 + (np.arange(cells) + 0.5) * sx,
                           z0 + (np.arange(cells) + 0.5) * sz, indexing="ij")
        inside = section_gaps((p,), _one(packed, k), y, X, Z) < 0.0
        area += float(np.count_nonzero(inside & (Z < h))) * sx * sz
    return area


def _one(packed: tuple, k: int) -> tuple:
    """Part k of the packed parts as a packing of its own (part index 0)."""
    shape, prm, tri, tri_normal, tri_start = packed
    a, b = int(tri_start[k]), int(tri_start[k + 1])
    return (shape[k:k + 1].copy(), prm[k:k + 1].copy(), np.ascontiguousarray(tri[a:b]),
            np.ascontiguousarray(tri_normal[a:b]), np.array([0, b - a], np.int64))


def bed_height_around(height_of_area, area: float, parts: tuple[Part, ...], packed: tuple,
                      y: float) -> float:
    """The bed height (m) whose U section below it, less the parts' sections below it, is the
    bed's area (m^2): height_of_area(a) the U's height for an area a (bed.bed_height), iterated
    to a fixed point (each part's section adds at most its width over the U's per metre)."""
    h = height_of_area(area)
    for _ in range(30):
        h_new = height_of_area(area + section_area_below(parts, packed, y, h))
        if abs(h_new - h) < 1.0e-9:
            return h_new
        h = h_new
    return h
