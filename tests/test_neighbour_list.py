"""The half neighbour list (vibroflow.dem.neighbours.build_half_list) against the brute-force
answer: every pair closer than r_i + r_j + skin, once, under the partner of higher id, in a
bounded box and across a periodic length; the same list on one thread and on all of them."""
from __future__ import annotations

import numpy as np
import pytest

from vibroflow.dem.neighbours import NeighbourList


def _brute(pos, radius, skin, ids, periodic_length):
    n = pos.shape[0]
    d = pos[:, None, :] - pos[None, :, :]
    if periodic_length > 0.0:
        d[..., 1] -= periodic_length * np.rint(d[..., 1] / periodic_length)
    cut = radius[:, None] + radius[None, :] + skin
    near = (d ** 2).sum(-1) < cut ** 2
    return [set(int(j) for j in np.nonzero(near[i] & (ids > ids[i]))[0]) for i in range(n)]


@pytest.mark.parametrize("periodic_length", [0.0, 0.05])
def test_the_half_list_holds_every_near_pair_once(periodic_length):
    rng = np.random.default_rng(3)
    n = 1500
    pos = rng.uniform(0.0, 1.0, (n, 3)) * np.array([0.12, 0.05, 0.08])
    radius = rng.uniform(0.002, 0.0035, n)
    skin = 0.3 * 0.00635
    nl = NeighbourList(skin, periodic_length)
    nl.build(pos.copy(), radius)
    ids = np.arange(n)
    want = _brute(pos, radius, skin, ids, periodic_length)
    got = [nl.nbr[nl.start[i]:nl.start[i + 1]] for i in range(n)]
    assert sum(len(w) for w in want) == nl.nbr.shape[0] > 2 * n
    for i in range(n):
        assert len(set(got[i].tolist())) == got[i].shape[0]      # each partner once
        assert set(got[i].tolist()) == want[i], i


def test_the_list_is_the_same_on_one_thread_and_on_all():
    """Each ball's entries in the same order whatever the thread count: the step's sums run in
    list order, so this is what its bit-for-bit numbers on any thread count rest on."""
    import numba

    rng = np.random.default_rng(8)
    pos = rng.uniform(0.0, 1.0, (3000, 3)) * np.array([0.15, 0.05, 0.1])
    radius = np.full(3000, 0.003175)
    lists = []
    threads = numba.get_num_threads()
    try:
        for t in (1, threads):
            numba.set_num_threads(t)
            nl = NeighbourList(0.3 * 0.00635)
            nl.build(pos.copy(), radius)
            lists.append((nl.start.copy(), nl.nbr.copy()))
    finally:
        numba.set_num_threads(threads)
    np.testing.assert_array_equal(lists[0][0], lists[1][0])
    np.testing.assert_array_equal(lists[0][1], lists[1][1])


def test_a_state_file_with_64_bit_indices_reads_as_the_32_bit_list(tmp_path):
    """The list's indices are int32 (neighbours.INDEX); a state file written with int64 ones
    reads back as the same list in int32, and a file this code writes keeps the same entries."""
    import h5py

    from vibroflow.dem.neighbours import INDEX
    from vibroflow.dem.output import load_state_file, save_state_file, state_checksum
    from vibroflow.dem.simulate import init_state, make_system
    from vibroflow.scenario.io import load_scenario

    scenario = load_scenario("tub47-quick", ["fill.count=40"])
    system = make_system(scenario)
    n = 40
    d = 0.00635
    # a lattice 1.02 d apart: every neighbour within the skin, none touching
    lattice = np.stack(np.meshgrid(np.arange(4), np.arange(2), np.arange(5), indexing="ij"),
                       axis=-1).reshape(-1, 3)
    pos = 1.02 * d * lattice + np.array([-0.01, 0.005, 0.03])
    radius = np.full(n, 0.5 * d)
    state = init_state(system, pos, np.zeros((n, 3)), np.zeros((n, 3)), radius,
                       np.full(n, 7800.0), np.zeros(n, np.int64))
    state.nl.build(state.pos, radius)
    assert state.nl.nbr.dtype == INDEX and state.nl.rpos.dtype == INDEX
    assert state.nl.nbr.shape[0] > 0
    path = tmp_path / "state.h5"
    save_state_file(path, state)
    back, _ = load_state_file(path)
    assert back.nl.nbr.dtype == INDEX
    np.testing.assert_array_equal(back.nl.nbr, state.nl.nbr)
    # the same file with the indices widened to int64, its checksum made anew
    with h5py.File(path, "r+") as f:
        g = f["state/neighbours"]
        wide = g["nbr"][()].astype(np.int64)
        del g["nbr"]
        g["nbr"] = wide
    with h5py.File(path, "r+") as f:
        f.attrs["checksum"] = state_checksum(f)
    back, _ = load_state_file(path)
    assert back.nl.nbr.dtype == INDEX
    np.testing.assert_array_equal(back.nl.nbr, state.nl.nbr)


def test_the_reverse_order_lists_each_balls_entries_by_first_ball():
    """The reverse order (NeighbourList.index_pairs) against its definition made by brute
    force: for each ball j, the entries (i, j) by ascending i, each entry's place in that
    order (rpos), the contact flags in that order (rflag), and no contact row yet (row -1)."""
    rng = np.random.default_rng(5)
    n = 2000
    pos = rng.uniform(0.0, 1.0, (n, 3)) * np.array([0.12, 0.05, 0.08])
    radius = rng.uniform(0.002, 0.0035, n)
    nl = NeighbourList(0.3 * 0.00635)
    nl.build(pos.copy(), radius)
    nl.flag[:] = rng.integers(0, 2, nl.flag.shape[0], dtype=np.uint8)
    nl.rout = None
    nl.index_pairs()
    first = np.repeat(np.arange(n), np.diff(nl.start))
    want = sorted(range(nl.nbr.shape[0]), key=lambda k: (int(nl.nbr[k]), int(first[k]), k))
    place = np.empty(len(want), np.int64)
    place[want] = np.arange(len(want))
    np.testing.assert_array_equal(nl.rpos, place)
    np.testing.assert_array_equal(nl.rflag[nl.rpos], nl.flag)
    np.testing.assert_array_equal(nl.rstart, np.concatenate(
        [[0], np.cumsum(np.bincount(nl.nbr, minlength=n))]))
    assert (nl.row == -1).all()


@pytest.mark.parametrize("n", [1, 5, 700])
def test_the_bounding_box_is_numpys_least_and_largest_coordinate(n):
    """The rebuild's box (neighbours.bounding_box, fixed chunks on the threads) is exactly
    numpy's min and max along each axis, on one thread and on all, for fewer balls than chunks
    too."""
    import numba

    from vibroflow.dem.neighbours import bounding_box

    pos = np.random.default_rng(n).normal(0.0, 0.1, (n, 3))
    threads = numba.get_num_threads()
    try:
        for t in (1, threads):
            numba.set_num_threads(t)
            lo, hi = bounding_box(pos)
            np.testing.assert_array_equal(lo, pos.min(axis=0))
            np.testing.assert_array_equal(hi, pos.max(axis=0))
    finally:
        numba.set_num_threads(threads)
