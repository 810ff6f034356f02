"""The DEM simulator as a pair of plain functions over a state record (JAX-MD style):

    system = make_system(scenario)          # what does not change: laws, walls, motion
    state = init_state(system, positions, velocities, angular_velocities, radii, materials)
    run_steps(system, state, n, ...)        # advance n steps in place

`DEMState` holds every array the run needs to continue bit for bit (positions, velocities,
forces, the neighbour list with its contact histories, the wall contacts' histories, the step
count); checkpoints and the settled-fill cache are just saved states.  When a run cannot go on,
`BlowUp` says why in one line (vibroflow.dem.blowup).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numba
import numpy as np

from ..scenario.checks import contact_times
from ..tub.motion import TubMotion, lab_to_tub_np, pose_np
from ..tub.parts import Part, PackedParts, pack, parts_of
from . import step as K
from .block_queue import queue_array, set_lanes
from .blowup import (BlowUp, blowup_message, check_finite_start, check_overlaps_at_start,
                     coincident_message, coincident_pair)
from .laws import history_width, material_index, pair_table
from . import memory_order as M
from .impact_order import ImpactOrder, ImpactsLost, impact_bound, lost_message
from .memory_order import by_id, space_order, store
from .neighbours import NeighbourList
from . import parts as PT
from .parts import EMPTY, N_LOAD, SLOTS, parts_record, sum_loads
from .records import Params, Work, balls_of, pairs_of, slots_of, walls_of
from .walls import N_PLANE, WALL_PLANE0, wall_kind

IMPACT_CAPACITY = 1 << 11  # rows per block of balls (step.NBLOCK), at least
# a block's rows past which they are flushed: fixes the flushes, hence the rows' order in
# dem.h5 (impact_order; ball-part rows: parts.IMPACT_FLUSH)
IMPACT_FLUSH = 1 << 10


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
    material_names: list[str]
    notes: dict = field(default_factory=dict)
    parts: tuple[Part, ...] = ()   # the scenario's parts (vibroflow.tub.parts)
    part_mat: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    packed: PackedParts = field(init=False, repr=False, compare=False)
    params: Params = field(init=False, repr=False, compare=False)  # the kernels' constants

    def __post_init__(self):
        self.params = Params(float(self.dt), self.gravity, self.table, self.tub, self.wall_mat,
                             self.planes, 0.5 * self.skin, float(self.max_overlap))
        self.packed = pack(self.parts)

    @property
    def n_parts(self) -> int:
        return len(self.parts)

    @property
    def n_walls(self) -> int:
        return WALL_PLANE0 + self.planes.shape[0]

    @property
    def history_width(self) -> int:
        """The columns of a ball pair's contact history (laws.history_width)."""
        return history_width(self.table)

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
    part_hist: np.ndarray | None = None  # (N, P, SLOTS, 6) ball-part contact histories
    part_key: np.ndarray | None = None   # (N, P, SLOTS) int64 their features (parts.EMPTY)
    part_load: np.ndarray | None = None  # (step.NBLOCK, P, 6) force, torque on the parts, per
    # block of the balls by id (vibroflow.dem.parts.sum_loads)
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
        move = self.mass * np.sum(self.vel**2, axis=1)
        spin = inertia * np.sum(self.omg**2, axis=1)
        if self.nl.ids is not None:  # summed by ball id, whatever the storage order
            by_id = np.empty((2, self.n))
            by_id[0, self.nl.ids] = move
            by_id[1, self.nl.ids] = spin
            move, spin = by_id
        return float(0.5 * np.sum(move) + 0.5 * np.sum(spin))


def make_system(scenario) -> DEMSystem:
    """Constant parameters of a scenario's run (its numbers do not depend on the number of
    threads: vibroflow.dem.step)."""
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
        material_names=list(index), notes=notes, parts=parts_of(scenario),
        part_mat=np.array([index[p.material] for p in scenario.parts or []], dtype=np.int64),
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
        nl=NeighbourList(system.skin, system.periodic_length, system.history_width),
        ref_tub=np.zeros((n, 3)),
        wall_hist=np.zeros((n, w, 6)), wall_flag=np.zeros((n, w), np.uint8),
        wall_fn=np.zeros((n, w)), wall_ft=np.zeros((n, w)),
        wall_slide=np.zeros((n, w), np.uint8), wall_point=np.zeros((n, w, 3)),
        wall_force=np.zeros((n, w, 3)),
        wall_arc=np.zeros(n),
    )
    ensure_part_arrays(system, state)
    check_finite_start(state)
    rebuild(system, state)
    pair = coincident_pair(system, state)
    if pair is not None:
        raise BlowUp(coincident_message(system, state, pair))
    _forces_now(system, state)
    check_overlaps_at_start(system, state, _buf(system, state).work.diag)
    return state


