"""The APIC transfer pair as a grid operator (vibroflow.continuum.transfer_operator) and the
steps that make several transfers (mpm.MPMSystem.transfers, timestep.transfers_per_step).

Known answers: the operator is the transfer pair itself (g2p then p2g with no force and no
motion, Jiang et al. 2015), so it must give the explicit pair's grid velocities; it keeps an
affine velocity field and the grid's momentum exactly (APIC's properties); and a step of
Courant number cfl making n transfers must damp the grid-scale motion as a one-transfer APIC
step of Courant number cfl / n does, whatever the step: the property the tub runs' default
rests on (continuum/options.py; each formulation's DEFAULT_TRANSFER_CFL).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from continuum_helpers import lattice, spinning_compressed_disc
from vibroflow.continuum.constitutive import ContinuumMaterial
from vibroflow.continuum.g2p import g2p
from vibroflow.continuum.grid import Grid
from vibroflow.continuum.grid_update import MASS_EPS, LabFrame
from vibroflow.continuum.mpm.solver import MPMSystem, init_state, run_steps
from vibroflow.continuum.p2g import p2g
from vibroflow.continuum.timestep import stable_dt, transfers_per_step
from vibroflow.continuum.transfer_operator import (HALF, expand, operator_of_points,
                                                   transfer_rows)
from vibroflow.errors import InputError

DX = 0.01


def cloud(seed=3, n=400):
    """A grid of 20 x 16 cells and n points of random masses scattered over its middle, their
    B-spline stencils clear of the grid's edge nodes (so every node they touch is updated)."""
    grid = Grid.covering(0.0, 0.2, 0.0, 0.16, DX)
    rng = np.random.default_rng(seed)
    lo = np.array([grid.x0, grid.z0]) + 3.0 * DX
    hi = np.array([grid.x0 + (grid.nx - 4) * DX, grid.z0 + (grid.nz - 4) * DX])
    x = lo + (hi - lo) * rng.random((n, 2))
    mass = rng.uniform(0.5, 2.0, n)
    return grid, x, mass


def operator(grid, x, mass):
    B = np.zeros((grid.nx, grid.nz, HALF))
    operator_of_points(x, mass, grid.x0, grid.z0, grid.dx, grid.periodic, B)
    return B


def explicit_pair(grid, x, mass, gv):
    """g2p (APIC) of the grid velocities gv to the points, then p2g with no stress and no
    force: the grid masses and the new grid velocities (momentum / mass; 0 where no mass)."""
    n = len(x)
    v, C, L = np.zeros((n, 2)), np.zeros((n, 4)), np.zeros((n, 4))
    gm, gmv, gf, _ = grid.zeros()
    g2p(x.copy(), v, C, L, gv, grid.x0, grid.z0, grid.dx, 0.0, grid.periodic, gm, gmv, 0.0)
    gm[:] = 0.0
    gmv[:] = 0.0
    p2g(x, v, C, mass, np.ones(n), np.zeros((n, 4)), np.zeros((n, 2)), grid.x0, grid.z0,
        grid.dx, grid.periodic, gm, gmv, gf)
    out = np.where(gm[..., None] > MASS_EPS, gmv / np.maximum(gm, MASS_EPS)[..., None], 0.0)
    return gm, out


def test_operator_is_the_apic_transfer_pair():
    """One application of the operator gives, at every node holding mass, the grid velocity
    that the explicit g2p then p2g gives (to round-off), for a random grid velocity field."""
    grid, x, mass = cloud()
    gv = np.random.default_rng(5).normal(0.0, 1.0, (grid.nx, grid.nz, 2))
    gm, expected = explicit_pair(grid, x, mass, gv)
    out = np.zeros_like(gv)
    transfer_rows(0, grid.nx, operator(grid, x, mass), gm, gv, out, grid.periodic, 0, 0)
    held = gm > MASS_EPS
    assert held.sum() > 100
    assert np.allclose(out[held], expected[held], rtol=1e-12, atol=1e-12)
    assert np.all(out[~held] == 0.0)


