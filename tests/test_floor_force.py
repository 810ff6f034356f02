"""The floor over the cycle (vibroflow.measure.floor_force) against known answers: a rigid
block on a floor shaken at Gamma (its force from the analytic motion, zero from
sin(psi) = 1 / Gamma), the floor's share of a resting bed's contact forces by hand, and the
U's regions."""
from __future__ import annotations

import math

import numpy as np
import pytest

from vibroflow.continuum.sampling import Samples
from vibroflow.measure.floor_force import (FLOOR_COLUMNS, floor_cycle, floor_force_of_contacts,
                                           read_floor_csv, region_lengths, region_of,
                                           sampled_take_off, write_floor_csv)


def block_force_over_weight(psi, gamma):
    """F / (M g) of a completely inelastic rigid block on a floor z_f = A sin(psi), psi =
    omega t, Gamma = A omega^2 / g (> 1): on the floor F / (M g) = 1 - Gamma sin(psi); it
    leaves at sin(psi0) = 1 / Gamma with the floor's speed and flies (z - z_f, in units of
    g / omega^2: (psi - psi0) cos(psi0) Gamma - (psi - psi0)^2 / 2 - Gamma (sin psi -
    sin psi0)) until it meets the floor, then rides it again."""
    psi0 = math.asin(1.0 / gamma)
    u = np.linspace(1e-6, 2 * math.pi, 200001)
    gap = gamma * math.cos(psi0) * u - 0.5 * u ** 2 - gamma * (np.sin(psi0 + u) - 1 / gamma)
    land = psi0 + u[np.argmax(gap < 0)]
    assert land < psi0 + 2 * math.pi          # lands within the cycle: one take-off a cycle
    p = np.mod(np.asarray(psi, float) - psi0, 2 * math.pi) + psi0
    flying = p < land
    return np.where(flying, 0.0, 1.0 - gamma * np.sin(p))


@pytest.mark.parametrize("gamma", [1.5, 3.0])
def test_a_rigid_block_leaves_the_floor_at_sin_psi_one_over_gamma(gamma):
    f, per, cycles, nb = 47.0, 64, 8, 4
    t = np.arange(cycles * per) / (f * per)
    weight = 9.81 * 2.0
    force = weight * block_force_over_weight(2 * math.pi * f * t, gamma)
    cyc = floor_cycle(force, t, 0.0, cycles / f, f, per, nb, weight)
    expect = math.asin(1.0 / gamma) / (2 * math.pi)
    assert cyc.take_off == pytest.approx(expect, abs=1.0 / per)
    assert all(b == pytest.approx(cyc.take_off, abs=1e-12) for b in cyc.take_off_batches)
    # a periodic force: every phase's mean is the analytic value, with no scatter
    np.testing.assert_allclose(cyc.force_over_weight,
                               block_force_over_weight(2 * math.pi * np.arange(per) / per,
                                                       gamma), atol=1e-12)
    np.testing.assert_allclose(cyc.stderr, 0.0, atol=1e-12)
    assert cyc.samples.tolist() == [cycles] * per


def test_a_bed_that_stays_on_the_floor_has_no_take_off():
    per = 8
    f = np.array([1.0, 0.5, 0.2, 0.1, 0.5, 1.5, 2.0, 1.8])
    assert math.isnan(sampled_take_off(f, per))
    # sampled at k / 8: falls to 0.05 a third of the way from 2/8 to 3/8
    f[3] = -0.1
    assert sampled_take_off(f, per) == pytest.approx(2 / 8 + 0.15 / 0.3 / 8, rel=1e-12)


def test_the_floor_force_of_a_resting_beds_contacts_by_hand():
    R = 0.15
    theta = np.array([0.2, -0.1])   # the tub's angle (rad) at the two samples

    def at(deg):                     # a point of the U at deg from its bottom, tub frame
        a = math.radians(deg)
        return [R * math.sin(a), 0.01, R - R * math.cos(a)]

    def inward(deg, size):           # a force along the U's inward normal there, tub axes
        a = math.radians(deg)
        return np.array([-math.sin(a), 0.0, math.cos(a)]) * size

    # sample 0: 2 N at the bottom, 1 N at 20 degrees (floor: cos 20 = 0.9396926 N up),
    # 1 N at -45 degrees and 1 N on the side wall (arcs and walls, not the floor), 5 N on a
    # partition (wall 1) at the bottom; sample 1: 3 N at -25 degrees only
    pos = np.array([at(0), at(20), at(-45), [R, 0.01, 0.3], at(0), at(-25)])
    f_tub = np.array([inward(0, 2.0), inward(20, 1.0), inward(-45, 1.0), [-1.0, 0, 0],
                      [0, 0, 5.0], inward(-25, 3.0)])
    snap = np.array([0, 0, 0, 0, 0, 1])
    wall = np.array([0, 0, 0, 0, 1, 0])
    th = theta[snap]
    # lab axes: the tub's axes turned by theta (vibroflow.tub.motion.tub_to_lab)
    f_lab = np.stack([np.cos(th) * f_tub[:, 0] - np.sin(th) * f_tub[:, 2], f_tub[:, 1],
                      np.sin(th) * f_tub[:, 0] + np.cos(th) * f_tub[:, 2]], axis=1)
    fz = floor_force_of_contacts(snap, wall, pos, f_lab, theta, 3, R)
    np.testing.assert_allclose(fz, [2.0 + 0.9396926, 3 * 0.9063078, 0.0], atol=1e-7)


