"""Kinetic theory's constants from the DEM: phi_rcp of g0 recovered from synthetic cells made by
Lun et al.'s pressure with a known phi_rcp; the walls' energy flux of synthetic contacts equals
sum F . v / (snapshots x area); [kinetic] in calibration.toml round-trips byte for byte."""
from __future__ import annotations

import math
import tomllib
from pathlib import Path

import numpy as np
import pytest

from vibroflow.calibration.kinetic import (fit_lun_frictional, fit_phi_rcp, frictional_pressure,
                                          kinetic_table, pressure_ratio)
from vibroflow.calibration.wall_energy import wall_flux_of_contacts
from vibroflow.continuum.kinetic_theory import KineticParameters
from vibroflow.continuum.temperature_field import calibrated_kinetic_parameters
from vibroflow.dem.walls import WALL_PARTITION_LO, WALL_U
from vibroflow.errors import InputError
from vibroflow.io.calibration_file import Calibration, read_calibration, write_calibration

DATA = Path(__file__).parent / "data"
RHO_S = 7800.0
E = 0.85


def _cells(phi_rcp, n=400, rel_p=0.0, rel_T=0.0, seed=1, form="chialvo_sundaresan"):
    """Cells with p = rho_s phi T (1 + 2 (1 + e) phi g0) exactly, then p and T each scattered
    log-normally by rel_p, rel_T (their batch-means errors)."""
    rng = np.random.default_rng(seed)
    phi = rng.uniform(0.1, 0.56, n)
    T = np.exp(rng.uniform(np.log(1e-4), np.log(2e-2), n))
    p = RHO_S * phi * T * pressure_ratio(phi, phi_rcp, E, form)
    p = p * np.exp(rel_p * rng.standard_normal(n))
    T = T * np.exp(rel_T * rng.standard_normal(n))
    return phi, T, p, np.full(n, 1e-4) * phi, np.full(n, rel_T) * T, np.full(n, rel_p) * p


def test_lun_pressure_ratio_is_the_ideal_gas_dilute_and_carnahan_starling_in_between():
    # phi -> 0: p = rho_s phi T; far from phi_rcp, g0 -> Carnahan-Starling (Lun's dilute slope)
    assert pressure_ratio([1e-9], 0.6, E)[0] == pytest.approx(1.0, abs=1e-8)
    phi = 0.2
    g_cs = (2 - phi) / (2 * (1 - phi) ** 3) + 1.1596 * phi**2 / (0.6 - phi) ** 1.5
    assert pressure_ratio([phi], 0.6, E)[0] == pytest.approx(1 + 2 * (1 + E) * phi * g_cs,
                                                             rel=1e-12)


@pytest.mark.parametrize("form", ["chialvo_sundaresan", "lun_savage"])
def test_phi_rcp_of_exact_cells_is_recovered_within_one_percent(form):
    phi, T, p, *_ = _cells(0.60, form=form)
    fit = fit_phi_rcp(phi, T, p, RHO_S, E, g0_form=form)
    assert fit["phi_rcp"] == pytest.approx(0.60, rel=1e-3)
    assert fit["rms_log_residual"] < 1e-6 and fit["status"] == "measured"
    assert fit["points"] == phi.size


def test_phi_rcp_of_noisy_cells_is_within_its_standard_error_and_the_error_is_honest():
    truth = 0.60
    est, se, chi2 = [], [], []
    for seed in range(40):
        phi, T, p, sphi, sT, sp = _cells(truth, n=300, rel_p=0.1, rel_T=0.05, seed=seed)
        fit = fit_phi_rcp(phi, T, p, RHO_S, E, sphi, sT, sp)
        est.append(fit["phi_rcp"]), se.append(fit["phi_rcp_stderr"])
        chi2.append(fit["chi2_per_dof"])
    est, se = np.array(est), np.array(se)
    # one fit: within two of its standard errors (95 %); the ensemble: 68 % within one, the
    # spread of the estimates the standard error, chi^2 per dof 1 (the weights are the errors)
    assert abs(est[0] - truth) < 2 * se[0]
    assert np.mean(np.abs(est - truth) < se) > 0.5
    assert np.std(est, ddof=1) == pytest.approx(np.mean(se), rel=0.3)
    assert abs(np.mean(est) - truth) < 3 * np.std(est, ddof=1) / np.sqrt(est.size)
    assert np.mean(chi2) == pytest.approx(1.0, rel=0.1)