def ensure_part_arrays(system: DEMSystem, state: DEMState) -> None:
    """Give the state its ball-part contact arrays (free slots, zero loads) where it has none
    of the system's shape."""
    p, n = system.n_parts, state.n
    if state.part_key is None or state.part_key.shape != (n, p, SLOTS):
        state.part_hist = np.zeros((n, p, SLOTS, 6))
        state.part_key = np.full((n, p, SLOTS), EMPTY, np.int64)
    if state.part_load is None or state.part_load.shape != (K.NBLOCK, p, N_LOAD):
        state.part_load = np.zeros((K.NBLOCK, p, N_LOAD))


class _Buffers:
    """Scratch arrays of the force assembly and the kernels' records of a state's arrays,
    made once per run."""

    def __init__(self, system: DEMSystem, state: DEMState):
        nblock = K.NBLOCK
        self.n = state.n
        self.work = Work(imp_buf=np.zeros((nblock, IMPACT_CAPACITY, K.N_IMP_BUF)),
                         imp_count=np.zeros(nblock, np.int64), diag=np.empty((nblock, K.N_DIAG)),
                         pose=np.zeros(8), moved=np.zeros(nblock), save=np.zeros((state.n, 9)),
                         imp_flush=np.array([IMPACT_FLUSH, PT.IMPACT_FLUSH], np.int64),
                         tile=np.zeros((nblock, K.N_TILE * K.TILE)),
                         tile_idx=np.zeros((nblock, K.N_TILE_IDX * K.TILE), np.int64),
                         queue=queue_array(nblock), row_next=np.zeros(nblock, np.int64))
        #: the storage order of the last space sort (memory_order), taken up again by the
        #: next run_steps call
        self.order: np.ndarray | None = None
        self.balls = balls_of(state)
        self.walls = walls_of(state)
        ensure_part_arrays(system, state)
        self.parts = parts_record(system.packed, system.part_mat, state.part_hist,
                                  state.part_key, nblock)
        #: the impact rows' flushes, in the order of the balls by id (impact_order)
        self.impacts = ImpactOrder(nblock, self.buffers, self.work.imp_flush)
        self.reset_diag()

    def fit(self, system: DEMSystem, nl: NeighbourList) -> None:
        """Grow the impact buffers, keeping their rows, to the flush threshold plus the most
        rows a block records in one step on list `nl` (impact_order.impact_bound), where they
        hold fewer: no block's rows can pass its buffer (impact_order)."""
        bound = impact_bound(nl.start, nl.chunk_bounds(K.NBLOCK), system.n_walls,
                             system.n_parts)
        need = [int(f) + int(b.max(initial=0)) for f, b in zip(self.work.imp_flush, bound)]
        old = self.buffers
        if need[0] > old[0].shape[1]:
            self.work = self.work._replace(imp_buf=_grown(old[0], need[0]))
        if need[1] > old[1].shape[1]:
            self.parts = self.parts._replace(imp=_grown(old[1], need[1]))

    def over_flush(self) -> bool:
        """Whether some block's rows in the buffers pass the flush threshold."""
        return any(bool(np.any(n > f)) for n, f in zip(self.counts, self.work.imp_flush))

    @property
    def buffers(self) -> tuple[np.ndarray, np.ndarray]:
        """The impact buffers: ball-ball and wall rows, ball-part rows."""
        return self.work.imp_buf, self.parts.imp

    @property
    def counts(self) -> tuple[np.ndarray, np.ndarray]:
        """Their rows recorded, per block of stored balls."""
        return self.work.imp_count, self.parts.imp_count

    def reset_diag(self):
        diag = self.work.diag
        diag[:] = -1.0
        diag[:, K.D_BALL_OVERLAP] = 0.0
        diag[:, K.D_WALL_OVERLAP] = 0.0


def _grown(buf: np.ndarray, rows: int) -> np.ndarray:
    """buf (nblock, capacity, width) with `rows` rows a block, its rows kept."""
    out = np.zeros((buf.shape[0], rows, buf.shape[2]))
    out[:, :buf.shape[1]] = buf
    return out


