"""A LIGGGHTS deck started from vibroflow's DEM's settled bed (vibroflow.liggghts.dem_fill,
`vibroflow export liggghts --fill-from`): the data file's lines by hand for a 3-ball bed, the deck
without insertion (and the same vibration as the inserted deck's), and the refusals of a missing,
foreign or mismatched run folder, of a bed that overlaps the bar, and of a count that differs.

The DEM run folders are made by hand (dem.h5 with its source, scenario and radii, summary.json),
and the settled bed is put into the fill cache (vibroflow.dem.fill.cache_dir) under the
scenario's key, where the DEM run would have left it: no settling runs here.
"""
from __future__ import annotations

import json
import subprocess
import sys

import h5py
import numpy as np
import pytest

from tests.cli_helpers import one_line_error

from vibroflow import liggghts as LG
from vibroflow.dem.fill import cache_dir, fill_cache_key
from vibroflow.dem.fingerprint import scenario_toml
from vibroflow.dem.output import save_state_file
from vibroflow.dem.simulate import init_state, make_system
from vibroflow.errors import InputError
from vibroflow.liggghts.dem_fill import DemFill, check_clear, data_file_text
from vibroflow.scenario.io import load_scenario

R_BALL = 0.003175      # m, tub47's media
RHO_STEEL = 7800.0     # kg/m^3
#: three balls resting near the bottom of the U (R = 0.15 m), clear of the bar at z = 0.10 m
BED = np.array([[0.0, 0.005, 0.02], [0.02, 0.01, 0.025], [-0.015, 0.015, 0.03]])


def case(*sets: str):
    """tub47-bar 19 mm long with 3 balls, 0.06 s of vibration."""
    return load_scenario("tub47-bar", ["tub.length=0.01905", "fill.count=3", "run.duration=0.06",
                                       "run.average_last=0.045", "run.batches=2", *sets])


def dem_run(folder, scenario, bed=BED, source="vibroflow", radius=None, overlap_over_d=0.01):
    """A finished DEM run folder made by hand, its settled bed `bed` in the fill cache."""
    n = bed.shape[0]
    radius = np.full(n, R_BALL) if radius is None else radius
    folder.mkdir(parents=True)
    with h5py.File(folder / "dem.h5", "w") as f:
        f.attrs["source"] = source
        f.attrs["scenario_toml"] = scenario_toml(scenario)
        f.attrs["n_particles"] = n
        f.create_dataset("particles/radius", data=radius)
    (folder / "summary.json").write_text(json.dumps(
        {"max_overlap_over_d": overlap_over_d, "max_wall_overlap_over_d": overlap_over_d}))
    system = make_system(scenario)
    state = init_state(system, bed, np.zeros((n, 3)), np.zeros((n, 3)), np.full(n, R_BALL),
                       np.full(n, RHO_STEEL), np.zeros(n, dtype=np.int64))
    save_state_file(cache_dir() / "fills" / f"{fill_cache_key(scenario)}.h5", state,
                    {"settle_info": "{}"})
    return folder


@pytest.fixture(autouse=True)
def _cache(tmp_path, monkeypatch):
    monkeypatch.setenv("VIBROFLOW_CACHE", str(tmp_path / "cache"))


# ----------------------------------------------------------------------------------------------
# The data file

def test_the_data_file_of_a_three_ball_bed_by_hand(tmp_path):
    """Header, box, 4 atom types and per ball "id type diameter density x y z", ball i as atom
    i + 1, the positions to the last bit."""
    bed = DemFill(BED, np.full(3, R_BALL), np.full(3, RHO_STEEL), tmp_path)
    text = data_file_text(bed, (-0.2, 0.2, -0.01, 0.03, -0.05, 0.6), 4)
    assert text.splitlines() == [
        "LIGGGHTS data file: the settled bed of a vibroflow DEM run", "",
        "3 atoms", "4 atom types", "",
        "-0.2 0.2 xlo xhi", "-0.01 0.03 ylo yhi", "-0.05 0.6 zlo zhi", "",
        "Atoms", "",
        "1 1 0.00635 7800.0 0.0 0.005 0.02",
        "2 1 0.00635 7800.0 0.02 0.01 0.025",
        "3 1 0.00635 7800.0 -0.015 0.015 0.03"]


def test_a_periodic_tub_takes_y_into_its_period(tmp_path):
    bed = DemFill(np.array([[0.0, -0.001, 0.02], [0.0, 0.021, 0.02]]), np.full(2, R_BALL),
                  np.full(2, RHO_STEEL), tmp_path)
    rows = data_file_text(bed, (-1, 1, 0, 0.02, 0, 1), 2, periodic_length=0.02).splitlines()[-2:]
    ys = [float(r.split()[5]) for r in rows]
    assert ys == pytest.approx([0.019, 0.001], abs=1e-15)


# ----------------------------------------------------------------------------------------------
# The deck

