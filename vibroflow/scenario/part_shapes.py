"""The shapes of the scenario's parts ([[parts]]) as plain numpy geometry: the surface read from
an STL file, points spread over a surface, and the signed distance of points to a part (positive
outside it, in the media).  The scenario's checks (part_checks.py) use them before a run; the
kernels' packed form and the exact contact surfaces are vibroflow/tub/parts.py, which reads its
triangles here.

Conventions (SI, tub frame): a cylinder's axis runs along y through (center_x, center_z) and
spans the slice; a box has half edges size/2 in its own axes, turned by angle_y about y, a
point's box coordinates being (c (x - cx) + s (z - cz), y - cy, -s (x - cx) + c (z - cz)) with
c, s = cos, sin(angle_y); a sphere is a ball; an STL surface is its triangles times `scale`
shifted by `center`.
"""
from __future__ import annotations

import math
from functools import lru_cache
from pathlib import Path

import numpy as np


class ShapeError(ValueError):
    """An STL file that cannot be read as a closed surface (the message says why)."""


def read_stl_triangles(path: str | Path) -> np.ndarray:
    """The triangles (n, 3, 3) of a binary or ASCII STL file, in the file's units.  The
    surface must be closed (every edge shared by two triangles), so that it has an inside.
    A file is parsed once per content version (its modification time and size): the scenario's
    checks, the fill and every solver read the same part."""
    p = Path(path)
    if not p.is_file():
        raise ShapeError("no such file")
    st = p.stat()
    return _parsed_stl(str(p.resolve()), st.st_mtime_ns, st.st_size).copy()


def _check_stl_layout(p: Path, size: int) -> None:
    """ShapeError unless the file is laid out as an STL: binary, an 80-byte header, a triangle
    count n and 50 bytes a triangle (84 + 50 n bytes), or ASCII, starting with "solid"."""
    with open(p, "rb") as f:
        head = f.read(84)
    if len(head) == 84 and 84 + 50 * int.from_bytes(head[80:84], "little") == size:
        return
    if head.lstrip().startswith(b"solid"):
        return
    n = int.from_bytes(head[80:84], "little") if len(head) == 84 else 0
    raise ShapeError(f"not a readable STL file: {size} bytes, neither a binary STL (84 + 50 x "
                     f"its {n} triangles = {84 + 50 * n} bytes: truncated or padded) nor an "
                     "ASCII one (starting with 'solid')")


@lru_cache(maxsize=32)
def _parsed_stl(path: str, mtime_ns: int, size: int) -> np.ndarray:
    import trimesh  # lazy: only STL parts need it

    p = Path(path)
    _check_stl_layout(p, size)
    try:
        mesh = trimesh.load(str(p), file_type="stl", force="mesh", process=True)
    except Exception as e:  # trimesh raises many types for a damaged file
        raise ShapeError(f"not a readable STL file ({type(e).__name__}: {e})") from e
    tri = np.asarray(mesh.triangles, dtype=np.float64)
    if tri.ndim != 3 or tri.shape[0] == 0:
        raise ShapeError("holds no triangles")
    if not np.all(np.isfinite(tri)):
        raise ShapeError("has a vertex that is not a finite number")
    if not mesh.is_watertight:
        raise ShapeError("is not a closed surface (an edge belongs to one triangle only)")
    if mesh.volume < 0:
        tri = tri[:, ::-1]  # outward normals: the triangles' order turned
    return np.ascontiguousarray(tri)


def placed_triangles(spec, base: Path | None = None) -> np.ndarray:
    """An STL part's triangles (n, 3, 3) in the tub frame (m): the file's times spec.scale plus
    spec.center; `base` resolves a relative file name."""
    path = Path(spec.file)
    if base is not None and not path.is_absolute():
        path = base / path
    return read_stl_triangles(path) * spec.scale + np.asarray(spec.center, dtype=np.float64)


def _box_axes(spec):
    c, s = math.cos(spec.angle_y), math.sin(spec.angle_y)
    return c, s, 0.5 * np.asarray(spec.size, dtype=np.float64)


def to_box(spec, p: np.ndarray) -> np.ndarray:
    """Points (m, 3) in a box's own axes (centred, unturned)."""
    c, s, _ = _box_axes(spec)
    d = p - np.asarray(spec.center)
    return np.stack([c * d[:, 0] + s * d[:, 2], d[:, 1], -s * d[:, 0] + c * d[:, 2]], axis=1)


def from_box(spec, q: np.ndarray) -> np.ndarray:
    """Points (m, 3) from a box's own axes back to the tub frame (the inverse of to_box)."""
    c, s, _ = _box_axes(spec)
    x = c * q[:, 0] - s * q[:, 2]
    z = s * q[:, 0] + c * q[:, 2]
    return np.stack([x, q[:, 1], z], axis=1) + np.asarray(spec.center)


