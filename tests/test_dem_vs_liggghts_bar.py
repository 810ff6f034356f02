"""The bar's impact map: vibroflow's DEM against LIGGGHTS 3.8 with the same bar as an STL mesh
(the export carries the part), on a short tub47-bar, judged against the seed-to-seed scatter.

The short case is benchmarks/bar_maps.py's SHORT_SETS (tub47-bar 19.05 mm long, 1500 balls,
the bar at z = 0.045 m under about 4 cm of media, 0.25 s of vibration averaged over the last
0.2 s).  The DEM runs fill seed 1 here, and LIGGGHTS starts from that run's own settled bed
(export_deck's fill_from: the same balls at rest, 1 um facets, settled until at rest, 0.02 s;
the bar's creases active edges, docs/liggghts.md "Parts in the export"), so that the two codes
differ in their contact dynamics only; the scatter is the DEM's map difference
between fill seeds 1 and 2, measured once with `python benchmarks/bar_maps.py --seeds 1 2` and
stored in tests/data/tub47-bar-short-maps/ (README.md there says how).  The maps are compared
as tub47.md compares fields: E(LIGGGHTS, DEM) of the impact rate per patch and of the mean
normal speed per patch (vibroflow.analysis.impact_maps) at most 1.5 times the DEM's
seed-to-seed E.  The rate maps and the speed maps agree (seed 1: E_rate 0.512, E_speed 0.224
against 0.828 and 0.360); the cycle-mean force on the bar agrees between the codes within
twice their batch-means errors combined.
LIGGGHTS' inserted bed is benchmarks/bar_maps.py's comparison (docs/validation.md section 27).
2 - 12 minutes on the shared 2-core machine, by its load (the DEM 1 - 3; LIGGGHTS on 2 ranks
27 000 steps, its fine meshes moving every step); slow, and skipped without LIGGGHTS.

The full tub47-bar (`benchmarks/bar_maps.py --case full`: 14 000 balls, 63.5 mm long, the bar
at z = 0.10 m, the same 0.25 s of vibration) is judged the same way on its stored maps,
tests/data/tub47-bar-full-maps/: each seed's LIGGGHTS run from the DEM's bed of that seed
against that DEM run, within 1.5 times the DEM's own seed-to-seed E.  These tests run no
simulation and need no LIGGGHTS.
"""
from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from vibroflow import liggghts as LG
from vibroflow.analysis.impact_maps import (cycle_mean, part_map, rate_difference,
                                            read_map_csv, speed_difference)
from vibroflow.dem.run import run_dem
from vibroflow.io.parts_file import read_parts
from vibroflow.scenario.io import load_scenario

needs_liggghts = pytest.mark.skipif(
    LG.find_liggghts() is None or shutil.which("mpirun") is None,
    reason="LIGGGHTS (apt-get install liggghts) or mpirun not installed")

DATA = Path(__file__).parent / "data" / "tub47-bar-short-maps"
FULL = Path(__file__).parent / "data" / "tub47-bar-full-maps"
#: benchmarks/bar_maps.py's SHORT_SETS
SHORT_SETS = ["tub.length=0.01905", "fill.count=1500", "parts.0.center=[0.05, 0.0, 0.045]",
              "fill.settle_time=0.5", "fill.max_settle_time=0.6", "run.duration=0.25",
              "run.average_last=0.2"]


def short_case(seed: int):
    return load_scenario("tub47-bar", [*SHORT_SETS, f"run.seed={seed}"])


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    """A folder with the DEM run of fill seed 1 in root/dem."""
    root = tmp_path_factory.mktemp("bar_maps")
    run_dem(short_case(1), root / "dem", progress=False)
    return root


def _print(name, e_codes, e_seed):
    print(f"\n{name}: E between the codes {e_codes:.3f}, the DEM's seed-to-seed E {e_seed:.3f}, "
          f"limit {1.5 * e_seed:.3f}")