def _full_operator(grid, x, mass):
    """B_ij = sum_p m_p w_ip w_jp (1 + 4/dx^2 r_ip . r_jp) as (nx, nz, 5, 5), straight from its
    definition (module docstring of transfer_operator), in numpy."""
    B = np.zeros((grid.nx, grid.nz, 5, 5))
    for xp, mp in zip(x, mass):
        nodes = []
        for gi in range(grid.nx):
            for gk in range(grid.nz):
                r = np.array([grid.x0 + gi * grid.dx, grid.z0 + gk * grid.dx]) - xp
                q = np.abs(r) / grid.dx
                w = np.where(q < 0.5, 0.75 - q**2, np.where(q < 1.5, 0.5 * (1.5 - q) ** 2, 0.0))
                if w[0] * w[1] > 0.0:
                    nodes.append((gi, gk, w[0] * w[1], r))
        for i, k, wi, ri in nodes:
            for j, l, wj, rj in nodes:
                B[i, k, j - i + 2, l - k + 2] += mp * wi * wj * (
                    1.0 + 4.0 / grid.dx**2 * (ri @ rj))
    return B


def test_stored_half_is_the_whole_symmetric_operator():
    """The stored half, expanded, is the operator of its definition built in numpy (to
    round-off), symmetric bit for bit, and its rows sum to the nodes' masses (sum_j w_jp = 1,
    sum_j w_jp r_jp = 0)."""
    grid, x, mass = cloud(seed=13, n=60)
    full = expand(operator(grid, x, mass))
    reference = _full_operator(grid, x, mass)
    assert np.abs(reference).max() > 0.1
    np.testing.assert_allclose(full, reference, rtol=1e-12, atol=1e-14)
    nx, nz = grid.nx, grid.nz
    for i in range(2, nx - 2):
        for k in range(2, nz - 2):
            for a in range(5):
                for b in range(5):
                    assert full[i, k, a, b] == full[i + a - 2, k + b - 2, 4 - a, 4 - b]
    gm, _ = explicit_pair(grid, x, mass, np.zeros((nx, nz, 2)))
    np.testing.assert_allclose(full.sum(axis=(2, 3)), gm, rtol=1e-12, atol=1e-14)


def test_operator_keeps_affine_fields_and_momentum():
    """An affine grid velocity v = a + M x comes back unchanged at every node holding mass
    (APIC reproduces affine fields), and a random field's momentum sum_i m_i v_i is kept to
    round-off (sum_i w_ip (x_i - x_p) = 0), while the field's kinetic energy falls (a white
    noise is mostly grid-scale motion, which the transfer pair damps)."""
    grid, x, mass = cloud(seed=7)
    B = operator(grid, x, mass)
    gm, _ = explicit_pair(grid, x, mass, np.zeros((grid.nx, grid.nz, 2)))
    held = gm > MASS_EPS
    X = grid.x0 + np.arange(grid.nx)[:, None] * grid.dx + 0.0 * np.arange(grid.nz)[None, :]
    Z = grid.z0 + np.arange(grid.nz)[None, :] * grid.dx + 0.0 * np.arange(grid.nx)[:, None]
    affine = np.stack([0.3 + 2.0 * X - 1.5 * Z, -0.2 + 0.7 * X + 4.0 * Z], axis=-1)
    out = np.zeros_like(affine)
    transfer_rows(0, grid.nx, B, gm, affine, out, grid.periodic, 0, 0)
    assert np.allclose(out[held], affine[held], rtol=0, atol=1e-12)

    rng = np.random.default_rng(11)
    gv = np.where(held[..., None], rng.normal(0.0, 1.0, (grid.nx, grid.nz, 2)), 0.0)
    transfer_rows(0, grid.nx, B, gm, gv, out, grid.periodic, 0, 0)
    P0 = (gm[..., None] * gv).sum(axis=(0, 1))
    P1 = (gm[..., None] * out).sum(axis=(0, 1))
    assert np.allclose(P1, P0, rtol=1e-12, atol=1e-12)
    # ... while the field's grid-scale noise is damped: its kinetic energy falls
    E0 = (gm[..., None] * gv**2).sum()
    E1 = (gm[..., None] * out**2).sum()
    assert E1 < 0.5 * E0


