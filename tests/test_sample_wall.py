"""A sample's wall contacts and floor force in one compiled pass (eulerian/sample_wall.py)
against numpy's masks as a sample took them before: the same contacts in the same order and the
same floor force bit for bit, and the floor force of a known load (a layer resting on a flat
floor: the sum of its weight over the slice)."""
from __future__ import annotations

import numpy as np

from vibroflow.continuum.eulerian.sample_wall import wall_contacts_work, wall_sample


def _case(rng, n=500, n_wall=120, n_floor=40):
    state = rng.integers(0, 3, n).astype(np.int8)
    fn, ft, mass = rng.random(n), rng.normal(size=n), rng.random(n)
    wall = np.sort(rng.choice(n, n_wall, replace=False)).astype(np.int64)
    point = rng.integers(0, 900, n_wall).astype(np.int64)
    arc = rng.random(n_wall)
    position = rng.normal(size=(n_wall, 3))
    floor = wall[np.sort(rng.choice(n_wall, n_floor, replace=False))]
    normal = rng.normal(size=(n_floor, 2))
    return state, fn, ft, mass, wall, point, arc, position, floor, normal


def test_contacts_and_floor_force_are_numpys():
    rng = np.random.default_rng(5)
    state, fn, ft, mass, wall, point, arc, position, floor, normal = _case(rng)
    half, length = 0.5, 0.0635
    out = wall_contacts_work(wall.size, floor.size)
    count, floor_force = wall_sample(state, fn, ft, mass, half, wall, point, arc, position,
                                     floor, normal, length, out)
    touching = np.nonzero((state[wall] > 0) & (mass[wall] >= half))[0]
    tc = wall[touching]
    assert 0 < count == touching.size < wall.size
    np.testing.assert_array_equal(out.particle[:count], point[touching].astype(np.int32))
    np.testing.assert_array_equal(out.fn[:count], fn[tc] * length)
    np.testing.assert_array_equal(out.ft[:count], np.abs(ft[tc]) * length)
    np.testing.assert_array_equal(out.sliding[:count], state[tc] == 2)
    np.testing.assert_array_equal(out.arc[:count], arc[touching])
    np.testing.assert_array_equal(out.position[:count], position[touching])
    want = float(np.sum(fn[floor] * normal[:, 1] - ft[floor] * normal[:, 0])) * length
    assert floor_force == want


def test_floor_force_of_a_resting_layer():
    # a layer of 30 cells of 2.5 kg/m on a flat floor (inward normal +z), no friction: the
    # floor carries their weight, 30 * 2.5 * 9.81 N/m, over a slice of 0.1 m
    n = 30
    fn = np.full(n, 2.5 * 9.81)
    out = wall_contacts_work(n, n)
    cells = np.arange(n, dtype=np.int64)
    count, force = wall_sample(np.ones(n, np.int8), fn, np.zeros(n), np.ones(n), 0.5, cells,
                               cells, np.zeros(n), np.zeros((n, 3)), cells,
                               np.tile([0.0, 1.0], (n, 1)), 0.1, out)
    assert count == n
    assert abs(force - n * 2.5 * 9.81 * 0.1) < 1e-12 * force
    # nothing pressing, nothing in contact; a floor of no cells carries nothing
    count, force = wall_sample(np.zeros(n, np.int8), fn, np.zeros(n), np.ones(n), 0.5, cells,
                               cells, np.zeros(n), np.zeros((n, 3)), cells[:0],
                               np.zeros((0, 2)), 0.1, out)
    assert count == 0 and force == 0.0