# ----------------------------------------------------------------------------------------------
# LIGGGHTS from the DEM's own settled bed (export_deck(fill_from=...), docs/liggghts.md)

@pytest.fixture(scope="module")
def fromdem(root):
    s = short_case(1)
    LG.export_deck(s, root / "deck-fromdem", fill_from=LG.dem_fill(root / "dem", s))
    LG.run_deck(root / "deck-fromdem", nprocs=2, timeout=3600)
    LG.import_run(root / "deck-fromdem" / "post", s, root / "liggghts-fromdem")
    return {"dem": part_map(root / "dem" / "parts.nc", "bar"),
            "liggghts": part_map(root / "liggghts-fromdem" / "parts.nc", "bar"),
            "dem1": read_map_csv(DATA / "dem-seed1.csv"),
            "dem2": read_map_csv(DATA / "dem-seed2.csv"),
            "summary": json.loads((root / "liggghts-fromdem" / "summary.json").read_text()),
            "force": {code: _mean_force(root / folder / "parts.nc")
                      for code, folder in (("dem", "dem"), ("liggghts", "liggghts-fromdem"))}}


def _mean_force(parts_nc):
    """The cycle-mean force on the bar (N, tub axes) and its batch-means error."""
    sel = read_parts(parts_nc).sel(part="bar")
    return cycle_mean(sel["force"].values, sel["force_stderr"].values)


@pytest.mark.slow
@needs_liggghts
def test_from_the_dems_bed_liggghts_keeps_every_ball_and_hits_the_bar_all_around(fromdem):
    """The DEM's 1500 balls all stay in LIGGGHTS' run, and in both codes they hit every one of
    the bar's 36 sectors."""
    assert fromdem["summary"]["n_particles"] == 1500
    assert fromdem["summary"]["balls_lost"] == 0
    for code in ("dem", "liggghts"):
        assert (fromdem[code]["rate"] > 0).all(), code


@pytest.mark.slow
@needs_liggghts
def test_from_the_dems_bed_the_impact_rate_maps_differ_by_no_more_than_the_seeds_do(fromdem):
    """E_rate(LIGGGHTS from the DEM's bed, DEM) <= 1.5 E_rate(DEM seed 2, DEM seed 1)."""
    e_seed = rate_difference(fromdem["dem2"], fromdem["dem1"])
    e_codes = rate_difference(fromdem["liggghts"], fromdem["dem"])
    _print("impact rate, the DEM's bed", e_codes, e_seed)
    assert e_codes <= 1.5 * e_seed


@pytest.mark.slow
@needs_liggghts
def test_from_the_dems_bed_the_mean_force_on_the_bar_agrees(fromdem):
    """The cycle-mean force on the bar, x and z: |F_LIGGGHTS - F_DEM| <= 2 sqrt(se_L^2 + se_D^2)
    (measured: seed 1 x 0.37 +- 0.31 against 0.58 +- 0.24 N, z 0.20 +- 0.48 against
    0.09 +- 0.25 N)."""
    (fl, el), (fd, ed) = fromdem["force"]["liggghts"], fromdem["force"]["dem"]
    print(f"\nmean force on the bar: LIGGGHTS {np.round(fl, 3)} +- {np.round(el, 3)} N, "
          f"DEM {np.round(fd, 3)} +- {np.round(ed, 3)} N")
    for a in (0, 2):
        assert abs(fl[a] - fd[a]) <= 2.0 * math.hypot(el[a], ed[a]), "xyz"[a]


@pytest.mark.slow
@needs_liggghts
def test_from_the_dems_bed_the_impact_speed_maps_differ_by_no_more_than_the_seeds_do(fromdem):
    """E_speed(LIGGGHTS from the DEM's bed, DEM) <= 1.5 E_speed(DEM seed 2, DEM seed 1)
    (measured: 0.224 against 0.360; docs/validation.md section 27)."""
    e_seed = speed_difference(fromdem["dem2"], fromdem["dem1"])
    e_codes = speed_difference(fromdem["liggghts"], fromdem["dem"])
    _print("mean normal speed, the DEM's bed", e_codes, e_seed)
    assert e_codes <= 1.5 * e_seed


