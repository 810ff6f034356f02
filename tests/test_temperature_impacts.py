"""Impact speeds a continuum infers from its granular temperature
(vibroflow.continuum.temperature_impacts), against hand-computed values: a calibration that
prefers the temperature gives v = max(b0 + b1 sqrt(T), 0) at each analysis node,
solid-fraction weighted over the bed (ball-ball) and the near-wall nodes (ball-wall); one that
prefers the shear rate, or a run without T, leaves the impact keys as they were.
"""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from vibroflow.continuum.sampling import Samples
from vibroflow.continuum.temperature_impacts import impacts_from_temperature
from vibroflow.io.calibration_file import ImpactRelation
from vibroflow.measure.phase_shear import near_wall_nodes

H, NXH, NZ, R = 0.02, 5, 8, 0.09
B0, B1 = -0.06, 1.35


def _run(preferred="temperature", temperature=True):
    s = Samples(4, 0, 0, cell_grid=(H, NXH, NZ), temperature=temperature)
    x = np.arange(-NXH, NXH + 1) * H
    z = np.arange(NZ) * H
    X, Z = np.meshgrid(x, z)
    # hot above z = 0.07, cold below: the cold nodes' relation is negative and clipped to 0
    T = np.where(Z > 0.07, 0.01, 0.001)
    pts = np.stack([X.ravel(), Z.ravel()], axis=1)
    for j in range(4):
        s.add_temperatures(j, pts, np.ones(pts.shape[0]), T.ravel())
    phi = np.where(Z < 0.12, 0.55, 0.2)
    phase = SimpleNamespace(x=x, z=z, h=H, solid_fraction=phi)
    rel = ImpactRelation(b0_temperature_cells_m_s=B0, b1_temperature_cells=B1,
                         preferred_relation=preferred)
    cal = SimpleNamespace(impacts=SimpleNamespace(ball_ball=rel, ball_wall=rel))
    impacts = {"ball_ball_mean_normal_speed": 0.05, "ball_wall_mean_normal_speed": 0.2,
               "inferred_from_shear_rate": "v = c0 + c1 d gamma_dot"}
    out = impacts_from_temperature(cal, s, phase, R, np.array([0, 0, 1, 1]), 2, impacts)
    return out, impacts, T, phi, phase


def test_the_temperature_relation_node_by_node_and_weighted_by_solid_fraction():
    out, impacts, T, phi, phase = _run()
    v = np.maximum(B0 + B1 * np.sqrt(T), 0.0)
    bed = float(np.sum(phi * v) / np.sum(phi))
    near = near_wall_nodes(phase, R)
    assert near.any() and not near.all()
    wall = float(np.sum(phi[near] * v[near]) / np.sum(phi[near]))
    block = out["impacts_from_temperature"]
    assert block["ball_ball_mean_normal_speed_m_s"] == pytest.approx(bed, rel=1e-12)
    assert block["ball_wall_mean_normal_speed_m_s"] == pytest.approx(wall, rel=1e-12)
    assert impacts["ball_ball_mean_normal_speed"] == pytest.approx(bed, rel=1e-12)
    assert 0.0 < bed < B0 + B1 * math.sqrt(0.01)
    # every sample holds the same T: no scatter between the batches
    assert block["ball_ball_mean_normal_speed_m_s_stderr"] == 0.0
    assert "ball_ball, ball_wall" in impacts["inferred_from_temperature"]
    assert "inferred_from_shear_rate" not in impacts


@pytest.mark.parametrize("preferred,temperature", [("shear_rate", True),
                                                   ("temperature", False)])
def test_shear_rate_preferred_or_no_temperature_leaves_the_impacts(preferred, temperature):
    out, impacts, *_ = _run(preferred, temperature)
    assert out == {}
    assert impacts == {"ball_ball_mean_normal_speed": 0.05, "ball_wall_mean_normal_speed": 0.2,
                       "inferred_from_shear_rate": "v = c0 + c1 d gamma_dot"}
