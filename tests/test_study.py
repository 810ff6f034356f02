"""`vibroflow run`: the study pipeline (DEM, calibration, continuum, comparison) with kept
stages, on a tiny tub (400 balls, 0.2 s of vibration)."""
from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from tests.test_calibrate import SMALL

from vibroflow.report.stage import report_stage
from vibroflow.study.methods import METHODS, method

#: every registered continuum method is a stage of its own (a method is one more entry)
STAGES = ("dem", "calibration", *METHODS, "comparison", "report")


def _mtimes(out):
    return {s: (out / s / "stage.json").stat().st_mtime_ns for s in STAGES}


def test_pipeline_runs_end_to_end(study):
    import xarray as xr

    import vibroflow
    from vibroflow.measure.bulk import read_csv
    from vibroflow.analysis.compare import field_difference

    scenario, out, summary, lines = study
    # two lines per stage that runs: when it starts (with its estimate, or that a first run of
    # a continuum has none), when it ends
    assert len(lines) == 2 * len(STAGES)
    for k, s in enumerate(STAGES):
        start, end = lines[2 * k], lines[2 * k + 1]
        assert start.startswith(f"[{k + 1}/{len(STAGES)}] {s}")
        said = "running, no estimate yet" if s in METHODS else "running, about"
        assert said in start, start
        assert end.startswith(f"[{k + 1}/{len(STAGES)}] {s}")
        assert "done in" in end and "time left" in end
    for s in STAGES:
        rec = json.loads((out / s / "stage.json").read_text())
        assert rec["stage"] == s and len(rec["hash"]) == 64
        assert not (out / s / "pending.json").exists()
    assert set(summary["methods"]) == {"dem", *METHODS}
    for name, m in summary["methods"].items():
        assert set(m["probes"]) == set(scenario.analysis.probes), name
        assert "ball_ball_mean_normal_speed" in m["impacts"]
    # the comparison stage's E is the field difference of the two tables (tub47.md)
    a = summary["methods"]["lagrangian"]["against_dem"]
    dem = read_csv(out / "dem" / "bulk_velocity.csv", cell_size=scenario.analysis.cell_size)
    lag = read_csv(out / "lagrangian" / "bulk_velocity.csv", cell_size=scenario.analysis.cell_size)
    assert a["field_difference_E"] == pytest.approx(field_difference(lag, dem), rel=1e-12)
    assert a["cost_ratio"] == pytest.approx(summary["methods"]["lagrangian"]["wall_time_s"]
                                            / summary["methods"]["dem"]["wall_time_s"])

    loaded = vibroflow.load(out)
    assert loaded["methods"] == summary["methods"]
    for name in ("dem", *METHODS):
        ds = loaded["fields"][name]
        assert isinstance(ds, xr.Dataset)
        # every cell of the table lands on its own grid point of the Dataset
        table = read_csv(out / name / "bulk_velocity.csv")
        assert int(np.isfinite(ds["vx"].values).sum()) == len(table)
        assert ds["samples"].values.sum() == pytest.approx(table.samples.sum())
        phi = ds["solid_fraction"].values
        assert np.all((phi >= 0) & (phi <= 1))


