"""Triangulated surfaces of the tub for other DEM codes (STL, SI units: m).

The tub's inner surface (vibroflow.tub.geometry) is cut into flat triangles:

* the U: the profile (half circle of radius R centred at (0, R), vertical walls x = +-R up to the
  rim) extruded along y from 0 to L_y.  The half circle is split into n equal arcs with n the
  smallest number whose chords deviate from the circle by less than `max_sagitta`
  (sagitta R (1 - cos(pi / 2n)), default 0.05 mm, so n = 61 for R = 0.15 m); every vertex lies on
  the analytic surface.  The vertical walls are split into pieces about as long as a chord, and
  the length into strips no longer than two chords, so no triangle is needle-like (LIGGGHTS
  warns about angles under 0.5 degree).
* the partitions: the rectangles [-R, R] x [0, rim] (x, z) at y = 0 and y = L_y, two triangles
  each.

Every facet's normal points into the tub, from the wall towards the balls (the convention of
vibroflow.dem.walls), and the vertices of each triangle are ordered counterclockwise about it
(right-hand rule), as STL requires.  LIGGGHTS reads ASCII STL only; `write_stl` can also write
binary STL for other tools.
"""
from __future__ import annotations

import math
import struct
from pathlib import Path

import numpy as np

from vibroflow.io.atomic import write_bytes_atomic
from vibroflow.tub.geometry import TubGeometry

#: largest chord-to-circle deviation of the U's facets (m)
DEFAULT_MAX_SAGITTA = 5.0e-5


def arc_segments(radius: float, max_sagitta: float = DEFAULT_MAX_SAGITTA) -> int:
    """Smallest number n of equal chords on the half circle of `radius` (m) whose sagitta
    R (1 - cos(pi / (2 n))) is below `max_sagitta` (m)."""
    if not (radius > 0 and max_sagitta > 0):
        raise ValueError(f"radius = {radius}, max_sagitta = {max_sagitta}: both must be > 0")
    if max_sagitta >= radius:
        return 1
    half_angle = math.acos(1.0 - max_sagitta / radius)  # half the angle one chord may span
    n = max(1, math.ceil(0.5 * math.pi / half_angle))
    while radius * (1.0 - math.cos(0.5 * math.pi / n)) >= max_sagitta:
        n += 1
    return n


def sagitta(radius: float, n: int) -> float:
    """Largest distance (m) between the half circle and its n-chord polygon."""
    return radius * (1.0 - math.cos(0.5 * math.pi / n))


def u_profile(geometry: TubGeometry, max_sagitta: float = DEFAULT_MAX_SAGITTA) -> np.ndarray:
    """Vertices (P, 2) of the faceted U profile (x, z), from the left rim down through the bottom
    to the right rim.  All of them lie on the analytic profile."""
    R, rim = geometry.radius, geometry.rim_height
    n = arc_segments(R, max_sagitta)
    chord = 2.0 * R * math.sin(0.5 * math.pi / n)
    a = np.linspace(-0.5 * math.pi, 0.5 * math.pi, n + 1)  # angle from the downward vertical
    arc = np.stack([R * np.sin(a), R - R * np.cos(a)], axis=1)
    arc[0] = (-R, R)  # exact ends (no round-off at the tangent points)
    arc[-1] = (R, R)
    side = rim - R
    if side > 0:
        m = max(1, math.ceil(side / chord))
        zs = np.linspace(R, rim, m + 1)[1:]
        left = np.stack([np.full(m, -R), zs[::-1]], axis=1)
        right = np.stack([np.full(m, R), zs], axis=1)
        return np.concatenate([left, arc, right])
    return arc


def u_triangles(geometry: TubGeometry, max_sagitta: float = DEFAULT_MAX_SAGITTA) -> np.ndarray:
    """Triangles (T, 3, 3) of the U surface (vertex coordinates x, y, z in m, tub frame), their
    normals pointing into the tub."""
    prof = u_profile(geometry, max_sagitta)
    L = geometry.length
    chord = float(np.max(np.hypot(*np.diff(prof, axis=0).T)))
    ny = max(1, math.ceil(L / (2.0 * chord)))
    ys = np.linspace(0.0, L, ny + 1)
    tris = []
    for k in range(prof.shape[0] - 1):
        (x0, z0), (x1, z1) = prof[k], prof[k + 1]
        for j in range(ny):
            ya, yb = ys[j], ys[j + 1]
            p00 = (x0, ya, z0)
            p10 = (x1, ya, z1)
            p01 = (x0, yb, z0)
            p11 = (x1, yb, z1)
            # The profile runs left rim -> bottom -> right rim; with the tangent t = p1 - p0 in
            # x-z and e_y, the inward normal is t x e_y (e.g. t = +x at the bottom gives +z...
            # t x e_y = (tx, 0, tz) x (0, 1, 0) = (-tz, 0, tx)), so (p00, p10, p11) is
            # counterclockwise about it.
            tris.append((p00, p10, p11))
            tris.append((p00, p11, p01))
    return np.asarray(tris, dtype=float)


