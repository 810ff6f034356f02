"""The DEM simulator as a pair of plain functions over a state record (JAX-MD style):

    system = make_system(scenario)          # what does not change: laws, walls, motion
    state = init_state(system, positions, velocities, angular_velocities, radii, materials)
    run_steps(system, state, n, ...)        # advance n steps in place

`DEMState` holds every array the run needs to continue bit for bit (positions, velocities,
forces, the neighbour list with its contact histories, the wall contacts' histories, the step
count); checkpoints and the settled-fill cache are just saved states.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ..tub.motion import TubMotion, lab_to_tub_np
from . import step as K
from ..scenario.checks import STEPS_PER_CONTACT, contact_times
from .laws import material_index, pair_table
from .neighbours import NeighbourList
from .walls import (N_PLANE, WALL_PARTITION_HI, WALL_PARTITION_LO, WALL_PLANE0, WALL_U,
                    wall_kind)

IMPACT_CAPACITY = 1 << 15  # per chunk, between flushes




class BlowUp(RuntimeError):
    """The run became unphysical, or its starting state cannot be run; the message (one line)
    names the balls and the cause the state shows: non-finite input, balls coincident or
    overlapping at the start, a ball behind a wall or outside the tub, and the time step only
    when it resolves the contact time too coarsely."""


@dataclass
class DEMSystem:
    """Everything constant during a run (SI units)."""

    dt: float
    gravity: np.ndarray            # (3,) m/s^2
    table: np.ndarray              # contact-law parameters, see laws.py
    tub: np.ndarray                # [radius, rim, length, periodic, present]
    wall_mat: np.ndarray           # material index of each wall slot
    planes: np.ndarray             # (P, N_PLANE) explicit plane walls
    motion: TubMotion              # the tub's vibration (amplitude factor applied)
    skin: float                    # Verlet skin (m)
    max_overlap: float             # blow-up bound (m)
    nchunk: int                    # force-assembly chunks (fixes the summation order)
    material_names: list[str]
    notes: dict = field(default_factory=dict)

    @property
    def n_walls(self) -> int:
        return WALL_PLANE0 + self.planes.shape[0]

    @property
    def periodic_length(self) -> float:
        return float(self.tub[2]) if (self.tub[4] > 0 and self.tub[3] > 0) else 0.0

    def motion_array(self, vibrating: bool) -> np.ndarray:
        return (self.motion if vibrating else TubMotion.still()).as_array()


@dataclass
class DEMState:
    step: int
    time_origin_step: int          # t = (step - time_origin_step) dt
    pos: np.ndarray
    vel: np.ndarray
    omg: np.ndarray
    force: np.ndarray
    torque: np.ndarray
    radius: np.ndarray
    mass: np.ndarray
    mat: np.ndarray
    nl: NeighbourList
    ref_tub: np.ndarray            # tub-frame positions at the last list build
    wall_hist: np.ndarray          # (N, W, 6)
    wall_flag: np.ndarray          # (N, W) uint8
    wall_fn: np.ndarray            # (N, W) N, at the last step
    wall_ft: np.ndarray            # (N, W) N
    wall_slide: np.ndarray         # (N, W) uint8
    wall_point: np.ndarray         # (N, W, 3) contact point (tub frame for tub walls)
    wall_force: np.ndarray         # (N, W, 3) force on the ball (N, lab axes), last step
    wall_arc: np.ndarray           # (N,) arc coordinate of the nearest U point (m)
    vibrating: bool = False
    scratch: object = field(default=None, repr=False, compare=False)  # not part of the state

    @property
    def n(self) -> int:
        return self.pos.shape[0]

    def time(self, dt: float) -> float:
        return (self.step - self.time_origin_step) * dt

    def kinetic_energy(self) -> float:
        """Translational + rotational kinetic energy in the lab frame (J)."""
        inertia = 0.4 * self.mass * self.radius**2
        return float(0.5 * np.sum(self.mass * np.sum(self.vel**2, axis=1))
                     + 0.5 * np.sum(inertia * np.sum(self.omg**2, axis=1)))


def make_system(scenario, nchunk: int | None = None) -> DEMSystem:
    """Constant parameters of a scenario's run (nchunk: force-assembly chunks, default
    run.force_chunks: a scenario's numbers do not depend on the number of threads)."""
    index = material_index(scenario)
    table = pair_table(scenario)
    if scenario.tub is not None:
        t = scenario.tub
        tub = np.array([t.radius, t.rim_height, t.length, float(t.periodic), 1.0])
        wall_mats = [index[t.wall_material], index[t.partition_material],
                     index[t.partition_material]]
    else:
        tub = np.array([1.0, 1.0, 1.0, 0.0, 0.0])
        wall_mats = [0, 0, 0]
    planes = np.zeros((len(scenario.walls or []), N_PLANE))
    for k, w in enumerate(scenario.walls or []):
        planes[k, 0:3] = w.point
        planes[k, 3:6] = w.normal
        planes[k, 6:9] = w.velocity
        planes[k, 9:12] = w.amplitude
        planes[k, 12] = 2.0 * math.pi * w.frequency
        planes[k, 13] = w.phase
        wall_mats.append(index[w.material])
    motion = TubMotion.of_scenario(scenario)
    if scenario.explicit:
        diam = max(p.diameter for p in scenario.particles)
    else:
        diam = scenario.fill.diameter
    try:  # for the blow-up diagnosis: is the time step a cause?
        notes = {"shortest_contact_time": shortest_contact_time(scenario)}
    except (ValueError, KeyError, ZeroDivisionError, OverflowError):
        notes = {}
    return DEMSystem(
        dt=scenario.run.dt, gravity=np.array(scenario.gravity, dtype=float), table=table,
        tub=tub, wall_mat=np.array(wall_mats, dtype=np.int64), planes=planes, motion=motion,
        skin=scenario.run.skin * diam, max_overlap=scenario.run.max_overlap * diam,
        nchunk=nchunk or scenario.run.force_chunks, material_names=list(index), notes=notes,
    )