def _winding_number(p: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Generalised winding number of points (m, 3) about a closed surface (Van Oosterom &
    Strackee 1983 solid angle, summed over the triangles / 4 pi): 1 inside, 0 outside."""
    out = np.zeros(len(p))
    for k in range(0, len(p), 256):
        a = tri[None, :, 0, :] - p[k:k + 256, None, :]
        b = tri[None, :, 1, :] - p[k:k + 256, None, :]
        c = tri[None, :, 2, :] - p[k:k + 256, None, :]
        la, lb, lc = (np.linalg.norm(v, axis=2) for v in (a, b, c))
        det = np.einsum("ijk,ijk->ij", a, np.cross(b, c))
        den = (la * lb * lc + np.einsum("ijk,ijk->ij", a, b) * lc
               + np.einsum("ijk,ijk->ij", b, c) * la + np.einsum("ijk,ijk->ij", c, a) * lb)
        out[k:k + 256] = 2.0 * np.arctan2(det, den).sum(axis=1) / (4.0 * math.pi)
    return out


def _triangle_distance(p: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Unsigned distance (m) from points (m, 3) to the nearest of the triangles, through the
    nearest point of each triangle (its face, an edge or a vertex; Ericson 2005, 5.1.5)."""
    best = np.full(len(p), np.inf)
    for t in tri:
        a, b, c = t
        ab, ac, ap = b - a, c - a, p - a
        # barycentric clamp by projecting on the plane, then onto the edges when outside
        n = np.cross(ab, ac)
        nn = float(n @ n)
        q = p - np.outer(ap @ n / nn, n)
        d = np.linalg.norm(p - q, axis=1)
        v0, v1, v2 = ab, ac, q - a
        d00, d01, d11 = ab @ ab, ab @ ac, ac @ ac
        d20, d21 = v2 @ v0, v2 @ v1
        den = d00 * d11 - d01 * d01
        v = (d11 * d20 - d01 * d21) / den
        w = (d00 * d21 - d01 * d20) / den
        inside = (v >= 0) & (w >= 0) & (v + w <= 1)
        edge = np.minimum.reduce([_segment_distance(p, a, b), _segment_distance(p, b, c),
                                  _segment_distance(p, c, a)])
        best = np.minimum(best, np.where(inside, d, edge))
    return best


def _segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ab = b - a
    t = np.clip((p - a) @ ab / float(ab @ ab), 0.0, 1.0)
    return np.linalg.norm(p - (a + np.outer(t, ab)), axis=1)


def signed_distance(spec, p: np.ndarray, triangles: np.ndarray | None = None) -> np.ndarray:
    """Signed distance (m) from points (m, 3) to a part's surface: positive outside the part,
    negative inside.  An STL part needs its placed triangles."""
    p = np.atleast_2d(np.asarray(p, dtype=np.float64))
    cx, cy, cz = spec.center
    if spec.shape == "cylinder":
        return np.hypot(p[:, 0] - cx, p[:, 2] - cz) - spec.radius
    if spec.shape == "sphere":
        return np.linalg.norm(p - np.asarray(spec.center), axis=1) - spec.radius
    if spec.shape == "box":
        _, _, h = _box_axes(spec)
        q = np.abs(to_box(spec, p)) - h
        outside = np.linalg.norm(np.maximum(q, 0.0), axis=1)
        return outside + np.minimum(q.max(axis=1), 0.0)
    d = _triangle_distance(p, triangles)
    return np.where(_winding_number(p, triangles) > 0.5, -d, d)


def surface_points(spec, y_range: tuple[float, float], triangles: np.ndarray | None = None,
                   n: int = 64) -> np.ndarray:
    """Points (m, 3) spread over a part's surface, about n along each direction; a cylinder's
    are taken over y_range (m), the slice it spans."""
    cx, cy, cz = spec.center
    if spec.shape == "cylinder":
        a = np.linspace(0.0, 2.0 * math.pi, 4 * n, endpoint=False)
        y = np.linspace(y_range[0], y_range[1], 3)
        A, Y = np.meshgrid(a, y, indexing="ij")
        return np.stack([cx + spec.radius * np.cos(A).ravel(), Y.ravel(),
                         cz + spec.radius * np.sin(A).ravel()], axis=1)
    if spec.shape == "sphere":
        k = np.arange(4 * n * n) + 0.5  # a Fibonacci lattice: even over the sphere
        polar = np.arccos(1.0 - 2.0 * k / len(k))
        az = math.pi * (1.0 + 5.0**0.5) * k
        u = np.stack([np.cos(az) * np.sin(polar), np.sin(az) * np.sin(polar), np.cos(polar)], 1)
        return np.asarray(spec.center) + spec.radius * u
    if spec.shape == "box":
        _, _, h = _box_axes(spec)
        g = np.linspace(-1.0, 1.0, n)
        U, V = (a.ravel() for a in np.meshgrid(g, g, indexing="ij"))
        faces = []
        for axis in range(3):
            o1, o2 = [k for k in range(3) if k != axis]
            for sign in (-1.0, 1.0):
                q = np.zeros((len(U), 3))
                q[:, axis] = sign * h[axis]
                q[:, o1] = U * h[o1]
                q[:, o2] = V * h[o2]
                faces.append(q)
        return from_box(spec, np.concatenate(faces))
    w = np.linspace(0.0, 1.0, 4)
    B = np.array([(1 - u - v, u, v) for u in w for v in w if u + v <= 1.0])
    return np.einsum("bk,tkd->tbd", B, triangles).reshape(-1, 3)