def partition_triangles(geometry: TubGeometry) -> np.ndarray:
    """Triangles (4, 3, 3) of the two partitions, rectangles [-R, R] x [0, rim] in x-z at y = 0
    (normal +y) and y = L_y (normal -y)."""
    R, rim, L = geometry.radius, geometry.rim_height, geometry.length
    a, b, c, d = (-R, 0.0), (R, 0.0), (R, rim), (-R, rim)

    def at(y, p):
        return (p[0], y, p[1])

    # at y = 0 the normal is +y: counterclockwise seen from +y means (x, z) turning from z to x,
    # i.e. clockwise in the x-z plane seen with x right and z up: a -> d -> c
    lo = [(at(0.0, a), at(0.0, d), at(0.0, c)), (at(0.0, a), at(0.0, c), at(0.0, b))]
    hi = [(at(L, a), at(L, b), at(L, c)), (at(L, a), at(L, c), at(L, d))]
    return np.asarray(lo + hi, dtype=float)


def facet_normals(tris: np.ndarray) -> np.ndarray:
    """Unit normals (T, 3) of triangles (T, 3, 3) by the right-hand rule."""
    tris = np.asarray(tris, dtype=float)
    n = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def stl_text(tris: np.ndarray, name: str = "surface") -> str:
    """ASCII STL of triangles (T, 3, 3); normals from the vertex order."""
    normals = facet_normals(tris)
    lines = [f"solid {name}"]
    for t, n in zip(np.asarray(tris, dtype=float), normals):
        lines.append(f"  facet normal {n[0]:.9e} {n[1]:.9e} {n[2]:.9e}")
        lines.append("    outer loop")
        for v in t:
            lines.append(f"      vertex {v[0]:.12e} {v[1]:.12e} {v[2]:.12e}")
        lines.append("    endloop")
        lines.append("  endfacet")
    lines.append(f"endsolid {name}")
    return "\n".join(lines) + "\n"


def stl_binary(tris: np.ndarray, name: str = "surface") -> bytes:
    """Binary STL (float32) of triangles (T, 3, 3)."""
    tris = np.asarray(tris, dtype=float)
    normals = facet_normals(tris)
    header = name.encode("ascii", "replace")[:80].ljust(80, b" ")
    rec = np.zeros(len(tris), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])
    rec["n"] = normals
    rec["v"] = tris
    return header + struct.pack("<I", len(tris)) + rec.tobytes()


def write_stl(path, tris: np.ndarray, name: str = "surface", binary: bool = False) -> Path:
    """Write triangles (T, 3, 3) to an STL file atomically; returns the path."""
    path = Path(path)
    data = stl_binary(tris, name) if binary else stl_text(tris, name).encode("ascii")
    return write_bytes_atomic(path, data)


def read_stl(path) -> tuple[np.ndarray, np.ndarray]:
    """Triangles (T, 3, 3) and stored normals (T, 3) of an ASCII or binary STL file."""
    data = Path(path).read_bytes()
    if data[:5] == b"solid" and b"facet" in data[:1024]:
        normals, verts = [], []
        for line in data.decode("ascii").splitlines():
            w = line.split()
            if not w:
                continue
            if w[0] == "facet":
                normals.append([float(x) for x in w[2:5]])
            elif w[0] == "vertex":
                verts.append([float(x) for x in w[1:4]])
        return np.asarray(verts).reshape(-1, 3, 3), np.asarray(normals).reshape(-1, 3)
    (count,) = struct.unpack("<I", data[80:84])
    rec = np.frombuffer(data[84:84 + 50 * count],
                        dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])
    return rec["v"].astype(float), rec["n"].astype(float)


def write_tub_meshes(geometry: TubGeometry, out_dir, max_sagitta: float = DEFAULT_MAX_SAGITTA,
                     binary: bool = False) -> dict[str, Path]:
    """Write tub_u.stl (the U) and, unless the length is periodic, partitions.stl into out_dir.
    Returns {"u": path, "partitions": path}."""
    out_dir = Path(out_dir)
    paths = {"u": write_stl(out_dir / "tub_u.stl", u_triangles(geometry, max_sagitta), "tub_u",
                            binary)}
    if not geometry.periodic:
        paths["partitions"] = write_stl(out_dir / "partitions.stl",
                                        partition_triangles(geometry), "partitions", binary)
    return paths