def init_state(system: DEMSystem, pos, vel, omg, radius, density, mat) -> DEMState:
    """A state at step 0 from initial positions etc.; computes the initial forces."""
    pos = np.ascontiguousarray(pos, dtype=np.float64)
    n = pos.shape[0]
    radius = np.ascontiguousarray(radius, dtype=np.float64)
    mass = 4.0 / 3.0 * math.pi * radius**3 * np.asarray(density, dtype=float)
    w = system.n_walls
    state = DEMState(
        step=0, time_origin_step=0, pos=pos,
        vel=np.array(vel, dtype=np.float64).reshape(n, 3),
        omg=np.array(omg, dtype=np.float64).reshape(n, 3),
        force=np.zeros((n, 3)), torque=np.zeros((n, 3)), radius=radius,
        mass=np.ascontiguousarray(mass), mat=np.ascontiguousarray(mat, dtype=np.int64),
        nl=NeighbourList(system.skin, system.periodic_length), ref_tub=np.zeros((n, 3)),
        wall_hist=np.zeros((n, w, 6)), wall_flag=np.zeros((n, w), np.uint8),
        wall_fn=np.zeros((n, w)), wall_ft=np.zeros((n, w)),
        wall_slide=np.zeros((n, w), np.uint8), wall_point=np.zeros((n, w, 3)),
        wall_force=np.zeros((n, w, 3)),
        wall_arc=np.zeros(n),
    )
    _check_finite_start(state)
    rebuild(system, state)
    pair = _coincident_pair(system, state)
    if pair is not None:
        raise BlowUp(_coincident_message(system, state, pair))
    _forces_now(system, state)
    _check_overlaps_at_start(system, state)
    return state


def _vec(v) -> str:
    return "(" + ", ".join(f"{float(x):.6g}" for x in np.ravel(v)) + ")"


def _ids(ids, at_most: int = 10) -> str:
    ids = [int(i) for i in ids]
    more = f" and {len(ids) - at_most} more" if len(ids) > at_most else ""
    return str(ids[:at_most]) + more


def _wall_name(w: int) -> str:
    if w == WALL_U:
        return "wall 0 (the tub's U wall)"
    if w == WALL_PARTITION_LO:
        return "wall 1 (the partition at y = 0)"
    if w == WALL_PARTITION_HI:
        return "wall 2 (the partition at y = length)"
    return f"wall {w} (plane walls[{w - WALL_PLANE0}])"


