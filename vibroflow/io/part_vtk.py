"""ParaView files of the parts in the bed: DIR/vtk/part_<name>.vtu, each part's surface as
triangles (m, where the scenario places it, in the frame the part is fixed in; carried by the
tub's motion into the other frame at a given pose) with its impact map from parts.nc as cell
data, one value per triangle from the patch it lies on:

    patch                          the patch index (vibroflow.tub.parts.patch_layout)
    impact_rate_per_area_1_per_m2_s  impacts per unit area and time (1/(m^2 s))
    normal_speed_mean_m_per_s      mean normal impact speed (m/s)
    energy_flux_W_per_m2           impact energy per unit area and time (W/m^2)

A cylinder is triangulated over the slice's length (SUB facets per patch around it), a sphere by
its polar bands and 36 meridians, a box by two triangles per face, an STL as it is.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from pyevtk.hl import unstructuredGridToVTK
from pyevtk.vtk import VtkTriangle

from ..tub.motion import lab_to_tub_np
from ..tub.parts import CYLINDER_SECTORS, SPHERE_BANDS, Part, pack
from .vtk import _c, _field_data, atomic_vtk, frame_field_data
from .vtk_frame import tub_to_lab_points

SUB = 4            # facets per cylinder sector
MERIDIANS = 36     # of a sphere's triangulation

#: cell field -> parts.nc variable
MAP_FIELDS = {"impact_rate_per_area_1_per_m2_s": "impact_rate_per_area",
              "normal_speed_mean_m_per_s": "normal_speed_mean",
              "energy_flux_W_per_m2": "energy_flux"}


def _quads_to_triangles(a, b, c, d):
    """Two triangles (a, b, c), (a, c, d) per quad (arrays (n, 3) of corners)."""
    return np.concatenate([np.stack([a, b, c], axis=1), np.stack([a, c, d], axis=1)])


def part_surface(part: Part, slice_length_m: float) -> tuple[np.ndarray, np.ndarray]:
    """(triangles (m, 3, 3) m in the part's frame, patch (m,) int) of a part's surface."""
    x0, y0, z0 = part.center
    if part.shape == "cylinder":
        n = CYLINDER_SECTORS * SUB
        a = np.linspace(0.0, 2.0 * math.pi, n + 1)
        x, z = x0 + part.radius * np.cos(a), z0 + part.radius * np.sin(a)

        def ring(y):
            return np.column_stack([x, np.full(n + 1, y), z])

        lo, hi = ring(0.0), ring(slice_length_m)
        tri = _quads_to_triangles(lo[:-1], lo[1:], hi[1:], hi[:-1])
        patch = np.tile(np.arange(n) // SUB, 2)
        return tri, patch
    if part.shape == "sphere":
        polar = np.linspace(0.0, math.pi, SPHERE_BANDS + 1)
        az = np.linspace(0.0, 2.0 * math.pi, MERIDIANS + 1)
        P, A = np.meshgrid(polar, az, indexing="ij")
        pts = np.stack([x0 + part.radius * np.sin(P) * np.cos(A),
                        y0 + part.radius * np.sin(P) * np.sin(A),
                        z0 + part.radius * np.cos(P)], axis=-1)
        tri = _quads_to_triangles(pts[:-1, :-1].reshape(-1, 3), pts[1:, :-1].reshape(-1, 3),
                                  pts[1:, 1:].reshape(-1, 3), pts[:-1, 1:].reshape(-1, 3))
        band = np.repeat(np.arange(SPHERE_BANDS), MERIDIANS)
        return tri, np.tile(band, 2)
    if part.shape == "box":
        h = np.asarray(part.half_size)
        c, s = math.cos(part.angle_y), math.sin(part.angle_y)
        tris, patch = [], []
        for face in range(6):
            axis, sign = face // 2, (1.0 if face % 2 else -1.0)
            u, v = [k for k in range(3) if k != axis]
            corners = []
            for du, dv in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                q = np.zeros(3)
                q[axis], q[u], q[v] = sign * h[axis], du * h[u], dv * h[v]
                corners.append([x0 + c * q[0] - s * q[2], y0 + q[1], z0 + s * q[0] + c * q[2]])
            a, b, cc, d = (np.array([p]) for p in corners)
            tris.append(_quads_to_triangles(a, b, cc, d))
            patch += [face, face]
        return np.concatenate(tris), np.array(patch)
    packed = pack((part,))
    return packed.tri.copy(), packed.tri_group.copy()


def write_part_surface(path: Path, part: Part, slice_length_m: float, maps: dict,
                       pose6=None, pivot=(0.0, 0.0), time_s: float | None = None) -> str:
    """Write a part's surface with its impact map: `maps` holds MAP_FIELDS' parts.nc variables
    of this part, one value per patch (NaN where nothing is known).  Where the scenario places
    it unless pose6 (vibroflow.io.vtk_frame.pose_at) is given: then the surface is carried
    from the frame it is fixed in to the other one by the tub's rigid motion at that pose
    (pivot: the motion's pivot (x, z) m), a tub-fixed part into the lab and a lab-fixed one
    into the tub frame, with field data time_s and the pose."""
    tri, patch = part_surface(part, slice_length_m)
    pts = tri.reshape(-1, 3)
    fd = None
    if pose6 is not None:
        if part.frame == "tub":
            pts = tub_to_lab_points(pts, pose6, pivot)
        else:
            pts = lab_to_tub_np(pts, float(pose6[0]), float(pose6[1]), float(pose6[2]), pivot)
        fd = _field_data(frame_field_data(0.0 if time_s is None else time_s, pose6))
    conn = _c(np.arange(pts.shape[0]), np.int64)
    offsets = _c(np.arange(1, tri.shape[0] + 1) * 3, np.int64)
    types = np.full(tri.shape[0], VtkTriangle.tid, dtype=np.uint8)
    cells = {"patch": _c(patch, np.int64)}
    for field, var in MAP_FIELDS.items():
        values = np.asarray(maps[var], dtype=float)
        cells[field] = _c(values[patch])
    return atomic_vtk(path, lambda base: unstructuredGridToVTK(
        base, _c(pts[:, 0]), _c(pts[:, 1]), _c(pts[:, 2]), connectivity=conn, offsets=offsets,
        cell_types=types, cellData=cells, fieldData=fd))