def test_the_regions_split_the_u():
    R = 0.15
    s = np.array([0.0, R * math.radians(29.0), -R * math.radians(31.0), 0.5 * math.pi * R - 1e-6,
                  0.5 * math.pi * R + 0.01])
    assert region_of(s, R).tolist() == [0, 0, 1, 1, 2]
    np.testing.assert_allclose(region_lengths(R, 0.4),
                               [R * math.pi / 3, 2 * R * math.pi / 3, 0.5])


def test_a_continuum_samples_floor_force_is_its_floor_points_z_force_over_the_slice():
    R, L = 0.15, 0.0635
    s = Samples(2, 3, 0)
    a = math.radians(25.0)
    x = np.array([[0.0, 0.001], [R * math.sin(a), R - R * math.cos(a)], [R, 0.2]])
    s.add_floor_force(1, np.array([10.0, 4.0, 7.0]), x, R, L)
    assert s.floor_force[1] == pytest.approx(14.0 * L, rel=1e-12)
    assert math.isnan(s.floor_force[0])
    back = Samples.from_arrays({**s.arrays(), "pos": s.pos[:0]}, 2, 3, 0)
    assert back.floor_force[1] == s.floor_force[1]


def test_floor_csv_holds_the_phases_force_and_error(tmp_path):
    f, per = 10.0, 8
    t = np.arange(4 * per) / (f * per)
    force = np.tile([2.0, 1.0, 0.0, 0.0, 0.0, 1.0, 2.0, 3.0], 4) + np.repeat([0, 0.1, 0, 0.1],
                                                                               per)
    cyc = floor_cycle(force, t, 0.0, 0.4, f, per, 4, 2.0)
    write_floor_csv(tmp_path / "floor.csv", cyc)
    back = read_floor_csv(tmp_path / "floor.csv")
    assert list(back) == list(FLOOR_COLUMNS)
    np.testing.assert_allclose(back["phase"], np.arange(per) / per)
    # batches 0.0, 0.1, 0.0, 0.1 above the pattern: mean +0.05 N, error 0.05 / sqrt(3) / 2 N
    np.testing.assert_allclose(back["force_over_weight"],
                               (np.array([2.0, 1, 0, 0, 0, 1, 2, 3]) + 0.05) / 2.0)
    np.testing.assert_allclose(back["force_over_weight_stderr"],
                               np.full(per, 0.1 / math.sqrt(3) / 2 / 2.0), rtol=1e-12)


@pytest.mark.slow
def test_an_eulerian_run_with_t_measures_its_wall_feed_the_same_when_resumed(tmp_path):
    """The Eulerian's wall feed measures from the start of each sample's step, which the
    compiled loop keeps (Sampler.keeps_sample_step_start): a run with T stopped twice inside
    its window and resumed writes the
    same floor.csv, wall_feed.csv, bulk_velocity.csv and temperature.csv, bit for bit, as the
    run never stopped."""
    from continuum_helpers import THREE_CYCLES

    from vibroflow.continuum.formulation import formulation
    from vibroflow.continuum.tub_run import run_continuum
    from vibroflow.scenario.io import load_scenario

    opt = formulation("eulerian").options(temperature=True, initial_temperature=0.01, cfl=0.1)
    s = load_scenario("tub47-quick", THREE_CYCLES)
    full = run_continuum(s, tmp_path / "full", "eulerian", options=opt)
    split = tmp_path / "split"
    assert run_continuum(s, split, "eulerian", options=opt,
                         stop_after_steps=full["steps"] // 2 + 7) is None
    assert run_continuum(s, split, "eulerian", options=opt, resume=True,
                         stop_after_steps=60) is None
    run_continuum(s, split, "eulerian", options=opt, resume=True)
    for name in ("floor.csv", "wall_feed.csv", "bulk_velocity.csv", "temperature.csv"):
        assert (split / name).read_bytes() == (tmp_path / "full" / name).read_bytes(), name
    assert np.isfinite(full["wall_feed"]["u_wall_W_m2"])
