"""What the parts of a LIGGGHTS run receive, as dem.h5's /part_impacts and /part_loads (the DEM's
own layout, vibroflow.dem.output), from the deck's dumps (vibroflow.liggghts.part_deck).

Impacts (`part_impacts`): post/part_contacts.dump holds, every step from one step before the
averaging window, the balls near the parts.  A ball touches part k at a step when its centre
is closer than its radius to the part's mesh, the triangles LIGGGHTS itself used: the deck's
part_<name>.stl (`deck_meshes`; 0.05 mm chords by default, 1 um with --fill-from), LIGGGHTS'
contact rule for a sphere on a mesh.  A mesh coarser than the deck's would start and end its
contacts elsewhere: the default 36 chords lie up to 48 um inside the bar, deeper than a
0.4 m/s impact's peak overlap v sqrt(m/k), and lose about 40 % of the contacts that LIGGGHTS'
250 chords make (docs/validation.md section 27).  An impact is a
step at which it touches the part and did not at the step before (the DEM's rule,
vibroflow.dem.parts), counted from the window's first step.  At that step, as the DEM takes
it: the contact point and outward normal n are those of the part's analytic surface nearest to
the ball's centre (vibroflow.tub.parts.part_nearest, in the part's frame), the patch is
`patch_of` there, and the relative velocity of the ball's surface at the contact,
v - r omega x n - v_part (v_part the tub's rigid velocity there for a tub-fixed part, 0 for a
lab-fixed one), gives the normal speed -v_rel . n, the tangential speed |v_rel - (v_rel . n) n|
and the energy 0.5 m v_n^2.

Loads (`part_load_rows`): at each snapshot, the part's rows of the wall/gran/local dump (mesh
index after the U's and the partitions'): the force on the part is minus the sum of the
contact forces on the balls, in the part's axes (tub axes for a tub-fixed part), and its torque
about the part's centre is that of each force at the analytic contact point, plus the
rolling resistance's moment, which the dump does not hold but LIGGGHTS' CDT model lets one
rebuild exactly from what it does (`PartRolling`; LIGGGHTS-PUBLIC 3.8 rolling_model_cdt.h and
surface_model_default.h, wall branch): for a contact of a ball (radius r, angular velocity
omega, lab) with triangle t of the part's mesh (the row's triangle), the overlap
delta = r - |c - q| (c the centre, q its nearest point on t), n = (c - q) / |c - q|, the elastic
normal force F_el = k_n delta (linear law; Hertz: 4/3 E* sqrt(r delta) delta), and the moment
on the part M = mu_r F_el (r - delta / 2) (w - (w . n) n) with w = omega / |omega| (LIGGGHTS
takes the ball's whole spin, not relative to a moving mesh, and removes the normal part after
scaling; the ball gets -M).  EPSD (`epsd2`) keeps its rolling moment as contact history, which
no dump holds: there the torque has no rolling part.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import NamedTuple

import numba as nb
import numpy as np

from vibroflow.errors import InputError
from vibroflow.liggghts.dumps import _whole_column, read_dump
from vibroflow.liggghts.parameters import pair_tables
from vibroflow.liggghts.part_deck import part_file
from vibroflow.liggghts.part_meshes import part_triangles
from vibroflow.liggghts.stl import DEFAULT_MAX_SAGITTA, read_stl
from vibroflow.scenario.laws import effective_moduli
from vibroflow.tub.motion import lab_to_tub_np, pose_np
from vibroflow.tub.parts import FRAME_TUB, P_CX, P_CY, P_CZ, P_FRAME, Part, closest_on_triangle, \
    pack, part_nearest, patch_of

#: the part dump's columns the import reads
PART_COLUMNS = ("id", "x", "y", "z", "vx", "vy", "vz", "omegax", "omegay", "omegaz", "radius")


@nb.njit(cache=True)
def _nearest_many(shape, prm, tri, tri_normal, tri_start, tri_group, k, pts):
    """part_nearest of part k for each point (n, 3): columns gap, nx, ny, nz, cx, cy, cz, patch."""
    out = np.empty((pts.shape[0], 8))
    for i in range(pts.shape[0]):
        gap, nx, ny, nz, cx, cy, cz, feat = part_nearest(shape, prm, tri, tri_normal,
                                                         tri_start, k, pts[i, 0], pts[i, 1],
                                                         pts[i, 2])
        out[i, 0], out[i, 1], out[i, 2], out[i, 3] = gap, nx, ny, nz
        out[i, 4], out[i, 5], out[i, 6] = cx, cy, cz
        out[i, 7] = patch_of(shape[k], tri_group, nx, ny, nz, feat)
    return out


@nb.njit(cache=True)
def _touching(tri, lo, hi, pts, rad):
    """For each point (n, 3): whether a triangle of tri (T, 3, 3; bounds lo, hi (T, 3)) lies
    closer than rad (n,) to it (LIGGGHTS' contact of a sphere with a mesh)."""
    out = np.zeros(pts.shape[0], np.bool_)
    for i in range(pts.shape[0]):
        px, py, pz, r = pts[i, 0], pts[i, 1], pts[i, 2], rad[i]
        for t in range(tri.shape[0]):
            if (px < lo[t, 0] - r or px > hi[t, 0] + r or py < lo[t, 1] - r
                    or py > hi[t, 1] + r or pz < lo[t, 2] - r or pz > hi[t, 2] + r):
                continue
            cx, cy, cz, _ = closest_on_triangle(px, py, pz, tri, t)
            if (px - cx) ** 2 + (py - cy) ** 2 + (pz - cz) ** 2 < r * r:
                out[i] = True
                break
    return out


def deck_meshes(deck_dir, parts: tuple[Part, ...]) -> list[np.ndarray]:
    """The triangles (T, 3, 3) of each part's mesh in the deck folder (part_<name>.stl, the
    file LIGGGHTS read); InputError naming the file when one is missing."""
    out = []
    for p in parts:
        path = Path(deck_dir) / part_file(p.name)
        if not path.is_file():
            raise InputError(f"{path}: no such file; the import finds the contacts with part "
                             f"{p.name!r} on the mesh LIGGGHTS used, which the deck writes there")
        out.append(read_stl(path)[0])
    return out


class PartGeometry:
    """The parts' analytic surfaces (vibroflow.tub.parts.pack) and their LIGGGHTS meshes
    (`meshes`: each part's triangles, (T, 3, 3) in the part's frame at rest; default the
    export's 0.05 mm chords, part_triangles), for points in the parts' frames."""

    def __init__(self, parts: tuple[Part, ...], length: float, periodic: bool,
                 meshes: list[np.ndarray] | None = None):
        self.parts = parts
        self.length = float(length)
        self.periodic = bool(periodic)
        self.exact = pack(parts)
        if meshes is None:
            meshes = [part_triangles(p, length, DEFAULT_MAX_SAGITTA) for p in parts]
        self.meshes = [np.ascontiguousarray(m, dtype=float) for m in meshes]
        self._lo = [m.min(axis=1) for m in self.meshes]
        self._hi = [m.max(axis=1) for m in self.meshes]

    def frame_points(self, k: int, pos_lab: np.ndarray, pose) -> np.ndarray:
        """Ball centres (n, 3, lab) in part k's frame: the tub frame for a tub-fixed part (pose:
        X, Z, theta, pivot_x, pivot_z), else the lab; y wrapped into [0, L_y) in a periodic tub
        (its cylinder mesh spans that) or, for another shape, taken as the image nearest its
        centre (as the DEM)."""
        p = self.parts[k]
        pts = np.array(pos_lab, dtype=float)
        if self.exact.prm[k, P_FRAME] == FRAME_TUB:
            X, Z, th, px, pz = pose
            pts = lab_to_tub_np(pts, X, Z, th, (px, pz))
        if self.periodic:
            if p.shape == "cylinder":
                pts[:, 1] = np.mod(pts[:, 1], self.length)
            else:
                dy = pts[:, 1] - p.center[1]
                pts[:, 1] = p.center[1] + dy - self.length * np.rint(dy / self.length)
        return pts

    def exact_nearest(self, k: int, pts: np.ndarray) -> np.ndarray:
        e = self.exact
        return _nearest_many(e.shape, e.prm, e.tri, e.tri_normal, e.tri_start, e.tri_group, k,
                             np.ascontiguousarray(pts))

    def mesh_touch(self, k: int, pts: np.ndarray, rad: np.ndarray) -> np.ndarray:
        """Whether each ball (centres pts (n, 3) in part k's frame, radii rad) touches part k's
        mesh.  Only balls within their radius of the analytic surface are tested: every
        vertex of a mesh lies on its (convex) part, so the mesh lies inside it and no farther
        ball can touch it."""
        out = np.zeros(pts.shape[0], bool)
        near = self.exact_nearest(k, pts)[:, 0] < rad if pts.shape[0] else out
        if np.any(near):
            out[near] = _touching(self.meshes[k], self._lo[k], self._hi[k],
                                  np.ascontiguousarray(pts[near]),
                                  np.ascontiguousarray(rad[near], dtype=float))
        return out


def _tub_pose(motion, t: float):
    p = pose_np(motion, t)
    return (float(p["X"]), float(p["Z"]), float(p["theta"]), float(p["Xdot"]), float(p["Zdot"]),
            float(p["thetadot"]))


def check_outside(geom: PartGeometry, pos_lab: np.ndarray, pose, ids, path) -> None:
    """InputError when a ball's centre lies inside a part (pose: X, Z, theta, pivot_x,
    pivot_z): its contacts from the inside would read as impacts."""
    for k, p in enumerate(geom.parts):
        inside = geom.exact_nearest(k, geom.frame_points(k, pos_lab, pose))[:, 0] < 0.0
        if np.any(inside):
            j = int(np.argmax(inside))
            raise InputError(f"{path}: ball id {ids[j]} (and {int(inside.sum()) - 1} more) lies "
                             f"inside part {p.name!r} at the first snapshot; the deck's fill must "
                             "leave the parts out (export the deck again)")


def part_impacts(path, geom: PartGeometry, motion, n0: int, dt: float, first_step: int,
                 ids: np.ndarray, density: float) -> dict:
    """The /part_impacts columns (module docstring) from the part dump at `path`: impacts at
    vibration steps >= first_step (relative to n0).  ids: the ball dump's sorted ids (a ball's
    index is its place there).  InputError for a dump that is not whole, lacks a column, skips
    a step or names a ball the ball dump does not have."""
    rows = {"time": [], "part": [], "patch": [], "position_part": [], "normal_speed": [],
            "tangential_speed": [], "energy": [], "ball": []}
    n_parts = len(geom.parts)
    before = [np.zeros(0, np.int64) for _ in range(n_parts)]
    last = None
    piv = (motion.pivot_x, motion.pivot_z)
    for snap in read_dump(path):
        c = {name: i for i, name in enumerate(snap.columns)}
        missing = [name for name in PART_COLUMNS if name not in c]
        if missing:
            raise InputError(f"{path}: line {snap.first_row - 1} (step {snap.step}): no column "
                             f"{' '.join(missing)}; the import needs {' '.join(PART_COLUMNS)}")
        if last is not None and snap.step != last + 1:
            raise InputError(f"{path}: line {snap.line + 1}: step {snap.step} after step {last}: "
                             "the part dump must hold every step (a step missing or repeated)")
        data = snap.data
        pid = _whole_column(path, snap, c["id"]) if data.shape[0] else np.zeros(0, np.int64)
        idx = np.clip(np.searchsorted(ids, pid), 0, max(ids.size - 1, 0))
        if pid.size and np.any(ids[idx] != pid):
            j = int(np.argmax(ids[idx] != pid))
            raise InputError(f"{path}: line {snap.first_row + j}: id {pid[j]} is not a ball of "
                             "the ball dump")
        t = (snap.step - n0) * dt
        X, Z, th, Xd, Zd, thd = _tub_pose(motion, t)
        pos = data[:, [c["x"], c["y"], c["z"]]]
        vel = data[:, [c["vx"], c["vy"], c["vz"]]]
        omg = data[:, [c["omegax"], c["omegay"], c["omegaz"]]]
        rad = data[:, c["radius"]]
        count = last is not None and snap.step - n0 >= first_step
        for k in range(n_parts):
            pts = geom.frame_points(k, pos, (X, Z, th, *piv))
            touch = geom.mesh_touch(k, pts, rad)
            now = pid[touch]
            if count:
                new = touch.copy()
                new[touch] = ~np.isin(now, before[k])
                if np.any(new):
                    _impact_rows(rows, geom, k, t, pts[new], vel[new], omg[new], rad[new],
                                 idx[new], (X, Z, th, Xd, Zd, thd, *piv), density)
            before[k] = now
        last = snap.step
    out = {}
    for name, dtype in (("time", "f8"), ("part", "i2"), ("patch", "i2"),
                        ("position_part", "f4"), ("normal_speed", "f4"),
                        ("tangential_speed", "f4"), ("energy", "f8"), ("ball", "i4")):
        shape = (0, 3) if name == "position_part" else (0,)
        out[name] = (np.concatenate(rows[name]).astype(dtype) if rows[name]
                     else np.zeros(shape, dtype))
    return out


def _impact_rows(rows, geom: PartGeometry, k: int, t: float, pts, vel, omg, rad, ball, pose,
                 density: float) -> None:
    """Append the impacts of the balls at part-frame centres pts on part k at time t."""
    X, Z, th, Xd, Zd, thd, px, pz = pose
    near = geom.exact_nearest(k, pts)
    n = near[:, 1:4]
    cpt = near[:, 4:7]
    tub_fixed = geom.exact.prm[k, P_FRAME] == FRAME_TUB
    c, s = math.cos(th), math.sin(th)
    if tub_fixed:
        n_lab = np.stack([c * n[:, 0] - s * n[:, 2], n[:, 1], s * n[:, 0] + c * n[:, 2]], axis=1)
        # the contact point in the lab, the tub's rigid velocity there (vibroflow.tub.motion)
        rx, rz = cpt[:, 0] - px, cpt[:, 2] - pz
        lx, lz = px + c * rx - s * rz + X, pz + s * rx + c * rz + Z
        v_wall = np.stack([Xd - thd * (lz - Z - pz), np.zeros(len(lx)),
                           Zd + thd * (lx - X - px)], axis=1)
    else:
        n_lab = n
        v_wall = np.zeros_like(n)
    v_rel = vel - rad[:, None] * np.cross(omg, n_lab) - v_wall
    vn = np.einsum("ij,ij->i", v_rel, n_lab)
    vt = np.linalg.norm(v_rel - vn[:, None] * n_lab, axis=1)
    mass = density * 4.0 / 3.0 * math.pi * rad**3
    prm = geom.exact.prm[k]
    rows["time"].append(np.full(len(vn), t))
    rows["part"].append(np.full(len(vn), k))
    rows["patch"].append(near[:, 7])
    rows["position_part"].append(cpt - prm[[P_CX, P_CY, P_CZ]])
    rows["normal_speed"].append(-vn)
    rows["tangential_speed"].append(vt)
    rows["energy"].append(0.5 * mass * vn**2)
    rows["ball"].append(ball)


class PartRolling(NamedTuple):
    """LIGGGHTS' rolling model for the balls' contacts with each part (module docstring): cdt
    (False: none or EPSD, no moment rebuilt), and per part mu_r, the linear k_n (N/m) or, with
    hertz, the Hertz modulus E* (Pa)."""

    cdt: bool
    hertz: bool
    mu_r: np.ndarray
    k_n: np.ndarray
    e_star: np.ndarray


def part_rolling(scenario) -> PartRolling:
    """The deck's rolling law for the balls' pairs with the parts (types 4, 5, ...)."""
    tables = pair_tables(scenario)
    ball = scenario.materials[scenario.fill.material]
    parts = scenario.parts or []
    e_star = np.array([effective_moduli(ball, scenario.materials[p.material])[0]
                       for p in parts], dtype=float)
    return PartRolling(tables.rolling == "cdt", tables.model == "hertz",
                       tables.rolling_friction[0, 3:3 + len(parts)].copy(),
                       tables.kn[0, 3:3 + len(parts)].copy(), e_star)


def _rolling_moments(rolling: PartRolling, k: int, tri, t, pts, omg, rad) -> np.ndarray:
    """The CDT moments (n, 3; N m) on part k of the balls at part-frame centres pts with
    angular velocities omg (part axes) and radii rad, each on triangle t of the part's mesh
    (module docstring)."""
    out = np.zeros((len(t), 3))
    for i in range(len(t)):
        if not 0 <= t[i] < len(tri):
            continue
        qx, qy, qz, _ = closest_on_triangle(pts[i, 0], pts[i, 1], pts[i, 2], tri, int(t[i]))
        d = pts[i] - (qx, qy, qz)
        dist = float(np.linalg.norm(d))
        delta = rad[i] - dist
        w = float(np.linalg.norm(omg[i]))
        if delta <= 0.0 or dist == 0.0 or w == 0.0:
            continue
        n = d / dist
        f_el = (4.0 / 3.0 * rolling.e_star[k] * math.sqrt(rad[i] * delta) * delta
                if rolling.hertz else rolling.k_n[k] * delta)
        u = omg[i] / w
        out[i] = rolling.mu_r[k] * f_el * (rad[i] - 0.5 * delta) * (u - np.dot(u, n) * n)
    return out


def _lab_to_tub(v, c: float, s: float):
    """Rows of lab-axis vectors in the tub's axes, the tub turned by theta about y (c, s its
    cosine and sine)."""
    return np.stack([c * v[:, 0] + s * v[:, 2], v[:, 1], -s * v[:, 0] + c * v[:, 2]], axis=1)


def part_load_rows(snap, snap_index: int, ids, pos_lab, pose, geom: PartGeometry,
                   first_mesh: int, path, omg_lab=None, radius=None,
                   rolling: PartRolling | None = None) -> dict:
    """The /part_loads rows (one per part) of one snapshot of the wall/gran/local dump (columns
    mesh, triangle, atom id, F_n (3), F_t (3) on the ball, lab axes); part k's rows have mesh
    index first_mesh + k.  pose: X, Z, theta, pivot_x, pivot_z.  With the balls' angular
    velocities omg_lab and radii (by sorted id) and a CDT `rolling`, the torque holds the
    rolling moments (module docstring)."""
    data = snap.data
    n_parts = len(geom.parts)
    force = np.zeros((n_parts, 3))
    torque = np.zeros((n_parts, 3))
    if data.shape[0]:
        mesh = _whole_column(path, snap, 0)
        pid = _whole_column(path, snap, 2)
        th = pose[2]  # rad; frame_points reads the pose's translation
        c, s = math.cos(th), math.sin(th)
        for k in range(n_parts):
            sel = mesh == first_mesh + k
            if not np.any(sel):
                continue
            j = np.clip(np.searchsorted(ids, pid[sel]), 0, ids.size - 1)
            ok = ids[j] == pid[sel]
            g = -(data[sel][ok, 3:6] + data[sel][ok, 6:9])  # on the part, lab axes
            pts = geom.frame_points(k, pos_lab[j[ok]], pose)
            if geom.exact.prm[k, P_FRAME] == FRAME_TUB:
                g = _lab_to_tub(g, c, s)
            arm = geom.exact_nearest(k, pts)[:, 4:7] - geom.exact.prm[k, [P_CX, P_CY, P_CZ]]
            force[k] = g.sum(axis=0)
            torque[k] = np.cross(arm, g).sum(axis=0)
            if rolling is not None and rolling.cdt and omg_lab is not None:
                w = omg_lab[j[ok]]
                if geom.exact.prm[k, P_FRAME] == FRAME_TUB:
                    w = _lab_to_tub(w, c, s)
                tri = _whole_column(path, snap, 1)[sel][ok]
                torque[k] += _rolling_moments(rolling, k, geom.meshes[k], tri, pts, w,
                                              radius[j[ok]]).sum(axis=0)
    return {"snapshot": np.full(n_parts, snap_index, np.int32),
            "part": np.arange(n_parts, dtype=np.int16), "force": force, "torque": torque}
