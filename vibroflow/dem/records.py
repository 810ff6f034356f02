"""The records the tub step's compiled kernels take (vibroflow.dem.step): numba named tuples of
arrays and numbers, unpacked into local variables at the top of each kernel.

`Balls` and `Walls` view a run's state arrays and `Work` its scratch arrays (made once per run,
vibroflow.dem.simulate); `Pairs` views the neighbour list, whose arrays a rebuild replaces;
`Params` holds the run's constants (vibroflow.dem.simulate.make_system).  `BoxBalls` and `Box`
are the Lees-Edwards box's (vibroflow.dem.periodic_box).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np


class Balls(NamedTuple):
    """One row a ball: the DEMState arrays of the same names."""

    pos: np.ndarray
    vel: np.ndarray
    omg: np.ndarray
    radius: np.ndarray
    mass: np.ndarray
    mat: np.ndarray
    force: np.ndarray
    torque: np.ndarray
    ref_tub: np.ndarray


class Pairs(NamedTuple):
    """The half neighbour list (vibroflow.dem.neighbours) and its blocks of balls."""

    start: np.ndarray      # (N + 1,) first list entry of each ball
    nbr: np.ndarray        # (M,) int32: the other ball of each entry
    hist: np.ndarray       # (M, 3 or 6) contact histories (laws.history_width)
    flag: np.ndarray       # (M,) uint8, 1 while in contact
    bounds: np.ndarray     # (nblock + 1,) first ball of each block


class PairSlots(NamedTuple):
    """The half list's entries in reverse order, ball j by ball j (the entries (i, j) where j
    is the second ball, ascending), and the touching entries' contact rows with their
    histories and their force and torque on j: the tub step's force assembly
    (vibroflow.dem.step, vibroflow.dem.neighbours, vibroflow.dem.contact_rows)."""

    out: np.ndarray        # (M, 6) force (N) and torque (N m) on j, a contact row each
    rstart: np.ndarray     # (N + 1,) first reverse position of each ball
    rpos: np.ndarray       # (M,) int32: reverse position of each list entry
    rflag: np.ndarray      # (M,) uint8 the list's contact flags in reverse order
    row: np.ndarray        # (M,) int32: each list entry's contact row (-1: none)
    rrow: np.ndarray       # (M,) int32: the contact row of each touching reverse position
    chist: np.ndarray      # (M, hist width) the contact rows' histories


class Walls(NamedTuple):
    """The ball-wall contacts, one slot a wall (vibroflow.dem.walls): the DEMState arrays
    wall_hist, wall_flag, ... wall_arc."""

    hist: np.ndarray
    flag: np.ndarray
    fn: np.ndarray
    ft: np.ndarray
    slide: np.ndarray
    point: np.ndarray
    force: np.ndarray
    arc: np.ndarray


class Work(NamedTuple):
    """Scratch arrays of the tub step, one row a block of balls (vibroflow.dem.step.NBLOCK),
    and one a ball for `save` (SI units)."""

    imp_buf: np.ndarray    # (nblock, capacity, N_IMP_BUF) impacts
    imp_count: np.ndarray  # (nblock,) impacts recorded
    diag: np.ndarray       # (nblock, step.N_DIAG) diagnostics
    pose: np.ndarray       # (8,) tub pose (step._pose_array)
    moved: np.ndarray      # (nblock,) largest squared move since the list build (m^2)
    save: np.ndarray       # (N, 9) each ball's position, velocity, spin before a drift
    imp_flush: np.ndarray  # (2,) a block's rows past which advance stops: ball-ball and wall,
    #                        ball-part (vibroflow.dem.impact_order)
    tile: np.ndarray       # (nblock, step.N_TILE * step.TILE) a tile of contacts' columns
    tile_idx: np.ndarray   # (nblock, step.N_TILE_IDX * step.TILE) int64 their entry, i, j
    queue: np.ndarray      # int64 the blocks' lanes, the lane count (vibroflow.dem.block_queue)
    row_next: np.ndarray   # (nblock,) int64 each block's next free contact row (contact_rows)


class Params(NamedTuple):
    """The run's constants."""

    dt: float              # s
    gravity: np.ndarray    # (3,) m/s^2
    table: np.ndarray      # contact-law parameters (vibroflow.dem.laws)
    tub: np.ndarray        # vibroflow.dem.walls' TUB_* entries
    wall_mat: np.ndarray   # material index of each wall slot
    planes: np.ndarray     # (P, N_PLANE) explicit plane walls
    half_skin: float       # m: a ball that moved further asks for a rebuild
    max_overlap: float     # m: the blow-up bound



def balls_of(state) -> Balls:
    """The Balls record of a vibroflow.dem.simulate.DEMState's arrays."""
    return Balls(*(getattr(state, name) for name in Balls._fields))


def walls_of(state) -> Walls:
    """The Walls record of a vibroflow.dem.simulate.DEMState's arrays."""
    return Walls(*(getattr(state, "wall_" + name) for name in Walls._fields))


def pairs_of(nl, nblock: int = 1) -> Pairs:
    """The Pairs record of a vibroflow.dem.neighbours.NeighbourList's current arrays, in
    `nblock` blocks of balls."""
    if nblock > 1:
        bounds = nl.chunk_bounds(nblock)
    else:
        bounds = np.array([0, nl.start.shape[0] - 1], np.int64)
    return Pairs(nl.start, nl.nbr, nl.hist, nl.flag, bounds)


def slots_of(nl) -> PairSlots:
    """The PairSlots record of a vibroflow.dem.neighbours.NeighbourList's current arrays."""
    nl.index_pairs()
    return PairSlots(nl.rout, nl.rstart, nl.rpos, nl.rflag, nl.row, nl.rrow, nl.chist)

class BoxBalls(NamedTuple):
    """The balls of the Lees-Edwards box (vibroflow.dem.periodic_step), one row a ball (SI)."""

    pos: np.ndarray        # (N, 3) m, wrapped into the box
    vel: np.ndarray        # (N, 3) m/s, lab velocities
    omg: np.ndarray        # (N, 3) rad/s
    force: np.ndarray      # (N, 3) N
    torque: np.ndarray     # (N, 3) N m
    radius: np.ndarray     # (N,) m
    mass: np.ndarray       # (N,) kg
    inertia: np.ndarray    # (N,) kg m^2
    disp: np.ndarray       # (N, 3) non-affine displacement since the list build (m)
    image: np.ndarray      # (N, 3) int64 box crossings
    degree: np.ndarray     # (N,) int64 contacts of each ball


class Box(NamedTuple):
    """The Lees-Edwards box and its control (the B_, R_, C_, S_ and Q_ entries of
    vibroflow.dem.periodic_step and vibroflow.dem.lees_edwards)."""

    box: np.ndarray        # lengths (m) and Lees-Edwards offset (m)
    rates: np.ndarray      # shear rate and dilation rates (1/s)
    ctrl: np.ndarray       # the box control's settings
    state: np.ndarray      # time, strains, sample counters, largest overlap
    virial: np.ndarray     # (3, 3) contact virial sum (N m)
    acc: np.ndarray        # the sampling block's sums
    table: np.ndarray      # (1, 1, N_PARAMS) the ball-ball contact law
