"""The granular temperature made inside the compiled step loops (mpm/temperature_loop.py,
eulerian/temperature_loop.py, temperature_balance.py) against the step-by-step path that makes
its balance in Python between one-step calls (solver.advance_stepwise, temperature_field.py):
the same state to round-off after many steps of a shaken, sheared layer with every term on
(the kinetic stress, the walls' slip and landing feed, the partitions, conduction)."""
from __future__ import annotations

import dataclasses
import math

import numba
import numpy as np
import pytest

from continuum_helpers import lattice

from vibroflow.continuum.boundary import PartitionFriction, Plane
from vibroflow.continuum.constitutive import ContinuumMaterial
from vibroflow.continuum.eulerian import solver as eulerian
from vibroflow.continuum.eulerian.mesh import EulerianMesh
from vibroflow.continuum.eulerian.wall import MeshWall
from vibroflow.continuum.grid import Grid
from vibroflow.continuum.grid_update import TubFrame
from vibroflow.continuum.kinetic_theory import KineticParameters
from vibroflow.continuum.mpm import solver as mpm
from vibroflow.continuum.temperature_field import TemperatureModel
from vibroflow.continuum.timestep import stable_dt
from vibroflow.continuum.wall_energy_flux import WallEnergy
from vibroflow.tub.motion import TubMotion

MAT = ContinuumMaterial()
DX = 0.01
WIDTH, DEPTH = 0.04, 0.03
#: the layer's shaking: 47 Hz at 2.5 g vertically and 1 g along x, so that it takes off, lands
#: and slides on its floor
FREQUENCY, GAMMA_Z, GAMMA_X = 47.0, 2.5, 1.0


def _motion():
    w2 = (2.0 * math.pi * FREQUENCY) ** 2
    return TubMotion(frequency=FREQUENCY, amplitude_x=GAMMA_X * 9.81 / w2,
                     amplitude_z=GAMMA_Z * 9.81 / w2, phase_z=0.0, amplitude_theta=0.0)


def _model(h, sliding=0.0):
    prm = KineticParameters(diameter_m=MAT.diameter, density_kg_m3=MAT.solid_density,
                            restitution=0.8, sliding_coefficient=sliding)
    return TemperatureModel(prm, h, 1e-3, True, WallEnergy(restitution=0.7))


def _layer(method, sliding=0.0):
    """(system, state): a layer DEPTH deep of the critical density on a frictional floor of
    an x-periodic strip WIDTH wide, between partitions, in the shaken frame, T0 = 1e-3."""
    frame = TubFrame(_motion())
    partitions = PartitionFriction(friction=0.3, length=0.05)
    if method == "lagrangian":
        sp = DX / 2
        kn = (MAT.bulk_modulus + 4 * MAT.shear_modulus / 3) / sp
        floor = Plane((0.0, 0.0), (0.0, 1.0), kn, friction=0.4)
        system = mpm.MPMSystem(Grid.periodic_strip(WIDTH, 0.0, 3 * DEPTH, DX), MAT,
                               stable_dt(MAT, DX, sp, [floor]), frame=frame,
                               boundaries=[floor, partitions],
                               temperature=_model(DX, sliding))
        state = mpm.init_state(system, lattice(0.0, WIDTH, 0.0, DEPTH, sp), sp * sp,
                               MAT.critical_density)
        return system, state
    mesh = EulerianMesh.box(0.0, WIDTH, 0.0, 3 * DEPTH, DX, periodic=True)
    wall = MeshWall((MAT.bulk_modulus + 4 * MAT.shear_modulus / 3) / mesh.h, 0.4)
    system = eulerian.EulerianSystem(mesh, MAT, stable_dt(MAT, DX, mesh.h, [wall]), frame=frame,
                                     wall=wall, partitions=partitions,
                                     temperature=_model(mesh.h, sliding))
    fill = mesh.inside & (system.x[:, 1] < DEPTH)
    state = eulerian.init_state(system, np.where(fill, MAT.critical_density * mesh.h ** 2, 0.0))
    return system, state


