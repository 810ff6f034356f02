"""The report's part sections (vibroflow.report.part_sections) on synthetic parts.nc files made
from the schema (vibroflow.io.parts_file): the DEM's measured speeds beside a continuum's
inferred ones with their difference and its error (hand computed), the force by phase as the
files hold it, the whole map's difference and the force's cycle mean (hand computed), a method without parts.nc said, none at all: no section; and the page of a
tiny study with them: one section per part, its name escaped, its figures drawn."""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from vibroflow.io.parts_file import MAX_PATCHES, empty_parts_dataset, write_parts
from vibroflow.report.part_sections import part_sections
from vibroflow.tub.parts import Part, patch_layout

SLICE_M = 0.019
BAR = Part(name="bar", shape="cylinder", center=(0.05, 0.0, 0.1), material="steel",
           radius=0.0125)


def synthetic_parts(method: str, name: str = "bar", speed: float = 0.2, seed: int = 0):
    """A parts.nc Dataset of one cylinder: speeds speed + 0.01 k on sector k (errors 0.01),
    the DEM's rates, medians, p95s and energy fluxes, force (phase, 0, -phase) N."""
    names, area = patch_layout(BAR, SLICE_M)
    ds = empty_parts_dataset([name], [names], [area], 4, method, 1.0, 5, "synthetic")
    n = len(names)
    ds["normal_speed_mean"].values[0, :n] = speed + 0.01 * np.arange(n)
    ds["normal_speed_mean_stderr"].values[0, :n] = 0.01
    if method == "dem":
        ds["impact_rate_per_area"].values[0, :n] = 1e4 * (1 + np.arange(n))
        ds["impact_rate_per_area_stderr"].values[0, :n] = 1e2
        ds["normal_speed_median"].values[0, :n] = 0.9 * (speed + 0.01 * np.arange(n))
        ds["normal_speed_p95"].values[0, :n] = 2.0 * (speed + 0.01 * np.arange(n))
        ds["energy_flux"].values[0, :n] = 3.0
        ds["energy_flux_stderr"].values[0, :n] = 0.3
    ds["force"].values[0, :, 0] = np.arange(4)
    ds["force"].values[0, :, 1] = 0.0
    ds["force"].values[0, :, 2] = -np.arange(4)
    ds["force_stderr"].values[0] = 0.1
    return ds


def test_part_section_sets_each_continuum_beside_the_dem(tmp_path):
    for method, speed in (("dem", 0.2), ("lagrangian", 0.25)):
        write_parts(tmp_path / method / "parts.nc", synthetic_parts(method, speed=speed))
    scenario = SimpleNamespace(parts=[SimpleNamespace(name="bar", shape="cylinder")])
    data = SimpleNamespace(methods=["dem", "lagrangian", "eulerian"], out=tmp_path,
                           scenario=scenario)
    sections, notes = part_sections(data)
    assert notes == ["eulerian: no parts.nc"]
    (s,) = sections
    assert s["name"] == "bar" and s["shape"] == "cylinder" and s["continua"] == ["lagrangian"]
    assert len(s["rows"]) == 36 < MAX_PATCHES + 1
    row = s["rows"][3]
    assert row["dem"] == pytest.approx((0.23, 0.01))
    assert row["lagrangian"] == pytest.approx((0.28, 0.01))
    assert row["lagrangian_diff"] == pytest.approx((0.05, math.sqrt(2) * 0.01))
    assert row["rate"] == pytest.approx((4e4, 1e2)) and row["p95"] == pytest.approx(0.46)
    assert row["area"] == pytest.approx(2 * math.pi * 0.0125 / 36 * SLICE_M)
    f, se, _, _ = s["forces"]["dem"]
    assert f[:, 2] == pytest.approx([0, -1, -2, -3]) and se[2, 0] == pytest.approx(0.1)
    # as a whole: every sector 0.05 m/s off, its E that over the DEM's mean speed weighted by
    # its rates 1e4 (1 + k); the noise 2 x 0.01 over the same; the force's cycle mean
    # (0 + 1 + 2 + 3) / 4 +- 0.1 / 2
    k = np.arange(36)
    v_mean = np.sum((1 + k) * (0.2 + 0.01 * k)) / np.sum(1 + k)
    d, noise = s["whole"]["lagrangian"]["map"]
    assert (d, noise) == (pytest.approx(0.05 / v_mean), pytest.approx(0.02 / v_mean))
    m, m_se = s["whole"]["dem"]["force"]
    assert m[0] == pytest.approx(1.5) and m_se[0] == pytest.approx(0.05)
    assert "map" not in s["whole"]["dem"]
    assert s["map"][:8] == b"\x89PNG\r\n\x1a\n" and s["distribution"][:8] == b"\x89PNG\r\n\x1a\n"


def test_no_parts_file_no_part_section(tmp_path):
    data = SimpleNamespace(methods=["dem", "lagrangian"], out=tmp_path,
                           scenario=SimpleNamespace(parts=None))
    assert part_sections(data) == ([], ["dem: no parts.nc", "lagrangian: no parts.nc"])
