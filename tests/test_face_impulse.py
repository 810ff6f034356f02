"""The stress's impulse through each Eulerian z face as the grid's operators make it
(continuum/eulerian/face_impulse.py, column_landing.face_impulses) against Newton's law for the
material above a face, the weight, and the elastic energy an elastic block's bounce returns.

A settled block at rest on the floor: over one step the stress's impulse through each face is
the weight above it times dt plus the momentum the material above gains (Newton's second law
for that material, the grid's external impulse above the floor's reach being its weight), and
the columns feed nothing.  An elastic block dropped onto the floor compresses and rebounds:
the stress's work through the faces (-S_f wbar_f summed) rises while it compresses and comes
back while it rebounds, and the columns' landing stays a small share of its kinetic energy.
"""
from __future__ import annotations

import numpy as np
import pytest
from continuum_helpers import eulerian_block

from vibroflow.continuum.column_landing import face_impulses
from vibroflow.continuum.eulerian import solver as eulerian
from vibroflow.continuum.eulerian.face_impulse import cell_impulse_z

G_ACC = 9.81
DX = 0.01


def _step(system, state):
    """One step: the start's (mass, v, density, stress), the cells' stress and external z
    impulses S, E (N s/m), the faces' (J, S_f, F) and the cells' landing sums."""
    start = (state.mass.copy(), state.v.copy(), state.density.copy(), state.stress.copy())
    eulerian.advance(system, state, 1)
    sums = eulerian.cell_wall_sums(system, state, start)
    g = system.grid_spec
    S = np.empty(state.n)
    E = np.empty(state.n)
    cell_impulse_z(start[0], state.volume, start[3], state.fext, system.mesh_record.tables,
                   system.mesh.ncz, system.work.gm, system.work.gmv, g.x0, g.z0, g.dx,
                   g.periodic, g.no_slip_rows, system.frame.as_array(),
                   state.t - 0.5 * system.dt, system.dt, S, E)
    faces = face_impulses(start[0], start[1], state.mass, state.v, S, E, system.mesh.open_z)
    return start, S, E, faces, sums


def test_the_stress_carries_the_weight_above_each_face_of_a_resting_block():
    # a 4 cm settled block (lithostatic stress, at rest) on the floor, one step
    system, state = eulerian_block((0.0, 0.0), 0.04, settled=True, dx=DX, columns=True)
    ncx, ncz = system.mesh.ncx, system.mesh.ncz
    dt = system.dt
    start, S, E, (J, Sf, F), sums = _step(system, state)
    m0 = start[0].reshape(ncx, ncz)
    gained = (state.mass * state.v[:, 1] - start[0] * start[1][:, 1]).reshape(ncx, ncz)
    Ec = E.reshape(ncx, ncz)
    filled = int(round(0.04 / system.mesh.h))
    for k in range(1, filled):
        weight = m0[:, k:].sum(axis=1) * G_ACC * dt
        # the external impulse on the material above: its weight (the wall's penalty force
        # starts at zero), to round-off
        assert Ec[:, k:].sum(axis=1) == pytest.approx(-weight, rel=1e-14)
        # Newton: the stress's impulse through the face is the weight above plus the
        # momentum the material above gains; the remap's transport of that momentum is the
        # difference, second order in dt (under 2e-5 of the weight's impulse)
        assert np.abs(Sf[:, k] - weight - gained[:, k:].sum(axis=1)).max() < 2e-5 * weight.min()
        assert J[:, k] == pytest.approx(weight + gained[:, k:].sum(axis=1), rel=1e-12)
    # away from the floor the stress alone carries the weight above (the lithostatic stress is
    # the continuum's equilibrium, the grid's to 0.5 %); the lowest faces carry less, the
    # block still settling onto the floor's penalty contact
    k = filled // 2
    assert Sf[:, k] == pytest.approx(m0[:, k:].sum(axis=1) * G_ACC * dt, rel=5e-3)
    assert np.all(sums[:, 3] == 0.0)


def test_an_elastic_blocks_bounce_gives_back_the_stress_work():
    # a settled elastic block (mu_s = 10: no plastic work) dropped onto the floor at 5 cm/s,
    # 80 steps (5.6 ms): it compresses (its centre of mass stopped at step ~12), rebounds and
    # flies
    speed = 0.05
    system, state = eulerian_block((0.0, -speed), 0.0375, settled=True, dx=DX, columns=True)
    ncx, ncz = system.mesh.ncx, system.mesh.ncz
    mass = state.mass.sum()
    kinetic = 0.5 * mass * speed ** 2
    work = []
    faces_fed = 0.0
    floor = np.zeros(state.n, bool)
    floor[system.wall_cells] = True
    rebound = 0.0
    for _ in range(80):
        start, S, E, (J, Sf, F), sums = _step(system, state)
        vbar = 0.5 * (start[1][:, 1] + state.v[:, 1]).reshape(ncx, ncz)
        wbar = np.zeros((ncx, ncz + 1))
        wbar[:, 1:ncz] = vbar[:, 1:] - vbar[:, :-1]
        work.append(float((-Sf * wbar).sum()))
        faces_fed += sums[~floor, 3].sum() * system.dt
        rebound = max(rebound, float((state.mass * state.v[:, 1]).sum() / mass))
    work = np.cumsum(work)
    # it leaves the floor at 0.8 of its impact speed
    assert rebound > 0.7 * speed
    # compressing, the stress takes most of the kinetic energy (0.62 of it); rebounding, it
    # gives it back: what is left is the settled block's prestress released in flight (-0.026)
    assert work.max() > 0.5 * kinetic
    assert abs(work[-1]) < 0.05 * kinetic
    # the columns' landing above the floor row: the transfers' exchange on the faces next to
    # a cell a hair below full (the floor row, the surface), 0.041 of the kinetic energy
    assert faces_fed < 0.06 * kinetic