def test_transfers_per_step():
    """round(cfl / transfer_cfl), at least one; None or 0: one; a FLIP blend: one, whatever
    transfer_cfl; a bad value: an InputError naming the field."""
    assert transfers_per_step(0.3, 0.015) == 20
    assert transfers_per_step(0.3, 0.0375) == 8
    assert transfers_per_step(0.3, None) == 1
    assert transfers_per_step(0.075, 0.3) == 1
    assert transfers_per_step(0.3, 0.0) == 1
    for bad in (-0.1, float("nan"), float("inf"), True):
        with pytest.raises(InputError, match="transfer_cfl"):
            transfers_per_step(0.3, bad)
    from vibroflow.continuum.formulation import formulation

    mpm_options = formulation("lagrangian").options
    assert mpm_options().transfers() == 20
    assert formulation("eulerian").options().transfers() == 8
    assert mpm_options(flip=0.99).transfers() == 1
    assert mpm_options(transfer_cfl=0).transfers() == 1
    with pytest.raises(InputError, match="transfers"):
        MPMSystem(Grid.covering(0.0, 0.1, 0.0, 0.1, DX), ContinuumMaterial(), 1e-4,
                  transfers=0)


def test_momentum_and_angular_momentum_conserved_with_transfers():
    """The spinning, translating, pre-compressed elastic disc of continuum_helpers, four transfers a
    step: linear and angular momentum (with the points' affine spin) kept to round-off."""
    system, state, p0 = spinning_compressed_disc(flip=0.0, transfers=4)
    dx = system.grid.dx
    P0, L0 = state.momentum(), state.angular_momentum(dx)
    run_steps(system, state, 200)
    assert np.allclose(state.momentum(), P0, rtol=1e-12, atol=0)
    assert state.angular_momentum(dx) == pytest.approx(L0, rel=1e-12)