def test_every_method_keeps_the_bed_mass_and_the_wall_obeys_coulomb(study):
    """Conservation and a contact law, checked on the study's own results: each method's table of
    cells holds the bed's whole solid volume (the time-averaged solid fraction over the cells'
    area times the tub's length is the balls' volume N pi d^3 / 6: to round-off for the DEM and
    the Lagrangian points, which the table bins whole; within 0.5 % for the Eulerian mesh, whose
    cells the table samples: 0.18 % on this small bed, 5e-5 on tub47-quick); no ball is lost; the
    Eulerian mass is conserved to round-off; and no wall contact of the DEM exceeds the lining's
    Coulomb friction |F_t| <= mu F_n, so neither do the contacts' mean ratio nor the effective
    friction (the ratio of sums) that the continuum gets."""
    import math

    from vibroflow.measure.bulk import read_csv
    from vibroflow.scenario.checks import find_contact

    scenario, out, summary, _ = study
    h, length, d = scenario.analysis.cell_size, scenario.tub.length, scenario.fill.diameter
    balls = scenario.fill.count * math.pi * d**3 / 6.0
    for name, rel in (("dem", 1e-9), ("lagrangian", 1e-9), ("eulerian", 5e-3)):
        table = read_csv(out / name / "bulk_velocity.csv", cell_size=h)
        assert table.solid_fraction.sum() * h * h * length == pytest.approx(balls, rel=rel), name
    dem = json.loads((out / "dem" / "summary.json").read_text())
    assert dem["balls_lost"] == 0 and dem["n_particles"] == scenario.fill.count
    eul = json.loads((out / "eulerian" / "summary.json").read_text())
    assert abs(eul["continuum"]["mass_error"]) < 1e-12
    mu = find_contact(scenario, scenario.fill.material, scenario.tub.wall_material).friction
    wc = dem["wall_contacts"]
    assert wc["count"] > 0
    assert wc["mean_ft_over_fn"] <= mu * (1 + 1e-6)
    assert wc["ratio_of_sums"] <= mu * (1 + 1e-6)
    assert 0.0 <= wc["sliding_fraction"] <= 1.0
    lag = json.loads((out / "lagrangian" / "summary.json").read_text())
    assert lag["continuum"]["wall_friction"] <= mu * (1 + 1e-6)


@pytest.mark.slow
def test_calibration_writes_into_its_own_folder_with_the_standalone_numbers(study, tmp_path):
    """The calibration stage's files (calibration.toml, fields.nc, pictures) are in
    DIR/calibration, none in DIR/dem; the calibration of the study's DEM into a folder of its
    own gives the same calibration.toml (but the time it was made); `--like DIR/dem` finds it."""
    from vibroflow.calibration.calibrate import calibrate
    from vibroflow.study.folder import calibration_of_run

    _, out, _, _ = study
    cal = out / "calibration"
    for name in ("calibration.toml", "fields.nc", "fields.png", "mu_I.png",
                 "wall_friction.png", "impacts.png"):
        assert (cal / name).is_file(), name
    dem_files = {p.name for p in (out / "dem").iterdir()}
    assert not dem_files & {"calibration.toml", "fields.nc", "calibration"}, dem_files
    calibrate(out / "dem", progress=False, pictures=False, out=tmp_path / "again")
    again, mine = ([ln for ln in (d / "calibration.toml").read_text().splitlines()
                    if not ln.startswith("created = ")] for d in (tmp_path / "again", cal))
    assert again == mine  # every number as the study's calibration wrote it (NaN included)
    assert calibration_of_run(out / "dem") == (cal / "calibration.toml").resolve()
    assert calibration_of_run(tmp_path / "again") == tmp_path / "again" / "calibration.toml"
    assert calibration_of_run(tmp_path) is None

def test_rerun_recomputes_nothing(study):
    from vibroflow.study import run_study

    scenario, out, _, _ = study
    before = _mtimes(out)
    lines: list[str] = []
    summary = run_study(scenario, out, echo=lines.append, extra_stages=[report_stage()])
    assert _mtimes(out) == before
    assert all("kept" in line for line in lines)
    assert set(summary["methods"]) == {"dem", *METHODS}


@pytest.mark.slow
def test_continuum_setting_reruns_only_continuum_and_comparison(study):
    from vibroflow.study import run_study

    scenario, out, _, _ = study
    before = _mtimes(out)
    lines: list[str] = []
    run_study(scenario, out, settings={"lagrangian": {"cfl": 0.25}}, echo=lines.append,
              extra_stages=[report_stage()])
    after = _mtimes(out)
    assert after["dem"] == before["dem"] and after["calibration"] == before["calibration"]
    assert after["lagrangian"] != before["lagrangian"]
    assert after["comparison"] != before["comparison"]
    rec = json.loads((out / "lagrangian" / "stage.json").read_text())
    assert rec["inputs"]["options"]["cfl"] == 0.25


def _cli(*args):
    env = dict(os.environ, NO_COLOR="1")
    return subprocess.run([sys.executable, "-m", "vibroflow.cli", *map(str, args)],
                          capture_output=True, text=True, env=env, stdin=subprocess.DEVNULL)


