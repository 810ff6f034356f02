"""The report's engineer's sections against known answers: the peak tub acceleration Gamma of a
motion by hand, the difference map of identical and of shifted fields, binned means of data
with a hand-computed mean and standard error, the turnover time of a solid-body rotation
(2 pi / Omega), the profiles of that rotation, the kinetic energy's whole-cycle means and the
steady-state test, and the E limit with its verdict in words (tub47.md's figures)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from vibroflow.measure.bulk import CellTable
from vibroflow.report import bed_state, flow_maps, mu_i_bins, profiles, verdict
from vibroflow.tub.motion import TubMotion

G = 9.81


def test_gamma_of_a_vertical_motion_by_hand():
    """A_z = 1.5 mm at 47 Hz: Gamma = 1.5e-3 (2 pi 47)^2 / 9.81 = 13.33; no horizontal motion
    and no rotation: the bottom of the U feels the same."""
    m = TubMotion(frequency=47.0, amplitude_x=0.0, amplitude_z=1.5e-3, amplitude_theta=0.0)
    g = bed_state.gamma(m, G)
    assert g["vertical"] == pytest.approx(13.3345, rel=1e-4)
    assert g["horizontal"] == 0.0
    assert g["bottom_of_u"] == pytest.approx(g["vertical"], rel=1e-5)


def test_gamma_of_a_circular_motion_is_constant_magnitude():
    """X = A sin(w t), Z = A sin(w t + pi/2): the tub circles, |a| = A w^2 at every instant."""
    m = TubMotion(frequency=30.0, amplitude_x=2e-3, phase_x=0.0, amplitude_z=2e-3,
                  phase_z=0.5 * math.pi, amplitude_theta=0.0)
    g = bed_state.gamma(m, G)
    want = 2e-3 * (2 * math.pi * 30.0) ** 2 / G
    assert g["bottom_of_u"] == pytest.approx(want, rel=1e-9)
    assert g["vertical"] == g["horizontal"] == pytest.approx(want, rel=1e-12)


def _disc(omega: float, h: float = 0.015, radius: float = 0.11, zc: float = 0.12,
          n_batches: int = 0, phi: float = 0.6) -> CellTable:
    """Cells of a solid-body rotation v = omega (-(z - zc), x) inside a disc about (0, zc)."""
    i = np.arange(-10, 11)
    k = np.arange(0, 20)
    X, Z = (a.ravel() for a in np.meshgrid(i * h, k * h))
    inside = np.hypot(X, Z - zc) <= radius
    x, z = X[inside], Z[inside]
    vx, vz = -omega * (z - zc), omega * x
    batches = {}
    if n_batches:
        batches = dict(batch_phi=np.tile(np.full(x.size, phi), (n_batches, 1)),
                       batch_vx=np.tile(vx, (n_batches, 1)), batch_vz=np.tile(vz, (n_batches, 1)),
                       batch_samples=np.ones((n_batches, x.size), dtype=np.int64))
    return CellTable(x=x, z=z, solid_fraction=np.full(x.size, phi), vx=vx, vz=vz,
                     samples=np.full(x.size, 100), cell_size=h, **batches)


def test_turnover_time_of_a_solid_body_rotation_is_one_revolution():
    """zeta = 2 Omega everywhere: T = 2 pi / Omega; identical batches give a zero error."""
    omega = 0.8
    t = bed_state.turnover_time(_disc(omega, n_batches=4), 0.3)
    assert t.time_s == pytest.approx(2 * math.pi / omega, rel=1e-9)
    assert t.mean_vorticity_1_s == pytest.approx(2 * omega, rel=1e-9)
    assert t.cells > 10
    assert t.stderr_s == pytest.approx(0.0, abs=1e-9)
    # clockwise turns as fast: the same time
    assert bed_state.turnover_time(_disc(-omega), 0.3).time_s == pytest.approx(
        2 * math.pi / omega, rel=1e-9)


def test_difference_map_of_identical_fields_is_zero_and_of_a_shift_the_shift():
    a = _disc(0.5)
    d = flow_maps.velocity_difference(a, a, 0.3)
    ok = np.isfinite(d["dspeed"])
    assert ok.sum() == len(a)
    assert np.all(d["dvx"][ok] == 0.0) and np.all(d["dspeed"][ok] == 0.0)
    b = _disc(0.5)
    b.vx, b.vz = b.vx + 0.01, b.vz - 0.02
    d = flow_maps.velocity_difference(b, a, 0.3)
    np.testing.assert_allclose(d["dvx"][ok], 0.01, rtol=1e-12)
    np.testing.assert_allclose(d["dvz"][ok], -0.02, rtol=1e-12)
    np.testing.assert_allclose(d["dspeed"][ok], math.hypot(0.01, 0.02), rtol=1e-12)
    # a cell below the solid fraction limit in either field is left out
    b.solid_fraction = b.solid_fraction.copy()
    b.solid_fraction[0] = 0.1
    assert np.isfinite(flow_maps.velocity_difference(b, a, 0.3)["dspeed"]).sum() == len(a) - 1


def test_profiles_of_a_solid_body_rotation():
    """vx(z) at x = 0 is -Omega (z - zc); vz(x) at mid-depth is Omega x; no batches: NaN
    errors; mid-depth is half the top cell's height at x = 0."""
    omega, zc = 0.8, 0.12
    t = _disc(omega, zc=zc)
    p = profiles.profiles({"dem": t}, 0.3)
    top = t.z[t.ix == 0].max()
    assert p.z_mid == pytest.approx(round(0.5 * top / 0.015) * 0.015)
    ln = p.lines["dem"]
    ok = np.isfinite(ln["vx"])
    np.testing.assert_allclose(ln["vx"][ok], -omega * (p.z_column[ok] - zc), rtol=1e-12)
    ok = np.isfinite(ln["vz"])
    np.testing.assert_allclose(ln["vz"][ok], omega * p.x_row[ok], atol=1e-15)
    assert np.isnan(ln["vx_stderr"]).all()


