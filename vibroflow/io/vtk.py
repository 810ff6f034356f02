"""ParaView output: ball snapshots (.vtu point clouds), their time collection (.pvd) and the tub's
surface (.vtu quad mesh).

Files are written atomically (vibroflow.io.atomic: a temporary name in the target folder, moved
into place with os.replace), so a reader never sees half a file.  Coordinates are in m,
velocities in m/s, angular velocities in rad/s, and every array's name carries its unit
(vibroflow.io.vtk_frame.FIELD_UNITS).  The balls and the tub's surface are written in one frame,
the tub's (tub47.md "Frames": x across, y along the tub, z up, origin at the lowest point of the
inner surface) or the lab's (vibroflow.io.vtk_frame).  In ParaView, show the balls with the
"Point Gaussian" representation (radius array "radius_m") or a Glyph filter with sphere glyphs
scaled by "radius_m".
"""
from __future__ import annotations

import os

import numpy as np
from pyevtk.hl import pointsToVTK, unstructuredGridToVTK
from pyevtk.vtk import VtkGroup, VtkLine, VtkQuad

from vibroflow.io.atomic import atomic_path
from vibroflow.io.vtk_frame import ball_frame, tub_to_lab_points
from vibroflow.tub.geometry import TubGeometry


def atomic_vtk(path, writer, suffix: str = ".vtu") -> str:
    """Run writer(base_without_extension) (a pyevtk writer, which appends `suffix` and returns
    the file it wrote) on a temporary name, then move the file to path: a reader never sees a
    half-written file."""
    path = os.fspath(path)
    final = path if path.endswith(suffix) else path + suffix
    with atomic_path(final, suffix=suffix) as tmp:
        tmp = os.fspath(tmp)
        written = writer(tmp[:-len(suffix)])
        if os.path.abspath(written) != os.path.abspath(tmp):
            raise RuntimeError(f"the VTK writer wrote {written}, not {tmp}")
    return final


def _c(a, dtype=np.float64):
    return np.ascontiguousarray(np.asarray(a), dtype=dtype)


def _field_data(field_data: dict | None) -> dict | None:
    if not field_data:
        return None
    return {name: _c(np.atleast_1d(np.asarray(a, dtype=float))) for name, a in field_data.items()}


def write_points_vtu(path, positions, point_data: dict, field_data: dict | None = None) -> str:
    """Write N points (positions (N, 3) m) as a .vtu point cloud; returns the file's path.

    point_data: name -> (N,) or (N, 3) array; field_data: name -> a number or a short array
    (the snapshot's time, the tub's pose).  The names carry their SI units
    (vibroflow.io.vtk_frame.FIELD_UNITS)."""
    p = np.asarray(positions, dtype=float)
    data = {}
    for name, a in point_data.items():
        a = np.asarray(a)
        if a.ndim == 2:
            data[name] = tuple(_c(a[:, j]) for j in range(3))
        else:
            data[name] = _c(a, np.int64 if a.dtype.kind in "iu" else np.float64)
    fd = _field_data(field_data)
    return atomic_vtk(path, lambda base: pointsToVTK(base, _c(p[:, 0]), _c(p[:, 1]),
                                                      _c(p[:, 2]), data=data, fieldData=fd))


def write_ball_frame(path, frame: str, pos_lab, vel_lab, omg_lab, radius, pose6, pivot,
                     time_s: float, ids=None) -> str:
    """Write one snapshot of N balls given in the lab (m, m/s, rad/s) as a .vtu in `frame`
    ("tub" or "lab", vibroflow.io.vtk_frame.ball_frame) at the tub's pose `pose6`; point data
    velocity_relative_m_per_s, velocity_lab_m_per_s, angular_velocity_rad_per_s,
    angular_velocity_relative_rad_per_s, radius_m, id; field data time_s and the pose
    (tub_X_m, tub_Z_m, tub_theta_rad)."""
    pos, fields = ball_frame(frame, pos_lab, vel_lab, omg_lab, pose6, pivot)
    n = pos.shape[0]
    fields["radius_m"] = np.broadcast_to(np.asarray(radius, dtype=float), (n,))
    fields["id"] = np.arange(n, dtype=np.int64) if ids is None else np.asarray(ids, np.int64)
    return write_points_vtu(path, pos, fields, frame_field_data(time_s, pose6))


def frame_field_data(time_s: float, pose6) -> dict:
    """Field data of a frame: its time (s) and the tub's pose then (m, m, rad)."""
    return {"time_s": float(time_s), "tub_X_m": float(pose6[0]), "tub_Z_m": float(pose6[1]),
            "tub_theta_rad": float(pose6[2])}