@pytest.mark.slow
def test_foreign_or_corrupt_dir_is_a_one_line_error(tmp_path):
    import vibroflow
    from vibroflow.errors import InputError

    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("mine\n")
    corrupt = tmp_path / "corrupt"
    corrupt.mkdir()
    (corrupt / "study.json").write_text("{not json")
    for folder in (foreign, corrupt):
        r = _cli("run", "tub47-quick", "--out", folder, "--set", "run.duration=0.2")
        assert r.returncode == 2, r.stderr
        assert r.stderr.startswith("error: ") and r.stderr.count("\n") == 1, r.stderr
        assert "Traceback" not in r.stderr
        with pytest.raises(InputError):
            vibroflow.load(folder)
    assert sorted(p.name for p in foreign.iterdir()) == ["notes.txt"]  # nothing written
    r = _cli("run", "--out", tmp_path / "new", "--set", "lagrangian.nope=1")
    assert r.returncode == 2 and "lagrangian.nope" in r.stderr
    assert not (tmp_path / "new").exists()


@pytest.mark.slow
def test_a_killed_run_resumes_where_it_stopped(study, tmp_path):
    """`vibroflow run` killed (SIGKILL) in the middle of its DEM stage, then run again: the DEM
    resumes from its checkpoint (stage record `resumed`), no stage of the killed run looks
    finished before that, and the numbers are those of the run that was never interrupted (the
    DEM's resume is bit for bit; run.checkpoint_every is not an input of any stage)."""
    import signal

    from vibroflow.scenario.io import load_scenario
    from vibroflow.study import run_study

    scenario, _, reference, _ = study
    out = tmp_path / "killed"
    sets = [a for s in [*SMALL, "run.checkpoint_every=0.05"] for a in ("--set", s)]
    # the fixture's VIBROFLOW_CACHE (the cached fill); the DEM SIGKILLs the whole run right
    # after its first checkpoint (vibroflow.dem.interrupts' fault injection): a kill from outside
    # raced the CI machine, which finished the DEM stage first
    env = dict(os.environ, NO_COLOR="1", VIBROFLOW_FAULT_KILL_AFTER_CHECKPOINT="1")
    proc = subprocess.run([sys.executable, "-m", "vibroflow.cli", "run", "tub47-quick",
                           "--out", str(out), *sets], env=env, capture_output=True, text=True,
                          timeout=600)
    assert proc.returncode == -signal.SIGKILL, (proc.returncode, proc.stderr)
    assert (out / "dem" / "checkpoint.h5").exists()
    assert (out / "dem" / "pending.json").exists()
    assert not (out / "dem" / "stage.json").exists() and not (out / "summary.json").exists()

    lines: list[str] = []
    resumed = run_study(load_scenario("tub47-quick", [*SMALL, "run.checkpoint_every=0.05"]),
                        out, echo=lines.append, extra_stages=[report_stage()])
    assert "running" in lines[0] and "(resumed)" in lines[1]
    assert json.loads((out / "dem" / "stage.json").read_text())["resumed"] is True
    a, b = resumed["methods"]["dem"], reference["methods"]["dem"]
    assert a["circulation"]["strength"] == b["circulation"]["strength"]
    assert a["probes"] == b["probes"] and a["impacts"] == b["impacts"]
    for name in METHODS:  # the continuum ran from the same calibration: the same numbers
        assert (resumed["methods"][name]["circulation"]["strength"]
                == reference["methods"][name]["circulation"]["strength"])


def test_time_left_names_the_stages_it_cannot_estimate():
    from vibroflow.study.pipeline import _about, _time_left
    from vibroflow.study.stages import Stage

    rest = [Stage(n, inputs=dict, run=lambda st, r: {}) for n in ("a", "b", "c", "d")]
    kept = {"a": None, "b": None, "c": None, "d": {"hash": "x"}}
    est = {"a": 30.0, "b": None, "c": 60.0, "d": 1000.0}
    # the kept stage d counts nothing; b has no estimate and says so
    assert (_time_left(rest, kept, est, set(), 0.5)
            == "time left ~ 45 s + the b stage (not estimated yet)")
    assert _time_left(rest[:1], kept, est, set(), 1.0) == "time left ~ 30 s"
    # c's estimate is its own wall time of the folder's previous run: not scaled
    assert (_time_left(rest, kept, est, {"c"}, 0.5)
            == "time left ~ 1.2 min + the b stage (not estimated yet)")  # 15 + 60 s
    assert _about(None).startswith("no estimate yet") and _about(150.0) == "about 2.5 min"