def test_cells_outside_the_range_or_too_uncertain_are_left_out():
    phi, T, p, sphi, sT, sp = _cells(0.60, n=200)
    sp = np.full(phi.size, 0.02) * p
    sT = np.full(phi.size, 0.02) * T
    sp[:50] = 10.0 * p[:50]          # log error 10: not enough samples
    phi2 = phi.copy()
    phi2[50:60] = 0.05               # dilute cells outside [0.1, 0.6]
    fit = fit_phi_rcp(phi2, T, p, RHO_S, E, sphi, sT, sp)
    assert fit["points"] == 140
    assert fit["phi_rcp"] == pytest.approx(0.60, rel=1e-3)


@pytest.mark.parametrize("kwargs, message", [
    (dict(restitution=1.5), "restitution = 1.5: must be in (0, 1]"),
    (dict(phi_range=(0.5, 0.2)), "phi_range = (0.5, 0.2): must be (lo, hi)"),
    (dict(g0_form="ma"), "g0_form = 'ma': must be one of"),
    (dict(rho_s=-1.0), "rho_s = -1.0: must be > 0"),
    (dict(phi_range=(0.58, 0.6)), "cells = 0: the phi_rcp fit needs at least 3 cells"),
])
def test_bad_fit_input_is_one_line(kwargs, message):
    phi, T, p, *_ = _cells(0.60, n=20)
    args = dict(rho_s=RHO_S, restitution=E) | kwargs
    with pytest.raises(InputError) as err:
        fit_phi_rcp(phi, T, p, **args)
    assert message in str(err.value) and "\n" not in str(err.value)
    with pytest.raises(InputError, match="must have one per cell"):
        fit_phi_rcp(phi, T[:-1], p, RHO_S, E)


# ----------------------------------------------------------------------------------------------

def _contacts(n_batches=4, n_phases=2, per_batch=3):
    """Snapshots (batch b, phase k) each with two U contacts in arc bin 0 (F.v = 2 W, and
    F.(v - V) = 1.5 W), one in arc bin 1 (F.v = -0.5 W) and one on a partition (F.v = 3 W)."""
    snaps = [(b, k) for b in range(n_batches) for _ in range(per_batch) for k in range(n_phases)]
    sb = np.array([b for b, _ in snaps] + [-1])       # one snapshot outside the window
    sph = np.array([k for _, k in snaps] + [0])
    F, v, V, arc, wall, snap = [], [], [], [], [], []
    for s in range(sb.size):
        for f, vel, mv, a, w in (((0, 0, 10.0), (0, 0, 0.2), (0, 0, 0.05), -0.01, WALL_U),
                                 ((0, 0, 10.0), (0, 0, 0.2), (0, 0, 0.05), -0.02, WALL_U),
                                 ((1.0, 0, 0), (-0.5, 0, 0), (0, 0, 0), 0.01, WALL_U),
                                 ((0, 20.0, 0), (0, 0.15, 0), (0, 0, 0), np.nan,
                                  WALL_PARTITION_LO)):
            F.append(f), v.append(vel), V.append(mv), arc.append(a), wall.append(w)
            snap.append(s)
    return dict(force=np.array(F), velocity=np.array(v), snapshot=np.array(snap),
                arc=np.array(arc), wall=np.array(wall), snapshot_phase=sph, snapshot_batch=sb,
                n_phases=n_phases, n_batches=n_batches), np.array(V)


def test_wall_power_of_known_contacts_is_sum_f_dot_v_over_snapshots_and_area():
    args, V = _contacts()
    L, A_p, edges = 0.2, 0.03, np.array([-0.03, 0.0, 0.03])
    out = wall_flux_of_contacts(**args, arc_edges=edges, length=L, partition_area=A_p,
                                mean_velocity=V, wall_velocity=args["velocity"])
    u, p = out["u"], out["partitions"]
    area = 0.03 * L
    # every used snapshot holds the same contacts: the flux of each bin is its contacts' power
    # over the bin's area, the same at every phase and in every batch (error 0)
    np.testing.assert_allclose(u["power"]["arc"], [4.0 / area, -0.5 / area], rtol=1e-12)
    np.testing.assert_allclose(u["fluctuation_power"]["arc"], [3.0 / area, -0.5 / area],
                               rtol=1e-12)
    np.testing.assert_allclose(u["power"]["phase_arc"], [[4 / area, -0.5 / area]] * 2,
                               rtol=1e-12)
    np.testing.assert_allclose(u["power"]["phase"], [3.5 / (2 * area)] * 2, rtol=1e-12)
    assert u["power"]["mean"] == pytest.approx(3.5 / (2 * area), rel=1e-12)
    assert u["power"]["mean_stderr"] == pytest.approx(0.0, abs=1e-9)
    assert p["power"]["mean"] == pytest.approx(3.0 / A_p, rel=1e-12)
    # F . v_wall with v_wall = v: the drive power is the same sum
    assert u["drive_power"]["mean"] == pytest.approx(u["power"]["mean"], rel=1e-12)