def _shear_wave_energy(cfl: float, transfers: int, T: float = 0.004, dx: float = 0.005,
                       wavelength: float = 0.04) -> float:
    """Kinetic energy left (mean over [T/2, T], over the initial) of a free, stress-free elastic
    disc (radius 6 cm, spacing dx, 5 mm by default, 2 x 2 points a cell) started with a shear
    wave vx = 0.01 sin(2 pi z / wavelength) m/s (8 cells of 5 mm), at Courant number cfl with
    `transfers` transfers a step."""
    mat = ContinuumMaterial(mu_s=2.0, mu_2=2.5)  # stays elastic: the transfers alone dissipate
    sp = dx / 2
    grid = Grid.covering(-0.12, 0.12, -0.12, 0.12, dx)
    x = lattice(-0.06, 0.06, -0.06, 0.06, sp)
    x = x[np.hypot(x[:, 0], x[:, 1]) < 0.06]
    v = np.zeros_like(x)
    v[:, 0] = 0.01 * np.sin(2.0 * math.pi * x[:, 1] / wavelength)
    dt = stable_dt(mat, dx, sp, cfl=cfl)
    system = MPMSystem(grid, mat, dt, frame=LabFrame((0.0, 0.0)), transfers=transfers)
    state = init_state(system, x, sp * sp, mat.critical_density * 1.0001, v=v)
    e0 = state.kinetic_energy()
    ke = []
    run_steps(system, state, int(round(T / dt)), lambda s: ke.append(s.kinetic_energy()))
    return float(np.mean(ke[len(ke) // 2:])) / e0


def test_damping_is_set_by_the_transfer_rate_not_the_step():
    """The grid-scale shear wave's energy after 4 ms at the same transfer rate (transfer_cfl
    0.05: cfl 0.1, 0.2, 0.4 with 2, 4, 8 transfers a step) is the same within 5 % (measured
    0.0384, 0.0379, 0.0374), and that of the one-transfer APIC step at cfl 0.05 (0.0388);
    one transfer a step at cfl 0.1, 0.2, 0.4 leaves 0.060, 0.098, 0.151: the plain APIC
    step's damping depends on the step, a factor 2.5 here."""
    reference = _shear_wave_energy(0.05, 1)
    same_rate = [_shear_wave_energy(c, transfers_per_step(c, 0.05)) for c in (0.1, 0.2, 0.4)]
    for e in same_rate:
        assert e == pytest.approx(reference, rel=0.05)
    plain = [_shear_wave_energy(c, 1) for c in (0.1, 0.4)]
    assert plain[0] > 1.3 * reference
    assert plain[1] > 2.0 * plain[0]
    assert plain[1] > 3.0 * reference


@pytest.mark.parametrize("transfers", [2, 3])
@pytest.mark.parametrize("axisymmetric", [False, True])
def test_grid_conditions_hold_after_the_transfers(transfers, axisymmetric):
    """A column collapsing on the rough (no-slip) floor, plane or axisymmetric, with 2 and 3
    transfers a step (the even count ends with a copy back, the odd one in place): after every
    step the grid's floor rows are still (and the axis has no radial velocity), as after the
    update itself, while the column above them moves."""
    import dataclasses

    from vibroflow.continuum.mpm.column import column_state, column_system
    from vibroflow.continuum.mpm.solver import advance

    base = column_system(0.2, 0.2, 0.02, axisymmetric=axisymmetric, rough_floor=True)
    system = dataclasses.replace(base, transfers=transfers)
    state = column_state(system, 0.2, 0.2)
    gv = system.work.gv
    for _ in range(20):
        advance(system, state, 5)
        assert system.no_slip_rows > 0
        assert np.all(gv[:, :system.no_slip_rows, :] == 0.0)
        if axisymmetric:
            assert np.all(gv[:system.axis_cols, :, 0] == 0.0)
    assert np.abs(gv).max() > 1e-2


def test_eulerian_parallel_loop_gives_the_serial_numbers_with_transfers_and_a_rough_floor():
    """The Eulerian column on the rough floor with 3 transfers a step: the loop with numba's
    parallel loops (forced, serial_below = 0) gives the serial loop's numbers bit for bit, and
    the floor's node rows are still after every step."""
    import dataclasses

    import numba as nb

    from vibroflow.continuum.eulerian import solver
    from vibroflow.continuum.eulerian.column import column_state, column_system

    def run(serial_below, threads):
        base = column_system(0.2, 0.2, 0.02, rough_floor=True)
        system = dataclasses.replace(base, transfers=3, serial_below=serial_below)
        state = column_state(system, 0.2, 0.2)
        old = nb.get_num_threads()
        nb.set_num_threads(threads)
        try:
            for _ in range(10):
                solver.advance(system, state, 10)
                assert np.all(system.work.gv[:, :system.no_slip_rows, :] == 0.0)
        finally:
            nb.set_num_threads(old)
        return state

    serial = run(solver.SERIAL_BELOW, 1)
    assert np.abs(serial.v).max() > 1e-2
    parallel = run(0, min(2, nb.config.NUMBA_NUM_THREADS))
    for f in ("mass", "v", "C", "stress"):
        np.testing.assert_array_equal(getattr(parallel, f), getattr(serial, f), err_msg=f)


def _mode_loss(nx: int) -> float:
    """1 - the amplitude one transfer leaves of a velocity mode of one wavelength across a
    periodic grid of nx cells of side 1/nx m (2 x 2 points a cell on a lattice), so k dx =
    2 pi / nx."""
    dx = 1.0 / nx
    grid = Grid(x0=0.0, z0=0.0, dx=dx, nx=nx, nz=12, periodic=True)
    X, Z = np.meshgrid((np.arange(2 * nx) + 0.5) * dx / 2, 3 * dx + (np.arange(12) + 0.5) * dx / 2,
                       indexing="ij")
    x = np.stack([X.ravel(), Z.ravel()], axis=1)
    mass = np.ones(len(x))
    gm, _ = explicit_pair(grid, x, mass, np.zeros((grid.nx, grid.nz, 2)))
    mode = np.sin(2.0 * math.pi * np.arange(nx) * dx)
    gv = np.zeros((nx, grid.nz, 2))
    gv[:, :, 1] = mode[:, None]
    out = np.zeros_like(gv)
    transfer_rows(0, nx, operator(grid, x, mass), gm, gv, out, True, 0, 0)
    return 1.0 - float(np.sum(out[:, 6, 1] * mode) / np.sum(mode * mode))


def test_a_transfer_damps_a_mode_at_fourth_order_in_k_dx():
    """APIC keeps affine velocity fields exactly, so a transfer's loss of a smooth mode starts
    at fourth order: 1 - amplitude = alpha (k dx)^4, alpha -> 0.024 (measured 0.0236, 0.0240,
    0.0241 at k dx = 0.39, 0.20, 0.098), while over (k dx)^2 the loss falls sixteenfold from the
    first to the last.  This is why the tub runs hold transfer_cfl / dx^3 fixed across grids
    (continuum/options.py, damping_transfer_cfl): the transfers are a hyperviscosity alpha c dx^3 /
    transfer_cfl."""
    kdx = np.array([2.0 * math.pi / n for n in (16, 32, 64)])
    loss = np.array([_mode_loss(n) for n in (16, 32, 64)])
    alpha = loss / kdx**4
    assert alpha == pytest.approx(0.024, rel=0.03)
    assert loss[0] / kdx[0] ** 2 > 12.0 * loss[2] / kdx[2] ** 2


def test_the_damping_is_the_same_on_every_grid_at_a_fixed_damping_length():
    """A shear wave of 8 cm (k dx = 0.39 and 0.20, where a transfer's loss is alpha (k dx)^4:
    test above) on grids of 5 and 2.5 mm, the transfers of ContinuumOptions with transfer_cfl
    0.025 at a damping length of 5 mm (cfl 0.4: 16 and 128 transfers a step): the kinetic
    energy left after 4 ms is the same within 8 % (measured 0.202 and 0.211), where
    damping_length = dx (16 transfers a step on both grids) leaves the fine grid's wave far
    less damped (0.369): with it the damping would be a property of the grid."""
    from vibroflow.continuum.formulation import formulation

    mpm_options = formulation("lagrangian").options
    rule = mpm_options(cfl=0.4, transfer_cfl=0.025, damping_length=0.005)
    coarse_n, fine_n = rule.transfers(0.005), rule.transfers(0.0025)
    assert (coarse_n, fine_n) == (16, 128)
    coarse = _shear_wave_energy(0.4, coarse_n, dx=0.005, wavelength=0.08)
    fine = _shear_wave_energy(0.4, fine_n, dx=0.0025, wavelength=0.08)
    per_dx_n = mpm_options(cfl=0.4, transfer_cfl=0.025, damping_length=0.0025).transfers(
        0.0025)
    assert per_dx_n == 16
    per_dx = _shear_wave_energy(0.4, per_dx_n, dx=0.0025, wavelength=0.08)
    print(f"\nenergy left: 5 mm {coarse:.3f}, 2.5 mm {fine:.3f} "
          f"(the rate held per cell, damping_length = dx: {per_dx:.3f})")
    assert fine == pytest.approx(coarse, rel=0.08)
    assert coarse < 0.5
    assert per_dx > 1.5 * coarse


def test_the_transfers_follow_the_grid_from_the_default_one():
    """The tub runs' rule (continuum/options.py): on the default grid the default 20 (Lagrangian)
    and 8 (Eulerian) transfers a step; on half of it eight times as many; a damping length
    equal to the grid gives transfer_cfl on every grid; a bad damping length is a one-line error."""
    from vibroflow.continuum.formulation import formulation
    from vibroflow.continuum.options import options_record
    from vibroflow.scenario.io import load_scenario

    tub = load_scenario("tub47")
    d3 = 3 * tub.fill.diameter
    lag, eul = formulation("lagrangian"), formulation("eulerian")
    # each formulation's default grid: 3 diameters, the Eulerian's rounded to fill the tub
    assert lag.grid(lag.options(), tub) == pytest.approx(d3)
    assert eul.grid(eul.options(), tub) == pytest.approx(0.01875)
    assert lag.transfers_on(lag.options(), tub) == 20
    assert lag.transfers_on(lag.options(dx=d3 / 2), tub) == 160
    assert lag.transfers_on(lag.options(dx=d3 / 2, damping_length=d3 / 2), tub) == 20
    assert eul.transfers_on(eul.options(), tub) == 8
    assert eul.transfers_on(eul.options(dx=0.009375), tub) == 64
    assert lag.transfers_on(lag.options(dx=d3 / 2, transfer_cfl=0), tub) == 1
    for bad in (0.0, -1.0, float("nan"), True):
        with pytest.raises(InputError, match="damping_length"):
            lag.options(damping_length=bad)
    # a run on a grid of its own names its damping length, so it is not taken for one made
    # with damping_length = dx
    assert options_record(lag.options())["damping_length"] is None
    assert options_record(lag.options(dx=0.01))["damping_length"] is not None
