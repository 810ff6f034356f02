"""The balls stored in space order during a run (vibroflow.dem.memory_order) give the numbers of
the balls stored by id, bit for bit:

- a falling bed, whose contacts and impacts start and end at every step, sorted at every
  neighbour rebuild, has the positions, velocities, forces, wall and pair histories of the
  unsorted run, and its impact rows, flush by flush, in the same order;
- a bed falling onto a part, sorted at every rebuild, gives the impact rows, the ball-part
  impact rows and the part loads of the unsorted run bit for bit, in the same order and the
  same flushes, on one thread and on two (the buffers made small, so that flushes come in
  the middle of the calls and at steps where the list is rebuilt);
- a run saved to a state file while its balls are in space order, read back and stepped on,
  ends where the uninterrupted one does;
- the ball-part impacts name the ids of the balls that hit the part;
- the slab order keeps every pair of a long bed within the three slabs about its first ball in
  memory, the locality it is chosen for.
"""
from __future__ import annotations

import numba
import numpy as np
import pytest

from dem_helpers import ball
from tests.test_dem_parts import _box, _sim
from vibroflow.dem import fill as F
from vibroflow.dem import memory_order as M
from vibroflow.dem import parts as P
from vibroflow.dem import simulate as S
from vibroflow.dem.output import load_state_file, save_state_file
from vibroflow.dem.parts import IMP_BALL
from vibroflow.scenario.io import load_scenario

ARRAYS = ("pos", "vel", "omg", "force", "torque", "ref_tub", "wall_hist", "wall_flag",
          "wall_fn", "wall_point", "wall_arc")


@pytest.fixture
def sort_at_every_rebuild(monkeypatch):
    monkeypatch.setattr(M, "SORT_EVERY", 1)


def _bed():
    sc = load_scenario("tub47-quick", ["fill.count=300"])
    system = S.make_system(sc)
    state = F.fill_state(system, sc)
    state.vibrating = True
    return system, state


def _steps(system, state, calls: int, sort: bool, impacts: list | None = None) -> bool:
    """`calls` run_steps calls of 100 steps, the balls left as the steps leave them between
    calls; whether they were ever stored other than by id."""
    moved = False
    for _ in range(calls):
        S.run_steps(system, state, 100, record_impacts=impacts is not None,
                    on_impacts=None if impacts is None else impacts.append,
                    memory_order=sort, keep_order=True)
        moved |= state.nl.ids is not None
    S.store_by_id(system, state)
    return moved


def _same_state(a, b) -> None:
    for name in ARRAYS:
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    for name in ("start", "nbr", "hist", "flag"):
        assert np.array_equal(getattr(a.nl, name), getattr(b.nl, name)), name
    assert a.nl.builds == b.nl.builds


def test_a_bed_sorted_at_every_rebuild_has_the_numbers_of_the_unsorted_one(
        sort_at_every_rebuild):
    system, plain = _bed()
    _s, stored = _bed()
    imp_plain, imp_stored = [], []
    _steps(system, plain, 40, False, imp_plain)
    assert _steps(system, stored, 40, True, imp_stored)  # the balls were stored anew
    assert plain.nl.builds > 10 and np.count_nonzero(plain.nl.flag) > 10
    _same_state(plain, stored)
    assert plain.kinetic_energy() == stored.kinetic_energy()
    assert sum(a.shape[0] for a in imp_plain) > 100
    _same_flushes(imp_plain, imp_stored)


def _same_flushes(a: list, b: list) -> None:
    assert len(a) == len(b)
    for x, y in zip(a, b):
        assert np.array_equal(x, y)