def test_wall_power_errors_are_the_batch_means_errors():
    args, V = _contacts(n_batches=4, n_phases=1, per_batch=2)
    # scale the forces of batch b by (1 + b): batch fluxes q (1 + b), error std / sqrt(4)
    b = args["snapshot_batch"][args["snapshot"]]
    args["force"] = args["force"] * (1.0 + np.where(b >= 0, b, 0))[:, None]
    out = wall_flux_of_contacts(**args, arc_edges=[-0.03, 0.0, 0.03], length=0.2,
                                partition_area=0.03)
    q = 3.0 / 0.03 * (1.0 + np.arange(4))
    assert out["partitions"]["power"]["mean"] == pytest.approx(q.mean(), rel=1e-12)
    assert out["partitions"]["power"]["mean_stderr"] == pytest.approx(
        q.std(ddof=1) / 2.0, rel=1e-12)


def test_bad_wall_contacts_are_one_line():
    args, _ = _contacts()
    bad = dict(args, velocity=args["velocity"][:-1])
    with pytest.raises(InputError, match="must have one per contact"):
        wall_flux_of_contacts(**bad, arc_edges=[0, 1], length=0.2, partition_area=0.1)
    with pytest.raises(InputError, match="arc_edges = .*must be at least two increasing"):
        wall_flux_of_contacts(**args, arc_edges=[1, 0], length=0.2, partition_area=0.1)
    with pytest.raises(InputError, match="length = 0.0"):
        wall_flux_of_contacts(**args, arc_edges=[0, 1], length=0.0, partition_area=0.1)


# ----------------------------------------------------------------------------------------------

def _kinetic_tables():
    args, V = _contacts()
    flux = wall_flux_of_contacts(**args, arc_edges=[-0.03, 0.0, 0.03], length=0.2,
                                 partition_area=0.03, mean_velocity=V,
                                 wall_velocity=args["velocity"])
    flux.update(arc_edges_m=np.array([-0.03, 0.0, 0.03]), phase_rad=np.array([0.0, np.pi]),
                length_m=0.2, partition_area_m2=0.03)
    phi, T, p, *_ = _cells(0.6, n=50)
    return kinetic_table(fit_phi_rcp(phi, T, p, RHO_S, E), flux, E, "contact law")


@pytest.mark.parametrize("case", ["tub47-dem", "tub47-quick-dem"])
def test_calibration_round_trips_with_and_without_kinetic(case, tmp_path):
    src = DATA / case / "calibration.toml"
    plain = read_calibration(src)
    assert plain.kinetic is None
    write_calibration(tmp_path / "a.toml", plain)
    write_calibration(tmp_path / "b.toml", read_calibration(tmp_path / "a.toml"))
    assert (tmp_path / "a.toml").read_bytes() == (tmp_path / "b.toml").read_bytes()
    tables = {**tomllib.loads(src.read_text()), "kinetic": _kinetic_tables()}
    rec = Calibration.from_dict(tables)
    assert rec.kinetic.phi_rcp == pytest.approx(0.6, rel=1e-3)
    assert rec.kinetic.restitution == E
    assert len(rec.kinetic.wall_flux.u_fluctuation_flux_by_phase_arc_W_m2) == 2
    write_calibration(tmp_path / "k.toml", rec)
    again = read_calibration(tmp_path / "k.toml")
    write_calibration(tmp_path / "k2.toml", again)
    assert (tmp_path / "k.toml").read_bytes() == (tmp_path / "k2.toml").read_bytes()
    # the existing tables keep their values and order; [kinetic] comes after them
    assert list(again.to_toml_dict())[:-1] == list(plain.to_toml_dict())
    assert again.rheology == plain.rheology


def test_a_bad_kinetic_table_is_one_line():
    tables = {**tomllib.loads((DATA / "tub47-dem" / "calibration.toml").read_text()),
              "kinetic": {"phi_rcp": "high"}}
    with pytest.raises(InputError, match=r"kinetic\.phi_rcp = 'high': must be a number"):
        Calibration.from_dict(tables)


def test_cells_that_lun_does_not_describe_put_phi_rcp_at_the_bound():
    # an ideal gas at every solid fraction: no collisional pressure, phi_rcp -> close packing
    rng = np.random.default_rng(3)
    phi = rng.uniform(0.1, 0.5, 100)
    T = np.full(100, 1e-3)
    fit = fit_phi_rcp(phi, T, RHO_S * phi * T, RHO_S, E)
    assert fit["status"].startswith("at the bound")