# ----------------------------------------------------------------------------------------------
# The full tub47-bar (benchmarks/bar_maps.py --case full: 14 000 balls, 63.5 mm long, the bar at
# z = 0.10 m, the short case's 0.25 s of vibration): the stored maps of both codes, each seed's
# LIGGGHTS run from the DEM's bed of that seed (tests/data/tub47-bar-full-maps/README.md), judged
# against the DEM's own seed-to-seed difference; no simulation runs here.

def _full_maps():
    return ({s: read_map_csv(FULL / f"dem-seed{s}.csv") for s in (1, 2)},
            {s: read_map_csv(FULL / f"liggghts-fromdem-seed{s}.csv") for s in (1, 2)})


@pytest.mark.parametrize("seed", [1, 2])
@pytest.mark.parametrize("measure, difference", [("impact rate", rate_difference),
                                                 ("mean normal speed", speed_difference)])
def test_full_bar_from_the_dems_bed_the_stored_maps_differ_by_no_more_than_the_seeds_do(
        measure, difference, seed):
    """E(LIGGGHTS from the DEM's bed of the seed, DEM of the seed) <= 1.5 E(DEM seed 2, DEM
    seed 1), of the impact rate and of the mean normal speed (measured: E_rate 0.272 and 0.282
    against 1.5 x 0.327 = 0.491; E_speed 0.164 and 0.148 against 1.5 x 0.150 = 0.225;
    docs/validation.md section 27, "The full tub47-bar")."""
    dem, lg = _full_maps()
    e_seed = difference(dem[2], dem[1])
    e_codes = difference(lg[seed], dem[seed])
    _print(f"full tub47-bar, {measure}, seed {seed}", e_codes, e_seed)
    assert e_codes <= 1.5 * e_seed


# ----------------------------------------------------------------------------------------------
# The tub47-bar preset as it stands (benchmarks/bar_maps.py --case preset: 3 s of vibration, the
# last 2 s averaged, 94 cycles): the stored maps of the DEM and of LIGGGHTS inserting its own bed,
# two fill seeds each (tests/data/tub47-bar-preset-maps/README.md); every map of one code against
# every map of the other, judged against each code's own seed-to-seed difference; no simulation
# runs here.

PRESET = Path(__file__).parent / "data" / "tub47-bar-preset-maps"


def _preset_maps():
    return ({s: read_map_csv(PRESET / f"dem-seed{s}.csv") for s in (1, 2)},
            {s: read_map_csv(PRESET / f"liggghts-seed{s}.csv") for s in (1, 2)})


@pytest.mark.parametrize("lg_seed", [1, 2])
@pytest.mark.parametrize("dem_seed", [1, 2])
@pytest.mark.parametrize("measure, difference", [("impact rate", rate_difference),
                                                 ("mean normal speed", speed_difference)])
def test_preset_bar_the_codes_maps_differ_by_no_more_than_each_codes_seeds_do(
        measure, difference, dem_seed, lg_seed):
    """E(LIGGGHTS seed a, DEM seed b) <= 1.5 x the smaller of E(DEM seed 2, DEM seed 1) and
    E(LIGGGHTS seed 2, LIGGGHTS seed 1), of the impact rate and of the mean normal speed
    (measured: E_rate 0.139 - 0.185 against 1.5 x 0.144 = 0.216, E_speed 0.041 - 0.073 against
    1.5 x 0.056 = 0.084; docs/validation.md section 27, "The preset's own window")."""
    dem, lg = _preset_maps()
    e_seed = min(difference(dem[2], dem[1]), difference(lg[2], lg[1]))
    e_codes = difference(lg[lg_seed], dem[dem_seed])
    _print(f"tub47-bar preset, {measure}, LIGGGHTS seed {lg_seed}, DEM seed {dem_seed}",
           e_codes, e_seed)
    assert e_codes <= 1.5 * e_seed
