"""The landing counted where the falling material is stopped: the pairs of Eulerian cells that
stop each other where voids close (continuum/compaction_landing.py) and the impulse through
each face along a column (continuum/column_landing.py), against hand values, the energy
bookkeeping of a loose block landing on a floor, Galilean invariance and the shaken layer.

A loose block (its material below the critical density: voids to close) falling onto the floor
at V is stopped row by row from the floor up, a completely inelastic compaction (Mehta & Luck
1990's block): with no dissipation and no other source (e = e_w = 1, an elastic material, T
passive), the fluctuation energy gained is, step by step, the normal kinetic energy the floor
row and the faces count (to round-off), and over the landing it is the block's
kinetic energy ½ M V^2 plus gravity's work while it stops, less the elastic energy left in
the compacted block; along the columns, the exchange that no stress carries: half of it, the
stress's work at the front being the rest.
"""
from __future__ import annotations


import numpy as np
import pytest
from continuum_helpers import eulerian_block

from vibroflow.continuum.column_landing import column_terms, face_impulses
from vibroflow.continuum.compaction_landing import compaction_terms
from vibroflow.continuum.eulerian import solver as eulerian
from vibroflow.continuum.temperature_field import fluctuation_energy_J_m
from vibroflow.continuum.wall_energy_flux import landing_terms
from vibroflow.measure.stats import stderr_of_batches
from benchmark_module import load_benchmark

G_ACC = 9.81
DX = 0.01
RHO_C = 1500.0


def test_a_pair_stopping_where_a_void_closes_loses_its_relative_normal_energy():
    # a column of three cells (h = 0.1 m) over a 2-cell periodic row, dt = 1e-4 s: hand values
    h, dt = 0.1, 1e-4
    full = RHO_C * h * h
    open_x = np.zeros((2, 3), bool)
    open_z = np.zeros((1, 4), bool)
    open_z[0, 1:3] = True
    # a: full, connected, at rest; b: half full, falling 0.5 -> 0.1 m/s; c: full, falling with b
    m0 = np.array([1.01 * full, 0.5 * full, 1.01 * full])
    rho0 = np.array([1.01 * RHO_C, RHO_C, 1.01 * RHO_C])
    v0 = np.array([[0.0, 0.0], [0.3, -0.5], [0.0, -0.5]])
    v1 = np.array([[0.0, 0.0], [0.3, -0.1], [0.0, -0.5]])
    out = np.zeros((3, 4))
    compaction_terms(m0, v0, rho0, np.zeros((3, 4)), v1, h, open_x, open_z, RHO_C, dt, out)
    mu = m0[0] * m0[1] / (m0[0] + m0[1])
    lost = 0.5 * mu * (0.5 ** 2 - 0.1 ** 2)           # b against a; c moved with b at the start
    shares = np.array([m0[1], m0[0], 0.0]) / (m0[0] + m0[1])
    assert out[:, 3] * dt == pytest.approx(lost * shares, rel=1e-12, abs=1e-15)
    assert np.all(out[:, :3] == 0.0)
    # the same pair both full and connected: elastic, nothing; separating: nothing
    out[:] = 0.0
    compaction_terms(np.full(3, 1.01 * full), v0, np.full(3, 1.01 * RHO_C), np.zeros((3, 4)), v1,
                     h, open_x,
                     open_z, RHO_C, dt, out)
    assert np.all(out == 0.0)
    compaction_terms(m0, -v0, rho0, np.zeros((3, 4)), -v1, h, open_x, open_z, RHO_C, dt, out)
    assert np.all(out == 0.0)
    # a compressive normal stress of 2000 Pa on a and b: its work on the approach,
    # 2000 Pa x 0.1 m x (0.5 + 0.1) / 2 m/s x dt, is stored, not lost
    sigma = np.zeros((3, 4))
    sigma[:2, 1] = -2000.0
    compaction_terms(m0, v0, rho0, sigma, v1, h, open_x, open_z, RHO_C, dt, out)
    assert out[:, 3] * dt == pytest.approx((lost - 2000.0 * h * 0.3 * dt) * shares, rel=1e-12)