def test_the_deck_reads_the_dem_bed_and_inserts_nothing(tmp_path):
    """read_data instead of create_box, no insertion, 0.02 s of settling then at most 8 chunks
    of 0.01 s, facets within 1 um of the circles (the U's half circle of R = 0.15 m in 431 arcs:
    R (1 - cos(pi / 862)) = 0.99 um, 430 arcs 1.0007 um), and from the vibration on the very
    lines of the inserted deck with the same facets."""
    s = case()
    bed = LG.dem_fill(dem_run(tmp_path / "dem", s), s)
    assert np.array_equal(bed.position, BED) and np.array_equal(bed.radius, np.full(3, R_BALL))
    info = LG.export_deck(s, tmp_path / "deck", fill_from=bed)
    LG.export_deck(s, tmp_path / "inserted", max_sagitta=1e-6)
    deck = (tmp_path / "deck" / "in.tub").read_text()
    inserted = (tmp_path / "inserted" / "in.tub").read_text()
    assert "read_data       fill.data\n" in deck and "create_box" not in deck
    for word in ("insert/rate/region", "particletemplate", "fillpass"):
        assert word in inserted and word not in deck, word
    assert "(431 arcs on the half circle, sagitta 0.0010 mm)" in deck
    assert "\nrun 2000\n" in deck and "variable settlepass loop 8\n" in deck
    assert info.settle_steps == 2000
    vib = "# ---- vibration"
    assert deck[deck.index(vib):] == inserted[inserted.index(vib):]
    # the data file's box is the deck's domain (which the deck rounds to 10 digits)
    box = [float(v) for v in deck.split("region          domain block ")[1].split()[:6]]
    data = (tmp_path / "deck" / "fill.data").read_text().splitlines()
    bounds = [float(v) for line in data[5:8] for v in line.split()[:2]]
    assert bounds == pytest.approx(box, rel=1e-9)
    assert data[8:] == data_file_text(bed, box, 4).splitlines()[8:]
    assert not (tmp_path / "inserted" / "fill.data").exists()
    readme = (tmp_path / "deck" / "README.txt").read_text()
    assert "reads the 3 balls of a vibroflow DEM run's settled bed from fill.data" in readme


# ----------------------------------------------------------------------------------------------
# Refusals

def test_a_missing_folder_or_one_without_a_finished_run_is_refused(tmp_path):
    s = case()
    with pytest.raises(InputError, match="no such folder"):
        LG.dem_fill(tmp_path / "nowhere", s)
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match="not a finished vibroflow DEM run"):
        LG.dem_fill(tmp_path / "empty", s)


def test_a_liggghts_import_is_refused(tmp_path):
    s = case()
    with pytest.raises(InputError, match="a run of 'liggghts', not of vibroflow's DEM"):
        LG.dem_fill(dem_run(tmp_path / "lg", s, source="liggghts"), s)


@pytest.mark.parametrize("sets, field", [(["run.seed=2"], "run.seed"),
                                         (["fill.count=4"], "fill"),
                                         (["parts.0.center=[0.05, 0.0, 0.045]"], "parts")])
def test_a_foreign_scenarios_fill_is_refused(tmp_path, sets, field):
    """Another seed, count or bar position makes another bed: refused, the field named."""
    folder = dem_run(tmp_path / "dem", case())
    with pytest.raises(InputError, match=f"another scenario's \\(differs in {field}\\)"):
        LG.dem_fill(folder, case(*sets))


def test_a_vibration_of_its_own_is_not_a_foreign_fill(tmp_path):
    """The vibration (amplitude, duration) does not shape the bed: accepted."""
    folder = dem_run(tmp_path / "dem", case())
    bed = LG.dem_fill(folder, case("run.duration=0.08", "motion.amplitude_z=0.001"))
    assert bed.n == 3


def test_radii_that_are_not_the_runs_are_refused(tmp_path):
    s = case()
    folder = dem_run(tmp_path / "dem", s, radius=np.array([R_BALL, R_BALL, 0.004]))
    with pytest.raises(InputError, match="radii by ball id"):
        LG.dem_fill(folder, s)


def test_a_ball_inside_the_bar_is_refused(tmp_path):
    """A ball 1 mm into the bar (radius 12.5 mm at (0.05, 0.10)) overlaps it by 1 mm, more
    than the run's largest overlap of 1 % of d (0.0635 mm)."""
    s = case()
    bed = BED.copy()
    bed[2] = [0.05, 0.01, 0.10 + 0.0125 + R_BALL - 0.001]
    with pytest.raises(InputError, match="ball 2 overlaps part bar by 0.001 m"):
        LG.dem_fill(dem_run(tmp_path / "dem", s, bed=bed), s)
    fill = DemFill(bed, np.full(3, R_BALL), np.full(3, RHO_STEEL), tmp_path)
    check_clear(fill, s, 0.00101, tmp_path)  # within an allowance of 1.01 mm


def test_a_count_other_than_the_scenarios_is_refused(tmp_path):
    bed = DemFill(BED[:2], np.full(2, R_BALL), np.full(2, RHO_STEEL), tmp_path)
    with pytest.raises(InputError, match="2 balls, the scenario's fill.count is 3"):
        LG.export_deck(case(), tmp_path / "deck", fill_from=bed)
    assert not (tmp_path / "deck").exists()


def test_the_command_line_refuses_a_missing_folder_in_one_line(tmp_path):
    r = subprocess.run([sys.executable, "-m", "vibroflow.cli", "export", "liggghts", "tub47-bar",
                        str(tmp_path / "deck"), "--fill-from", str(tmp_path / "nowhere")],
                       capture_output=True, text=True)
    line = one_line_error(r)
    assert "--fill-from" in line and "no such folder" in line
