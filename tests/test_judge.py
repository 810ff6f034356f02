"""`vibroflow compare`: runs judged against a reference method's runs over an ensemble of fill
seeds (vibroflow.analysis.judge), checked on folders whose fields differ by a known noise.

The references are one mean field plus independent Gaussian noise of sigma on each velocity
component in each cell, as runs that differ only in their fill seed: two of them differ by
E = 2 sigma / V (V the reference's mean speed), the noise-free field differs from one by
sqrt(2) sigma / V and from the mean of four by sqrt(2) sigma / 2V, and a field with a
systematic error of 4 sigma on vx everywhere differs from one by sqrt(16 + 2) sigma / V.  So
the noise-free field agrees with the references (0.71 times the floor, where 1.5 is allowed)
and the biased one does not (2.12 times).
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from vibroflow.measure.bulk import CellTable, write_csv

U, SIGMA, H = 0.05, 0.005, 0.015
N_CELLS = 4000
V = U * (1 + SIGMA**2 / (2 * U**2))   # the mean speed of a noisy field (2D Rician, 2nd order)


def _write_run(folder, vx, vz, x, z, phi, strength, stderr, case="tub47", window=(1.0, 3.0),
               method=None, sense="counterclockwise", calibrated_on=None, options=None):
    folder.mkdir(parents=True)
    write_csv(CellTable(x=x, z=z, solid_fraction=phi, vx=vx, vz=vz,
                        samples=np.full(x.size, 100, np.int64), cell_size=H),
              folder / "bulk_velocity.csv")
    summary = {"case": case, "source": "test",
               "circulation": {"sense": sense, "strength": strength, "strength_stderr": stderr},
               "window": {"t_start": window[0], "t_end": window[1]}}
    if method:
        summary["method"] = method
    if calibrated_on:   # a continuum's summary names its calibration's DEM run (tub_run.py)
        summary["continuum"] = {"calibration": {"source_run": calibrated_on}}
    if options is not None:   # and the options it ran with
        summary.setdefault("continuum", {})["options"] = options
    (folder / "summary.json").write_text(json.dumps(summary))
    return folder


@pytest.fixture
def ensemble(tmp_path):
    """Four noisy reference runs, the noise-free field as a 'continuum' run, and one with a
    systematic error of 4 sigma on vx; their folders."""
    rng = np.random.default_rng(12)
    ii = np.arange(N_CELLS)
    x, z = (ii % 40 - 20) * H, (ii // 40) * H
    phi = rng.uniform(0.35, 0.6, N_CELLS)
    ang = rng.uniform(0, 2 * np.pi, N_CELLS)
    vx, vz = U * np.cos(ang), U * np.sin(ang)
    refs = [_write_run(tmp_path / f"dem{k}", vx + rng.normal(0, SIGMA, N_CELLS),
                       vz + rng.normal(0, SIGMA, N_CELLS), x, z, phi, s, 0.05e-3)
            for k, s in enumerate((2.40e-3, 2.55e-3, 2.50e-3, 2.35e-3))]
    exact = _write_run(tmp_path / "exact", vx, vz, x, z, phi, 2.50e-3, 0.04e-3,
                       method="lagrangian")
    biased = _write_run(tmp_path / "biased", vx + 4 * SIGMA, vz, x, z, phi, 3.20e-3, 0.04e-3,
                        method="eulerian")
    return refs, exact, biased, (x, z, phi, vx, vz)


def test_compare_measures_the_floor_and_judges_against_every_seed(run_cli, ensemble, tmp_path):
    refs, exact, biased, _ = ensemble
    out = tmp_path / "judgement.json"
    args = [exact, biased]
    for r in refs:
        args += ["-r", r]
    res = run_cli("compare", *args, "--json", out)
    assert res.returncode == 0, res.stderr
    j = json.loads(out.read_text())
    floor = j["floor"]
    assert len(floor["pairs"]) == 12
    assert floor["E_seed"] == pytest.approx(2 * SIGMA / V, rel=0.03)
    assert j["limit"] == pytest.approx(1.5 * floor["E_seed"], rel=1e-12)
    ex, bi = j["results"]
    assert ex["method"] == "lagrangian" and len(ex["E_each"]) == 4
    assert ex["E_mean"] == pytest.approx(math.sqrt(2) * SIGMA / V, rel=0.03)
    assert ex["E_mean_field"] == pytest.approx(math.sqrt(2) * SIGMA / (2 * V), rel=0.03)
    assert ex["fields_agree"] is True
    # the biased field: |dv|^2 = (4 sigma - noise)^2 + noise^2 -> 18 sigma^2 against each seed
    assert bi["E_mean"] == pytest.approx(math.sqrt(18) * SIGMA / V, rel=0.03)
    assert bi["fields_agree"] is False
    # strengths: the references' mean 2.45e-3 with the scatter's error 0.0456e-3 (n = 4)
    assert j["reference_strength"] == pytest.approx(2.45e-3, rel=1e-12)
    assert j["reference_strength_stderr"] == pytest.approx(
        np.std([2.40e-3, 2.55e-3, 2.50e-3, 2.35e-3], ddof=1) / 2, rel=1e-9)
    assert ex["strengths_agree"] is True            # 2.50 against 2.45: 2 %
    assert bi["strengths_agree"] is False           # 3.20 against 2.45: 31 %
    assert "fields agree: yes" in res.stdout and "fields agree: no" in res.stdout


def test_a_folder_of_seeds_stands_for_its_runs_in_natural_order(run_cli, ensemble, tmp_path):
    """`-r FOLDER` (a folder holding run folders and no summary.json of its own) is the same
    judgement as one `-r` per run: the floor over the same twelve ordered pairs, each result
    against the same four references; the runs taken in natural order (seed2 before seed10)."""
    import shutil

    from vibroflow.analysis.judge import run_folders

    refs, exact, _, _ = ensemble
    seeds = tmp_path / "seeds"
    for name, r in zip(("seed10", "seed2", "seed1", "seed3"), refs):
        shutil.copytree(r, seeds / name)
    (seeds / "notes").mkdir()            # a folder without a run is not one
    assert [p.name for p in run_folders([seeds])] == ["seed1", "seed2", "seed3", "seed10"]
    one, each = tmp_path / "one.json", tmp_path / "each.json"
    assert run_cli("compare", exact, "-r", seeds, "--json", one).returncode == 0
    args = [exact]
    for name in ("seed1", "seed2", "seed3", "seed10"):
        args += ["-r", seeds / name]
    assert run_cli("compare", *args, "--json", each).returncode == 0
    a, b = json.loads(one.read_text()), json.loads(each.read_text())
    assert a["floor"]["E_seed"] == b["floor"]["E_seed"]
    assert a["results"][0]["E_each"] == b["results"][0]["E_each"]
    assert a["floor"]["E_seed"] == pytest.approx(2 * SIGMA / V, rel=0.03)


def test_compare_with_one_reference_needs_the_floor(run_cli, ensemble):
    refs, exact, _, _ = ensemble
    res = run_cli("compare", exact, "-r", refs[0])
    assert res.returncode == 0
    assert "cannot be judged" in res.stdout and "fields agree: cannot say" in res.stdout
    res = run_cli("compare", exact, "-r", refs[0], "--e-seed", "0.2")
    assert res.returncode == 0 and "fields agree: yes" in res.stdout


def test_compare_bad_input_is_one_line(run_cli, ensemble, tmp_path):
    refs, exact, _, (x, z, phi, vx, vz) = ensemble
    other = _write_run(tmp_path / "quick", vx, vz, x, z, phi, 1e-3, 0.0, case="tub47-quick")
    late = _write_run(tmp_path / "late", vx, vz, x, z, phi, 1e-3, 0.0, window=(0.5, 1.5))
    out = tmp_path / "never.json"
    empty = tmp_path / "empty"       # a folder with neither a run nor run folders in it
    empty.mkdir()
    for args, needle in [
        ((tmp_path / "nowhere", "-r", refs[0]), "no such run folder"),
        ((exact, "-r", empty), "not a finished run"),
        ((exact,), "--reference"),
        (("-r", refs[0]), "RESULT"),
        ((other, "-r", refs[0]), "case"),
        ((late, "-r", refs[0]), "window"),
        ((exact, "-r", refs[0], "--e-seed", "0"), "--e-seed"),
        ((exact, "-r", refs[0], "-r", exact), "a lagrangian run among dem (test) runs"),
    ]:
        res = run_cli("compare", *args, "--json", out)
        assert res.returncode == 2, (args, res.stdout, res.stderr)
        assert needle in res.stderr and res.stderr.count("\n") == 1, res.stderr
        assert "Traceback" not in res.stderr
        assert not out.exists()


def test_the_judgement_says_each_runs_take_off():
    """`vibroflow compare` prints the bed's take-off of a run's summary.json "floor" block
    (measure.floor_force): the phase (± its batches' error, taken on the circle), that it never
    leaves the floor, or nothing without one."""
    import math

    from vibroflow.analysis.judge import _take_off, _take_off_entry, result_from_summary

    base = {"window": {"t_start": 0.5, "t_end": 1.5}, "circulation": {"strength": 1e-3}}
    runs = [result_from_summary({**base, **extra}, "run", None) for extra in
            ({"floor": {"take_off_phase": 0.1234}}, {"floor": {"take_off_phase": None}}, {},
             {"floor": {"take_off_phase": 0.064,
                        "take_off_phase_batches": [0.993, 0.999, 0.099, 0.092]}})]
    assert runs[0].take_off == 0.1234 and math.isnan(runs[1].take_off)
    assert runs[2].take_off is None
    said = [_take_off(_take_off_entry(r)) for r in runs]
    # batches either side of the cycle's end: -0.071, -0.065, 0.035, 0.028 about 0.064, whose
    # sd over sqrt(4) is 0.0288
    assert said == [", leaves the floor at t f 0.123", ", never leaves the floor", "",
                    ", leaves the floor at t f 0.064 +- 0.029"]


def test_runs_of_one_method_are_judged_as_an_ensemble_of_calibrations(run_cli, ensemble,
                                                                      tmp_path):
    """Three runs of one method, as if calibrated on three DEM seeds: the noise-free field with
    a systematic error of b sigma on vx, b = 0, 2, 4, so that E against each seed is
    sqrt(b^2 + 2) sigma / V: 1.41, 2.45 and 4.24 sigma / V against the limit 3 sigma / V (two
    of three agree); strengths 2.50, 2.60 and 3.20 e-3 against the seeds' 2.45 e-3 (two of
    three within 10 %).  The ensemble's E is those three's mean and spread."""
    refs, _, _, (x, z, phi, vx, vz) = ensemble
    draws = [_write_run(tmp_path / f"lag{k}", vx + b * SIGMA, vz, x, z, phi, s, 0.04e-3,
                        method="lagrangian", calibrated_on=f"runs/seed{k}/dem")
             for k, (b, s) in enumerate(((0, 2.50e-3), (2, 2.60e-3), (4, 3.20e-3)), start=1)]
    out = tmp_path / "j.json"
    args = [*draws]
    for r in refs:
        args += ["-r", r]
    res = run_cli("compare", *args, "--json", out)
    assert res.returncode == 0, res.stderr
    j = json.loads(out.read_text())
    want = np.sqrt([2.0, 6.0, 18.0]) * SIGMA / V
    assert [r["E_mean"] for r in j["results"]] == pytest.approx(want, rel=0.03)
    assert [r["calibration_source_run"] for r in j["results"]] == [
        "runs/seed1/dem", "runs/seed2/dem", "runs/seed3/dem"]
    (g,) = j["ensembles"]
    assert g["method"] == "lagrangian" and g["n"] == 3
    assert g["E_mean"] == pytest.approx(want.mean(), rel=0.03)
    assert g["E_sd"] == pytest.approx(want.std(ddof=1), rel=0.05)
    assert (g["E_min"], g["E_max"]) == (min(r["E_mean"] for r in j["results"]),
                                        max(r["E_mean"] for r in j["results"]))
    assert g["E_mean_over_limit"] == pytest.approx(want.mean() / (3 * SIGMA / V), rel=0.04)
    assert g["strength_ratio_min"] == pytest.approx(2.50 / 2.45, rel=1e-9)
    assert g["strength_ratio_max"] == pytest.approx(3.20 / 2.45, rel=1e-9)
    assert (g["strengths_agree"], g["fields_agree"]) == (2, 2)
    assert "lagrangian over its 3 runs, each calibrated on another DEM run:" in res.stdout
    assert "strengths agree in 2 of 3" in res.stdout and "fields agree in 2 of 3" in res.stdout
    # one run of a method is no ensemble
    res = run_cli("compare", draws[0], *args[3:], "--json", out)
    assert json.loads(out.read_text())["ensembles"] == [] and " over its " not in res.stdout


def test_an_ensemble_pools_only_runs_of_the_same_options(run_cli, ensemble, tmp_path):
    """Four runs of one method, two with the granular temperature off and two with it on (the
    same fields as the calibrations' test above, b = 0, 4 and 0, 4): two ensembles of two, each
    with its own mean E, sqrt(2) and sqrt(18) sigma / V averaged, labelled by the options away
    from their defaults."""
    refs, _, _, (x, z, phi, vx, vz) = ensemble
    base = {"transfer_cfl": 0.5, "temperature": False, "cfl": 0.3}
    runs = []
    for k, (b, temp) in enumerate(((0, False), (4, False), (0, True), (4, True)), start=1):
        runs.append(_write_run(tmp_path / f"lag{k}", vx + b * SIGMA, vz, x, z, phi, 2.5e-3,
                               0.04e-3, method="lagrangian", calibrated_on=f"runs/seed{k}/dem",
                               options={**base, "temperature": temp}))
    out = tmp_path / "j.json"
    res = run_cli("compare", *runs, *(a for r in refs for a in ("-r", r)), "--json", out)
    assert res.returncode == 0, res.stderr
    j = json.loads(out.read_text())
    assert [g["n"] for g in j["ensembles"]] == [2, 2]
    off, on = j["ensembles"]
    assert off["options"] == "transfer_cfl=0.5" and off["folders"] == [str(r) for r in runs[:2]]
    assert on["options"] == "temperature=True, transfer_cfl=0.5"
    want = np.sqrt([2.0, 18.0]).mean() * SIGMA / V
    assert off["E_mean"] == pytest.approx(want, rel=0.03)
    assert on["E_mean"] == pytest.approx(want, rel=0.03)
    assert "lagrangian (temperature=True, transfer_cfl=0.5) over its 2 runs" in res.stdout
    assert "  options: transfer_cfl=0.5" in res.stdout


def test_a_run_at_its_formulations_defaults_is_labelled_defaults():
    """transfer_cfl's default is the formulation's own (0.015 Lagrangian, 0.0375 Eulerian)."""
    from dataclasses import asdict

    from vibroflow.analysis.judge import options_label
    from vibroflow.continuum.formulation import formulation

    # the summary's block (continuum/tub_run.py): the options as a dict
    for method in ("lagrangian", "eulerian"):
        record = asdict(formulation(method).options())
        assert options_label({"options": record}, method) == "defaults"
    eul = asdict(formulation("eulerian").options())
    assert options_label({"options": eul}, "lagrangian") == "transfer_cfl=0.0375"


def test_one_reference_gives_es_error_over_both_runs_batches(run_cli, tmp_path):
    """A DEM run at (U, 0) in every batch and a continuum whose six batches sit at (U, c_k) in
    every cell, both with their bulk_velocity_batches.csv: E = mean(c) / U, linear in the
    continuum's batches, so its error is their batch-means error sd(c) / sqrt(6) / U; printed
    and in the JSON.  Without the batches' files there is none."""
    from vibroflow.measure.bulk_batches import BATCHES_CSV_NAME, write_batch_csvs

    c = np.array([0.004, 0.006, 0.005, 0.009, 0.003, 0.007])
    x, z = np.arange(10) * H, np.zeros(10)

    def run(folder, vz_b, method=None):
        nb = vz_b.size
        bvz = np.repeat(vz_b[:, None], x.size, axis=1)
        t = CellTable(x=x, z=z, solid_fraction=np.full(x.size, 0.55), vx=np.full(x.size, U),
                      vz=bvz.mean(axis=0), samples=np.full(x.size, 100 * nb), cell_size=H,
                      batch_phi=np.full((nb, x.size), 0.55), batch_vx=np.full((nb, x.size), U),
                      batch_vz=bvz, batch_samples=np.full((nb, x.size), 100))
        _write_run(folder, t.vx, t.vz, x, z, t.solid_fraction, 2.5e-3, 0.05e-3, method=method)
        write_batch_csvs(t, folder)
        return folder

    dem = run(tmp_path / "dem", np.zeros(6))
    cont = run(tmp_path / "lag", c, method="lagrangian")
    r = run_cli("compare", cont, "-r", dem, "--e-seed", "0.1", "--json", tmp_path / "j.json")
    assert r.returncode == 0, r.stderr
    (res,) = json.loads((tmp_path / "j.json").read_text())["results"]
    want = np.std(c, ddof=1) / np.sqrt(6) / U
    assert res["E_mean"] == pytest.approx(c.mean() / U, rel=1e-9)
    assert res["E_stderr"] == pytest.approx(want, rel=1e-6)
    assert res["E_stderr_of"] == "batches"
    assert f"E against the reference {c.mean() / U:.3f} +- {want:.3f}" in r.stdout
    (cont / BATCHES_CSV_NAME).unlink()
    (dem / BATCHES_CSV_NAME).unlink()
    r = run_cli("compare", cont, "-r", dem, "--e-seed", "0.1", "--json", tmp_path / "j.json")
    (res,) = json.loads((tmp_path / "j.json").read_text())["results"]
    assert res["E_stderr"] is None
    # a damaged batches' file is a one-line error naming it
    (dem / BATCHES_CSV_NAME).write_text("batch,x\n0,abc\n")
    r = run_cli("compare", cont, "-r", dem, "--e-seed", "0.1")
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert str(dem / BATCHES_CSV_NAME) in r.stderr.strip().splitlines()[-1]