def test_the_wall_is_the_pairs_infinitely_heavy_limit_and_the_pair_is_galilean():
    # two cells side by side across a periodic x face (ncx = 2, ncz = 1), the right one loose
    h, dt = 0.1, 1e-4
    open_x = np.ones((3, 1), bool)
    open_x[1] = False                            # only the periodic face 0 between 1 and 0
    open_z = np.zeros((2, 2), bool)
    heavy = 1e12
    m0 = np.array([heavy, 0.3])
    rho0 = np.array([RHO_C, 0.9 * RHO_C])
    v0 = np.array([[0.0, 0.0], [0.4, 0.0]])      # cell 1 moves towards cell 0 through face 0
    v1 = np.array([[0.0, 0.0], [0.1, 0.0]])
    out = np.zeros((2, 4))
    compaction_terms(m0, v0, rho0, np.zeros((2, 4)), v1, h, open_x, open_z, RHO_C, dt, out)
    wall = np.zeros((1, 4))
    landing_terms(v0[1:], m0[1:], v1[1:], m0[1:], np.array([[-1.0, 0.0]]), np.ones(1), dt, wall)
    assert out[:, 3].sum() == pytest.approx(wall[0, 3], rel=1e-9)
    assert out[1, 3] == pytest.approx(wall[0, 3], rel=1e-9)
    moved = np.zeros((2, 4))
    u = np.array([2.0, -3.0])
    compaction_terms(m0, v0 + u, rho0, np.zeros((2, 4)), v1 + u, h, open_x, open_z, RHO_C, dt,
                     moved)
    assert moved[:, 3] == pytest.approx(out[:, 3], rel=1e-12)


def _column(v1_top):
    """One column of three cells (h = 0.1 m, ncx = 1) over a closed floor, its z faces open:
    a full, connected cell at rest, a half-full one and a full one, both falling at 0.5 m/s;
    (h, m0, rho0, v0, open_x, open_z) and the end velocities with the half-full cell slowed to
    0.1 m/s and the top one to v1_top (m/s)."""
    h = 0.1
    full = RHO_C * h * h
    m0 = np.array([1.01 * full, 0.5 * full, 1.01 * full])
    rho0 = np.array([1.01 * RHO_C, RHO_C, 1.01 * RHO_C])
    v0 = np.array([[0.0, 0.0], [0.0, -0.5], [0.0, -0.5]])
    v1 = np.array([[0.0, 0.0], [0.0, -0.1], [0.0, v1_top]])
    open_z = np.zeros((1, 4), bool)
    open_z[0, 1:3] = True
    return h, m0, rho0, v0, v1, np.zeros((2, 3), bool), open_z


