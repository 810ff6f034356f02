"""Newton's third law, bit for bit: the contact law seen from either ball of a pair.

The known answer is IEEE arithmetic.  When balls i and j trade places, the branch vector, the
relative velocity, the relative spin and the unit normal change sign exactly (a - b = -(b - a),
x / d = -(-x / d)), products of two negated numbers are the same numbers, and r_i w_i + r_j w_j
is r_j w_j + r_i w_i (IEEE addition commutes).  So the law (vibroflow.dem.contact) evaluated
from j's side, with the history negated, gives the exact negative of the force on i, the torque
on j as its torque on the first ball and the torque on i as its torque on the second, and the
negated history after the step (a zero history may come out as +0 on one side and -0 on
the other: the same number, which the law never divides by), for every kind of law (linear and Hertz, each rolling model),
sticking and sliding, over many steps; the minimum image across a periodic length is
antisymmetric too.  This is what lets a full neighbour list, each pair evaluated from both sides
with a history of its own, give the step's numbers (benchmarks/dem_full_list.py).
"""
from __future__ import annotations

import numpy as np
import pytest

from tests.dem_helpers import law_row
from vibroflow.dem import laws as L
from vibroflow.dem.contact import (branch_vector, contact_force_with, normal_constants,
                                   pair_contact_velocity, unit_normal)

N = 400
STEPS = 12
DT = 2e-6


def _side(par, branch, vel, omg, a, b, ra, rb, ma, mb, hist, dt):
    """The law of the pair from ball a's side (a first): force on a, torques on a and b, fn,
    sliding; `hist` advanced in place."""
    d2 = branch @ branch
    delta, nx, ny, nz = unit_normal(branch[0], branch[1], branch[2], d2, ra + rb)
    vx, vy, vz = pair_contact_velocity(vel, omg, a, b, ra, rb, nx, ny, nz)
    r_eff = ra * rb / (ra + rb)
    m_eff = ma * mb / (ma + mb)
    kn, damp = normal_constants(par, r_eff, m_eff)
    out = contact_force_with(delta, nx, ny, nz, vx, vy, vz, omg[a, 0] - omg[b, 0],
                             omg[a, 1] - omg[b, 1], omg[a, 2] - omg[b, 2], ra, rb, r_eff, par,
                             kn, damp, hist, dt)
    return np.array(out[:3]), np.array(out[3:6]), np.array(out[6:9]), out[9], out[11]


def _bits(x):
    return np.asarray(x, np.float64).view(np.uint64)


@pytest.mark.parametrize("model", [L.MODEL_LINEAR, L.MODEL_HERTZ])
@pytest.mark.parametrize("roll", [L.ROLL_NONE, L.ROLL_CDT, L.ROLL_EPSD, L.ROLL_CDT_LIGGGHTS])
def test_either_side_of_a_pair_gives_the_same_contact_to_the_bit(model, roll):
    rng = np.random.default_rng(7 + 10 * model + roll)
    par = law_row(model, roll)
    top = 2e-4 if model == L.MODEL_LINEAR else 2e-5
    slid = 0
    for _ in range(N):
        ri, rj = rng.uniform(1.5e-3, 3e-3, 2)
        mi, mj = rng.uniform(2e-4, 3e-4, 2)
        u = rng.normal(size=3)
        u /= np.linalg.norm(u)
        branch = u * (ri + rj - rng.uniform(1e-9, top))
        vel = rng.normal(0.0, 0.2, (2, 3))
        omg = rng.normal(0.0, 60.0, (2, 3))
        if rng.random() < 0.1:
            omg[1] = omg[0]  # no relative spin: the CDT laws' guard
        h_i = np.zeros(6)
        if rng.random() < 0.7:
            h_i[:3] = rng.normal(0.0, top / 2, 3)
            h_i[3:] = rng.normal(0.0, 5e-5, 3)
        h_j = -h_i
        for _ in range(STEPS):
            f_i, ti_i, tj_i, fn_i, sl_i = _side(par, branch, vel, omg, 0, 1, ri, rj, mi, mj,
                                                h_i, DT)
            f_j, ti_j, tj_j, fn_j, sl_j = _side(par, -branch, vel, omg, 1, 0, rj, ri, mj, mi,
                                                h_j, DT)
            assert np.array_equal(_bits(f_j), _bits(-f_i))
            assert np.array_equal(_bits(ti_j), _bits(tj_i))  # on j, as the first ball
            assert np.array_equal(_bits(tj_j), _bits(ti_i))  # on i, as the second ball
            assert fn_j == fn_i and sl_j == sl_i
            # the same numbers; a zero history may come out +0 on one side and -0 on the
            # other (a - a is +0 either way), which no later operation of the law tells apart
            assert np.array_equal(h_j, -h_i)
            assert np.array_equal(_bits(h_j[h_i != 0.0]), _bits(-h_i[h_i != 0.0]))
            slid += sl_i
            # the balls move on: new velocities and spins, the same contact
            vel += rng.normal(0.0, 0.05, (2, 3))
            omg += rng.normal(0.0, 10.0, (2, 3))
    assert slid > 0  # sliding contacts were among them


def test_the_minimum_image_is_antisymmetric():
    rng = np.random.default_rng(3)
    length = 0.0635
    pos = rng.uniform(-0.2, 0.2, (500, 3))
    pos[:, 1] = rng.uniform(0.0, length, 500)
    pos[::7, 1] = pos[1::7, 1][:pos[::7].shape[0]] + 0.5 * length  # ties at half the length
    pairs = np.concatenate([rng.integers(0, 500, (2000, 2)),
                            np.stack([np.arange(0, 497, 7), np.arange(1, 498, 7)], axis=1)])
    for i, j in pairs[pairs[:, 0] != pairs[:, 1]]:
        a = np.array(branch_vector(pos, i, j, length))
        b = np.array(branch_vector(pos, j, i, length))
        assert np.array_equal(_bits(b), _bits(-a))