def test_binned_means_by_hand():
    """Four points in one bin (mu 1, 2, 3, 4: mean 2.5, se std/2 = 0.6455), two in another
    (fewer than MIN_PER_BIN: left out), I <= 0 and NaN dropped."""
    I = [0.011, 0.012, 0.013, 0.017, 0.2, 0.3, 0.0, np.nan]
    mu = [1.0, 2.0, 3.0, 4.0, 0.5, 0.6, 9.0, 1.0]
    b = mu_i_bins.binned_means(I, mu, bins_per_decade=4, min_per_bin=3)
    assert b.count.tolist() == [4]
    assert b.mean_mu[0] == pytest.approx(2.5)
    assert b.stderr_mu[0] == pytest.approx(np.std([1, 2, 3, 4], ddof=1) / 2)
    assert (b.lo[0], b.hi[0]) == pytest.approx((0.01, 10 ** -1.75))
    assert b.mean_I[0] == pytest.approx(0.01325)


def test_binned_means_of_noisy_data_meet_the_known_mean():
    """mu = 0.4 + noise of sigma 0.05 in every bin: each bin's mean within 4 standard errors of
    0.4, and the error near sigma / sqrt(n)."""
    rng = np.random.default_rng(3)
    I = 10 ** rng.uniform(-3, -1, 4000)
    mu = 0.4 + rng.normal(0, 0.05, I.size)
    b = mu_i_bins.binned_means(I, mu)
    assert len(b.count) == 8
    assert np.all(np.abs(b.mean_mu - 0.4) < 4 * b.stderr_mu)
    np.testing.assert_allclose(b.stderr_mu, 0.05 / np.sqrt(b.count), rtol=0.2)


def test_kinetic_energy_cycle_means_and_steady_state():
    """A series E0 + a sin(2 pi f t) sampled 40 times a cycle: every whole-cycle block mean is
    E0; steady.  The same with a ramp of 40 % over the window: not steady."""
    f, e0 = 40.0, 0.08
    t = np.arange(0, 1.5, 1 / (40 * f))
    e = e0 + 0.05 * np.sin(2 * np.pi * f * t)
    ct, cm = bed_state.cycle_means(t, e, f)
    np.testing.assert_allclose(cm, e0, atol=1e-12)
    assert ct[0] == pytest.approx(0.05)  # blocks of 4 cycles (0.1 s at 40 Hz)
    ke = bed_state.kinetic_energy(t, e, 0.5, 1.5, f, 4)
    assert ke.steady and ke.mean == pytest.approx(e0, abs=1e-12)
    ramp = bed_state.kinetic_energy(t, e * (1 + 0.4 * np.clip(t - 0.5, 0, 1)), 0.5, 1.5, f, 4)
    assert not ramp.steady


def test_e_limit_and_verdict_in_words():
    """tub47.md's ten-seed floor 0.206: limit 0.309; tub47-quick's two seeds 0.166: 0.249
    (docs/validation.md section 16), with the caveat of few seeds; no figure for another
    amplitude; the words."""
    lim = verdict.ensemble_limit("tub47", 1.0)
    assert lim.limit == pytest.approx(0.309) and lim.seeds == 10 and not lim.caveat
    quick = verdict.ensemble_limit("tub47-quick", 1.0)
    assert quick.limit == pytest.approx(0.249) and "likely low" in quick.caveat
    assert verdict.ensemble_limit("tub47-quick", 0.7) is None
    assert verdict.verdict(0.2, 0.249) == ("0.80 x the limit: within the DEM's own scatter",
                                           "ok")
    assert verdict.verdict(0.481, 0.249) == ("1.93 x the limit: the flow differs", "bad")
    assert verdict.verdict(0.3, None)[1] == ""


def test_e_limit_from_seeds_is_the_pairs_mean():
    """Two seeds whose fields differ by a uniform 10 % of a uniform flow: E = 0.1 / 1.0 and
    0.1 / 1.1 for the two orders, limit 1.5 x their mean."""
    a = _disc(0.0)
    a.vx = np.full(len(a), 1.0)
    b = _disc(0.0)
    b.vx = np.full(len(b), 1.1)
    lim = verdict.seeds_limit([a, b])
    assert lim.e_seed == pytest.approx(0.5 * (0.1 / 1.1 + 0.1 / 1.0))
    assert lim.seeds == 2 and "measured" in lim.source


def test_a_scenario_changed_from_its_preset_is_said_so():
    """The ensemble figure is the preset's: a --set that changes the flow is named in the
    caveat, a seed or a probe is not."""
    from vibroflow.scenario.io import load_scenario

    assert verdict.differs_from_preset(load_scenario("tub47-quick", ["run.seed=7"])) == ()
    sc = load_scenario("tub47-quick", ["fill.count=400", "analysis.probes.P1.x=-0.03"])
    assert verdict.differs_from_preset(sc) == ("fill.count",)