def test_a_face_loses_the_impulse_beyond_it_on_its_mean_relative_velocity():
    # hand values, dt = 1e-4 s, no external impulse, no stress, the masses unmoved: the face
    # between the resting cell and the half-full one stops both cells above it, its impulse
    # m_1 0.4 + m_2 0.2 (N s/m) on its mean relative velocity (0.5 + 0.1) / 2 m/s; the face
    # above sees no approach at the start and counts nothing
    dt = 1e-4
    h, m0, rho0, v0, v1, open_x, open_z = _column(-0.3)
    zero = np.zeros(3)
    out = np.zeros((3, 4))
    column_terms(m0, v0, rho0, m0, v1, zero, zero, h, open_z, RHO_C, dt, out)
    lost = (m0[1] * 0.4 + m0[2] * 0.2) * 0.3
    shares = np.array([m0[1], m0[0], 0.0]) / (m0[0] + m0[1])
    assert out[:, 3] * dt == pytest.approx(lost * shares, rel=1e-12, abs=1e-15)
    assert np.all(out[:, :3] == 0.0)
    # Galilean: the column moving at u along z (its masses unmoved) counts the same
    moved = np.zeros((3, 4))
    u = np.array([0.7, -2.0])
    column_terms(m0, v0 + u, rho0, m0, v1 + u, zero, zero, h, open_z, RHO_C, dt, moved)
    assert moved[:, 3] == pytest.approx(out[:, 3], rel=1e-12)
    # and with mass carried down through the faces (the remap's term cancels the momentum the
    # moved mass carries): the same at rest and moving
    m1 = m0 * np.array([1.1, 0.95, 0.9])
    m1[2] += m0.sum() - m1.sum()
    fed = []
    for du in (np.zeros(2), u):
        o = np.zeros((3, 4))
        column_terms(m0, v0 + du, rho0, m1, v1 + du, zero, zero, h, open_z, RHO_C, dt, o)
        fed.append(o[:, 3])
    assert fed[0][0] > 0.0
    assert fed[1] == pytest.approx(fed[0], rel=1e-9)
    # the stress's impulse: half of the half-full cell's stop (0.2 m/s of its 0.4) carried by
    # the stress (its nodal forces, gathered) is no loss; the rest is
    S = np.array([-m0[1] * 0.2, m0[1] * 0.2, 0.0])
    out[:] = 0.0
    column_terms(m0, v0, rho0, m0, v1, S, zero, h, open_z, RHO_C, dt, out)
    assert out[:, 3] * dt == pytest.approx((lost - m0[1] * 0.2 * 0.3) * shares, rel=1e-12)
    J, Sf, F = face_impulses(m0, v0, m0, v1, S, zero, open_z)
    assert J[0, 1:3] == pytest.approx([m0[1] * 0.4 + m0[2] * 0.2, m0[2] * 0.2], rel=1e-12)
    assert Sf[0, 1:3] == pytest.approx([m0[1] * 0.2, 0.0], abs=1e-15)
    assert np.all(F == 0.0)


def test_a_pair_alone_is_the_column_faces_special_case_and_free_fall_feeds_nothing():
    # two cells exchanging momentum only with each other: the face's impulse on its mean
    # relative velocity is the pair's mu (w_0^2 - w_1^2) / 2 (compaction_terms), to round-off
    dt = 1e-4
    h, m0, rho0, v0, v1, open_x, open_z = _column(-0.5)
    m0[0] *= 4.0                                 # heavy enough that b does not rebound
    m0[2] = 0.0
    v1[0, 1] = -m0[1] * 0.4 / m0[0]
    zero = np.zeros(3)
    col = np.zeros((3, 4))
    column_terms(m0, v0, rho0, m0, v1, zero, zero, h, open_z, RHO_C, dt, col)
    pair = np.zeros((3, 4))
    compaction_terms(m0, v0, rho0, np.zeros((3, 4)), v1, h, open_x, open_z, RHO_C, dt, pair)
    assert col[:2, 3].min() > 0.0
    assert col[:, 3] == pytest.approx(pair[:, 3], rel=1e-12)
    # the column falling freely under gravity (each cell gaining g dt from the external
    # impulse, the faces approaching at the start): no exchange, nothing
    h, m0, rho0, v0, v1, open_x, open_z = _column(-0.5)
    out = np.zeros((3, 4))
    column_terms(m0, v0, rho0, m0, v0 + np.array([0.0, -G_ACC * dt]), zero, -m0 * G_ACC * dt,
                 h, open_z, RHO_C, dt, out)
    # nothing but round-off beside the column's kinetic energy M (0.5 m/s)^2 / 2
    assert out[:, 3].max() * dt < 1e-12 * 0.5 * m0.sum() * 0.25


def _loose_block(v, looseness, height, settled=False):
    """(system, state): continuum_helpers.eulerian_block on a smooth floor in an 8 cm box, its
    landing counted along the columns."""
    return eulerian_block(v, height, looseness=looseness, settled=settled, dx=DX, columns=True)


def _mechanical_energy(system, state):
    """The mean motion's kinetic plus gravity's potential energy (J/m)."""
    return float(0.5 * (state.mass * (state.v ** 2).sum(axis=1)).sum()
                 + G_ACC * (state.mass * system.x[:, 1]).sum())


