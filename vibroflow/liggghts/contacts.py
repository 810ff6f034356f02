"""The contacts of a LIGGGHTS run as vibroflow's dem.h5 rows: ball-wall from `compute
wall/gran/local` (`_wall_rows`), ball-ball from `compute pair/gran/local` (`_pair_rows`).

The pair rows map the dump's atom ids to the sorted snapshot, order each pair i < j (negating the
force when it swaps them: the dumped force is the one on the first id, PAIR_FORCE_SIGN), and
every import checks that the contacts touch and push on the whole (PairCheck).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vibroflow.dem.walls import WALL_PARTITION_HI, WALL_PARTITION_LO, WALL_U
from vibroflow.errors import InputError
from vibroflow.liggghts.dumps import _whole_column
from vibroflow.liggghts.parameters import type_materials
from vibroflow.scenario.checks import find_contact
from vibroflow.tub.motion import lab_to_tub_np

#: relative tolerance of |F_t| = mu |F_n| that marks a wall contact as sliding
SLIDING_TOLERANCE = 1.0e-4


def _arc_of(tx, tz, R):
    """Arc coordinate (m, from the bottom, positive towards +x) of the point of the U nearest
    to tub-frame points (tx, tz) (as vibroflow.tub.geometry.u_wall_nearest)."""
    tx = np.asarray(tx, dtype=float)
    tz = np.asarray(tz, dtype=float)
    quarter = 0.5 * math.pi * R
    on_circle = tz <= R
    s_circle = R * np.arctan2(tx, -(tz - R))
    s_side = np.sign(np.where(tx >= 0, 1.0, -1.0)) * (quarter + (tz - R))
    return np.where(on_circle, s_circle, s_side)


def _wall_rows(snap, snap_index, ids, pos_lab, pose, motion, scenario, geom, path):
    """vibroflow wall_contacts rows from one snapshot of the wall/gran/local dump.

    Columns (compute wall/gran/local id force_normal force_tangential): mesh id (0 = the U,
    1 = the partitions, then the parts, whose rows are left out here), triangle id, particle id, F_n (3), F_t (3) on the ball, lab frame.
    LIGGGHTS-PUBLIC 3.8 does not fill contactPoint (it dumps zeros), so the contact point is
    taken as vibroflow does: the point of the analytic wall nearest to the ball's centre (tub
    frame); it differs from the facet's by at most the facets' sagitta.  F_n is |F_n| signed by
    the analytic wall normal (positive pushing the ball into the tub), F_t is |F_t|, and a
    contact slides when |F_t| >= mu |F_n| (LIGGGHTS truncates the tangential spring there).
    Raises InputError for another number of columns or indices that are not whole numbers.
    """
    data = snap.data
    if data.shape[1] != WALL_COLUMNS:
        raise InputError(f"{path}: line {snap.first_row - 1} (step {snap.step}): "
                         f"{data.shape[1]} columns, expected {WALL_COLUMNS} (compute "
                         "wall/gran/local id force_normal force_tangential)")
    if data.shape[0] == 0:
        return None
    mesh, tri, pid = (_whole_column(path, snap, j) for j in range(3))
    fnv = data[:, 3:6]
    ftv = data[:, 6:9]
    k = np.clip(np.searchsorted(ids, pid), 0, ids.size - 1)
    # mesh indices from the parts' on are the parts' contacts (vibroflow.liggghts.part_contacts)
    good = (ids[k] == pid) & (mesh < (1 if scenario.tub.periodic else 2))
    mesh, tri, k, fnv, ftv = mesh[good], tri[good], k[good], fnv[good], ftv[good]
    if scenario.tub.periodic:
        wall = np.zeros(mesh.shape, np.int8)
    else:
        # partitions.stl: triangles 0, 1 at y = 0, triangles 2, 3 at y = L_y
        wall = np.where(mesh == 0, WALL_U,
                        np.where(tri < 2, WALL_PARTITION_LO, WALL_PARTITION_HI)).astype(np.int8)
    X, Z, th = pose[0], pose[1], pose[2]
    piv = (motion.pivot_x, motion.pivot_z)
    ball = lab_to_tub_np(pos_lab[k], X, Z, th, piv)
    R = geom.radius
    # analytic nearest point and inward normal (tub frame)
    tx, ty, tz = ball[:, 0], ball[:, 1], ball[:, 2]
    rho = np.hypot(tx, tz - R)
    rho = np.where(rho > 0, rho, 1.0)
    on_circle = tz <= R
    ux, uz = tx / rho, (tz - R) / rho
    cx = np.where(on_circle, R * ux, np.where(tx >= 0, R, -R))
    cz = np.where(on_circle, R + R * uz, tz)
    nx = np.where(on_circle, -ux, np.where(tx >= 0, -1.0, 1.0))
    nz = np.where(on_circle, -uz, 0.0)
    ny = np.zeros_like(nx)
    cy = ty.copy()
    lo = wall == WALL_PARTITION_LO
    hi = wall == WALL_PARTITION_HI
    part = lo | hi
    cx = np.where(part, tx, cx)
    cz = np.where(part, tz, cz)
    cy = np.where(lo, 0.0, np.where(hi, geom.length, cy))
    nx = np.where(part, 0.0, nx)
    nz = np.where(part, 0.0, nz)
    ny = np.where(lo, 1.0, np.where(hi, -1.0, ny))
    # normal in lab axes (the rotation turns x towards z)
    c, s = math.cos(th), math.sin(th)
    n_lab = np.stack([c * nx - s * nz, ny, s * nx + c * nz], axis=1)
    # |F_n| as LIGGGHTS splits the force (along the line from the contact point to the centre,
    # the facet's normal), its sign from the analytic wall normal (negative: the damping pulls)
    fn = np.linalg.norm(fnv, axis=1) * np.where(np.einsum("ij,ij->i", fnv, n_lab) < 0, -1.0, 1.0)
    ft = np.linalg.norm(ftv, axis=1)
    arc = np.where(wall == WALL_U, _arc_of(tx, tz, R), np.nan)
    mats = type_materials(scenario)
    mu_u = find_contact(scenario, mats[0], mats[1]).friction
    mu_p = mu_u if scenario.tub.periodic else find_contact(scenario, mats[0], mats[2]).friction
    mu = np.where(wall == WALL_U, mu_u, mu_p)
    # at the limit the ratio is mu to the dump's 6 significant digits
    sliding = (ft > 0) & (ft >= mu * np.abs(fn) * (1.0 - SLIDING_TOLERANCE))
    pos_tub = np.stack([cx, cy, cz], axis=1)
    return {"snapshot": np.full(k.shape, snap_index, np.int32), "particle": k.astype(np.int32),
            "wall": wall, "position_tub": pos_tub.astype(np.float32),
            "arc": arc.astype(np.float32), "fn": fn.astype(np.float32),
            "ft": ft.astype(np.float32), "sliding": sliding,
            "force_lab": (fnv + ftv).astype(np.float32)}


#: columns of the wall/gran/local dump: mesh, triangle and atom id, F_n (3), F_t (3)
WALL_COLUMNS = 9
#: columns of the pair/gran/local dump: id (id1, id2, periodic-image flag), force (3)
PAIR_COLUMNS = 6
#: the `force` of compute pair/gran/local is the force on the first particle of its `id` pair
#: (+1) or on the second (-1).  Established with LIGGGHTS 3.8.0 (Debian), 300 balls settled in
#: a small tub (docs/liggghts.md): 99.97 % of the dumped contacts have F . (r_id1 - r_id2) > 0,
#: and adding F to id1 and -F to id2, plus the wall forces and the weight, gives LIGGGHTS' own
#: per-atom force to 1e-3 m g (tests/test_liggghts_io.py); the source agrees (add_pair(i, j, F)
#: with F what pair gran adds to f[i]).  Checked again on every import (PairCheck).
PAIR_FORCE_SIGN = 1.0
#: the dumped contacts must touch: |r_i - r_j| <= (r_i + r_j)(1 + this) (10-digit positions;
#: a wrong id mapping puts the partners a diameter or more apart)
PAIR_TOUCH_TOLERANCE = 1.0e-3
#: the smallest sum f_on_i . (r_i - r_j) / sum |f| |r_i - r_j| over an import's contacts
#: accepted as repulsive: a bed's contact forces are mostly normal and pushing (+0.95 to +0.99
#: measured, at rest and vibrated); the opposite convention gives the negative of that, ids
#: mapped to the wrong balls about 0
PAIR_MIN_REPULSION = 0.5


@dataclass
class PairCheck:
    """What the pair rows of an import add up to, for the sign check (`verdict`)."""

    contacts: int = 0
    virial: float = 0.0          # sum f_on_i . (r_i - r_j) (J)
    magnitude: float = 0.0       # sum |f| |r_i - r_j| (J)
    repulsive: int = 0           # contacts with f_on_i . (r_i - r_j) > 0

    def add(self, force: np.ndarray, branch: np.ndarray) -> None:
        w = np.einsum("ij,ij->i", force, branch)
        self.contacts += int(w.size)
        self.virial += float(w.sum())
        self.magnitude += float(np.sum(np.linalg.norm(force, axis=1)
                                       * np.linalg.norm(branch, axis=1)))
        self.repulsive += int(np.count_nonzero(w > 0))

    @property
    def repulsion(self) -> float:
        """sum f . b / sum |f| |b|: +1 all pushing along the line of centres, -1 all pulling."""
        return self.virial / self.magnitude if self.magnitude > 0 else float("nan")

    def verdict(self, path) -> None:
        """Raise InputError unless the contacts push on the whole."""
        if self.contacts and not self.repulsion > PAIR_MIN_REPULSION:
            raise InputError(
                f"{path}: the ball-ball contact forces pull the balls together on the whole "
                f"(sum f.(r_i - r_j) / sum |f||r_i - r_j| = {self.repulsion:.3g} over "
                f"{self.contacts} contacts, a bed gives > {PAIR_MIN_REPULSION}): the force "
                "column is not the force on the first id (another LIGGGHTS version or compute "
                "layout?)")


def _pair_rows(snap, snap_index, ids, pos_lab, radius, period, path, check: PairCheck):
    """vibroflow ball_contacts rows from one snapshot of the pair/gran/local dump.

    Columns (compute pair/gran/local id force): id1, id2, periodic-image flag, F (3, lab axes)
    with F the force on id1 by id2 (PAIR_FORCE_SIGN).  ids are mapped to the indices of the
    sorted snapshot (`ids`), each pair ordered i < j (F negated when swapped: Newton's third
    law), the rows sorted by (i, j) so the result does not depend on LIGGGHTS' rank order.
    The branch r_i - r_j is the minimum image along y when the tub is periodic (period > 0),
    as the calibration takes it; a pair across the periodic boundary (flag 1) is then as close
    as any other, which the touch check verifies.  Rows with an exactly zero force carry no
    stress and are dropped (a LIGGGHTS build whose compute also lists near pairs within a
    contact distance factor may write untouching pairs so; 3.8.0 wrote none in our runs):
    vibroflow stores touching pairs only.
    Raises InputError for another number of columns, ids that are not whole numbers, an id
    not in the snapshot, a pair twice, or partners apart.
    """
    data = snap.data
    if data.shape[1] != PAIR_COLUMNS:
        raise InputError(f"{path}: line {snap.first_row - 1} (step {snap.step}): "
                         f"{data.shape[1]} columns, expected {PAIR_COLUMNS} (compute "
                         "pair/gran/local id force)")
    force = PAIR_FORCE_SIGN * data[:, 3:6]
    keep = np.any(force != 0.0, axis=1)
    id1 = _whole_column(path, snap, 0)[keep]
    id2 = _whole_column(path, snap, 1)[keep]
    force = force[keep]
    a = np.clip(np.searchsorted(ids, id1), 0, ids.size - 1)
    b = np.clip(np.searchsorted(ids, id2), 0, ids.size - 1)
    bad = (ids[a] != id1) | (ids[b] != id2) | (id1 == id2)
    if np.any(bad):
        k = int(np.argmax(bad))
        raise InputError(f"{path}: snapshot {snap_index}: contact of ids {id1[k]}, {id2[k]}, "
                         "not two balls of the snapshot")
    swap = a > b
    i = np.where(swap, b, a)
    j = np.where(swap, a, b)
    force = np.where(swap[:, None], -force, force)
    order = np.lexsort((j, i))
    i, j, force = i[order], j[order], force[order]
    if i.size > 1 and np.any((i[1:] == i[:-1]) & (j[1:] == j[:-1])):
        k = int(np.argmax((i[1:] == i[:-1]) & (j[1:] == j[:-1])))
        raise InputError(f"{path}: snapshot {snap_index}: the contact of ids {ids[i[k]]}, "
                         f"{ids[j[k]]} appears twice (would count its force twice)")
    branch = pos_lab[i] - pos_lab[j]
    if period > 0.0:
        branch[:, 1] -= period * np.round(branch[:, 1] / period)
    dist = np.linalg.norm(branch, axis=1)
    apart = dist > (radius[i] + radius[j]) * (1.0 + PAIR_TOUCH_TOLERANCE)
    if np.any(apart):
        k = int(np.argmax(apart))
        raise InputError(f"{path}: snapshot {snap_index}: balls {ids[i[k]]} and {ids[j[k]]} "
                         f"are {dist[k]:.6g} m apart, more than their radii "
                         f"{radius[i[k]] + radius[j[k]]:.6g} m, yet in contact (ids not "
                         "those of the ball dump?)")
    check.add(force, branch)
    return {"snapshot": np.full(i.shape, snap_index, np.int32), "i": i.astype(np.int32),
            "j": j.astype(np.int32), "force_lab": force.astype(np.float32)}
