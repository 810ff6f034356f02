"""The tub step's contact law over a tile of contacts (vibroflow.dem.step._law_tile, vectorised
across contacts by LLVM) against the scalar law the walls, the parts and the periodic box call
(vibroflow.dem.contact.contact_force_with, after contact.unit_normal and
contact.pair_contact_velocity, as the step evaluated each contact one by one).

The known answer is IEEE arithmetic: an elementwise loop vectorised across contacts makes the
same operations in the same order for each contact (no FMA contraction without fastmath; packed
square roots and divisions are correctly rounded, as the scalar ones), and a branch turned into
a select of both sides keeps the side it picks.  So every force, torque and history comes out
equal bit for bit, for every kind of law (linear and Hertz, each rolling model), sliding and
sticking contacts, zero and non-zero histories, one tile's law resolved once (_law_tile) or
contact by contact (_law_tile_mixed).
"""
from __future__ import annotations

import numba as nb
import numpy as np
import pytest

from tests.dem_helpers import law_row
from vibroflow.dem import laws as L
from vibroflow.dem import step as S
from vibroflow.dem.contact import contact_force_with, normal_constants, pair_contact_velocity
from vibroflow.dem.contact import unit_normal

N = 300
DT = 2e-6


def _contacts(model, seed):
    """N random touching pairs: ball 2m and ball 2m + 1 of (2N, 3) velocity and spin arrays,
    the branch vector, the radii and a history (a third of them zero, a few spins equal)."""
    rng = np.random.default_rng(seed)
    ri = rng.uniform(1.5e-3, 3e-3, N)
    rj = rng.uniform(1.5e-3, 3e-3, N)
    top = 2e-4 if model == L.MODEL_LINEAR else 2e-5
    delta = rng.uniform(1e-9, top, N)
    u = rng.normal(size=(N, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    branch = u * (ri + rj - delta)[:, None]
    vel = rng.normal(0.0, 0.2, (2 * N, 3))
    omg = rng.normal(0.0, 60.0, (2 * N, 3))
    omg[1:N // 10:2] = omg[0:N // 10 - 1:2]  # relative spin zero: CDT's guard
    hist = np.zeros((N, 6))
    hist[:, :3] = rng.normal(0.0, 1e-4 if model == L.MODEL_LINEAR else 1e-5, (N, 3))
    hist[:, 3:] = rng.normal(0.0, 5e-5, (N, 3))
    hist[rng.random(N) < 1 / 3] = 0.0
    mass = rng.uniform(2e-4, 3e-4, (N, 2))
    return ri, rj, branch, vel, omg, hist, mass


@nb.njit(cache=True)
def _scalar(ri, rj, branch, vel, omg, hist, mass, par, dt, out, sliding):
    """Each contact through the scalar law; out[m] = force on i, torques on i and on j."""
    for m in range(ri.shape[0]):
        i, j = 2 * m, 2 * m + 1
        dx, dy, dz = branch[m, 0], branch[m, 1], branch[m, 2]
        rsum = ri[m] + rj[m]
        delta, nx, ny, nz = unit_normal(dx, dy, dz, dx * dx + dy * dy + dz * dz, rsum)
        vx, vy, vz = pair_contact_velocity(vel, omg, i, j, ri[m], rj[m], nx, ny, nz)
        m_eff = mass[m, 0] * mass[m, 1] / (mass[m, 0] + mass[m, 1])
        r_eff = ri[m] * rj[m] / (ri[m] + rj[m])
        kn, damp = normal_constants(par, r_eff, m_eff)
        fx, fy, fz, tix, tiy, tiz, tjx, tjy, tjz, _fn, _ft, sl = contact_force_with(
            delta, nx, ny, nz, vx, vy, vz, omg[i, 0] - omg[j, 0], omg[i, 1] - omg[j, 1],
            omg[i, 2] - omg[j, 2], ri[m], rj[m], r_eff, par, kn, damp, hist[m], dt)
        out[m, 0], out[m, 1], out[m, 2] = fx, fy, fz
        out[m, 3], out[m, 4], out[m, 5] = tix, tiy, tiz
        out[m, 6], out[m, 7], out[m, 8] = tjx, tjy, tjz
        sliding[m] = sl


def _tiled(ri, rj, branch, vel, omg, hist, mass, par, mixed):
    """The same contacts through the step's tiles (the columns _pair_block fills)."""
    T = S.TILE
    out = np.empty((N, 9))
    new_hist = np.empty((N, 6))
    table = par.reshape(1, 1, -1)
    mat = np.zeros(2 * N, np.int64)
    for s in range(0, N, T):
        n = min(T, N - s)
        b = np.full(S.N_TILE * T, np.nan)
        bi = np.zeros(S.N_TILE_IDX * T, np.int64)
        sl = slice(s, s + n)
        i, j = 2 * np.arange(s, s + n), 2 * np.arange(s, s + n) + 1

        def put(col, x):
            b[col * T:col * T + n] = x

        put(S.T_DX, branch[sl, 0])
        put(S.T_DY, branch[sl, 1])
        put(S.T_DZ, branch[sl, 2])
        put(S.T_D2, branch[sl, 0] * branch[sl, 0] + branch[sl, 1] * branch[sl, 1]
            + branch[sl, 2] * branch[sl, 2])
        put(S.T_RSUM, ri[sl] + rj[sl])
        put(S.T_RI, ri[sl])
        put(S.T_RJ, rj[sl])
        for a in range(3):
            put(S.T_DVX + a, vel[i, a] - vel[j, a])
            put(S.T_WIX + a, omg[i, a])
            put(S.T_WJX + a, omg[j, a])
        r_eff = ri[sl] * rj[sl] / (ri[sl] + rj[sl])
        m_eff = mass[sl, 0] * mass[sl, 1] / (mass[sl, 0] + mass[sl, 1])
        put(S.T_REFF, r_eff)
        consts = np.array([normal_constants(par, r, m) for r, m in zip(r_eff, m_eff)])
        put(S.T_KN, consts[:, 0])
        put(S.T_DAMP, consts[:, 1])
        for a in range(6):
            put(S.T_H0 + a, hist[sl, a])
        bi[S.I_I * T:S.I_I * T + n] = i
        bi[S.I_J * T:S.I_J * T + n] = j
        if mixed:
            S._law_tile_mixed(n, b, bi, mat, table, DT)
        else:
            S._law_tile(n, b, par, DT)
        for a in range(9):
            out[sl, a] = b[(S.T_FX + a) * T:(S.T_FX + a) * T + n]
        for a in range(6):
            new_hist[sl, a] = b[(S.T_H0 + a) * T:(S.T_H0 + a) * T + n]
    return out, new_hist


@pytest.mark.parametrize("model", [L.MODEL_LINEAR, L.MODEL_HERTZ])
def test_the_tiled_law_gives_the_scalar_laws_bits(model):
    for roll in (L.ROLL_NONE, L.ROLL_CDT, L.ROLL_EPSD, L.ROLL_CDT_LIGGGHTS):
        par = law_row(model, roll)
        ri, rj, branch, vel, omg, hist, mass = _contacts(model, 31 + roll)
        ref = np.empty((N, 9))
        sliding = np.zeros(N, np.int64)
        ref_hist = hist.copy()
        _scalar(ri, rj, branch, vel, omg, ref_hist, mass, par, DT, ref, sliding)
        # both regimes and both kinds of history are exercised
        assert 0.1 * N < sliding.sum() < 0.9 * N, (roll, sliding.sum())
        assert np.any(hist[:, 0] == 0.0) and np.any(hist[:, 0] != 0.0)
        for mixed in (False, True):
            out, new_hist = _tiled(ri, rj, branch, vel, omg, hist, mass, par, mixed)
            assert np.array_equal(out, ref), (roll, mixed)
            assert np.array_equal(new_hist, ref_hist), (roll, mixed)
