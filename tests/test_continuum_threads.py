"""Reproducibility of the parallel continuum steps (continuum/fused.py, eulerian/fused.py).

The same run gives the same numbers bit for bit on one thread and on two: the per-point and
per-cell kernels write only their own points, the remap works on whole rows and columns, and
the material points' scatter sums per-chunk buffers in a fixed order, the chunks fixed by the
system (a tub run: the scenario's run.force_chunks), not by the threads; the chunked sum is the
serial sum to round-off (two chunks against one).  The Eulerian cells' scatter, gather and
transfer operator sum each node's terms on one thread in a fixed order (eulerian/
column_scatter.py, operator_build.py): its numbers depend on neither the threads nor the
chunks, bit for bit.  The tub47-quick bed in the vibrating tub (TubFrame) with the U wall, the
partitions' friction and, for the Lagrangian, a frictional lid (boundary.Plane) moving down
onto the bed.
"""
from __future__ import annotations

import dataclasses

import numba
import numpy as np
import pytest

from vibroflow.continuum.bed import bed_area
from vibroflow.continuum.boundary import Plane
from vibroflow.continuum.eulerian import solver as eul
from vibroflow.continuum.eulerian.formulation import bed_masses
from vibroflow.continuum.formulation import formulation
from vibroflow.continuum.grid_update import TubFrame
from vibroflow.continuum.material import material_of
from vibroflow.continuum.mpm.formulation import settled_bed
from vibroflow.continuum.mpm.solver import MPMSystem, init_state, run_steps
from vibroflow.scenario.io import load_scenario
from vibroflow.tub.motion import TubMotion

FIELDS = ("x", "v", "C", "L", "stress", "volume", "density", "gamma_dot", "phase")


@pytest.fixture(scope="module")
def scenario():
    return load_scenario("tub47-quick", [])


def _threads(n):
    if numba.config.NUMBA_NUM_THREADS < n:
        pytest.skip(f"numba has fewer than {n} threads here")
    numba.set_num_threads(n)


def _lagrangian(scenario, chunks, threads, steps=300):
    _threads(threads)
    try:
        mat = material_of(scenario, None)
        frame = TubFrame(TubMotion.of_scenario(scenario))
        mpm = formulation("lagrangian")
        base = mpm.make_system(scenario, mat, None, mpm.options(), frame)
        x, volume, density, stress, h = settled_bed(scenario, mat, 0.5 * base.grid.dx)
        lid = Plane((0.0, h), (0.0, -1.0), base.boundaries[0].stiffness, friction=0.3,
                    velocity=(0.0, -0.3))
        system = MPMSystem(base.grid, mat, base.dt, frame, base.boundaries + [lid],
                           chunks=chunks)
        state = init_state(system, x, volume, density, stress=stress)
        run_steps(system, state, steps)
    finally:
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    out = {f: getattr(state, f) for f in FIELDS}
    out.update({f"wall{j}_{k}": a for j, hist in enumerate(state.history)
                for k, a in hist.items()})
    return out


def _eulerian(scenario, chunks, threads, steps=150):
    _threads(threads)
    try:
        mat = material_of(scenario, None)
        frame = TubFrame(TubMotion.of_scenario(scenario))
        mesh = formulation("eulerian")
        system = mesh.make_system(scenario, mat, None, mesh.options(), frame)
        system = dataclasses.replace(system, chunks=chunks)
        mass, density, stress, _ = bed_masses(system, bed_area(scenario, mat), 9.81)
        state = eul.init_state(system, mass, density, stress=stress)
        eul.run_steps(system, state, steps)
    finally:
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    out = {f: getattr(state, f) for f in ("mass", "v", "C", "L", "stress", "density",
                                          "gamma_dot", "phase")}
    out.update({f"wall_{k}": a for k, a in state.wall.items()})
    out["mass_error_max"] = np.array(state.mass_error_max)  # a sum over every cell
    return out


def _same(a, b):
    for k in a:
        assert np.array_equal(a[k], b[k]), f"{k} differs between the runs"


def _close(a, b, what):
    """Two-chunk against one-chunk run: equal to round-off, relative to each field's scale
    (the chaos of 300 steps of a granular bed stays far below this)."""
    for k in a:
        if a[k].dtype.kind != "f" or k == "gamma_dot":
            continue  # phases, contact states, plastic rates: a round-off tips them at yield
        scale = max(np.abs(b[k]).max(), 1e-300)
        err = np.abs(a[k].astype(float) - b[k].astype(float)).max() / scale
        assert err < 1e-9, f"{what}: {k} differs by {err:.3g} of its scale"


def test_lagrangian_same_numbers_on_one_thread_and_on_two(scenario):
    two = _lagrangian(scenario, chunks=2, threads=2)
    one = _lagrangian(scenario, chunks=2, threads=1)
    _same(one, two)
    # the bed moved and the lid pressed on it: the check is not vacuous
    assert np.abs(two["v"]).max() > 1e-3 and np.abs(two["wall2_fn"]).max() > 0
    serial = _lagrangian(scenario, chunks=1, threads=1)
    _close(two, serial, "two chunks against the serial scatter")


def test_eulerian_same_numbers_on_one_thread_and_on_two(scenario):
    two = _eulerian(scenario, chunks=2, threads=2)
    one = _eulerian(scenario, chunks=2, threads=1)
    _same(one, two)
    assert np.abs(two["v"]).max() > 1e-3
    serial = _eulerian(scenario, chunks=1, threads=1)
    _same(two, serial)