def test_cells_scattered_far_about_the_closure_say_so_in_the_status():
    phi, T, p, *_ = _cells(0.60, n=400, rel_p=1.0)
    fit = fit_phi_rcp(phi, T, p, RHO_S, E)
    assert fit["rms_log_residual"] == pytest.approx(1.0, rel=0.1)
    assert "the closure does not describe them" in fit["status"]
    assert "scatter" not in fit_phi_rcp(*_cells(0.60, n=400, rel_p=0.1)[:3], RHO_S, E)["status"]


def _frictional_cells(n=400, rel_p=0.05, seed=3):
    """Cells with Lun's plus Johnson & Jackson's pressure (phi_rcp 0.63, Fr 0.02 Pa, phi_min
    0.5, n = 2, p = 5), p scattered log-normally by rel_p."""
    rng = np.random.default_rng(seed)
    phi = rng.uniform(0.1, 0.6, n)
    T = np.exp(rng.uniform(np.log(1e-4), np.log(2e-2), n))
    p = RHO_S * phi * T * pressure_ratio(phi, 0.63, E) + frictional_pressure(phi, 0.63, 0.02, 0.5)
    return phi, T, p * np.exp(rel_p * rng.standard_normal(n))


def test_the_joint_fit_recovers_known_frictional_constants():
    phi, T, p = _frictional_cells()
    fit = fit_lun_frictional(phi, T, p, RHO_S, E)
    for key, true in (("phi_rcp", 0.63), ("frictional_Pa", 0.02), ("frictional_phi_min", 0.5)):
        assert abs(fit[key] - true) < 3.0 * fit[key + "_stderr"], key
    assert fit["phi_rcp"] == pytest.approx(0.63, abs=2e-3)
    assert fit["frictional_Pa"] == pytest.approx(0.02, rel=0.2)
    assert fit["frictional_phi_min"] == pytest.approx(0.5, abs=0.01)
    # the scatter is the cells' own 5 %; Lun's pressure alone cannot follow the frictional part
    assert fit["rms_log_residual"] == pytest.approx(0.05, rel=0.15)
    assert fit["lun_rms_log_residual"] > 2.0 * fit["rms_log_residual"]
    table = kinetic_table(fit, None, E, "contact law")
    assert table["frictional_Pa"] == fit["frictional_Pa"] and "Johnson" in table["model"]


def test_cells_without_a_frictional_pressure_give_luns_fit_and_say_so():
    phi, T, p, *_ = _cells(0.60, n=200, rel_p=0.05)
    fit = fit_lun_frictional(phi, T, p, RHO_S, E)
    lun = fit_phi_rcp(phi, T, p, RHO_S, E)
    assert fit["frictional_Pa"] == 0.0 and math.isnan(fit["frictional_phi_min"])
    assert fit["phi_rcp"] == lun["phi_rcp"] and fit["phi_rcp_stderr"] > 0
    assert "no frictional pressure" in fit["status"]


def test_a_run_reads_the_calibrated_kinetic_constants():
    src = DATA / "tub47-quick-dem" / "calibration.toml"
    plain = read_calibration(src)
    prm = KineticParameters(restitution=E)
    assert calibrated_kinetic_parameters(prm, plain) == prm       # no [kinetic]: unchanged
    assert calibrated_kinetic_parameters(prm, None) == prm
    fit = fit_lun_frictional(*_frictional_cells(), RHO_S, E)
    rec = Calibration.from_dict({**tomllib.loads(src.read_text()),
                                 "kinetic": kinetic_table(fit, None, E, "contact law")})
    got = calibrated_kinetic_parameters(prm, rec)
    assert (got.phi_rcp, got.frictional_Pa, got.frictional_phi_min) == (
        fit["phi_rcp"], fit["frictional_Pa"], fit["frictional_phi_min"])
    assert (got.frictional_n, got.frictional_p, got.restitution) == (2.0, 5.0, E)
    # cells without a frictional pressure: phi_rcp only, Fr stays 0
    lun = fit_lun_frictional(*_cells(0.60, n=200, rel_p=0.05)[:3], RHO_S, E)
    rec = Calibration.from_dict({**tomllib.loads(src.read_text()),
                                 "kinetic": kinetic_table(lun, None, E, "contact law")})
    got = calibrated_kinetic_parameters(prm, rec)
    assert got.phi_rcp == lun["phi_rcp"] and got.frictional_Pa == 0.0


