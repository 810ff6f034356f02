"""The U wall's feed and the take-off (vibroflow.continuum.wall_feed,
vibroflow.measure.floor_force; benchmarks/tub_wall_feed.py's measures) against hand values: a
wall cell's net feed (the run's balance's slip production, landing and collision loss, in W per
metre of thickness), its sum by region and phase, and the take-off phase of a force sampled at
the phases k / P."""
from __future__ import annotations

import math

import numpy as np
import pytest

from vibroflow.continuum.kinetic_theory import LUN_SAVAGE, KineticParameters
from vibroflow.continuum.temperature_field import TemperatureModel
from vibroflow.continuum.wall_energy_flux import WallEnergy
from vibroflow.continuum.wall_feed import cell_feed_W_m, feed_by_region
from vibroflow.measure.floor_force import (region_lengths, sampled_take_off, wall_feed_cycle,
                                           write_wall_feed_csv)

PRM = KineticParameters(diameter_m=0.00635, density_kg_m3=7800.0, restitution=0.9,
                        phi_rcp=0.64, g0_form=LUN_SAVAGE)


def test_a_wall_cells_feed_is_slip_production_plus_landing_less_the_loss():
    # one 1 cm cell at phi 0.5, T 0.01 m^2/s^2 touching the wall over 1 cm, slip 0.2 m/s,
    # e_w 0.8, the friction rule with a friction power above J&J's diffuse production:
    # production 2 x 125.76 W/m^2 x 0.01 m = 2.5152 W/m (test_wall_energy_flux.py's hand
    # value at phi' = 0.5, doubled), loss 33.956 W/m^2 x 0.01 m = 0.33956 W/m, landing
    # 0.2 W/m: 2.5152 + 0.2 - 0.33956 = 2.3756 W/m
    model = TemperatureModel(PRM, 0.01, 0.0, True, WallEnergy(restitution=0.8))
    sums = np.array([[[0.01, 0.01 * 0.04, 100.0, 0.2]]])
    feed = cell_feed_W_m(np.full((1, 1), 0.5), np.full((1, 1), 0.01), sums, 0.01, model)
    assert feed[0, 0] == pytest.approx(2.3756, rel=2e-4)
    # a friction power of 1 W/m caps the production: 1 + 0.2 - 0.33956
    sums[0, 0, 2] = 1.0
    feed = cell_feed_W_m(np.full((1, 1), 0.5), np.full((1, 1), 0.01), sums, 0.01, model)
    assert feed[0, 0] == pytest.approx(0.86044, rel=2e-4)


def test_the_take_off_is_read_at_the_sampled_phases():
    # force / weight sampled at k / 8: 1 at 0/8, 0.3 at 1/8, 0 at 2/8 .. 4/8, then 2: it falls
    # to 0.05 between 1/8 and 2/8, at 1/8 + (0.3 - 0.05) / 0.3 / 8 = 0.2292
    f = np.array([1.0, 0.3, 0.0, 0.0, 0.0, 2.0, 2.5, 1.5])
    assert sampled_take_off(f, 8) == pytest.approx(0.125 + 0.25 / 0.3 / 8, rel=1e-12)


def test_the_feed_is_summed_by_region_and_phase_over_the_regions_wall(tmp_path):
    R, H, f, per = 0.15, 0.4, 10.0, 4
    a = math.radians(45.0)
    # a floor cell 2 W/m, an arc cell 3 W/m, a side-wall cell -1 W/m
    x = np.array([[0.0, 0.002], [-R * math.sin(a), R - R * math.cos(a)], [R, 0.3]])
    row = feed_by_region(x, np.array([2.0, 3.0, -1.0]), R)
    np.testing.assert_allclose(row, [2.0, 3.0, -1.0])
    # four cycles of four phases, the feed on at phase 2/4 only, doubled in the last two
    # cycles: by phase 2/4 the floor's mean 3 W/m over its 0.15 pi / 3 m, its batch error
    # (2 batches: 2 and 4 W/m) 1 W/m over the same length
    t = np.arange(4 * per) / (f * per)
    on = (np.arange(4 * per) % per == 2) * np.where(np.arange(4 * per) < 2 * per, 1.0, 2.0)
    cyc = wall_feed_cycle(on[:, None] * row, t, 0.0, 0.4, f, per, 2, region_lengths(R, H))
    L = region_lengths(R, H)
    np.testing.assert_allclose(cyc.by_phase[2], 1.5 * row / L)
    np.testing.assert_allclose(cyc.by_phase_stderr[2], 0.5 * np.abs(row) / L)
    np.testing.assert_allclose(cyc.by_phase[[0, 1, 3]], 0.0)
    # the cycle mean: a quarter of the samples fed, 1.5 on average
    np.testing.assert_allclose(cyc.by_region, 1.5 * row / 4 / L)
    assert cyc.u_wall == pytest.approx(1.5 * row.sum() / 4 / L.sum())
    write_wall_feed_csv(tmp_path / "wall_feed.csv", cyc)
    lines = (tmp_path / "wall_feed.csv").read_text().splitlines()
    assert lines[0].startswith("phase,floor_W_m2,floor_W_m2_stderr,arcs_W_m2")
    assert float(lines[3].split(",")[1]) == pytest.approx(3.0 / L[0])


def test_the_dems_wall_flux_is_summed_into_the_regions_by_arc_length():
    from types import SimpleNamespace

    from vibroflow.measure.floor_force import dem_wall_feed

    # R 0.15 m: the floor to 0.0785 m of arc, the arcs to 0.2356 m. Bins centred at -0.275
    # (side wall), -0.175 (arc), -0.05, 0.05 (floor) and 0.2 m (arc)
    t = SimpleNamespace(
        arc_edges_m=[-0.3, -0.25, -0.1, 0.0, 0.1, 0.3],
        u_fluctuation_flux_by_arc_W_m2=[7.0, 10.0, 100.0, 200.0, 30.0],
        u_fluctuation_flux_by_arc_stderr_W_m2=[1.0, 3.0, 4.0, 4.0, 3.0],
        u_fluctuation_flux_by_phase_arc_W_m2=[[7.0, 10.0, 100.0, 200.0, 30.0],
                                              [0.0, 0.0, 0.0, 0.0, 0.0]],
        u_fluctuation_flux_by_phase_arc_stderr_W_m2=[[1.0] * 5, [0.0] * 5],
        u_fluctuation_flux_W_m2=50.0, u_fluctuation_flux_stderr_W_m2=2.0,
        u_fluctuation_flux_by_phase_W_m2=[100.0, 0.0])
    d = dem_wall_feed(t, 0.15)
    # floor (100 x 0.1 + 200 x 0.1) / 0.2 = 150; arcs (10 x 0.15 + 30 x 0.2) / 0.35 = 21.43;
    # side wall 7; errors in quadrature: floor sqrt(0.4^2 + 0.4^2) / 0.2 = 2.828
    np.testing.assert_allclose(d["by_region_W_m2"], [150.0, 7.5 / 0.35, 7.0])
    np.testing.assert_allclose(d["by_region_W_m2_stderr"][0], math.sqrt(0.32) / 0.2)
    np.testing.assert_allclose(d["by_phase_W_m2"][1], 0.0)
    assert d["u_wall_W_m2"] == 50.0