def write_pvd(path, entries) -> str:
    """Write a ParaView collection (.pvd) of (time s, filename) entries with pyevtk's VtkGroup,
    atomically; returns its path.  Filenames are written relative to the .pvd's folder (a
    relative name is taken as lying in that folder)."""
    path = os.fspath(path)
    folder = os.path.dirname(os.path.abspath(path))
    with atomic_path(path, suffix=".pvd") as tmp:
        group = VtkGroup(os.fspath(tmp)[: -len(".pvd")])
        for t, fname in entries:
            group.addFile(os.path.join(folder, os.fspath(fname)), sim_time=float(t))
        group.save()
    return path


def tub_surface_mesh(geometry: TubGeometry, n_profile: int = 200):
    """Quad mesh of the tub in the tub frame: the U surface extruded from y = 0 to L_y, and (unless
    periodic) the two partitions at y = 0 and y = L_y, each as quads between mirror chords of the
    U profile.  Returns (points (P, 3), quads (Q, 4) int, part (Q,) int: 0 U wall, 1 partition
    y = 0, 2 partition y = L_y)."""
    n = int(n_profile) + (int(n_profile) % 2)  # even: profile point j mirrors n-1-j
    prof = geometry.profile(n)  # (n, 2) x, z from the left rim through the bottom
    L = geometry.length
    pts = [np.column_stack([prof[:, 0], np.zeros(n), prof[:, 1]]),
           np.column_stack([prof[:, 0], np.full(n, L), prof[:, 1]])]
    j = np.arange(n - 1)
    quads = [np.column_stack([j, j + 1, n + j + 1, n + j])]
    part = [np.zeros(n - 1, dtype=np.int64)]
    if not geometry.periodic:
        m = np.arange(n // 2 - 1)  # chord m joins j = m and n-1-m (same height)
        for side, base in ((1, 0), (2, n)):
            quads.append(np.column_stack([base + m, base + m + 1, base + n - 2 - m,
                                          base + n - 1 - m]))
            part.append(np.full(m.size, side, dtype=np.int64))
    return np.vstack(pts), np.vstack(quads).astype(np.int64), np.concatenate(part)


def write_tub_surface(path, geometry: TubGeometry, n_profile: int = 200, pose6=None,
                      pivot=(0.0, 0.0), time_s: float | None = None) -> str:
    """Write the tub's U surface and partitions (m) as a .vtu quad mesh with cell data "part"
    (0 U wall, 1 partition y = 0, 2 partition y = L_y); returns the file's path.  In the tub
    frame unless pose6 (vibroflow.io.vtk_frame.pose_at) is given: then moved into the lab by
    the tub's rigid motion at that pose (pivot: the motion's pivot (x, z) m), with field data
    time_s and the pose."""
    pts, quads, part = tub_surface_mesh(geometry, n_profile)
    fd = None
    if pose6 is not None:
        pts = tub_to_lab_points(pts, pose6, pivot)
        fd = _field_data(frame_field_data(0.0 if time_s is None else time_s, pose6))
    conn = _c(quads.ravel(), np.int64)
    offsets = _c(np.arange(1, quads.shape[0] + 1) * 4, np.int64)
    types = np.full(quads.shape[0], VtkQuad.tid, dtype=np.uint8)
    return atomic_vtk(path, lambda base: unstructuredGridToVTK(
        base, _c(pts[:, 0]), _c(pts[:, 1]), _c(pts[:, 2]), connectivity=conn, offsets=offsets,
        cell_types=types, cellData={"part": _c(part, np.int64)}, fieldData=fd))


def write_section_lines(path, segments: list[np.ndarray], y: float, pose6=None,
                        pivot=(0.0, 0.0), time_s: float | None = None) -> str:
    """Write outlines in the plane y (m) as a .vtu of line cells with cell data "part" (the
    index of each outline in `segments`, a list of (M, 2, 2) arrays of ((start, end), (x, z))
    m in the tub frame); moved into the lab at the pose pose6 as write_tub_surface does."""
    part = np.concatenate([np.full(len(s), k, np.int64) for k, s in enumerate(segments)]
                          or [np.zeros(0, np.int64)])
    seg = (np.concatenate(segments) if segments else np.zeros((0, 2, 2))).reshape(-1, 2)
    pts = np.column_stack([seg[:, 0], np.full(len(seg), y), seg[:, 1]])
    fd = None
    if pose6 is not None:
        pts = tub_to_lab_points(pts, pose6, pivot)
        fd = _field_data(frame_field_data(0.0 if time_s is None else time_s, pose6))
    n = part.size
    return atomic_vtk(path, lambda base: unstructuredGridToVTK(
        base, _c(pts[:, 0]), _c(pts[:, 1]), _c(pts[:, 2]),
        connectivity=_c(np.arange(2 * n), np.int64),
        offsets=_c(np.arange(1, n + 1) * 2, np.int64),
        cell_types=np.full(n, VtkLine.tid, dtype=np.uint8),
        cellData={"part": _c(part, np.int64)}, fieldData=fd))