# The delete-one-batch jackknife (kinetic.jackknife_errors, measure.stats.jackknife_stderr)

def test_the_jackknife_of_the_batch_mean_is_the_batch_means_standard_error():
    from vibroflow.measure.stats import (jackknife_of_batches, jackknife_stderr,
                                         stderr_of_batches)

    b = np.random.default_rng(5).normal(3.0, 0.7, 9)
    left_out = [(b.sum() - x) / (b.size - 1) for x in b]
    assert jackknife_stderr(left_out) == pytest.approx(stderr_of_batches(b), rel=1e-12)
    # the same through the batches' left-out means, cell by cell; a key the statistic does not
    # return is a failed left-out value: NaN
    cells = np.stack([b, 2.0 * b], axis=1)
    se = jackknife_of_batches(lambda m: {"a": m[0], "b": m[1]}, [cells], ["a", "b", "c"])
    assert se["a"] == pytest.approx(stderr_of_batches(b), rel=1e-12)
    assert se["b"] == pytest.approx(2.0 * stderr_of_batches(b), rel=1e-12)
    assert math.isnan(se["c"])
    assert math.isnan(jackknife_stderr([1.0])) and math.isnan(jackknife_stderr([1.0, np.nan]))


def _batched_cells(seed, n_batches=8, n=300, tilt=0.6, rel=0.02):
    """Lun's cells (phi_rcp 0.60) seen through n_batches batches whose pressure shares a tilt
    a_b (phi - 0.35) across every cell of batch b, a ~ N(0, tilt), plus each cell's own scatter
    rel: the cells of one batch err together, as a chaotic bed's neighbouring cells do.  A
    Dataset of the batches' mean fields with their batch-means errors, and the batches."""
    import xarray as xr

    rng = np.random.default_rng(seed)
    phi = rng.uniform(0.1, 0.56, n)
    T = np.exp(rng.uniform(np.log(1e-4), np.log(2e-2), n))
    p0 = RHO_S * phi * T * pressure_ratio(phi, 0.60, E)
    a = tilt * rng.standard_normal((n_batches, 1))
    pb = p0 * np.exp(a * (phi - 0.35) + rel * rng.standard_normal((n_batches, n)))
    Tb, phib = np.broadcast_to(T, pb.shape).copy(), np.broadcast_to(phi, pb.shape).copy()
    se = lambda x: x.std(axis=0, ddof=1) / math.sqrt(n_batches)  # noqa: E731
    ds = xr.Dataset({k: ("cell", v) for k, v in (
        ("solid_fraction", phi), ("temperature", T), ("pressure", pb.mean(axis=0)),
        ("solid_fraction_stderr", 1e-4 * phi), ("temperature_stderr", 1e-3 * T),
        ("pressure_stderr", se(pb)))})
    return ds, {"solid_fraction": phib, "temperature": Tb, "pressure": pb}


def test_the_jackknife_error_is_the_spread_of_phi_rcp_over_draws_where_least_squares_is_not():
    from vibroflow.calibration.kinetic import fit_cells

    est, jack, lsq = [], [], []
    for seed in range(30):
        ds, batches = _batched_cells(seed)
        full = fit_cells(ds, RHO_S, E)
        fit = fit_cells(ds, RHO_S, E, batches=batches)
        assert fit["phi_rcp"] == full["phi_rcp"]  # the value is the fit on every batch
        assert fit["phi_rcp_stderr_least_squares"] == full["phi_rcp_stderr"]
        assert fit["stderr_method"] == "delete-one-batch jackknife over 8 batches"
        est.append(fit["phi_rcp"]), jack.append(fit["phi_rcp_stderr"])
        lsq.append(full["phi_rcp_stderr"])
    spread = np.std(est, ddof=1)
    # the jackknife follows the draws' spread (30 draws: its sd known to about 13 %, each
    # jackknife error to about a quarter), the per-cell covariance falls far short of it
    assert np.sqrt(np.mean(np.square(jack))) == pytest.approx(spread, rel=0.35)
    assert np.sqrt(np.mean(np.square(lsq))) < 0.5 * spread


def test_a_constant_the_cells_do_not_resolve_keeps_its_nan_error():
    from vibroflow.calibration.kinetic import fit_cells

    ds, batches = _batched_cells(0, n_batches=4)
    fit = fit_cells(ds, RHO_S, E, joint=True, batches=batches)
    assert fit["frictional_Pa"] == 0.0 and math.isnan(fit["frictional_Pa_stderr"])
    assert np.isfinite(fit["phi_rcp_stderr"]) and "jackknife over 4" in fit["stderr_method"]
