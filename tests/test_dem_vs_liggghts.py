"""vibroflow's DEM against another code: LIGGGHTS 3.8 on tub47-quick, judged as tub47.md judges.

The same scenario runs in both codes: vibroflow with fill seeds 1 and 2, LIGGGHTS (the exported
deck, 2 MPI ranks, `vibroflow.liggghts`) with fill seed 1.  Both use LIGGGHTS' rolling
resistance (`rolling_model = "cdt_liggghts"` on every contact pair, docs/liggghts.md
"Differences that remain"), so that the codes differ only where they must (the faceted wall,
the fill).  The beds are chaotic and filled differently, so they are compared as tub47.md
compares any two runs: the circulation strengths agree within max(10 %, 2 sigma) with the same
sense, and the field difference E between the codes is at most 1.5 times vibroflow's own
seed-to-seed E.  About 20 minutes on 2 cores (LIGGGHTS about 15 of them).
"""
from __future__ import annotations

import functools
import json
import shutil
from pathlib import Path

import pytest

from vibroflow import liggghts as LG
from vibroflow.analysis.compare import field_difference, fields_agree, strengths_agree
from vibroflow.dem.run import run_dem
from vibroflow.measure.bulk import read_csv
from vibroflow.scenario.io import load_scenario

needs_liggghts = pytest.mark.skipif(
    LG.find_liggghts() is None or shutil.which("mpirun") is None,
    reason="LIGGGHTS (apt-get install liggghts) or mpirun not installed")

pytestmark = [pytest.mark.slow, needs_liggghts]


def scenario(seed: int):
    """tub47-quick with LIGGGHTS' rolling torque on all three contact pairs."""
    sets = [f"contacts.{n}.rolling_model=cdt_liggghts" for n in range(3)]
    return load_scenario("tub47-quick", [*sets, f"run.seed={seed}"])


@functools.cache
def vibroflow_run(root: Path, seed: int) -> Path:
    out = root / f"vibroflow-seed{seed}"
    run_dem(scenario(seed), out, progress=False)
    return out


@functools.cache
def liggghts_run(root: Path, seed: int) -> Path:
    s = scenario(seed)
    deck = root / f"liggghts-seed{seed}"
    LG.export_deck(s, deck)
    LG.run_deck(deck, nprocs=2, timeout=3600)
    out = root / f"liggghts-seed{seed}-result"
    LG.import_run(deck / "post", s, out)
    return out


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    root = tmp_path_factory.mktemp("dem_vs_liggghts")
    return {"vf1": vibroflow_run(root, 1), "vf2": vibroflow_run(root, 2),
            "lg1": liggghts_run(root, 1)}


def _circulation(folder: Path) -> dict:
    return json.loads((folder / "summary.json").read_text())["circulation"]


def _table(folder: Path):
    return read_csv(folder / "bulk_velocity.csv", cell_size=scenario(1).analysis.cell_size)


def test_the_codes_roll_the_bed_equally_strongly(runs):
    """tub47.md: strengths agree within max(10 %, 2 sigma) of their batch-means errors."""
    v, g = _circulation(runs["vf1"]), _circulation(runs["lg1"])
    print(f"\nstrength vibroflow {v['strength']:.4e} +- {v['strength_stderr']:.1e}, "
          f"LIGGGHTS {g['strength']:.4e} +- {g['strength_stderr']:.1e} m^2/s")
    assert v["sense"] == g["sense"] == "counterclockwise"
    assert strengths_agree(g["strength"], g["strength_stderr"], v["strength"],
                           v["strength_stderr"], g["sense"], v["sense"])


def test_the_codes_flow_fields_differ_by_no_more_than_the_seeds_do(runs):
    """tub47.md: E(LIGGGHTS, vibroflow) <= 1.5 E(vibroflow seed 2, vibroflow seed 1)."""
    phi = scenario(1).analysis.min_solid_fraction
    vf1, vf2, lg1 = (_table(runs[k]) for k in ("vf1", "vf2", "lg1"))
    e_seed = field_difference(vf2, vf1, phi)
    e_codes = field_difference(lg1, vf1, phi)
    print(f"\nE between the codes {e_codes:.3f}, vibroflow's seed-to-seed E {e_seed:.3f}, "
          f"limit {1.5 * e_seed:.3f}")
    assert fields_agree(e_codes, e_seed)
