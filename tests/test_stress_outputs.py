"""The continuum's phase-resolved stress map (continuum/stress_outputs.py, stress.csv) against
hand values: the invariants of known stress states, the cells' volume-weighted means, the phase
means over the window's cycles with their batch-means errors, the inertial number from the
phase shear rate, and the file's rows."""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from vibroflow.continuum.sampling import Samples
from vibroflow.continuum.stress_outputs import (STRESS_COLUMNS, invariants, phase_stress,
                                                write_stress_csv)


def test_invariants_of_known_stress_states():
    """Simple shear on an isotropic pressure p0: p = p0 and tau_eq = |sigma_xz|; uniaxial
    compression s along z: p = s / 3 and tau_eq = s / sqrt(3) (the deviator's -2s/3, s/3, s/3);
    an isotropic tension gives a negative pressure and no shear."""
    p, tau = invariants(np.array([[-2.0e3, -2.0e3, -500.0, -2.0e3],
                                  [0.0, -900.0, 0.0, 0.0],
                                  [10.0, 10.0, 0.0, 10.0]]))
    assert p == pytest.approx([2.0e3, 300.0, -10.0], rel=1e-14)
    assert tau == pytest.approx([500.0, 900.0 / math.sqrt(3.0), 0.0], rel=1e-14, abs=1e-12)


def test_a_cells_stress_is_its_points_volume_weighted_mean():
    """Two points of volumes 1 and 3 in one cell, one in another, one outside the map: the
    first cell holds (a + 3 b) / 4, the second its point's stress, the rest nothing."""
    s = Samples(2, 4, 0, cell_grid=(0.01, 1, 2))
    a, b, c = np.array([-1.0, -2.0, 0.5, -1.5]), np.array([-3.0, -4.0, -0.5, -2.5]), \
        np.array([-7.0, -7.0, 1.0, -7.0])
    x = np.array([[0.001, 0.0], [-0.002, 0.003], [0.01, 0.01], [5.0, 5.0]])
    s.add_cell_stresses(1, x, np.array([1.0, 3.0, 2.0, 1.0]), np.stack([a, b, c, c]))
    assert s.stress_cell[1, 0, 1] == pytest.approx((a + 3.0 * b) / 4.0, rel=1e-15)
    assert s.stress_cell[1, 1, 2] == pytest.approx(c)
    held = np.isfinite(s.stress_cell[1]).all(axis=-1)
    assert held.sum() == 2 and np.isnan(s.stress_cell[0]).all()
    back = Samples.from_arrays(s.arrays(), 2, 4, 0, cell_grid=(0.01, 1, 2))
    assert np.array_equal(back.stress_cell, s.stress_cell, equal_nan=True)


