"""The standard errors of fields.nc's cycle-mean shear rate and temperature
(calibration.run_fields.add_cycle_mean_errors) and of the report's DEM shear rate in a probe's
cell (report.data.StudyData.dem_shear_rate_at): the delete-one-batch jackknife, which for a
mean over the batches is the batch-means standard error (known answers worked by hand)."""
import math
from types import SimpleNamespace

import numpy as np
import pytest
import xarray as xr

from vibroflow.calibration.run_fields import add_cycle_mean_errors
from vibroflow.report.data import StudyData


def _left_out(per_batch: np.ndarray) -> np.ndarray:
    """(nb, ...) per-batch arrays -> each batch's left-out mean over the others."""
    nb = per_batch.shape[0]
    return (per_batch.sum(axis=0)[None] - per_batch) / (nb - 1)


def _fields(shear_b, temp_b, sf):
    """The time averages and the left-out phase fields of batches whose phase fields are shear_b
    and temp_b (nb, phases, x, z), all batches at solid fraction sf (phases, x, z)."""
    nb, n_ph, nx, nz = shear_b.shape
    coords = {"x": np.arange(nx) * 0.005, "z": np.arange(nz) * 0.005}
    avg = xr.Dataset({"shear_rate_cycle_mean": (("x", "z"), np.zeros((nx, nz)),
                                                {"units": "s-1"}),
                      "temperature_cycle_mean": (("x", "z"), np.zeros((nx, nz)),
                                                 {"units": "m2 s-2"})}, coords=coords)
    dims = ("batch", "phase", "x", "z")
    loo = xr.Dataset({"shear_rate": (dims, _left_out(shear_b)),
                      "temperature": (dims, _left_out(temp_b)),
                      "solid_fraction": (dims, np.repeat(sf[None], nb, axis=0))},
                     coords={"batch": np.arange(nb), "phase": np.arange(n_ph), **coords})
    return avg, loo


def test_the_jackknife_of_a_cycle_mean_is_its_batch_means_error():
    """Batch b's phase fields at one solid fraction per phase: the cycle mean is linear in the
    batch, so the jackknife is the batch means' standard error sd(c_b) / sqrt(nb), c_b each
    batch's own solid-fraction-weighted cycle mean."""
    rng = np.random.default_rng(3)
    nb, n_ph, nx, nz = 6, 4, 3, 2
    shear_b = rng.uniform(0.5, 9.0, (nb, n_ph, nx, nz))
    temp_b = rng.uniform(1e-3, 1e-2, (nb, n_ph, nx, nz))
    sf = rng.uniform(0.2, 0.6, (n_ph, nx, nz))
    avg, loo = _fields(shear_b, temp_b, sf)
    add_cycle_mean_errors(avg, loo)
    for name, per_batch in (("shear_rate", shear_b), ("temperature", temp_b)):
        c_b = (per_batch * sf[None]).sum(axis=1) / sf.sum(axis=0)[None]
        expect = c_b.std(axis=0, ddof=1) / np.sqrt(nb)
        np.testing.assert_allclose(avg[name + "_cycle_mean_stderr"].values, expect, rtol=1e-10)
        assert avg[name + "_cycle_mean_leave_one_out"].dims == ("batch", "x", "z")
    assert avg["shear_rate_cycle_mean_stderr"].attrs["units"] == "s-1"
    assert avg["temperature_cycle_mean_stderr"].attrs["units"] == "m2 s-2"


def test_by_hand_four_batches_and_a_point_one_batch_missed():
    """One phase, batches 1, 2, 3, 4 1/s: the error is sd / 2 = sqrt(5/3) / 2 = 0.6455 1/s; a
    point where one left-out field is empty has no error."""
    shear_b = np.array([1.0, 2.0, 3.0, 4.0]).reshape(4, 1, 1, 1) * np.ones((4, 1, 2, 1))
    sf = np.full((1, 2, 1), 0.5)
    avg, loo = _fields(shear_b, shear_b * 1e-3, sf)
    loo["shear_rate"][2, 0, 1, 0] = np.nan
    loo["solid_fraction"][2, 0, 1, 0] = 0.0
    add_cycle_mean_errors(avg, loo)
    se = avg["shear_rate_cycle_mean_stderr"].values
    assert se[0, 0] == pytest.approx(np.sqrt(5.0 / 3.0) / 2.0, rel=1e-12)
    assert np.isnan(se[1, 0])