def _buf(system: DEMSystem, state: DEMState) -> _Buffers:
    state.nl.widen_history(system.history_width)
    b = state.scratch
    if b is None or b.n != state.n:
        b = state.scratch = _Buffers(system, state)
    return b


def _tub_pose(system: DEMSystem, state: DEMState) -> np.ndarray:
    pose = np.zeros(8)
    pose[6], pose[7] = system.motion.pivot_x, system.motion.pivot_z
    K._pose_array(system.motion_array(state.vibrating), pose[6], pose[7],
                  state.time(system.dt), pose)
    return pose


def rebuild(system: DEMSystem, state: DEMState, sort: bool = False) -> None:
    """Rebuild the neighbour list (keeping contact histories) and its reference positions;
    with `sort`, store the balls in space order first (vibroflow.dem.memory_order)."""
    old_of = None
    if sort:
        b = _buf(system, state)
        old_of = space_order(state.pos, state.radius, system.skin,
                             state.nl.id_arrays(state.n)[0])
        store(state, b.work.diag, old_of, keep_list=False)
        b.order = state.nl.ids
    state.nl.build(state.pos, state.radius, old_of)
    pose = _tub_pose(system, state)
    state.ref_tub[:] = lab_to_tub_np(state.pos, pose[0], pose[1], pose[2],
                                     (pose[6], pose[7]))


def _forces_now(system: DEMSystem, state: DEMState) -> None:
    b = _buf(system, state)
    b.work.pose[:] = _tub_pose(system, state)
    set_lanes(b.work.queue, numba.get_num_threads())
    K.compute_forces(state.time(system.dt), False, False, False, b.balls,
                     pairs_of(state.nl, K.NBLOCK), slots_of(state.nl), b.walls, system.params,
                     b.work, b.parts)
    _sum_part_loads(system, state)
    for count in b.counts:
        count[:] = 0


def _sum_part_loads(system: DEMSystem, state: DEMState) -> None:
    """state.part_load from the balls' loads on the parts at the last step, block of the balls
    by id by block (vibroflow.dem.parts.sum_loads; the list of that step)."""
    if system.n_parts:
        prt, nl = _buf(system, state).parts, state.nl
        sum_loads(prt.contrib, prt.ncontrib, nl.id_arrays(state.n)[1], nl.id_blocks(K.NBLOCK)[0],
                  state.part_load)


def part_loads_now(system: DEMSystem, state: DEMState) -> np.ndarray:
    """(P, 6) force (N) and torque about each part's centre (N m) of the balls on each part at
    the last step, part axes (tub axes for a tub-fixed part): the blocks' sums added in block
    order."""
    out = np.zeros((system.n_parts, N_LOAD))
    for c in range(K.NBLOCK):
        out += state.part_load[c]
    return out


def take_max_overlaps(system: DEMSystem, state: DEMState) -> tuple[float, float]:
    """Largest ball-ball and ball-wall overlaps (m) since the last call."""
    b = _buf(system, state)
    diag = b.work.diag
    out = (float(diag[:, K.D_BALL_OVERLAP].max()), float(diag[:, K.D_WALL_OVERLAP].max()))
    b.reset_diag()
    return out


def overlap_maxima(state: DEMState) -> np.ndarray | None:
    """The diagnostics of the step (largest overlaps and the balls, step.D_*) since the last
    take_max_overlaps, or None before the first step; a checkpoint carries them so that the
    series of a resumed run is exact."""
    return state.scratch.work.diag if state.scratch is not None else None


def set_overlap_maxima(system: DEMSystem, state: DEMState, diag: np.ndarray) -> None:
    """Restore the diagnostics of overlap_maxima (a resumed checkpoint's)."""
    _buf(system, state).work.diag[:] = diag


def store_by_id(system: DEMSystem, state: DEMState) -> None:
    """The balls stored back by id (memory_order), where a space sort stored them anew: what
    run_steps(keep_order=True)'s caller does before it reads the state's arrays."""
    rows = by_id(state)
    if rows is not None:
        store(state, _buf(system, state).work.diag, rows)


def forget_histories(state: DEMState) -> None:
    """Every contact's tangential spring xi_t and elastic rolling torque set to zero (ball-ball,
    ball-wall, ball-part; contact.py's hist), the contacts themselves kept: the start of a code
    that reads the bed from positions and velocities alone, as LIGGGHTS' read_data does
    (docs/validation.md section 27)."""
    state.nl.hist[:] = 0.0
    state.wall_hist[:] = 0.0
    if state.part_hist is not None:
        state.part_hist[:] = 0.0