def _window_samples(frequency, n_phases, n_cycles, n_batches, stress_of):
    """Samples at the n_phases phases of n_cycles cycles from t = 0, each sample's stress on a
    3 x 2 cell map stress_of(phase bin, batch) in cell (0, 1) alone."""
    times = np.arange(n_cycles * n_phases) / (frequency * n_phases)
    s = Samples(times.size, 1, 0, cell_grid=(0.01, 1, 2))
    per_batch = n_cycles // n_batches
    for j in range(times.size):
        s.stress_cell[j, 0, 1] = stress_of(j % n_phases, (j // n_phases) // per_batch)
    return s, times


#: the hand case's frequency (Hz), phases, batches' offset e, pressures p_k (Pa), frictions mu_k
F_HZ, P4, E_OFF = 47.0, 4, 0.1
PK = np.array([1.0e3, 2.0e3, 500.0, 4.0e3])
MUK = np.array([0.3, 0.4, 0.25, 0.5])


def _two_batch_stress(n_batches: int = 2):
    """The hand case's PhaseStress: four phases, four cycles in n_batches batches, at phase k an
    isotropic pressure p_k with a shear sigma_xz = -mu_k p_k (1 + e) in the first batch and
    (1 - e) in the others, in cell (0, 1) of a 3 x 2 map at a phase shear rate of 3 1/s."""
    def stress_of(k, b):
        tau = MUK[k] * PK[k] * (1.0 + E_OFF if b == 0 else 1.0 - E_OFF)
        return [-PK[k], -PK[k], -tau, -PK[k]]

    s, times = _window_samples(F_HZ, P4, 4, n_batches, stress_of)
    phase = SimpleNamespace(x=np.array([-0.01, 0.0, 0.01]), z=np.array([0.0, 0.01]),
                            phase_shear_rate=np.full((P4, 2, 3), 3.0),
                            phase_solid_fraction=np.full((P4, 2, 3), 0.58))
    return phase_stress(s, times, F_HZ, P4, (0.0, 4.0 / F_HZ), n_batches, phase, 7800.0,
                        0.00635)


def test_phase_means_their_friction_errors_and_inertial_number_by_hand():
    """Four phases, four cycles in two batches: at phase k an isotropic pressure p_k with a
    shear sigma_xz = -mu_k p_k (1 + e) in the first batch and (1 - e) in the second.  The phase
    mean's friction is mu_k; each batch's is mu_k (1 +- e), so its batch-means error is mu_k e;
    I = gamma_dot d / sqrt(p_k / rho_s) with the phase shear rate; cells that held nothing are
    NaN with no samples."""
    e, pk, muk = E_OFF, PK, MUK
    ps = _two_batch_stress()
    assert ps.pressure[:, 0, 1] == pytest.approx(pk, rel=1e-14)
    assert ps.friction[:, 0, 1] == pytest.approx(muk, rel=1e-13)
    assert ps.shear_stress[:, 0, 1] == pytest.approx(muk * pk, rel=1e-13)
    assert ps.friction_stderr[:, 0, 1] == pytest.approx(muk * e, rel=1e-12)
    assert ps.inertial_number[:, 0, 1] == pytest.approx(3.0 * 0.00635 / np.sqrt(pk / 7800.0),
                                                        rel=1e-14)
    assert (ps.samples[:, 0, 1] == 4).all() and (ps.samples[:, 1] == 0).all()
    assert np.isnan(ps.friction[:, 1]).all()


def test_the_stress_file_holds_a_row_for_each_cell_and_phase_with_material(tmp_path):
    f, P = 47.0, 2
    s, times = _window_samples(f, P, 4, 2, lambda k, b: [-1.0e3, -1.0e3, 200.0 * (k + 1),
                                                         -1.0e3])
    phase = SimpleNamespace(x=np.array([-0.01, 0.0, 0.01]), z=np.array([0.0, 0.01]),
                            phase_shear_rate=np.full((P, 2, 3), 2.0),
                            phase_solid_fraction=np.full((P, 2, 3), 0.58))
    ps = phase_stress(s, times, f, P, (0.0, 4.0 / f), 2, phase, 7800.0, 0.00635)
    assert write_stress_csv(tmp_path / "stress.csv", ps)
    rows = np.genfromtxt(tmp_path / "stress.csv", delimiter=",", names=True)
    assert list(rows.dtype.names) == list(STRESS_COLUMNS)
    assert rows.size == 2
    assert rows["x"] == pytest.approx([0.0, 0.0]) and rows["z"] == pytest.approx([0.0, 0.0])
    assert rows["phase"] == pytest.approx([0, 1])
    assert rows["friction_coefficient"] == pytest.approx([0.2, 0.4], rel=1e-14)
    assert rows["friction_coefficient_stderr"] == pytest.approx([0.0, 0.0], abs=1e-15)
    assert rows["samples"] == pytest.approx([4, 4])
    assert not write_stress_csv(tmp_path / "none.csv", None)
    assert not (tmp_path / "none.csv").exists()


def test_height_phase_table_by_hand(tmp_path):
    """Cells on mu(I) times e^(+a) in the highest third of heights and e^(-a) in the lowest,
    the middle third on the curve: the table's residuals, about the curve fitted to them all,
    are below 0 and above it and 2a apart, their correlation with height positive, and the
    medians of mu and p by hand; the share at yield by hand; a continuum's stress.csv read back
    gives the same cells; a missing file is one error."""
    from vibroflow.analysis.stress_state import (continuum_points, height_phase_table,
                                                 share_at_yield)
    from vibroflow.continuum.rheology import mu_of_I
    from vibroflow.errors import InputError

    rng = np.random.default_rng(3)
    n, a = 600, 0.2
    I = np.exp(rng.uniform(np.log(0.005), np.log(0.2), n))
    z = np.repeat([0.01, 0.05, 0.09], n // 3)
    sign = np.repeat([-1.0, 0.0, 1.0], n // 3)
    mu = mu_of_I(I, 0.28, 0.55, 0.036) * np.exp(a * sign)
    p = np.repeat([3000.0, 1500.0, 500.0], n // 3)
    phase = np.tile(np.arange(2), n // 2)
    pts = {"mu": mu, "I": I, "pressure": p, "z": z, "phase": phase}
    tab = height_phase_table(pts)
    for r in tab["rows"]:
        assert r["res_high"] - r["res_low"] == pytest.approx(2.0 * a, abs=0.03)
        assert r["res_low"] < 0.0 < r["res_high"]
        assert r["corr"] > 0.5
        assert (r["p_low"], r["p_high"]) == (3000.0, 500.0)
    assert share_at_yield(pts, 10.0) == 0.0 and share_at_yield(pts, 0.0) == 1.0
    # three of four cells at or above mu_s = 0.3, the one at it counted
    assert share_at_yield({"mu": np.array([0.1, 0.3, 0.4, 0.5])}, 0.3) == 0.75
    lines = ["x,z,phase,solid_fraction,shear_rate,pressure,shear_stress,friction_coefficient,"
             "friction_coefficient_stderr,inertial_number,samples"]
    for k in range(n):
        lines.append(f"0.0,{float(z[k])!r},{phase[k]},0.58,2.0,{float(p[k])!r},"
                     f"{float(mu[k] * p[k])!r},{float(mu[k])!r},,{float(I[k])!r},4")
    lines.append("0.0,0.2,0,0.3,2.0,100.0,30.0,0.3,,0.01,4")       # dilute: left out
    lines.append("0.0,0.2,0,0.58,2.0,0.0,0.0,,,,4")                # no pressure: left out
    (tmp_path / "stress.csv").write_text("\n".join(lines) + "\n")
    back = continuum_points(tmp_path / "stress.csv")
    assert np.array_equal(back["mu"], mu) and np.array_equal(back["phase"], phase)
    with pytest.raises(InputError, match="no such file"):
        continuum_points(tmp_path / "none.csv")


def test_each_batchs_stress_is_written_beside_the_map_and_read_back(tmp_path):
    """The hand case above (four phases, two batches, friction mu_k (1 + e) in the first batch
    and mu_k (1 - e) in the second, pressure p_k in both): stress_batches.csv holds a row per
    batch, cell and phase with that friction and pressure, and continuum_points reads them
    back onto stress.csv's cells; a damaged file is a one-line error naming it; one batch
    writes no file."""
    from vibroflow.analysis.stress_state import continuum_points
    from vibroflow.continuum.stress_outputs import (STRESS_BATCH_COLUMNS,
                                                    write_stress_batches_csv)
    from vibroflow.errors import InputError

    P, e, pk, muk = P4, E_OFF, PK, MUK
    ps = _two_batch_stress()
    assert write_stress_csv(tmp_path / "stress.csv", ps)
    assert write_stress_batches_csv(tmp_path / "stress_batches.csv", ps)
    rows = np.genfromtxt(tmp_path / "stress_batches.csv", delimiter=",", names=True)
    assert list(rows.dtype.names) == list(STRESS_BATCH_COLUMNS) and rows.size == 2 * P
    for b, sign in ((0, 1.0), (1, -1.0)):
        mine = rows[rows["batch"] == b]
        assert mine["phase"] == pytest.approx(np.arange(P))
        assert mine["friction_coefficient"] == pytest.approx(muk * (1 + sign * e), rel=1e-13)
        assert mine["pressure"] == pytest.approx(pk, rel=1e-14)
    pts = continuum_points(tmp_path / "stress.csv")
    assert pts["batch_mu"] == pytest.approx(np.stack([muk * (1 + e), muk * (1 - e)]), rel=1e-13)
    assert pts["batch_pressure"] == pytest.approx(np.stack([pk, pk]), rel=1e-14)
    (tmp_path / "stress_batches.csv").write_text("batch,x\n0,0.0\n")
    with pytest.raises(InputError, match="stress_batches.csv: not a continuum's"):
        continuum_points(tmp_path / "stress.csv")
    one = _two_batch_stress(1)
    assert not write_stress_batches_csv(tmp_path / "one.csv", one)
    assert not (tmp_path / "one.csv").exists()


def test_the_stress_tables_errors_are_the_batches_scatter():
    """Four batches whose every cell reads mu = 0.40, 0.42, 0.44, 0.46 and p = 1, 2, 3, 4 kPa:
    the median mu's error is sd(0.40 .. 0.46) / 2 = 0.012910, the median p's 645.50 Pa, the
    share at or above mu_s = 0.43 (batches 0, 0, 1, 1) sd / 2 = 0.28868, and each phase's
    thirds the median mu's; a batch's empty cells are left out (half of batch 0's cells
    empty: the same); one batch gives none."""
    from vibroflow.analysis.stress_state import batch_errors

    n = 60
    m = np.array([0.40, 0.42, 0.44, 0.46])
    bm = np.repeat(m[:, None], n, axis=1)
    bm[0, ::2] = np.nan
    pts = {"mu": bm[1], "pressure": np.full(n, 2.0e3), "z": np.tile([0.01, 0.05, 0.09], n // 3),
           "phase": np.repeat([0, 1], n // 2), "batch_mu": bm,
           "batch_pressure": np.repeat(1.0e3 * np.arange(1, 5)[:, None], n, axis=1)}
    se = batch_errors(pts, 0.43)
    want = np.std(m, ddof=1) / 2.0
    assert se["median_mu"] == pytest.approx(want, rel=1e-9)
    assert se["median_pressure"] == pytest.approx(np.std([1e3, 2e3, 3e3, 4e3], ddof=1) / 2,
                                                  rel=1e-12)
    assert se["share"] == pytest.approx(np.std([0, 0, 1, 1], ddof=1) / 2, rel=1e-12)
    assert set(se["thirds"]) == {0, 1}
    for lo, hi in se["thirds"].values():
        assert (lo, hi) == (pytest.approx(want, rel=1e-9), pytest.approx(want, rel=1e-9))
    assert batch_errors({**pts, "batch_mu": bm[:1], "batch_pressure": bm[:1]}, 0.43) is None
    assert batch_errors({k: v for k, v in pts.items() if not k.startswith("batch")}, 0.43) is None


def test_the_dems_batches_go_into_fields_nc_and_back_onto_the_same_cells(tmp_path):
    """Phase fields of 2 phases on a 3 x 2 grid, every cell dense and sheared but one (dilute),
    with four batches whose friction is 0.3, 0.4, 0.5, 0.6 everywhere: with_batch_fields puts
    them in the phase-resolved group as friction_coefficient_batches (batch, phase, x, z),
    fields.nc holds them, and dem_points gives each batch's friction at the same dense cells
    as the pooled points; one batch adds nothing."""
    import xarray as xr

    from vibroflow.analysis.stress_state import dem_points
    from vibroflow.calibration.run_fields import read_fields, with_batch_fields, write_fields

    P, nx, nz, nb = 2, 3, 2, 4
    shape = (P, nx, nz)
    dims = ("phase", "x", "z")
    phi = np.full(shape, 0.58)
    phi[1, 2, 1] = 0.2
    ph = xr.Dataset({"friction_coefficient": (dims, np.full(shape, 0.45)),
                     "inertial_number": (dims, np.full(shape, 0.01)),
                     "pressure": (dims, np.full(shape, 2.0e3), {"units": "Pa"}),
                     "shear_rate": (dims, np.full(shape, 2.0)),
                     "shear_rate_stderr": (dims, np.full(shape, 0.1)),
                     "solid_fraction": (dims, phi)},
                    coords={"phase": np.arange(P) * np.pi, "x": np.arange(nx) * 0.005,
                            "z": np.arange(nz) * 0.005})
    mu_b = np.array([0.3, 0.4, 0.5, 0.6])
    batches = {"friction_coefficient": mu_b[:, None, None, None] * np.ones((nb,) + shape),
               "pressure": 1.0e3 * np.arange(1, nb + 1)[:, None, None, None]
               * np.ones((nb,) + shape)}
    full = with_batch_fields(ph, batches)
    assert full["friction_coefficient_batches"].dims == ("batch",) + dims
    assert full["pressure_batches"].attrs["units"] == "Pa"
    avg = xr.Dataset({"solid_fraction": (("x", "z"), np.full((nx, nz), 0.58))},
                     coords={"x": ph["x"].values, "z": ph["z"].values})
    write_fields(tmp_path / "fields.nc", avg, full)
    pts = dem_points(read_fields(tmp_path / "fields.nc", phase_resolved=True))
    n = P * nx * nz - 1
    assert pts["mu"].size == n and pts["batch_mu"].shape == (nb, n)
    assert pts["batch_mu"] == pytest.approx(np.repeat(mu_b[:, None], n, axis=1), rel=1e-15)
    assert pts["batch_pressure"][:, 0] == pytest.approx([1e3, 2e3, 3e3, 4e3], rel=1e-15)
    one = with_batch_fields(ph, {k: v[:1] for k, v in batches.items()})
    assert "friction_coefficient_batches" not in one