def _landing_steps(system, state, n):
    """Per step: the fluctuation energy gained (J/m), the landing the states give (the floor
    row's, the columns' and the x faces' pairs', J/m), the mechanical energy lost (J/m), the
    largest shear rate, the wall cells' part of the landing (J/m) and what the pairs alone
    (compaction_terms over every open face) would count (J/m)."""
    c = system.wall_cells
    h = system.mesh.h
    rho_s = system.temperature.params.density_kg_m3
    void = system.temperature.grid.void_solid_fraction
    rows = []
    for _ in range(n):
        start = (state.mass.copy(), state.v.copy(), state.density.copy(), state.stress.copy())
        e_before = fluctuation_energy_J_m(state.mass, state.temperature)
        k_before = _mechanical_energy(system, state)
        eulerian.advance(system, state, 1)
        sums = eulerian.cell_wall_sums(system, state, start)
        # a cell below the void solid fraction holds no fluctuation energy (temperature_step)
        held = state.mass / (rho_s * h * h) >= void
        pairs = np.zeros((state.n, 4))
        compaction_terms(*start, state.v, h, system.mesh.open_x, system.mesh.open_z,
                         system.material.critical_density, system.dt, pairs)
        rows.append((fluctuation_energy_J_m(state.mass, state.temperature) - e_before,
                     sums[held, 3].sum() * system.dt, k_before - _mechanical_energy(system, state),
                     state.gamma_dot.max(), sums[c, 3].sum() * system.dt,
                     pairs[held, 3].sum() * system.dt))
    return np.array(rows)


def _loose_landing():
    """A 4 cm loose block (0.8 of the critical density) landing at 0.5 m/s, the 200 steps
    (14 ms) until it has stopped: its mass (kg/m), its kinetic energy at impact (J/m) and
    _landing_steps' rows."""
    speed = 0.5
    system, state = _loose_block((0.0, -speed), 0.8, 0.04)
    mass = state.mass.sum()
    return mass, 0.5 * mass * speed ** 2, _landing_steps(system, state, 200)


@pytest.mark.slow
def test_a_loose_block_landing_feeds_the_exchange_no_stress_carries():
    mass, impact, r = _loose_landing()
    assert np.all(r[:, 3] == 0.0)                # elastic: no plastic work
    # step by step the floor row's and the faces' loss is the fluctuation energy's gain, to
    # the round-off of the block's fluctuation energy (0.86 J/m)
    assert r[:, 0] == pytest.approx(r[:, 1], rel=1e-9, abs=1e-13)
    gained, lost = r[:, 0].sum(), r[:, 2].sum()
    # the completely inelastic compaction (Mehta & Luck 1990's block) would turn the mean
    # motion's whole loss (kinetic plus gravity's potential energy, 0.887 J/m: 1.18 of the
    # impact's, the compaction's 8 mm of fall adding to it) into fluctuation energy; the
    # columns, the stress's exact impulse taken out, count 0.496 of it.  The stress's work
    # through the faces is 0.316 J/m, of which the compacted block stores 0.011: the rest the
    # grid's stress path destroys uncounted (docs/validation.md section 22)
    assert gained == pytest.approx(0.496 * lost, rel=0.05)
    # the pairs alone count 0.07 of it (0.18 with the floor row's landing): the smeared front
    assert r[:, 5].sum() < 0.1 * lost


def test_a_settled_block_resting_or_sliding_compacts_nothing():
    # Galilean: a settled block sliding at 0.5 m/s along a smooth floor feeds what it feeds at
    # rest (its surface's residual ringing), and that is nothing beside a landing at the same
    # speed (M u^2 / 2)
    speed = 0.5
    fed = []
    for u in (0.0, speed):
        system, state = _loose_block((u, 0.0), 1.0, 0.04, settled=True)
        impact = 0.5 * state.mass.sum() * speed ** 2
        fed.append(_landing_steps(system, state, 100)[:, 1].sum())
    assert fed[1] == pytest.approx(fed[0], rel=0.02)
    assert fed[1] < 1e-4 * impact


