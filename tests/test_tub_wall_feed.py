"""benchmarks/tub_wall_feed.py's measures against hand values: a wall cell's net feed (the
run's balance's slip production, landing and collision loss, in W per metre of thickness), the
U's arc regions, and the take-off phase of a force sampled at the phases k / P."""
from __future__ import annotations

import math

import numpy as np
import pytest

from vibroflow.continuum.kinetic_theory import LUN_SAVAGE, KineticParameters
from vibroflow.continuum.temperature_field import TemperatureModel
from vibroflow.continuum.wall_energy_flux import WallEnergy
from benchmark_module import load_benchmark

PRM = KineticParameters(diameter_m=0.00635, density_kg_m3=7800.0, restitution=0.9,
                        phi_rcp=0.64, g0_form=LUN_SAVAGE)


def test_a_wall_cells_feed_is_slip_production_plus_landing_less_the_loss():
    # one 1 cm cell at phi 0.5, T 0.01 m^2/s^2 touching the wall over 1 cm, slip 0.2 m/s,
    # e_w 0.8, the friction rule with a friction power above J&J's diffuse production:
    # production 2 x 125.76 W/m^2 x 0.01 m = 2.5152 W/m (test_wall_energy_flux.py's hand
    # value at phi' = 0.5, doubled), loss 33.956 W/m^2 x 0.01 m = 0.33956 W/m, landing
    # 0.2 W/m: 2.5152 + 0.2 - 0.33956 = 2.3756 W/m
    bench = load_benchmark("tub_wall_feed")
    model = TemperatureModel(PRM, 0.01, 0.0, True, WallEnergy(restitution=0.8))
    sums = np.array([[[0.01, 0.01 * 0.04, 100.0, 0.2]]])
    feed = bench.cell_feed_W_m(np.full((1, 1), 0.5), np.full((1, 1), 0.01), sums, 0.01, model)
    assert feed[0, 0] == pytest.approx(2.3756, rel=2e-4)
    # a friction power of 1 W/m caps the production: 1 + 0.2 - 0.33956
    sums[0, 0, 2] = 1.0
    feed = bench.cell_feed_W_m(np.full((1, 1), 0.5), np.full((1, 1), 0.01), sums, 0.01, model)
    assert feed[0, 0] == pytest.approx(0.86044, rel=2e-4)


def test_the_regions_split_the_u_and_the_take_off_is_read_at_the_sampled_phases():
    bench = load_benchmark("tub_wall_feed")
    R = 0.15
    s = np.array([0.0, R * math.radians(29.0), -R * math.radians(31.0), 0.5 * math.pi * R - 1e-6,
                  0.5 * math.pi * R + 0.01])
    assert bench.region_of(s, R).tolist() == [0, 0, 1, 1, 2]
    # both sides: 60 degrees of floor, 120 of arcs, two 0.25 m walls above z = R to 0.4 m
    np.testing.assert_allclose(bench.region_lengths(R, 0.4),
                               [R * math.pi / 3, 2 * R * math.pi / 3, 0.5])
    # force / weight sampled at k / 8: 1 at 0/8, 0.3 at 1/8, 0 at 2/8 .. 4/8, then 2: it falls
    # to 0.05 between 1/8 and 2/8, at 1/8 + (0.3 - 0.05) / 0.3 / 8 = 0.2292
    f = np.array([1.0, 0.3, 0.0, 0.0, 0.0, 2.0, 2.5, 1.5])
    assert bench.take_off(f, 8) == pytest.approx(0.125 + 0.25 / 0.3 / 8, rel=1e-12)