def test_without_batches_nothing_is_added():
    avg = xr.Dataset({"shear_rate_cycle_mean": (("x", "z"), np.zeros((2, 2)))})
    add_cycle_mean_errors(avg, None)
    assert list(avg.data_vars) == ["shear_rate_cycle_mean"]


def _study(ds):
    return SimpleNamespace(dem_fields=ds,
                           scenario=SimpleNamespace(analysis=SimpleNamespace(cell_size=0.015)))


def test_a_probe_cells_shear_rate_and_its_error_by_hand():
    """The 15 mm cell centred at (0, 15 mm) holds the 5 mm grid's x -5, 0, 5 mm and z 10, 15,
    20 mm.  Its value is the density-weighted mean of the map there; with each left-out map
    constant (1, 2, 3, 4 1/s) in the cell, its error is the jackknife's
    sqrt(3/4 * sum (theta_b - 2.5)^2) = sqrt(15/4) 1/s (batches 3 times as far apart as their
    left-out means, sd sqrt(15) / 2 over sqrt(4))."""
    x = np.arange(-4, 5) * 0.005
    z = np.arange(0, 7) * 0.005
    X, Z = np.meshgrid(x, z, indexing="ij")
    shear = 100.0 * X + 1000.0 * Z                    # 1/s, a plane
    density = np.where(X > 0.001, 3.0, 1.0) * 4000.0  # kg/m^3: the right column weighs 3 x
    loo = np.array([1.0, 2.0, 3.0, 4.0])[:, None, None] * np.ones((4,) + X.shape)
    ds = xr.Dataset({"shear_rate_cycle_mean": (("x", "z"), shear),
                     "density": (("x", "z"), density),
                     "shear_rate_cycle_mean_leave_one_out": (("batch", "x", "z"), loo)},
                    coords={"x": x, "z": z, "batch": np.arange(4)})
    value, se = StudyData.dem_shear_rate_at(_study(ds), 0.001, 0.016)
    # x weights 1, 1, 3 over -5, 0, 5 mm: mean x 2 mm; z mean 15 mm
    assert value == pytest.approx(100.0 * 0.002 + 1000.0 * 0.015, rel=1e-12)
    assert se == pytest.approx(np.sqrt(15.0 / 4.0), rel=1e-12)
    # a fields.nc without the left-out maps: the value, no error
    value2, se2 = StudyData.dem_shear_rate_at(
        _study(ds.drop_vars("shear_rate_cycle_mean_leave_one_out")), 0.001, 0.016)
    assert value2 == value and np.isnan(se2)


def test_a_continuums_inferred_impact_speed_carries_its_shear_rates_and_its_relations_error():
    """v = c0 + c1 d gamma_dot: its error from the run's shear rate is |c1| d se(gamma_dot),
    from the relation sqrt(se0^2 + (d gamma_dot)^2 se1^2 + 2 d gamma_dot cov), independent:
    c0 = 0.05 +- 0.01 m/s, c1 = 0.8 +- 0.1, cov -5e-4 m/s, d = 6.35 mm, gamma_dot 4 +- 0.5
    1/s: v = 0.07032 m/s, run 0.00254, relation sqrt(8.10516e-5), together 0.0093543 m/s; a
    probe without the run's error gets none."""
    from vibroflow.report.figures import inferred_impact_speed_errors, inferred_impact_speeds

    probes = {"P1": {"shear_rate_1_s": 4.0, "shear_rate_1_s_stderr": 0.5},
              "P2": {"shear_rate_1_s": 2.0, "shear_rate_1_s_stderr": None}}
    data = SimpleNamespace(
        impact_fit=lambda kind: {"c0": 0.05, "c1": 0.8, "c0_stderr": 0.01, "c1_stderr": 0.1,
                                 "covariance": -5e-4},
        diameter=0.00635, continuum_block=lambda name: {"probes": probes})
    assert inferred_impact_speeds(data, "lagrangian")["P1"] == pytest.approx(0.07032)
    errors = inferred_impact_speed_errors(data, "lagrangian")
    assert errors == {"P1": pytest.approx(math.sqrt(0.00254**2 + 8.10516e-5), rel=1e-9)}
    assert errors["P1"] == pytest.approx(0.0093543, rel=1e-4)