def _check_finite_start(state: DEMState) -> None:
    """BlowUp naming the balls and fields of a starting state that holds NaN or infinity, or a
    radius or mass not > 0: the kernels would turn it into NaN everywhere (and the neighbour
    grid into nonsense) and the blow-up would be blamed on the time step."""
    bad = []
    for name, a in (("position", state.pos), ("velocity", state.vel),
                    ("angular_velocity", state.omg), ("radius", state.radius),
                    ("mass", state.mass)):
        rows = a.reshape(state.n, -1)
        wrong = ~np.isfinite(rows).all(axis=1)
        if name in ("radius", "mass"):
            wrong |= ~(rows[:, 0] > 0.0)
        bad += [(int(i), name, rows[i]) for i in np.nonzero(wrong)[0]]
    if bad:
        shown = ", ".join(f"ball {i} {name} = {_vec(v)}" for i, name, v in bad[:5])
        more = f" and {len(bad) - 5} more" if len(bad) > 5 else ""
        raise BlowUp(f"blow-up at t = 0 s: non-finite input: {shown}{more}; the starting state "
                     "must be finite (radius and mass > 0); not a time-step problem")


def _list_pairs(system: DEMSystem, state: DEMState) -> tuple[np.ndarray, np.ndarray,
                                                            np.ndarray]:
    """(i, j, squared centre distance) of the neighbour list's pairs, minimum image in y when
    periodic, summed in the kernel's order (dx^2 + dy^2 + dz^2)."""
    nl = state.nl
    i = np.repeat(np.arange(state.n), np.diff(nl.start))
    j = nl.nbr
    d = state.pos[i] - state.pos[j]
    L = system.periodic_length
    if L > 0.0:
        d[:, 1] -= L * np.rint(d[:, 1] / L)
    return i, j, d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2]


def _coincident_pair(system: DEMSystem, state: DEMState) -> tuple[int, int] | None:
    """The first pair of balls at one spot (zero centre distance: no contact normal, and the
    kernel's 1/d divides by zero), or None."""
    if not np.all(np.isfinite(state.pos)):
        return None
    i, j, d2 = _list_pairs(system, state)
    hit = np.nonzero(d2 == 0.0)[0]
    if hit.size == 0:
        return None
    return int(i[hit[0]]), int(j[hit[0]])


def _coincident_message(system: DEMSystem, state: DEMState, pair: tuple[int, int]) -> str:
    i, j = pair
    where = (f"blow-up at t = {state.time(system.dt):.6g} s: balls {i} and {j} are coincident "
             f"(both centres at {_vec(state.pos[i])} m): two balls on one spot have no contact "
             "normal")
    if state.step == 0:
        return f"{where}; the starting positions put them there; not a time-step problem"
    return f"{where}; they met head-on with no repulsion between them"


def _check_overlaps_at_start(system: DEMSystem, state: DEMState) -> None:
    """BlowUp when the starting positions already break the overlap bound (two balls deep in
    each other, a ball behind a wall) or put a ball outside the tub: the first step would blow
    up, and not because of the time step.  The set-up force evaluation has measured them."""
    b = _buf(system, state)
    diag = b.diag
    d = 2.0 * float(state.radius.max())
    bound = system.max_overlap
    c = int(np.argmax(diag[:, K.D_BALL_OVERLAP]))
    if diag[c, K.D_BALL_OVERLAP] > bound:
        i, j = int(diag[c, K.D_BALL_I]), int(diag[c, K.D_BALL_J])
        raise BlowUp(f"blow-up at t = 0 s: balls {i} and {j} overlap by "
                     f"{diag[c, K.D_BALL_OVERLAP] / d:.1%} of d at the start (bound "
                     f"{bound / d:.0%}): the starting positions overlap; not a time-step "
                     "problem")
    cw = int(np.argmax(diag[:, K.D_WALL_OVERLAP]))
    if diag[cw, K.D_WALL_OVERLAP] > bound:
        i, w = int(diag[cw, K.D_WALL_I]), int(diag[cw, K.D_WALL_W])
        delta = float(diag[cw, K.D_WALL_OVERLAP])
        r = float(state.radius[i])
        if delta >= r:
            raise BlowUp(f"blow-up at t = 0 s: ball {i} is behind {_wall_name(w)} at the start: "
                         f"its centre {_vec(state.pos[i])} m lies {(delta - r) * 1e3:.3g} mm "
                         "beyond the wall; the starting positions put it there; not a "
                         "time-step problem")
        raise BlowUp(f"blow-up at t = 0 s: ball {i} overlaps {_wall_name(w)} by "
                     f"{delta / d:.1%} of d at the start (bound {bound / d:.0%}): the starting "
                     "positions put it into the wall; not a time-step problem")
    lost = [int(x) for x in diag[:, K.D_LOST] if x >= 0]
    if lost:
        raise BlowUp(f"blow-up at t = 0 s: ball(s) {_ids(lost)} start outside the tub (ball "
                     f"{lost[0]} at {_vec(state.pos[lost[0]])} m); the starting positions put "
                     "them there; not a time-step problem")