@pytest.mark.slow
def test_run_vtk_writes_the_paraview_files_of_the_dem_and_every_method(run_cli, tmp_path,
                                                                        monkeypatch):
    """`vibroflow run --vtk --vtk-frame lab --vtk-every 0.02` on a tiny tub: the DEM's balls
    and each continuum's grid (early frames, the window's snapshots), with the tub's surface at
    each instant, in the lab frame; a rerun with the same flags, or without --vtk, keeps every
    stage; a rerun in the tub frame runs the stages again and writes the tub-frame files."""
    from tests.vtk_reader import read_pvd

    monkeypatch.setenv("VIBROFLOW_CACHE", str(tmp_path / "cache"))
    out = tmp_path / "run"
    sets = [a for s in [*SMALL, "run.duration=0.12", "run.average_last=0.09"]
            for a in ("--set", s)]
    flags = ["--vtk", "--vtk-frame", "lab", "--vtk-every", "0.02"]
    r = run_cli("run", "tub47-quick", "--out", out, *flags, *sets, timeout=1200)
    assert r.returncode == 0, r.stderr
    # the last lines: each method's strength with its error, as summary.json holds them
    from vibroflow.rounding import plus_minus
    summary = json.loads((out / "summary.json").read_text())
    for name, m in summary["methods"].items():
        c = m["circulation"]
        assert (f"{name}: circulation {c['sense']} "
                f"{plus_minus(c['strength'], c['strength_stderr'])} m^2/s") in r.stdout
    dem = out / "dem" / "vtk"
    entries = read_pvd(dem / "snapshots.pvd")
    # early frames at 0, 0.02 s before the window at 0.03 s, then 4 cycles x 8 snapshots
    assert [f for _, f in entries[:2]] == ["early_00000.vtu", "early_00001.vtu"]
    assert len(entries) == 2 + 32
    assert len(read_pvd(dem / "tub.pvd")) == len(entries)
    assert json.loads((dem / "vtk.json").read_text()) == {"frame": "lab", "every": 0.02,
                                                          "start": 0.0}
    for name in METHODS:
        # the continua's too: the early frames at 0 and 0.02 s, then the last cycle's 8
        vdir = out / name / "vtk"
        grid = read_pvd(vdir / "grid.pvd")
        assert [f for _, f in grid[:2]] == ["grid_early_00000.vts", "grid_early_00001.vts"]
        assert len(grid) == 2 + 8, name
        assert all(f.endswith(".vts") for _, f in grid)
        assert len(read_pvd(vdir / "tub.pvd")) == 2 + 8
    for again in (flags, []):
        r = run_cli("run", "tub47-quick", "--out", out, *again, *sets, timeout=1200)
        assert r.returncode == 0, r.stderr
        assert r.stdout.count("up to date, kept") == len(STAGES), r.stdout
    r = run_cli("run", "tub47-quick", "--out", out, "--vtk", *sets, timeout=1200)
    assert r.returncode == 0, r.stderr
    assert any(line.startswith("[1/") and "done in" in line for line in r.stdout.splitlines())
    assert (dem / "tub.vtu").is_file() and not (dem / "tub.pvd").exists()
    first = out / next(iter(METHODS)) / "vtk" / "grid.pvd"
    assert all(f.endswith(".vtr") for _, f in read_pvd(first))


def test_force_chunks_changes_the_continuum_stage_hash_and_not_the_dem_stage_hash(tmp_path):
    # run.force_chunks fixes the continuum's scatter sums only (DEVELOPERS.md "Threads")
    from vibroflow.scenario.io import load_scenario
    from vibroflow.study.pipeline import stage_hash
    from vibroflow.study.stages import Study, stages_of

    def hashes(chunks):
        scenario = load_scenario("tub47-quick", [*SMALL, f"run.force_chunks={chunks}"])
        methods = [(m, m.make_options({})) for m in map(method, METHODS)]
        study = Study(out=tmp_path, scenario=scenario, methods=methods)
        h: dict[str, str] = {}
        for s in stages_of(study):
            h[s.name] = stage_hash(s, study, h)
        return h

    two, three = hashes(2), hashes(3)
    assert two["dem"] == three["dem"] and two["calibration"] == three["calibration"]
    for name in METHODS:
        assert two[name] != three[name]