@pytest.mark.parametrize("method", ["lagrangian", "eulerian"])
def test_the_compiled_balance_is_the_step_by_step_one(method):
    solver = mpm if method == "lagrangian" else eulerian
    system, fused = _layer(method)
    _, stepwise = _layer(method)
    # a cycle and a tenth: the layer leaves the floor, flies, lands on it and is pressed
    n = int(round(1.1 / (FREQUENCY * system.dt)))
    solver.advance(system, fused, n)
    solver.advance_stepwise(system, stepwise, n)
    assert fused.step == stepwise.step == n
    assert fused.t == pytest.approx(stepwise.t, rel=1e-14)
    # the check is not vacuous: the layer moved, is stressed, and its T changed
    held = stepwise.mass > 0
    assert np.abs(stepwise.v).max() > 0.02 and np.abs(stepwise.stress).max() > 10.0
    assert np.abs(stepwise.temperature[held] / 1e-3 - 1.0).min() > 0.1
    for name in ("temperature", "v", "stress", "mass"):
        a, b = getattr(fused, name), getattr(stepwise, name)
        scale = np.abs(b).max()
        assert np.abs(a - b).max() <= 1e-9 * scale, f"{name} differs"


@pytest.mark.parametrize("method", ["lagrangian", "eulerian"])
def test_the_compiled_balance_with_the_dense_sliding_loss_is_the_step_by_step_one(method):
    solver = mpm if method == "lagrangian" else eulerian
    system, fused = _layer(method, sliding=0.358)
    _, stepwise = _layer(method, sliding=0.358)
    _, off = _layer(method)
    n = int(round(1.1 / (FREQUENCY * system.dt)))
    solver.advance(system, fused, n)
    solver.advance_stepwise(system, stepwise, n)
    solver.advance(_layer(method)[0], off, n)
    held = stepwise.mass > 0
    # the pressed layer loses more: the sliding loss is on
    assert stepwise.temperature[held].mean() < 0.9 * off.temperature[off.mass > 0].mean()
    for name in ("temperature", "v", "stress", "mass"):
        a, b = getattr(fused, name), getattr(stepwise, name)
        assert np.abs(a - b).max() <= 1e-9 * np.abs(b).max(), f"{name} differs"


def _on_threads(method, threads):
    """The layer after a cycle and a tenth with `threads` numba threads, the Eulerian mesh
    made to take its parallel loop (serial_below 0)."""
    if numba.config.NUMBA_NUM_THREADS < threads:
        pytest.skip(f"numba has fewer than {threads} threads here")
    solver = mpm if method == "lagrangian" else eulerian
    system, state = _layer(method)
    if method == "eulerian":
        system = dataclasses.replace(system, serial_below=0)
    numba.set_num_threads(threads)
    try:
        solver.advance(system, state, int(round(1.1 / (FREQUENCY * system.dt))))
    finally:
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    return state


@pytest.mark.slow
@pytest.mark.parametrize("method", ["lagrangian", "eulerian"])
def test_the_compiled_balance_gives_the_same_numbers_on_one_thread_and_on_two(method):
    # the balance runs serially between the step's chunked parallel loops (DEVELOPERS.md,
    # "Threads"): the numbers depend on the chunks, never on the threads
    one, two = _on_threads(method, 1), _on_threads(method, 2)
    for name in ("temperature", "v", "stress", "mass"):
        assert np.array_equal(getattr(one, name), getattr(two, name)), f"{name} differs"


def test_the_eulerian_loop_keeps_its_last_steps_start_as_the_feed_does():
    """The compiled loop's keep (temperature_loop.StepStart) holds the start of its call's last
    step: what EulerianWallFeed.before_last_step keeps before that step made in a call of its
    own (masses, velocities, densities, the scattered stress with the kinetic stress added),
    bit for bit, the same steps either way, and the feed measured from it the same."""
    from vibroflow.continuum.eulerian.wall_feed import EulerianWallFeed

    (system, kept), (_, split) = _layer("eulerian"), _layer("eulerian")
    # a third of a cycle: the layer in flight off its floor, then 7 steps as it lands
    n = int(round(0.6 / (FREQUENCY * system.dt)))
    eulerian.advance(system, kept, n)
    eulerian.advance(system, split, n)
    kept_feed, split_feed = EulerianWallFeed(system, kept), EulerianWallFeed(system, split)
    eulerian.advance(system, kept, 7, kept_feed.last_step_start())
    eulerian.advance(system, split, 6)
    split_feed.before_last_step()
    eulerian.advance(system, split, 1)
    assert kept.step == split.step == n + 7
    for a, b in zip(kept_feed.start, split_feed.start):
        assert np.array_equal(a, b)
    for name in ("temperature", "v", "stress", "mass", "density"):
        assert np.array_equal(getattr(kept, name), getattr(split, name)), name
    (_, q_k), (_, q_s) = kept_feed.feed(), split_feed.feed()
    assert np.array_equal(q_k, q_s) and np.abs(q_s).max() > 0.0