class _Buffers:
    """Scratch arrays of the force assembly, made once per run."""

    def __init__(self, system: DEMSystem, n: int):
        self.fbuf = np.zeros((system.nchunk, n, 3))
        self.tbuf = np.zeros((system.nchunk, n, 3))
        self.imp_buf = np.zeros((system.nchunk, IMPACT_CAPACITY, 6))
        self.imp_count = np.zeros(system.nchunk, np.int64)
        self.diag = np.empty((system.nchunk, K.N_DIAG))
        self.pose = np.zeros(8)
        self.reset_diag()

    def reset_diag(self):
        self.diag[:] = -1.0
        self.diag[:, K.D_BALL_OVERLAP] = 0.0
        self.diag[:, K.D_WALL_OVERLAP] = 0.0


def _buf(system: DEMSystem, state: DEMState) -> _Buffers:
    b = state.scratch
    if b is None or b.fbuf.shape[1] != state.n or b.fbuf.shape[0] != system.nchunk:
        b = state.scratch = _Buffers(system, state.n)
    return b


def _tub_pose(system: DEMSystem, state: DEMState) -> np.ndarray:
    pose = np.zeros(8)
    pose[6], pose[7] = system.motion.pivot_x, system.motion.pivot_z
    K._pose_array(system.motion_array(state.vibrating), pose[6], pose[7],
                  state.time(system.dt), pose)
    return pose


def rebuild(system: DEMSystem, state: DEMState) -> None:
    """Rebuild the neighbour list (keeping contact histories) and its reference positions."""
    state.nl.build(state.pos, state.radius)
    pose = _tub_pose(system, state)
    state.ref_tub[:] = lab_to_tub_np(state.pos, pose[0], pose[1], pose[2],
                                     (pose[6], pose[7]))


def _forces_now(system: DEMSystem, state: DEMState) -> None:
    b = _buf(system, state)
    pose = _tub_pose(system, state)
    K.compute_forces(state.time(system.dt), system.dt, pose, state.pos, state.vel, state.omg,
                     state.radius, state.mass, state.mat, system.gravity, system.table,
                     state.nl.start, state.nl.nbr, state.nl.hist, state.nl.flag, system.tub,
                     system.wall_mat, system.planes, state.wall_hist, state.wall_flag,
                     state.wall_fn, state.wall_ft, state.wall_slide, state.wall_point,
                     state.wall_force, state.wall_arc, state.force, state.torque, b.fbuf,
                     b.tbuf, state.nl.chunk_bounds(system.nchunk), b.imp_buf, b.imp_count,
                     False, b.diag, False, state.ref_tub,
                     np.zeros(system.nchunk))
    b.imp_count[:] = 0


def take_impacts(system: DEMSystem, state: DEMState) -> np.ndarray:
    """Impacts recorded since the last call: (M, 6) [time, kind, x, y, z, speed] (lab), in a
    fixed order (chunk by chunk)."""
    b = _buf(system, state)
    parts = [b.imp_buf[c, :min(b.imp_count[c], IMPACT_CAPACITY)] for c in range(system.nchunk)]
    b.imp_count[:] = 0
    return np.concatenate(parts) if parts else np.zeros((0, 6))


