"""The Eulerian wall layer's landing source of granular temperature against energy bookkeeping
and Galilean invariance (wall_energy_flux.landing_terms, eulerian/solver.cell_wall_sums).

A block falling onto the floor at V: the wall cells' material is stopped by the closed faces,
so the normal kinetic energy m_row V^2 / 2 of the row on the floor (plus gravity's small work
while it stops) leaves the mean motion and, with no dissipation (e = e_w = 1) and no other
source (passive T, an elastic block), is exactly the fluctuation energy gained, step by step;
a block resting on the floor, at rest or sliding along it, lands nowhere, and one resting on
a floor shaken below 1 g (moving with it, never leaving it) feeds what it feeds on a still one.
"""
from __future__ import annotations

import numpy as np
import pytest
from continuum_helpers import eulerian_block

from vibroflow.continuum.eulerian import solver as eulerian
from vibroflow.continuum.grid_update import TubFrame
from vibroflow.continuum.temperature_field import fluctuation_energy_J_m
from vibroflow.continuum.wall_energy_flux import landing_terms
from vibroflow.tub.motion import TubMotion

G_ACC = 9.81
DX = 0.01
HEIGHT = 0.02


def test_the_landing_is_the_normal_kinetic_energy_lost_while_approaching():
    # hand values, m = 0.2 kg/m, dt = 1e-4 s, the wall's normal +z
    normal = np.array([[0.0, 1.0]] * 4)
    v0 = np.array([[0.3, -0.5], [0.3, -0.5], [0.0, 0.4], [0.0, -0.5]])
    v1 = np.array([[0.3, -0.2], [0.0, 0.1], [0.0, 0.0], [0.0, -0.2]])
    m = np.full(4, 0.2)
    fn = np.array([1.0, 1.0, 1.0, 0.0])
    out = np.zeros((4, 4))
    landing_terms(v0, m, v1, m, normal, fn, 1e-4, out)
    # slowed from 0.5 to 0.2: 0.1 (0.25 - 0.04) J/m; stopped (and leaving): 0.1 * 0.25 J/m;
    # leaving the wall, or not touching it: nothing; the other columns untouched
    assert out[:, 3] * 1e-4 == pytest.approx([0.021, 0.025, 0.0, 0.0], abs=1e-15)
    assert np.all(out[:, :3] == 0.0)


def _block(v, settled, mu_w=0.3):
    """(system, state): a block HEIGHT deep in a 6 cm box (continuum_helpers.eulerian_block),
    at the critical density, moving at v (m/s), its landing above the floor row by the pairs."""
    return eulerian_block(v, HEIGHT, settled=settled, mu_w=mu_w, box_height=0.06, dx=DX)


def _steps(system, state, n):
    """Per step: the fluctuation energy gained (J/m) and the wall cells' normal kinetic energy
    lost while approaching the floor (J/m), computed here from the states."""
    c = system.wall_cells
    normal = system.mesh.normal[c]
    rows = []
    for _ in range(n):
        m0, v0 = state.mass[c].copy(), state.v[c].copy()
        e_before = fluctuation_energy_J_m(state.mass, state.temperature)
        eulerian.advance(system, state, 1)
        vn0 = (v0 * normal).sum(axis=1)
        vn1 = np.minimum((state.v[c] * normal).sum(axis=1), 0.0)
        e0 = np.where((vn0 < 0.0) & (state.wall["fn"][c] > 0.0), 0.5 * m0 * vn0 ** 2, 0.0)
        lost = np.clip(e0 - 0.5 * state.mass[c] * vn1 ** 2, 0.0, e0).sum()
        rows.append((fluctuation_energy_J_m(state.mass, state.temperature) - e_before, lost,
                     state.gamma_dot.max()))
    return np.array(rows)


@pytest.mark.slow
def test_a_landing_block_turns_its_floor_rows_normal_energy_into_temperature():
    speed = 0.5
    system, state = _block((0.0, -speed), settled=False)
    row_mass = state.mass[system.wall_cells].sum()
    r = _steps(system, state, 5)               # until the floor row has stopped
    assert np.all(r[:, 2] == 0.0)                # elastic: no plastic work, no other source
    # step by step the mean flow's loss is the fluctuation energy's gain, to round-off
    assert r[:, 0] == pytest.approx(r[:, 1], rel=1e-9, abs=1e-15)
    # the closed faces stop the floor row: its normal kinetic energy at impact, plus gravity's
    # work while it stops (under 1e-3 of it), is what the landing feeds
    assert r[:, 1].sum() == pytest.approx(0.5 * row_mass * speed ** 2, rel=1e-3)


def test_a_block_resting_or_sliding_on_the_floor_lands_nowhere():
    # Galilean: a settled block sliding at 0.5 m/s along a smooth floor feeds what it feeds at
    # rest, and that is nothing beside a landing at the same speed (m_row u^2 / 2)
    speed = 0.5
    fed = []
    for u in (0.0, speed):
        system, state = _block((u, 0.0), settled=True, mu_w=0.0)
        row_mass = state.mass[system.wall_cells].sum()
        r = _steps(system, state, 100)
        fed.append(r[:, 1].sum())
        assert fluctuation_energy_J_m(state.mass, state.temperature) < \
            1e-4 * 0.5 * row_mass * speed ** 2
    assert fed[1] == pytest.approx(fed[0], rel=0.02)
    assert fed[1] < 1e-4 * 0.5 * row_mass * speed ** 2


def test_a_block_resting_on_a_moving_floor_feeds_what_it_feeds_on_a_still_one():
    # Galilean: the floor shaken vertically at Gamma = 0.5 (47 Hz) carries the block with it,
    # whose wall row then never approaches the floor: over one cycle the landing is the still
    # floor's (the settled block's residual ringing) within 1 %
    fed = []
    frequency = 47.0
    omega = 2.0 * np.pi * frequency
    for gamma in (0.0, 0.5):
        system, state = _block((0.0, 0.0), settled=True)
        if gamma > 0.0:
            system.frame = TubFrame(TubMotion(frequency=frequency, amplitude_x=0.0,
                                              amplitude_z=gamma * G_ACC / omega ** 2,
                                              phase_z=0.0, amplitude_theta=0.0), (0.0, -G_ACC))
        fed.append(_steps(system, state, int(round(1.0 / (frequency * system.dt))))[:, 1].sum())
    assert fed[1] == pytest.approx(fed[0], rel=0.01)
