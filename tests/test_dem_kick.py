"""The tub step's kick pass (vibroflow.dem.step._kick_block: each ball's update one straight
line of arithmetic) against the plain velocity-Verlet sequence written out in NumPy
(elementwise IEEE operations, no FMA): the second half kick, then the next step's first half
kick and drift, bit for bit, on random balls; the largest squared move in the tub frame and
the first ball whose move is NaN or infinite, as the plain loop finds them."""
from __future__ import annotations

import numpy as np
import pytest

from vibroflow.dem import step as K
from vibroflow.dem.block_queue import queue_array
from vibroflow.dem.records import Balls, Pairs, Params, Work


def _balls(n, seed, bad=()):
    rng = np.random.default_rng(seed)
    radius = rng.uniform(1e-3, 5e-3, n)
    mass = 7800.0 * 4.0 / 3.0 * np.pi * radius ** 3
    b = Balls(pos=rng.normal(0.0, 0.1, (n, 3)), vel=rng.normal(0.0, 0.5, (n, 3)),
              omg=rng.normal(0.0, 50.0, (n, 3)), radius=radius, mass=mass,
              mat=np.zeros(n, np.int64), force=rng.normal(0.0, 1.0, (n, 3)) * mass[:, None],
              torque=rng.normal(0.0, 1e-4, (n, 3)), ref_tub=rng.normal(0.0, 0.1, (n, 3)))
    for i, x in bad:
        b.pos[i, 1] = x
    return b


def _records(balls, bounds):
    nblock = len(bounds) - 1
    n = balls.pos.shape[0]
    pairs = Pairs(np.zeros(n + 1, np.int64), np.zeros(0, np.int64), np.zeros((0, 6)),
                  np.zeros(0, np.uint8), np.asarray(bounds, np.int64))
    params = Params(2e-6, np.array([0.0, 0.0, -9.81]), np.zeros((1, 1, 16)), np.zeros(5),
                    np.zeros(3, np.int64), np.zeros((0, 14)), 1e-3, 1e-3)
    pose = np.array([1e-3, -2e-3, 0.03, 0.1, -0.2, 1.5, 0.05, 0.2])
    work = Work(np.zeros((nblock, 1, K.N_IMP_BUF)), np.zeros(nblock, np.int64),
                np.full((nblock, K.N_DIAG), -1.0), pose, np.zeros(nblock), np.zeros((n, 9)),
                np.zeros(2, np.int64), np.zeros((nblock, 1)), np.zeros((nblock, 1), np.int64),
                queue_array(nblock), np.zeros(nblock, np.int64))
    return pairs, params, work


def _plain(b, dt, pose, drift):
    """The plain sequence: half kick; the move in the tub frame; half kick and drift."""
    half_dt = 0.5 * dt
    im = 1.0 / b.mass
    ii = 1.0 / (0.4 * b.mass * b.radius * b.radius)
    pos, vel, omg = b.pos.copy(), b.vel.copy(), b.omg.copy()
    for a in range(3):
        vel[:, a] = vel[:, a] + half_dt * b.force[:, a] * im
        omg[:, a] = omg[:, a] + half_dt * b.torque[:, a] * ii
    cth, sth = np.cos(pose[2]), np.sin(pose[2])
    rx = pos[:, 0] - pose[0] - pose[6]
    rz = pos[:, 2] - pose[1] - pose[7]
    dx = pose[6] + cth * rx + sth * rz - b.ref_tub[:, 0]
    dy = pos[:, 1] - b.ref_tub[:, 1]
    dz = pose[7] - sth * rx + cth * rz - b.ref_tub[:, 2]
    d2 = dx * dx + dy * dy + dz * dz
    save = np.concatenate([pos, vel, omg], axis=1)
    if drift:
        for a in range(3):
            vel[:, a] = vel[:, a] + half_dt * b.force[:, a] * im
            omg[:, a] = omg[:, a] + half_dt * b.torque[:, a] * ii
            pos[:, a] = pos[:, a] + dt * vel[:, a]
    return pos, vel, omg, save, d2


@pytest.mark.parametrize("drift", [False, True])
def test_the_kick_pass_gives_the_plain_sequences_bits(drift):
    n = 1000
    bounds = [0, 1, 300, 301, 700, 1000]
    bad = [(320, np.nan), (500, np.inf), (900, np.nan), (950, -np.inf)]
    b = _balls(n, 7, bad)
    pairs, params, work = _records(b, bounds)
    pos, vel, omg, save, d2 = _plain(b, params.dt, work.pose, drift)
    for c in range(len(bounds) - 1):
        K._kick_block(c, b, pairs, params, work, drift)
    assert np.array_equal(b.vel, vel) and np.array_equal(b.omg, omg)
    assert np.array_equal(b.pos, pos, equal_nan=True)
    if drift:
        assert np.array_equal(work.save, save, equal_nan=True)
    for c in range(len(bounds) - 1):
        lo, hi = bounds[c], bounds[c + 1]
        d = d2[lo:hi]
        finite = d < 1e300
        assert work.moved[c] == max(d[finite].max(initial=0.0), 0.0)
        first = np.flatnonzero(~finite)
        assert work.diag[c, K.D_NAN] == (lo + first[0] if first.size else -1.0)