def take_max_overlaps(system: DEMSystem, state: DEMState) -> tuple[float, float]:
    """Largest ball-ball and ball-wall overlaps (m) since the last call."""
    b = _buf(system, state)
    out = (float(b.diag[:, K.D_BALL_OVERLAP].max()), float(b.diag[:, K.D_WALL_OVERLAP].max()))
    b.reset_diag()
    return out


def _time_step_cause(system: DEMSystem) -> tuple[bool, str]:
    """(is the time step a likely cause, words on it): only when it resolves the shortest
    contact time with fewer than STEPS_PER_CONTACT steps."""
    tc = system.notes.get("shortest_contact_time")
    if not tc or not math.isfinite(tc):
        return False, f"time step dt = {system.dt:.3g} s (contact time not known)"
    per = tc / system.dt
    words = (f"time step dt = {system.dt:.3g} s, {per:.1f} steps per shortest contact time "
             f"{tc:.3g} s")
    return per < STEPS_PER_CONTACT * (1.0 - 1e-9), words


def _blowup_message(system: DEMSystem, state: DEMState, diag: np.ndarray) -> str:
    """One line: when, which balls, and the cause the state shows."""
    t = state.time(system.dt)
    d = 2.0 * float(state.radius.max())
    nan = [int(x) for x in diag[:, K.D_NAN] if x >= 0]
    lost = [int(x) for x in diag[:, K.D_LOST] if x >= 0]
    c = int(np.argmax(diag[:, K.D_BALL_OVERLAP]))
    cw = int(np.argmax(diag[:, K.D_WALL_OVERLAP]))
    dt_is_cause, dt_words = _time_step_cause(system)
    too_coarse = (f"likely cause: {dt_words}, too large (at least {STEPS_PER_CONTACT:.0f} "
                  "needed)")
    finite = np.isfinite(state.vel).all(axis=1)
    vmax = float(np.sqrt((state.vel[finite] ** 2).sum(axis=1)).max()) if finite.any() else 0.0
    if nan:
        where = f"blow-up at t = {t:.6g} s: ball(s) {_ids(nan)} have non-finite position"
        if dt_is_cause:
            return f"{where}; {too_coarse}"
        return (f"{where}; not the time step ({dt_words}); the largest finite speed is "
                f"{vmax:.3g} m/s: look at the starting velocities and the materials' density "
                "and contact stiffness")
    if diag[c, K.D_BALL_OVERLAP] > system.max_overlap:
        i, j = int(diag[c, K.D_BALL_I]), int(diag[c, K.D_BALL_J])
        where = (f"blow-up at t = {t:.6g} s: balls {i} and {j} overlap by "
                 f"{diag[c, K.D_BALL_OVERLAP] / d:.1%} of d (bound {system.max_overlap / d:.0%})")
        if dt_is_cause:
            return f"{where}; {too_coarse}"
        v = float(np.linalg.norm(state.vel[i] - state.vel[j]))
        return (f"{where}; likely cause: contact stiffness k_n too low for the load or for "
                f"their relative speed {v:.3g} m/s ({dt_words}: enough)")
    if diag[cw, K.D_WALL_OVERLAP] > system.max_overlap:
        i, w = int(diag[cw, K.D_WALL_I]), int(diag[cw, K.D_WALL_W])
        where = (f"blow-up at t = {t:.6g} s: ball {i} overlaps {_wall_name(w)} by "
                 f"{diag[cw, K.D_WALL_OVERLAP] / d:.1%} of d (bound "
                 f"{system.max_overlap / d:.0%})")
        if dt_is_cause:
            return f"{where}; {too_coarse}"
        v = float(np.linalg.norm(state.vel[i]))
        return (f"{where}; likely cause: wall contact stiffness k_n too low for the load or "
                f"for the ball's speed {v:.3g} m/s ({dt_words}: enough)")
    where = (f"blow-up at t = {t:.6g} s: ball(s) {_ids(lost)} outside the tub (ball {lost[0]} "
             f"at {_vec(state.pos[lost[0]])} m)" if lost else
             f"blow-up at t = {t:.6g} s: no ball named by the kernel")
    if dt_is_cause:
        return f"{where}; {too_coarse}, so a fast ball passed through the wall"
    v = float(np.linalg.norm(state.vel[lost[0]])) if lost else vmax
    return (f"{where}; likely cause: wall contact stiffness too low for the ball's speed "
            f"{v:.3g} m/s, so it passed through the wall ({dt_words}: enough)")


