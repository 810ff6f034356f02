"""The partitions' friction and the bed's take-off (docs/validation.md section 22, "Why the
tub's bed stays on the floor"): a stiff layer in a slot takes off as a block whatever the
partitions' friction; the partitions' friction along the mean flow (calibration.wall_friction)
against hand values; the option that takes it (ContinuumOptions.partition_friction)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from continuum_helpers import shaken_mpm_layer

from vibroflow.calibration.wall_friction import along_flow, cell_mean_velocity
from vibroflow.continuum.boundary import PartitionFriction
from vibroflow.continuum.material import boundary_friction
from vibroflow.continuum.options import ContinuumOptions, options_record
from vibroflow.errors import InputError
from vibroflow.io.calibration_file import read_calibration
from vibroflow.scenario.io import load_scenario

CALIBRATION = "tests/data/tub47-quick-dem/calibration.toml"


def _shaken_slot(gamma, mu_p, spacing=0.01905):
    """continuum_helpers.shaken_mpm_layer in a slot of width `spacing` (m) whose partitions'
    friction is mu_p: the phases, the floor's normal force (N/m) and the partitions'
    compressed volume sum(p V) (N) at every step of the first cycle, and the layer's weight
    (N/m)."""
    phase, force, pv = [], [], []
    for ph, state, floor in shaken_mpm_layer(gamma, walls=[PartitionFriction(mu_p, spacing)]):
        phase.append(ph)
        force.append(state.history[floor.slot]["fn"].sum())
        p = -(state.stress[:, 0] + state.stress[:, 1] + state.stress[:, 3]) / 3.0
        pv.append((np.maximum(p, 0.0) * state.volume).sum())
    return np.array(phase), np.array(force), np.array(pv), 9.81 * state.mass.sum()


def test_a_stiff_layer_in_a_slot_takes_off_as_a_block_whatever_the_partitions_friction():
    # a block moving with its floor does not slip on the partitions and one in flight carries
    # no stress, so the partitions' friction -2 mu_p p / L_y along -v adds nothing to either:
    # the layer leaves the floor where the floor's acceleration falls to -g, at
    # asin(1 / gamma) / (2 pi) = 0.1161 for gamma = 1.5 (Mehta & Luck 1990), with the tub47-
    # quick slot's spacing and a friction three times the calibrated one, as without it; in
    # flight the partitions' pressure sum(p V) is under 1e-3 of its value at rest
    gamma = 1.5
    leave = math.asin(1.0 / gamma) / (2.0 * math.pi)
    for mu_p in (0.0, 0.45):
        phase, force, pv, weight = _shaken_slot(gamma, mu_p)
        assert force[0] == pytest.approx(weight, rel=0.1)
        first_free = phase[np.argmax(force <= 0.0)]
        assert first_free == pytest.approx(leave, abs=0.02)
        flight = (phase > first_free + 0.05) & (phase < 0.5)
        assert flight.any() and np.all(force[flight] == 0.0)
        assert pv[flight].max() < 1e-3 * pv[0]


def test_the_friction_along_the_flow_against_hand_values():
    # a tangential force against the flow counts whole, one across it nothing, one along it
    # negatively; at rest nothing
    assert along_flow(-0.15, 0.0, 2.0, 0.0) == pytest.approx(0.15, abs=1e-15)
    assert along_flow(0.0, -0.15, 0.0, 0.3) == pytest.approx(0.15, abs=1e-15)
    assert along_flow(0.0, 0.15, 2.0, 0.0) == pytest.approx(0.0, abs=1e-15)
    assert along_flow(0.1, 0.0, 1.0, 0.0) == pytest.approx(-0.1, abs=1e-15)
    assert along_flow(0.1, 0.2, 0.0, 0.0) == 0.0
    # two contacts of F_n = 1 N at the Coulomb limit 0.15, each slipping at 60 degrees to the
    # mean flow (its fluctuation): their ratio of sums is 0.15, the mean flow feels
    # 0.15 cos 60 = 0.075
    a = np.radians([60.0, -60.0])
    ft_x, ft_z = -0.15 * np.cos(a), -0.15 * np.sin(a)
    along = along_flow(ft_x, ft_z, np.full(2, 0.4), np.zeros(2))
    assert along.sum() / 2.0 == pytest.approx(0.075, rel=1e-12)
    assert np.hypot(ft_x, ft_z).sum() / 2.0 == pytest.approx(0.15, rel=1e-12)


def test_each_ball_takes_its_cells_mean_velocity():
    # cells of 15 mm centred on multiples of 15 mm: x = 0.007 and -0.007 share the cell at 0,
    # x = 0.008 is in the next one
    ux, uz = cell_mean_velocity([0.007, -0.007, 0.008], [0.0, 0.0, 0.0], [1.0, 3.0, 5.0],
                                [0.0, 2.0, -1.0], 0.015)
    assert ux.tolist() == [2.0, 2.0, 5.0]
    assert uz.tolist() == [1.0, 1.0, -1.0]


def test_the_choice_options_take_the_command_lines_hyphens():
    """along-flow and unloading-law (the command line's spelling) are along_flow and
    unloading_law, in a study's --set as in `vibroflow continuum`."""
    from vibroflow.continuum.options import ContinuumOptions
    from vibroflow.study.methods import method
    from vibroflow.study.pipeline import split_settings

    o = ContinuumOptions(transfer_cfl=None, partition_friction="along-flow",
                         moduli="unloading-law")
    assert (o.partition_friction, o.moduli) == ("along_flow", "unloading_law")
    _, settings = split_settings(["lagrangian.partition_friction=along-flow"])
    assert method("lagrangian").make_options(settings["lagrangian"]).partition_friction == \
        "along_flow"


def test_the_partition_friction_option_takes_the_calibrations_friction_along_the_flow():
    s = load_scenario("tub47-quick")
    cal = read_calibration(CALIBRATION)
    _, mu_w, mu_p = boundary_friction(s, cal)
    assert mu_p == cal.partitions.friction
    _, mu_w2, mu_flow = boundary_friction(s, cal, "along_flow")
    assert mu_flow == cal.partitions.friction_along_flow and mu_w2 == mu_w
    with pytest.raises(InputError, match="friction_along_flow"):
        boundary_friction(s, None, "along_flow")
    with pytest.raises(InputError, match="partition_friction = 'sideways'"):
        ContinuumOptions(transfer_cfl=None, partition_friction="sideways")
    # at its default the option is no part of a run's record (its fingerprint)
    assert "partition_friction" not in options_record(ContinuumOptions(transfer_cfl=None))
    assert options_record(ContinuumOptions(transfer_cfl=None, partition_friction="along_flow")
                          )["partition_friction"] == "along_flow"
