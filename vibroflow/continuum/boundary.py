"""Boundaries of the continuum: small pluggable objects that add forces to the material points.

Every boundary adds its force on each point (N per metre of thickness, in the solver's frame)
to the points' external force before the particle-to-grid transfer, using the point's position
and velocity at the start of the step.  A boundary object gives the compiled step loop
(fused.py) its numbers as one record of BOUNDARY_DTYPE (`record()`: its kind, and the fields
of that kind by name), and `boundary_forces` runs the kernel of the record's kind
(`u_wall_forces`, `plane_forces`, `part_wall_forces`, `partition_forces`): a new kind of
boundary is a class, a kernel and a branch of `boundary_forces` here, and the step loop stays
as it is.  A boundary with a per-point history (`init_history(n)`,
`state.history[self.slot]`; the penalty walls) says so (`has_history`); the walls also have
`lost(state)`: the ids of the points the last step found through the wall by more than their
own side, which the solver reports as a blow-up (mpm/solver.py).

Wall contact (`UWall`, `Plane`): a penalty contact with a constant normal stiffness, as the
published finite element study of the tub did (a linear pressure-overclosure law), and Coulomb
friction (the point-wall analogue of Bardenhagen, Brackbill & Sulsky 2000's frictional contact):

* a point p of volume V_p (m^2) is a square of side l_p = sqrt(V_p); it touches the wall when its
  centre is closer than l_p/2, with overclosure delta = l_p/2 - gap (m);
* normal pressure k_n delta (k_n the contact stiffness, Pa/m) on the contact length l_p, plus a
  dashpot of damping ratio zeta on the point's mass: F_n = max(0, k_n l_p delta -
  2 zeta sqrt(m_p k_n l_p) v_n) (N/m), never adhesive;
* tangential: an elastic slip spring on the accumulated tangential displacement xi (the point's
  history, reset when it leaves the wall), F_t = -k_t l_p xi - 2 zeta sqrt(m_p k_t l_p) v_t, with
  the Coulomb limit |F_t| <= mu_w F_n (then xi is rescaled to the limit and the point slides).
  k_t = k_n by default.  A point sticks exactly when the friction needed is below mu_w F_n.

`UWall` is the tub's U (vibroflow.tub.geometry.u_wall_nearest: the same surface the DEM's balls
touch) fixed in the tub frame, where the solver works (grid_update.py); its motion enters through
the frame's inertial forces, computed from vibroflow.tub.motion.  `Plane` is a flat wall moving
with constant acceleration, for tests.  `PartWall` is a rigid part of the scenario's [[parts]]
(vibroflow.tub.parts) fixed in the tub frame, with the U wall's law: the point's gap and normal
are those of the part's nearest surface point in the slice's section y = L_y / 2
(tub.parts.part_nearest; a part spanning the slice, continuum/part_obstacle.py).

`PartitionFriction`: the two partitions at y = 0 and y = L_y as a depth-averaged body force
f = -2 mu_p p / L_y along the velocity relative to the tub, per unit volume (Jop, Forterre &
Pouliquen 2005, models.md), with p the point's pressure; it is capped at the force that stops the
point in one step, so it cannot reverse its velocity (a Coulomb-consistent regularisation).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numba as nb
import numpy as np

from vibroflow.errors import InputError
from vibroflow.tub.geometry import distance_to_wall_np, u_wall_nearest
from vibroflow.tub.parts import part_nearest

#: a penalty contact's state: none, sticking, sliding at the Coulomb limit
NO_CONTACT, STICK, SLIDE = 0, 1, 2

#: kinds of boundary (BOUNDARY_DTYPE's `kind`): the tub's U wall, a moving plane wall, the
#: partitions' friction, a part (tub.parts) in the tub frame
U_WALL, PLANE_WALL, PARTITIONS, PART_WALL = 0, 1, 2, 3

#: a boundary's numbers for the compiled step (`record()`): kind; hist, the row of a wall's
#: history in the step's stacked histories (mpm.solver.pack_boundaries); a penalty wall's k_n,
#: k_t (Pa/m), damping ratio zeta and friction mu; the U's radius (m); a plane through (px, pz) +
#: (vx, vz) t + (ax, az) t^2 / 2 (m) with unit normal (nx, nz); the partitions' friction mu_p
#: and spacing L_y (m); a part's index `part` in the packed parts (tub.parts.pack) and the
#: section's y (m)
BOUNDARY_DTYPE = np.dtype([("kind", np.int64), ("hist", np.int64), ("kn", np.float64),
                           ("kt", np.float64), ("zeta", np.float64), ("mu", np.float64),
                           ("radius", np.float64), ("px", np.float64), ("pz", np.float64),
                           ("nx", np.float64), ("nz", np.float64), ("vx", np.float64),
                           ("vz", np.float64), ("ax", np.float64), ("az", np.float64),
                           ("friction", np.float64), ("length", np.float64),
                           ("part", np.int64), ("y", np.float64)])

#: no parts, packed as `boundary_forces` takes them: shape codes, parameters, triangles, their
#: normals and first indices (tub.parts.PackedParts)
NO_PARTS = (np.zeros(0, np.int64), np.zeros((0, 10)), np.zeros((0, 3, 3)), np.zeros((0, 3)),
            np.zeros(1, np.int64))


@nb.njit(cache=True, inline="always")
def _penalty(gap, nx, nz, vrx, vrz, mass, volume, xi, kn, kt, zeta, mu, dt):
    """Penalty contact force (fx, fz, fn, ft, xi, state) of one point (module docstring)."""
    l = np.sqrt(volume)
    delta = 0.5 * l - gap
    if delta <= 0.0:
        return 0.0, 0.0, 0.0, 0.0, 0.0, NO_CONTACT
    kk = kn * l
    vn = vrx * nx + vrz * nz
    fn = kk * delta - 2.0 * zeta * np.sqrt(mass * kk) * vn
    if fn < 0.0:
        fn = 0.0
    tx = nz
    tz = -nx
    vt = vrx * tx + vrz * tz
    kkt = kt * l
    xi = xi + vt * dt
    ft = -kkt * xi - 2.0 * zeta * np.sqrt(mass * kkt) * vt
    lim = mu * fn
    state = STICK
    if abs(ft) > lim:
        ft = lim if ft > 0.0 else -lim
        xi = -ft / kkt if kkt > 0.0 else 0.0
        state = SLIDE
    return fn * nx + ft * tx, fn * nz + ft * tz, fn, ft, xi, state


@nb.njit(cache=True, inline="always")
def _contact(p, gap, nx, nz, vrx, vrz, mass, volume, xi, fext, f_out, fn_out, ft_out,
             state_out, kn, kt, zeta, mu, dt):
    """Point p's penalty contact with a wall at gap (m) along the unit normal (nx, nz), its
    velocity relative to the wall (vrx, vrz) (m/s): its force added to fext, its history xi
    and the outputs f_out, fn_out, ft_out, state_out written (`u_wall_forces`).  Returns 1
    when the point has gone through the wall (centre beyond it by more than its side), else 0."""
    deep = 1 if gap < -np.sqrt(volume[p]) else 0
    fx, fz, fn, ft, xn, st = _penalty(gap, nx, nz, vrx, vrz, mass[p], volume[p], xi[p], kn, kt,
                                      zeta, mu, dt)
    fext[p, 0] += fx
    fext[p, 1] += fz
    f_out[p, 0] = fx
    f_out[p, 1] = fz
    xi[p] = xn
    fn_out[p] = fn
    ft_out[p] = ft
    state_out[p] = st
    return deep


@nb.njit(cache=True)
def u_wall_forces(x, v, mass, volume, xi, fext, f_out, fn_out, ft_out, state_out, radius, kn,
                  kt, zeta, mu, dt):
    """Add the U wall's contact force to fext (N, 2) (N/m); history xi (N,) (m) in place;
    the force f_out (N, 2), its normal and tangential parts fn_out, ft_out (N/m) and state_out
    (0 none, 1 stick, 2 slide) per point.  The wall is still
    in the solver's (tub) frame; radius (m) of the U (tub.geometry).  Returns the number of
    points gone through the wall (centre beyond it by more than the point's side)."""
    deep = 0
    for p in range(x.shape[0]):
        gap, nx, nz, cx, cz, s = u_wall_nearest(x[p, 0], x[p, 1], radius)
        deep += _contact(p, gap, nx, nz, v[p, 0], v[p, 1], mass, volume, xi, fext, f_out,
                         fn_out, ft_out, state_out, kn, kt, zeta, mu, dt)
    return deep


@nb.njit(cache=True)
def plane_motion(px0, pz0, vx, vz, ax, az, t):
    """(px, pz, vx, vz) at time t (s) of a plane through (px0, pz0) (m) at t = 0 moving with
    the velocity (vx, vz) + (ax, az) t (m/s): Plane.at, and the compiled step's
    (`boundary_forces`)."""
    return (px0 + vx * t + 0.5 * ax * t * t, pz0 + vz * t + 0.5 * az * t * t, vx + ax * t,
            vz + az * t)


@nb.njit(cache=True)
def plane_forces(x, v, mass, volume, xi, fext, f_out, fn_out, ft_out, state_out, px, pz, nx,
                 nz, wvx, wvz, kn, kt, zeta, mu, dt):
    """Add a plane wall's contact force (through (px, pz) m, unit normal (nx, nz) into the
    material, moving at (wvx, wvz) m/s) to fext; as `u_wall_forces` (with its return)."""
    deep = 0
    for p in range(x.shape[0]):
        gap = (x[p, 0] - px) * nx + (x[p, 1] - pz) * nz
        deep += _contact(p, gap, nx, nz, v[p, 0] - wvx, v[p, 1] - wvz, mass, volume, xi, fext,
                         f_out, fn_out, ft_out, state_out, kn, kt, zeta, mu, dt)
    return deep


@nb.njit(cache=True, inline="always")
def part_section_nearest(parts, k, y, px, pz):
    """(gap m, nx, nz) of the point (px, pz) from part k of the packed parts (NO_PARTS'
    layout) in the section at y (m): tub.parts.part_nearest's gap with its normal's x-z part
    made unit (a part spanning the slice has none along y near its surface)."""
    shape, prm, tri, tri_normal, tri_start = parts
    gap, nx, ny, nz, cx, cy, cz, feat = part_nearest(shape, prm, tri, tri_normal, tri_start, k,
                                                     px, y, pz)
    n = np.sqrt(nx * nx + nz * nz)
    if n < 1.0e-12:
        return gap, 0.0, 1.0
    return gap, nx / n, nz / n


@nb.njit(cache=True)
def part_wall_forces(x, v, mass, volume, xi, fext, f_out, fn_out, ft_out, state_out, parts, k,
                     y, kn, kt, zeta, mu, dt):
    """Add the contact force of part k of the packed parts (at rest in the solver's frame) in
    the section at y (m) to fext; as `u_wall_forces` (with its return)."""
    deep = 0
    for p in range(x.shape[0]):
        gap, nx, nz = part_section_nearest(parts, k, y, x[p, 0], x[p, 1])
        deep += _contact(p, gap, nx, nz, v[p, 0], v[p, 1], mass, volume, xi, fext, f_out,
                         fn_out, ft_out, state_out, kn, kt, zeta, mu, dt)
    return deep


@nb.njit(cache=True)
def partition_forces(v, mass, volume, stress, fext, mu_p, length, dt):
    """Add the partitions' friction -2 mu_p p V_p / L_y along -v (N/m) to fext, capped at
    m_p |v| / dt (module docstring).  stress (N, 4) [xx, zz, xz, yy] Pa; length L_y (m)."""
    for p in range(v.shape[0]):
        pr = -(stress[p, 0] + stress[p, 1] + stress[p, 3]) / 3.0
        if pr <= 0.0:
            continue
        sp = np.sqrt(v[p, 0] ** 2 + v[p, 1] ** 2)
        if sp <= 0.0:
            continue
        f = 2.0 * mu_p * pr * volume[p] / length
        cap = mass[p] * sp / dt
        if f > cap:
            f = cap
        fext[p, 0] -= f * v[p, 0] / sp
        fext[p, 1] -= f * v[p, 1] / sp


@nb.njit(cache=True)
def boundary_forces(b, x, v, mass, volume, stress, fext, hist, parts, a, e, t, dt):
    """Add the force of the boundary b (a BOUNDARY_DTYPE record) on the points a:e to fext
    (N, 2) (N/m) at time t (s) over dt (s), with its kind's kernel; x, v (N, 2), mass, volume
    (N,), stress (N, 4) the points' (mpm.solver.MPMState); hist = (xi, f, fn, ft, state) the
    walls' stacked histories (mpm.solver.pack_boundaries), row b.hist this wall's; parts the
    packed parts (NO_PARTS' layout).  Returns the number of points gone through a wall (0 for
    the partitions)."""
    if b.kind == PARTITIONS:
        partition_forces(v[a:e], mass[a:e], volume[a:e], stress[a:e], fext[a:e], b.friction,
                         b.length, dt)
        return 0
    xi, f, fn, ft, st = hist
    q = b.hist
    if b.kind == U_WALL:
        return u_wall_forces(x[a:e], v[a:e], mass[a:e], volume[a:e], xi[q, a:e], fext[a:e],
                             f[q, a:e], fn[q, a:e], ft[q, a:e], st[q, a:e], b.radius, b.kn,
                             b.kt, b.zeta, b.mu, dt)
    if b.kind == PART_WALL:
        return part_wall_forces(x[a:e], v[a:e], mass[a:e], volume[a:e], xi[q, a:e], fext[a:e],
                                f[q, a:e], fn[q, a:e], ft[q, a:e], st[q, a:e], parts, b.part,
                                b.y, b.kn, b.kt, b.zeta, b.mu, dt)
    px, pz, wvx, wvz = plane_motion(b.px, b.pz, b.vx, b.vz, b.ax, b.az, t)
    return plane_forces(x[a:e], v[a:e], mass[a:e], volume[a:e], xi[q, a:e], fext[a:e],
                        f[q, a:e], fn[q, a:e], ft[q, a:e], st[q, a:e], px, pz, b.nx, b.nz, wvx,
                        wvz, b.kn, b.kt, b.zeta, b.mu, dt)


class _Contact:
    """Shared parts of the penalty walls: per-point slip history and last contact forces."""

    slot: int = -1

    def _check(self):
        for name in ("stiffness", "friction", "damping_ratio"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise InputError(f"{type(self).__name__}.{name} = {v!r}: must be >= 0")
        if not self.stiffness > 0:
            raise InputError(f"{type(self).__name__}.stiffness = {self.stiffness!r}: must be "
                             "> 0 Pa/m")

    def lost(self, state) -> np.ndarray | None:
        """Ids of the points that the last add_forces found through the wall (centre beyond
        it by more than their side sqrt(V_p)): the solution has blown up; None if none."""
        if not getattr(self, "_deep", 0):
            return None
        return np.nonzero(self._gap(state) < -np.sqrt(state.volume))[0]

    @property
    def tangential_stiffness(self) -> float:
        return self.stiffness * self.tangential_ratio

    has_history = True

    def _record(self, kind: int) -> np.ndarray:
        r = np.zeros((), BOUNDARY_DTYPE)
        r["kind"] = kind
        r["kn"], r["kt"] = self.stiffness, self.tangential_stiffness
        r["zeta"], r["mu"] = self.damping_ratio, self.friction
        return r

    def init_history(self, n: int) -> dict:
        """Per-point arrays: slip xi (m), last force f (N, 2) with its normal and tangential
        parts fn, ft (N/m), state (0 none, 1 stick, 2 slide)."""
        return {"xi": np.zeros(n), "f": np.zeros((n, 2)), "fn": np.zeros(n), "ft": np.zeros(n),
                "state": np.zeros(n, np.int8)}


@dataclass(kw_only=True)
class _TubLaw(_Contact):
    """The wall law of the tub's own surfaces, the U and the parts: contact stiffness (Pa/m),
    Coulomb friction mu_w (-), damping ratio (-), k_t / k_n."""

    stiffness: float
    friction: float
    damping_ratio: float = 0.16
    tangential_ratio: float = 1.0

    def __post_init__(self):
        self._check()


@dataclass(kw_only=True)
class UWall(_TubLaw):
    """The tub's U wall (tub frame): radius (m) of tub.geometry, with the tub's wall law."""

    radius: float

    def record(self) -> np.ndarray:
        """Its BOUNDARY_DTYPE record (module docstring)."""
        r = self._record(U_WALL)
        r["radius"] = self.radius
        return r

    def _gap(self, state) -> np.ndarray:
        return distance_to_wall_np(state.x[:, 0], state.x[:, 1], self.radius)


@dataclass
class Plane(_Contact):
    """A flat wall through `point` (m) with unit `normal` towards the material, moving with
    `velocity` + `acceleration` t (m/s, m/s^2) from t = 0; stiffness (Pa/m), friction (-)."""

    point: tuple[float, float]
    normal: tuple[float, float]
    stiffness: float
    friction: float = 0.0
    damping_ratio: float = 0.5
    tangential_ratio: float = 1.0
    velocity: tuple[float, float] = (0.0, 0.0)
    acceleration: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self):
        self._check()
        n = math.hypot(*self.normal)
        if not n > 0:
            raise InputError(f"Plane.normal = {self.normal!r}: must not be zero")
        self.normal = (self.normal[0] / n, self.normal[1] / n)

    def at(self, t: float):
        """Point (m) and velocity (m/s) of the plane at time t (s)."""
        px, pz, wvx, wvz = plane_motion(self.point[0], self.point[1], self.velocity[0],
                                        self.velocity[1], self.acceleration[0],
                                        self.acceleration[1], t)
        return (px, pz), (wvx, wvz)

    def record(self) -> np.ndarray:
        """Its BOUNDARY_DTYPE record (module docstring)."""
        r = self._record(PLANE_WALL)
        r["px"], r["pz"] = self.point
        r["nx"], r["nz"] = self.normal
        r["vx"], r["vz"] = self.velocity
        r["ax"], r["az"] = self.acceleration
        return r

    def _gap(self, state) -> np.ndarray:
        (px, pz), _ = self.at(self._t_last)
        return (state.x[:, 0] - px) * self.normal[0] + (state.x[:, 1] - pz) * self.normal[1]


@nb.njit(cache=True)
def part_gaps(parts, k, y, x, gap_out):
    """Gaps (m) of the points x (N, 2) from part k in the section at y (part_section_nearest)."""
    for p in range(x.shape[0]):
        gap_out[p] = part_section_nearest(parts, k, y, x[p, 0], x[p, 1])[0]


@nb.njit(cache=True)
def _section_nearest_loop(parts, k, y, x, z, out):
    for p in range(x.shape[0]):
        out[p, 0], out[p, 1], out[p, 2] = part_section_nearest(parts, k, y, x[p], z[p])


def part_section_nearest_np(parts, k: int, y: float, x, z):
    """(gap m, nx, nz) arrays of part_section_nearest at the points (x, z) (m)."""
    xs = np.ascontiguousarray(np.ravel(x), dtype=float)
    zs = np.ascontiguousarray(np.ravel(z), dtype=float)
    out = np.zeros((xs.size, 3))
    _section_nearest_loop(parts, int(k), float(y), xs, zs, out)
    shape = np.shape(x)
    return out[:, 0].reshape(shape), out[:, 1].reshape(shape), out[:, 2].reshape(shape)


@dataclass(kw_only=True)
class PartWall(_TubLaw):
    """Part `index` of the packed parts `packed` (a tuple in NO_PARTS' layout; tub.parts.pack
    of the run's parts, every PartWall of a system sharing it) as a wall in the tub frame, in
    the section at y (m), named `name`, with the tub's wall law."""

    name: str
    packed: tuple
    index: int
    y: float

    def record(self) -> np.ndarray:
        """Its BOUNDARY_DTYPE record (module docstring)."""
        r = self._record(PART_WALL)
        r["part"], r["y"] = self.index, self.y
        return r

    def gap(self, x: np.ndarray) -> np.ndarray:
        """Gaps (m) of the points x (N, 2) from the part's surface (positive outside)."""
        out = np.zeros(x.shape[0])
        part_gaps(self.packed, self.index, self.y, np.ascontiguousarray(x, dtype=float), out)
        return out

    def _gap(self, state) -> np.ndarray:
        return self.gap(state.x)


@dataclass
class PartitionFriction:
    """The partitions' friction as a depth-averaged body force: friction mu_p (-), partition
    spacing L_y (m)."""

    friction: float
    length: float
    slot: int = -1

    def __post_init__(self):
        if not (math.isfinite(self.friction) and self.friction >= 0):
            raise InputError(f"partition friction = {self.friction!r}: must be >= 0")
        if not self.length > 0:
            raise InputError(f"partition spacing L_y = {self.length!r}: must be > 0 m")

    has_history = False

    def init_history(self, n: int) -> dict:
        return {}

    def record(self) -> np.ndarray:
        """Its BOUNDARY_DTYPE record: friction mu_p (-), spacing L_y (m)."""
        r = np.zeros((), BOUNDARY_DTYPE)
        r["kind"] = PARTITIONS
        r["friction"], r["length"] = self.friction, self.length
        return r