def run_steps(system: DEMSystem, state: DEMState, nsteps: int, record_impacts: bool = False,
              on_impacts: Callable[[np.ndarray], None] | None = None) -> None:
    """Advance the state by `nsteps` steps in place (rebuilding the list as needed)."""
    b = _buf(system, state)
    motion = system.motion_array(state.vibrating)
    b.pose[6], b.pose[7] = system.motion.pivot_x, system.motion.pivot_z
    half_skin = 0.5 * system.skin
    left = nsteps
    while left > 0:
        try:
            done, status = K.advance(
                state.step, left, system.dt, state.time_origin_step, motion, state.pos,
                state.vel, state.omg, state.radius, state.mass, state.mat, system.gravity,
                system.table, state.nl.start, state.nl.nbr, state.nl.hist, state.nl.flag,
                system.tub, system.wall_mat, system.planes, state.wall_hist, state.wall_flag,
                state.wall_fn, state.wall_ft, state.wall_slide, state.wall_point,
                state.wall_force, state.wall_arc, state.force, state.torque, b.fbuf, b.tbuf,
                state.nl.chunk_bounds(system.nchunk), state.ref_tub, half_skin, b.imp_buf,
                b.imp_count, record_impacts, b.diag, system.max_overlap, b.pose)
        except ZeroDivisionError:
            # 1/d of two coincident balls (numba raises it, as Python does); the step count is
            # unknown here, so the time is that of the call's start
            pair = _coincident_pair(system, state)
            if pair is None:
                raise
            raise BlowUp(_coincident_message(system, state, pair)) from None
        state.step += done
        left -= done
        if status == K.BLOWUP:
            raise BlowUp(_blowup_message(system, state, b.diag))
        if status == K.REBUILD:
            rebuild(system, state)
        if on_impacts is not None and (status == K.IMPACTS_FULL or left == 0):
            imp = take_impacts(system, state)
            if imp.shape[0]:
                on_impacts(imp)
        elif status == K.IMPACTS_FULL:
            take_impacts(system, state)


def wall_contacts_now(system: DEMSystem, state: DEMState) -> dict[str, np.ndarray]:
    """The current ball-wall contacts: particle, wall slot, contact point (tub frame), arc,
    F_n, |F_t|, sliding, force (the wall's force on the ball, N, lab axes), impact kind."""
    i, w = np.nonzero(state.wall_flag)
    arc = np.where(w == 0, state.wall_arc[i], np.nan)
    point = state.wall_point[i, w].copy()
    plane = w >= WALL_PLANE0
    if np.any(plane):
        # a plane wall's contact point is kept in the lab frame by the kernel
        from ..tub.motion import TubMotion, lab_to_tub_np, pose_np
        motion = system.motion if state.vibrating else TubMotion.still()
        pz = pose_np(motion, state.time(system.dt))
        point[plane] = lab_to_tub_np(point[plane], float(pz["X"]), float(pz["Z"]),
                                     float(pz["theta"]), (motion.pivot_x, motion.pivot_z))
    return {"particle": i.astype(np.int32), "wall": w.astype(np.int8),
            "position_tub": point.astype(np.float32), "point_tub": point,
            "arc": arc.astype(np.float32), "fn": state.wall_fn[i, w].astype(np.float32),
            "ft": state.wall_ft[i, w].astype(np.float32),
            "sliding": state.wall_slide[i, w].astype(bool),
            "force": state.wall_force[i, w],
            "kind": np.array([wall_kind(int(x)) for x in w], dtype=np.int8)}


def shortest_contact_time(scenario) -> float:
    """Shortest head-on contact time (s) of the pairs that can touch in this scenario: the one
    the scenario's time-step check uses (vibroflow.scenario.checks.contact_times)."""
    times = contact_times(scenario)
    return times[0][1] if times else math.inf