def _shaken_layer(columns):
    """The Eulerian shaken layer of benchmarks/wall_feed.py (5 cm, tub47's 1.5 mm at 47 Hz,
    T coupled, its landing by the pairs or along the `columns`), 35 cycles: the cycle-mean
    landing feed and the floor row's part (W/m^2), each with its batch-means standard error
    over five batches of the 30 cycles after the first 5."""
    wf = load_benchmark("wall_feed")
    r, _, _ = wf.run(0.05, 35, "eulerian", columns)
    cycle = np.floor(r[:, 0] * wf.FREQUENCY + 1e-9).astype(int)
    batches = np.array_split(np.arange(5, cycle.max() + 1), 5)

    def mean(col):
        per = np.array([r[np.isin(cycle, b), col].mean() for b in batches])
        return per.mean(), float(stderr_of_batches(per))

    return mean(2), mean(5)


@pytest.fixture(scope="module")
def shaken_layer():
    """_shaken_layer by the pairs."""
    return _shaken_layer(False)


@pytest.fixture(scope="module")
def shaken_layer_columns():
    """_shaken_layer along the columns."""
    return _shaken_layer(True)


@pytest.mark.slow
def test_the_shaken_layers_landing_is_counted_where_the_layer_is_stopped(shaken_layer):
    # the layer leaves the floor and lands as a block (docs/validation.md section 22): the
    # pairs above the floor row, where its voids close, count as much again as the floor
    # row's 1.67 +- 0.12 W/m^2 (3.37 +- 0.15 W/m^2 in all)
    (total, _), (floor, _) = shaken_layer
    assert total > 2.0
    assert total > 1.5 * floor


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="the Eulerian layer's landing feeds 3.37 +- 0.15 W/m^2, "
                   "0.012 of the DEM's 274 +- 12 (the Lagrangian's dashpot 73.5 +- 19): the "
                   "pairs count a fraction of the compaction front's loss (the loose block's "
                   "0.18)")
def test_the_shaken_layers_landing_feeds_the_dems_wall_flux(shaken_layer):
    (total, se), _ = shaken_layer
    assert abs(total - 274.0) < 3.0 * np.hypot(se, 12.0)


@pytest.mark.slow
def test_the_columns_count_the_shaken_layers_whole_landing(shaken_layer_columns):
    # the columns count the stop of the whole layer above each face, the stress's impulse
    # taken out: 155 +- 15 W/m^2, 46 times the pairs' 3.37 +- 0.15 (docs/validation.md
    # section 22); the DEM's 274 +- 12: the strict xfail below
    (total, _), _ = shaken_layer_columns
    assert total > 100.0


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="along the columns the Eulerian layer's landing feeds "
                   "155 +- 15 W/m^2, 0.57 of the DEM's 274 +- 12, at phases 4/8 - 7/8 (the "
                   "DEM's 5/8 - 7/8)")
def test_the_columns_landing_feeds_the_dems_wall_flux(shaken_layer_columns):
    (total, _), _ = shaken_layer_columns
    assert 274.0 / 1.5 < total < 1.5 * 274.0


def test_the_compiled_loop_counts_the_columns_as_the_step_by_step_path_does():
    # the loose block's first 60 steps (its front moving up): the compiled loop
    # (eulerian/temperature_loop.py) and the step-by-step path (solver.cell_wall_sums) give the
    # same temperature and velocities, bit for bit
    runs = [_loose_block((0.0, -0.5), 0.8, 0.04) for _ in range(2)]
    eulerian.advance(*runs[0], 60)
    eulerian.advance_stepwise(*runs[1], 60)
    assert runs[0][1].temperature.max() > 0.0
    assert np.array_equal(runs[0][1].temperature, runs[1][1].temperature)
    assert np.array_equal(runs[0][1].v, runs[1][1].v)
