"""ParaView output: ball snapshots (.vtu point clouds), their time collection (.pvd) and the tub's
surface (.vtu quad mesh).

Files are written atomically (vibroflow.io.atomic: a temporary name in the target folder, moved
into place with os.replace), so a reader never sees half a file.  Coordinates are in m,
velocities in m/s, angular velocities in rad/s; the frame is whatever the caller passes (the
tub surface is in the tub frame, tub47.md "Frames": x across, y along the tub, z up, origin at
the lowest point of the inner surface).  In ParaView, show the balls with the "Point Gaussian"
representation (radius array "radius") or a Glyph filter with sphere glyphs scaled by "radius".
"""
from __future__ import annotations

import os

import numpy as np
from pyevtk.hl import pointsToVTK, unstructuredGridToVTK
from pyevtk.vtk import VtkGroup, VtkQuad

from vibroflow.io.atomic import atomic_path
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


def write_snapshot_vtu(path, positions, velocities, angular_velocities, radius, ids=None,
                       extra: dict | None = None) -> str:
    """Write one snapshot of N balls as a .vtu point cloud; returns the file's path.

    positions (N, 3) m, velocities (N, 3) m/s, angular_velocities (N, 3) rad/s, radius (N,) m,
    ids (N,) int (default 0..N-1); extra: more point arrays name -> (N,) or (N, 3).
    Point data: "velocity", "angular_velocity", "radius", "id" and the extras.
    """
    p = np.asarray(positions, dtype=float)
    v = np.asarray(velocities, dtype=float)
    w = np.asarray(angular_velocities, dtype=float)
    n = p.shape[0]
    ids = np.arange(n) if ids is None else np.asarray(ids)
    data = {
        "velocity": (_c(v[:, 0]), _c(v[:, 1]), _c(v[:, 2])),
        "angular_velocity": (_c(w[:, 0]), _c(w[:, 1]), _c(w[:, 2])),
        "radius": _c(np.broadcast_to(np.asarray(radius, dtype=float), (n,))),
        "id": _c(ids, np.int64),
    }
    for name, a in (extra or {}).items():
        a = np.asarray(a)
        data[name] = (tuple(_c(a[:, j]) for j in range(3)) if a.ndim == 2 else _c(a))
    return atomic_vtk(path, lambda base: pointsToVTK(base, _c(p[:, 0]), _c(p[:, 1]),
                                                      _c(p[:, 2]), data=data))


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


def write_tub_surface(path, geometry: TubGeometry, n_profile: int = 200) -> str:
    """Write the tub's U surface and partitions (tub frame, m) as a .vtu quad mesh with cell
    data "part" (0 U wall, 1 partition y = 0, 2 partition y = L_y); returns the file's path."""
    pts, quads, part = tub_surface_mesh(geometry, n_profile)
    conn = _c(quads.ravel(), np.int64)
    offsets = _c(np.arange(1, quads.shape[0] + 1) * 4, np.int64)
    types = np.full(quads.shape[0], VtkQuad.tid, dtype=np.uint8)
    return atomic_vtk(path, lambda base: unstructuredGridToVTK(
        base, _c(pts[:, 0]), _c(pts[:, 1]), _c(pts[:, 2]), connectivity=conn, offsets=offsets,
        cell_types=types, cellData={"part": _c(part, np.int64)}))