def run_steps(system: DEMSystem, state: DEMState, nsteps: int, record_impacts: bool = False,
              on_impacts: Callable[[np.ndarray], None] | None = None,
              on_part_impacts: Callable[[np.ndarray], None] | None = None,
              memory_order: bool | None = None, keep_order: bool = False) -> None:
    """Advance the state by `nsteps` steps in place (rebuilding the list as needed); the
    recorded impacts go to on_impacts ((M, 6) rows [time, kind, x, y, z, speed], lab) and
    on_part_impacts ((M, N_IMP) rows of vibroflow.dem.parts' IMP_* columns, ball ids), in
    flushes in the order of the balls by id (vibroflow.dem.impact_order).  memory_order:
    store the balls in space order during the steps (vibroflow.dem.memory_order; None: from
    MEMORY_ORDER_FROM balls on), with the same numbers and rows either way.  The state comes
    back stored by id, or with `keep_order` as the steps left it (a caller that reads its
    arrays calls store_by_id first; kinetic_energy needs not), which spares the storing of
    calls that only step on."""
    b = _buf(system, state)
    if memory_order is None:
        memory_order = state.n >= M.MEMORY_ORDER_FROM
    if (memory_order and state.nl.ids is None and b.order is not None
            and b.order.shape[0] == state.n):
        store(state, b.work.diag, b.order)  # the last sort's order, taken up again
    try:
        _run_steps(system, state, nsteps, record_impacts, on_impacts, on_part_impacts,
                   memory_order)
    except BaseException:
        store_by_id(system, state)
        raise
    if not keep_order:
        store_by_id(system, state)


def _run_steps(system: DEMSystem, state: DEMState, nsteps: int, record_impacts: bool,
               on_impacts, on_part_impacts, memory_order: bool) -> None:
    b = _buf(system, state)
    motion = system.motion_array(state.vibrating)
    b.work.pose[6], b.work.pose[7] = system.motion.pivot_x, system.motion.pivot_z
    left = nsteps
    b.fit(system, state.nl)
    set_lanes(b.work.queue, numba.get_num_threads())
    while left > 0:
        try:
            done, status = K.advance(state.step, left, state.time_origin_step, motion,
                                     record_impacts, b.balls, pairs_of(state.nl, K.NBLOCK),
                                     slots_of(state.nl), b.walls, system.params, b.work, b.parts)
        except ZeroDivisionError:
            # 1/d of two coincident balls (numba raises it, as Python does); the step count is
            # unknown here, so the time is that of the call's start
            store_by_id(system, state)
            pair = coincident_pair(system, state)
            if pair is None:
                raise
            raise BlowUp(coincident_message(system, state, pair)) from None
        state.step += done
        left -= done
        if status == K.IMPACTS_LOST:
            raise ImpactsLost(lost_message(b.buffers, b.counts, state.step))
        order = b.impacts
        if record_impacts:  # with the list of the steps, before a rebuild
            order.tag(b.buffers, b.counts, state.nl, state.time_origin_step, system.dt)
        if left == 0:
            _sum_part_loads(system, state)
        if status == K.BLOWUP:
            store_by_id(system, state)
            raise BlowUp(blowup_message(system, state, b.work.diag))
        if status == K.REBUILD:
            order.rebuilds.append(state.step)
            rebuild(system, state, sort=memory_order and state.nl.builds % M.SORT_EVERY == 0)
            b.fit(system, state.nl)
        # a block past the threshold is drained before the next call (impact_order's bound)
        if status == K.IMPACTS_FULL or left == 0 or order.exceeded() or b.over_flush():
            order.settle(b.buffers, b.counts, state.step, (on_impacts, on_part_impacts))
        if left == 0:
            order.finish((on_impacts, on_part_impacts), on_impacts is not None)


def wall_contacts_now(system: DEMSystem, state: DEMState) -> dict[str, np.ndarray]:
    """The current ball-wall contacts: particle, wall slot, contact point (tub frame), arc,
    F_n, |F_t|, sliding, force (the wall's force on the ball, N, lab axes), impact kind."""
    i, w = np.nonzero(state.wall_flag)
    arc = np.where(w == 0, state.wall_arc[i], np.nan)
    point = state.wall_point[i, w].copy()
    plane = w >= WALL_PLANE0
    if np.any(plane):
        # a plane wall's contact point is kept in the lab frame by the kernel
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