def _bar_run(sort: bool, threads: int):
    """300 balls dropped from their fill lattice around tub47-bar's bar in a short, narrow tub,
    20 calls of 100 steps, every 3rd call ending with the balls stored by id: the flushes of
    impact and ball-part impact rows, and the part loads after each call."""
    sc = load_scenario("tub47-bar", ["fill.count=300", "tub.length=0.01905",
                                     "tub.radius=0.04", "tub.rim_height=0.12",
                                     "parts.0.center=[0.0, 0.0, 0.035]",
                                     "fill.lattice_spacing=1.01", "fill.insert_above=0.0"])
    system = S.make_system(sc)
    before = numba.get_num_threads()
    numba.set_num_threads(threads)
    try:
        state = F.fill_state(system, sc)
        state.vibrating = True
        imp, part_imp, loads = [], [], []
        for call in range(20):
            S.run_steps(system, state, 100, record_impacts=True, on_impacts=imp.append,
                        on_part_impacts=part_imp.append, memory_order=sort,
                        keep_order=call % 3 != 2)
            loads.append(S.part_loads_now(system, state))
        S.store_by_id(system, state)
    finally:
        numba.set_num_threads(before)
    return imp, part_imp, np.array(loads), state


def test_a_bed_on_a_part_sorted_gives_the_rows_and_loads_of_the_unsorted_one(
        sort_at_every_rebuild, monkeypatch):
    # a flush after 4 rows of one block, some within a call; buffers of 8 rows a block at
    # first, grown to the bound (impact_order)
    monkeypatch.setattr(S, "IMPACT_FLUSH", 4)
    monkeypatch.setattr(P, "IMPACT_FLUSH", 4)
    monkeypatch.setattr(S, "IMPACT_CAPACITY", 8)
    monkeypatch.setattr(P, "IMPACT_CAPACITY", 8)
    imp, part_imp, loads, plain = _bar_run(False, 1)
    assert len(imp) > 20  # more flushes than calls
    assert sum(a.shape[0] for a in part_imp) > 10  # balls hit the bar
    assert np.count_nonzero(loads[:, 0, 0]) > 5  # and rest on it
    for threads in (1, 2):
        if threads > numba.config.NUMBA_NUM_THREADS:
            continue
        imp_s, part_imp_s, loads_s, stored = _bar_run(True, threads)
        assert stored.nl.builds > 10
        _same_flushes(imp, imp_s)
        _same_flushes(part_imp, part_imp_s)
        assert np.array_equal(loads, loads_s)
        assert np.array_equal(plain.pos, stored.pos)


def test_a_state_saved_in_space_order_resumes_to_the_same_numbers(tmp_path,
                                                                  sort_at_every_rebuild):
    system, whole = _bed()
    _steps(system, whole, 20, True)
    _s, first = _bed()
    _steps(system, first, 10, True)
    save_state_file(tmp_path / "state.h5", first)
    again, _attrs = load_state_file(tmp_path / "state.h5")
    again.vibrating = True
    _steps(system, again, 10, True)
    _same_state(whole, again)


def test_part_impacts_name_the_ids_of_the_balls(sort_at_every_rebuild):
    # six balls from all sides onto a box, each one's id known from its start
    rng = np.random.default_rng(4)
    dirs = rng.normal(size=(6, 3))
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    balls = [ball(0.022 * n, vel=tuple(-1.0 * n)) for n in dirs]
    runs = {}
    for sort in (False, True):
        sim = _sim(_box(), balls, mu=0.3)
        rows, moved = [], False
        for _ in range(100):
            S.run_steps(sim.system, sim.state, 50, record_impacts=True,
                        on_part_impacts=rows.append, memory_order=sort, keep_order=True)
            moved |= sim.state.nl.ids is not None
        S.store_by_id(sim.system, sim.state)
        runs[sort] = (np.concatenate(rows), moved, sim.state)
    (plain, _, a), (stored, moved, b) = runs[False], runs[True]
    assert moved
    assert sorted(set(plain[:, IMP_BALL].astype(int))) == list(range(6))  # every ball hit
    assert np.array_equal(plain, stored)
    assert np.array_equal(a.pos, b.pos) and np.array_equal(a.part_hist, b.part_hist)


@pytest.mark.slow
def test_a_run_sorted_from_the_first_ball_writes_the_rows_of_the_unsorted_run(tmp_path,
                                                                             monkeypatch):
    # run_dem in this process, the sort forced on a 400-ball tub: every snapshot, wall contact,
    # time-series and impact row as without it, in the same order
    import h5py

    from tests.test_calibrate import SMALL
    from vibroflow.dem.run import run_dem

    monkeypatch.setenv("VIBROFLOW_CACHE", str(tmp_path / "cache"))
    sc = load_scenario("tub47-quick", SMALL)
    monkeypatch.setattr(M, "SORT_EVERY", 1)
    run_dem(sc, out_dir=tmp_path / "plain")
    monkeypatch.setattr(M, "MEMORY_ORDER_FROM", 0)
    run_dem(sc, out_dir=tmp_path / "sorted")
    with h5py.File(tmp_path / "plain" / "dem.h5") as fa, \
            h5py.File(tmp_path / "sorted" / "dem.h5") as fb:
        for group in ("snapshots", "wall_contacts", "series"):
            for name in fa[group]:
                assert np.array_equal(fa[group][name][()], fb[group][name][()],
                                      equal_nan=True), f"{group}/{name}"
        for name in fa["impacts"]:
            assert fa["impacts"][name].shape[0] > 0
            assert np.array_equal(fa["impacts"][name][()], fb["impacts"][name][()]), name


def test_the_slab_order_keeps_every_pair_within_three_slabs_in_memory():
    """Stored in slab order (memory_order.space_order), a long bed's neighbour pairs, which are
    at most one cell apart along the slab axis (a cell is the list's cut-off), lie fewer places
    apart in memory than the balls of three slabs: the working set of the pair pass.  The
    random ids stored by id spread them over the whole bed."""
    from vibroflow.dem.neighbours import NeighbourList

    rng = np.random.default_rng(11)
    n, r, skin = 6000, 0.003, 0.002
    pos = rng.uniform(0.0, 1.0, (n, 3)) * np.array([0.06, 0.6, 0.04])
    radius = np.full(n, r)
    ids = rng.permutation(n)
    order = M.space_order(pos, radius, skin, ids)
    cell = 2.0 * r + skin
    slab = np.floor((pos[order, 1] - pos[:, 1].min()) / cell).astype(np.int64)
    assert (np.diff(slab) >= 0).all()  # the longest axis, y, is the slowest
    per_slab = np.bincount(slab)
    three = max(per_slab[k:k + 3].sum() for k in range(per_slab.shape[0]))
    nl = NeighbourList(skin)
    nl.build(pos[order].copy(), radius)
    first = np.repeat(np.arange(n), np.diff(nl.start))
    apart = np.abs(first - nl.nbr).max()
    assert 0 < apart < three < n / 10
    unsorted = NeighbourList(skin)
    unsorted.build(pos[ids].copy(), radius)
    first = np.repeat(np.arange(n), np.diff(unsorted.start))
    assert np.abs(first - unsorted.nbr).max() > n / 2


@pytest.mark.parametrize("shape", [(0.06, 0.6, 0.04), (0.5, 0.05, 0.05), (0.05, 0.05, 0.5),
                                   (0.1, 0.1, 0.1), (0.2, 0.2, 0.0)])
def test_the_slab_order_is_its_definition_from_the_balls_own_cells(shape):
    """space_order takes the cells' extent from the bounding box; its order is the definition:
    the balls' cells, the axis with the most of them (z, x, y on a tie) slowest, then the first
    of the other two in the order z, x, y, then the last, each cell's balls by id, with the
    extent read off the balls' own cells (a flat bed, all of its balls at one height, too)."""
    rng = np.random.default_rng(int(1000 * sum(shape)))
    n, r, skin = 3000, 0.003, 0.002
    pos = rng.uniform(0.0, 1.0, (n, 3)) * np.array(shape) + 0.1
    radius = rng.uniform(0.5 * r, r, n)
    ids = rng.permutation(n)
    cell = 2.0 * radius.max() + skin
    c = np.floor((pos - pos.min(axis=0)) / cell).astype(np.int64)
    extent = c.max(axis=0)
    order_axes = sorted((2, 0, 1), key=lambda a: -extent[a])
    rest = [a for a in (2, 0, 1) if a != order_axes[0]]
    expected = np.lexsort((ids, c[:, rest[1]], c[:, rest[0]], c[:, order_axes[0]]))
    assert np.array_equal(M.space_order(pos, radius, skin, ids), expected)
