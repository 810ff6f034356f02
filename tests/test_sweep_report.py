"""The sweep report (DIR/report.html of a sweep, `vibroflow report SWEEP_DIR`) on sweep folders
written by hand (points' summary.json with known numbers, a failed point): the limit on E from
tub47.md's ten-seed figure and from the sweep's own seeds (uniform fields whose E is worked by
hand), the verdicts, the failed point's row, escaping, and the
page in headless Chromium (figures loaded, the table within the page's width)."""
from __future__ import annotations

import base64
import contextlib
import html
import io
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from vibroflow.scenario.io import load_scenario
from vibroflow.study.sweep_folder import KIND, write_record
from vibroflow.study.sweep_points import FACTOR_KEY, point_name

CHROMIUM = Path(shutil.which("chromium") or "/usr/bin/chromium")
CHROMEDRIVER = Path(shutil.which("chromedriver") or "/usr/bin/chromedriver")
SEEDS = Path(__file__).parent / "data" / "tub47-dem-seeds"
#: a failed point's error, with characters that HTML must escape
ERROR = "BlowUp: balls <12> & 'x' overlap"


def _method(strength, se, sense, E=None, agrees=None):
    m = {"probes": {"P1": {"vx": 0.01, "vx_stderr": 0.001, "vz": 0.0, "vz_stderr": 0.001}},
         "circulation": {"sense": sense, "strength": strength, "strength_stderr": se},
         "impacts": {"ball_ball_mean_normal_speed": 0.1, "ball_wall_mean_normal_speed": 0.2},
         "wall_time_s": 10.0}
    if E is not None:
        m["against_dem"] = {"field_difference_E": E, "circulation_agrees": agrees}
    return m


def make_sweep(out: Path, points: dict, varied=(FACTOR_KEY,), source="tub47",
               fixed=()) -> Path:
    """A sweep folder: points = values -> summary's methods (dict), an error (str) or None
    (not run yet); fixed: the sweep's --set items."""
    base = load_scenario(source, list(fixed)).model_dump(mode="json")
    record = {"kind": KIND, "source": source, "varied": list(varied), "fixed_settings": list(fixed),
              "base": {"scenario": base, "settings": {}, "shear_cell": False}, "points": {}}
    for values, what in points.items():
        vals = dict(zip(varied, values))
        name = point_name(vals)
        folder = out / "points" / name
        folder.mkdir(parents=True)
        record["points"][name] = {"values": vals, "overrides": []}
        if isinstance(what, str):
            (folder / "failed.json").write_text(json.dumps({"error": what}))
        elif what is not None:
            (folder / "summary.json").write_text(json.dumps({"methods": what}))
    write_record(out, record)
    return out


@pytest.fixture
def sweep(tmp_path):
    """Factors 0.5 and 1 finished (the Lagrangian E 0.25, then 0.5), 1.5 failed."""
    return make_sweep(tmp_path / "sweep", {
        (0.5,): {"dem": _method(3.27e-4, 1.4e-5, "counterclockwise"),
                 "lagrangian": _method(3.0e-4, 2e-5, "counterclockwise", 0.25, True)},
        (1.0,): {"dem": _method(5.0e-4, 2e-5, "counterclockwise"),
                 "lagrangian": _method(2.0e-4, 2e-5, "clockwise", 0.5, False)},
        (1.5,): ERROR})


def _rows(page: str) -> dict[tuple[str, str], str]:
    """(point, method) -> the row's HTML."""
    out = {}
    for m in re.finditer(r'<tr class="[^"]*" data-point="([^"]+)"[^>]*>(.*?)</tr>', page, re.S):
        cells = re.findall(r"<td[^>]*>(.*?)</td>", m.group(2), re.S)
        out[(m.group(1), cells[1])] = m.group(2)
    return out


def test_limit_verdicts_and_failed_point_against_known_answers(sweep):
    from PIL import Image

    from vibroflow.report.sweep_report import write_sweep_report

    page = write_sweep_report(sweep).read_text(encoding="utf-8")
    # 1.5 x tub47's floor at each factor (verdict.ENSEMBLE_FLOORS): 0.146, 0.206, 0.160
    limits = [float(v) for v in re.findall(r'data-limit="([^"]+)"', page)]
    assert limits == pytest.approx([0.219, 0.309, 0.24], abs=1e-12)
    rows = _rows(page)
    low, high = point_name({FACTOR_KEY: 0.5}), point_name({FACTOR_KEY: 1.0})
    assert "1.14 x the limit: the flow differs; circulation agrees" in rows[(low, "lagrangian")]
    assert "1.62 x the limit: the flow differs; circulation differs" in rows[(high, "lagrangian")]
    ratio = re.findall(r'data-value="([^"]+)"', rows[(high, "lagrangian")])
    assert any(float(v) == pytest.approx(0.5 / 0.309) for v in ratio)
    assert ">3.27 ± 0.14<" in rows[(low, "dem")]  # 1e-4 m^2/s
    failed = rows[(point_name({FACTOR_KEY: 1.5}), "-")]
    assert ">failed<" in failed and "BlowUp: balls &lt;12&gt; &amp; &#39;x&#39; overlap" in failed
    assert "<12>" not in page
    imgs = re.findall(r'src="data:image/png;base64,([^"]+)"', page)
    assert len(imgs) == 6  # strength, sense, E; probes, impacts, wall time
    for b in imgs:
        assert Image.open(io.BytesIO(base64.b64decode(b))).size[0] > 100
    assert "http" not in page.replace("http-equiv", "")  # no external link


def _uniform_table(path: Path, vx: float, vz: float) -> None:
    """A bulk_velocity.csv of a 6 x 4 grid of 15 mm cells, solid fraction 0.55 and velocity
    (vx, vz) m/s in every cell."""
    rows = ["x,z,solid_fraction,vx,vz,samples"]
    rows += [f"{0.015 * i - 0.0375:.4f},{0.015 * k:.3f},0.55,{vx},{vz},1000"
             for k in range(4) for i in range(6)]
    path.write_text("\n".join(rows) + "\n")


def test_limit_from_the_sweeps_own_seeds(tmp_path):
    """Three points differing only in run.seed, each DEM a uniform field (vx, vz): the limit is
    1.5 x the mean E over the six ordered pairs (tub47.md), each pair's E = |v_a - v_b| / |v_b|
    for uniform fields, worked by hand."""
    from vibroflow.report.sweep_data import SweepData

    v = {1: (0.1, 0.0), 2: (0.1, 0.01), 3: (0.1, -0.01)}  # m/s
    dem = _method(5e-4, 2e-5, "counterclockwise")
    out = make_sweep(tmp_path / "seeds", {(1.0, k): {"dem": dem} for k in v},
                     varied=(FACTOR_KEY, "run.seed"))
    for k, (vx, vz) in v.items():
        dem_dir = out / "points" / point_name({FACTOR_KEY: 1.0, "run.seed": k}) / "dem"
        dem_dir.mkdir()
        _uniform_table(dem_dir / "bulk_velocity.csv", vx, vz)
    data = SweepData.read(out)
    (lim,) = data.limits.values()
    # (a, b): |dvz| / |v_b|; |v_1| = 0.1, |v_2| = |v_3| = sqrt(0.0101) m/s
    s = np.sqrt(0.0101)
    pairs = [0.01 / s, 0.01 / 0.1,   # (1, 2), (2, 1)
             0.01 / s, 0.01 / 0.1,   # (1, 3), (3, 1)
             0.02 / s, 0.02 / s]     # (2, 3), (3, 2)
    assert lim.e_seed == pytest.approx(np.mean(pairs), rel=1e-9)
    assert lim.limit == pytest.approx(1.5 * np.mean(pairs), rel=1e-9)
    assert "6 ordered pairs of this sweep's 3 seeds" in lim.source


def test_no_limit_for_a_changed_case_is_said(tmp_path):
    from vibroflow.report.sweep_report import limits_text
    from vibroflow.report.sweep_data import SweepData

    out = make_sweep(tmp_path / "s", {(1.0, 300): {"dem": _method(5e-4, 2e-5, "clockwise")}},
                     varied=(FACTOR_KEY, "fill.count"))
    ((line, value),) = limits_text(SweepData.read(out))
    assert value is None and line.startswith("No limit on E at ") and "changes fill.count" in line


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "vibroflow.cli", *map(str, args)],
                          capture_output=True, text=True, stdin=subprocess.DEVNULL, timeout=300)


def test_report_command_on_a_sweep_and_on_a_corrupt_one(sweep, tmp_path):
    r = _cli("report", sweep)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == f"sweep report in {sweep / 'report.html'}"
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "sweep.json").write_text("{not json")
    r = _cli("report", bad)
    assert r.returncode == 2 and r.stderr.startswith("error: ") and r.stderr.count("\n") == 1
    assert "corrupt sweep record" in r.stderr and not (bad / "report.html").exists()
    assert "--out" not in r.stderr  # `vibroflow report` takes none


@contextlib.contextmanager
def chromium(page: Path, width: int = 1000):
    """A headless Chromium showing `page` once loaded (skips without the Debian packages)."""
    if not (CHROMIUM.exists() and CHROMEDRIVER.exists()):
        pytest.skip("headless Chromium needs the Debian packages chromium and chromium-driver")
    webdriver = pytest.importorskip("selenium.webdriver")
    from selenium.webdriver.chrome.service import Service
    from selenium.webdriver.support.ui import WebDriverWait

    opts = webdriver.ChromeOptions()
    opts.binary_location = str(CHROMIUM)
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                f"--window-size={width},900"):
        opts.add_argument(arg)
    driver = webdriver.Chrome(service=Service(str(CHROMEDRIVER)), options=opts)
    try:
        driver.set_page_load_timeout(60)
        driver.get(page.resolve().as_uri())
        WebDriverWait(driver, 60, poll_frequency=0.2).until(
            lambda d: d.execute_script("return document.readyState") == "complete")
        yield driver
    finally:
        driver.quit()


def check_rendered(driver, n_images: int, failed: dict[str, str]) -> None:
    """The sweep report as a browser shows it: the headings in order, every figure loaded, the
    table within the page's width (no horizontal scrolling), each failed point's row with its
    reason (failed: point -> a part of its error)."""
    from vibroflow.report.sweep_report import SECTIONS

    heads = driver.execute_script(
        "return Array.from(document.querySelectorAll('h2')).map(h => h.textContent.trim())")
    assert heads == list(SECTIONS.values())
    imgs = driver.execute_script(
        "return Array.from(document.images).map(i => [i.alt, i.complete, i.naturalWidth])")
    assert len(imgs) == n_images and all(i[1] and i[2] > 0 for i in imgs), imgs
    assert {i[0] for i in imgs} >= {"circulation strength against the amplitude factor",
                                    "circulation sense against the amplitude factor",
                                    "field difference E against the amplitude factor"}
    widths = driver.execute_script(
        "const t = document.querySelector('table.sweep');"
        "return [t.scrollWidth, t.parentElement.clientWidth,"
        " document.documentElement.scrollWidth, document.documentElement.clientWidth]")
    assert widths[0] <= widths[1] and widths[2] <= widths[3], widths
    rows = driver.execute_script(
        "return Array.from(document.querySelectorAll('tr.unfinished')).map(r =>"
        " [r.dataset.point, r.dataset.status, r.innerText, r.getBoundingClientRect().height])")
    assert {r[0] for r in rows} == set(failed)
    for point, status, text, height in rows:
        assert status == "failed" and failed[point] in text and height > 0


def test_sweep_report_renders_in_headless_chromium(sweep):
    from vibroflow.report.sweep_report import write_sweep_report

    with chromium(write_sweep_report(sweep), width=900) as driver:
        check_rendered(driver, 6, {point_name({FACTOR_KEY: 1.5}): ERROR})


def _cells(page: str) -> list[list[str]]:
    """Every table row's cells as text (the value in data-value where there is one)."""
    rows = []
    for m in re.finditer(r'<tr class="[^"]*" data-point="[^"]+"[^>]*>(.*?)</tr>', page, re.S):
        rows.append([html.unescape(c) for c in re.findall(r"<td[^>]*>(.*?)</td>", m.group(1),
                                                           re.S)])
    return rows


@pytest.fixture
def seeded(tmp_path):
    """Seeds 1 - 3 at factors 0.5 and 1.0; seed 3 at 1.0 failed. The DEMs at 1.0 are tub47's
    seeds 1 and 2 (their E, 0.106 +- ..., gives the limit there); at 0.5 there are none."""
    dem = {1: 4.0e-4, 2: 5.0e-4, 3: 6.0e-4}
    E = {1: 0.2, 2: 0.3, 3: 0.4}
    points = {}
    for f in (0.5, 1.0):
        for k in (1, 2, 3):
            points[(f, k)] = (ERROR if (f, k) == (1.0, 3) else {
                "dem": _method(dem[k], 2e-5, "counterclockwise"),
                "lagrangian": _method(5.0e-4, 3e-5, "clockwise" if k == 3 else
                                      "counterclockwise", E[k], k != 3)})
    out = make_sweep(tmp_path / "seeded", points, varied=(FACTOR_KEY, "run.seed"))
    for k in (1, 2):
        dem_dir = out / "points" / point_name({FACTOR_KEY: 1.0, "run.seed": k}) / "dem"
        dem_dir.mkdir()
        shutil.copy(SEEDS / f"seed{k}" / "bulk_velocity.csv", dem_dir)
    return out


def test_seeds_pool_into_means_with_standard_errors_by_hand(seeded):
    """Strength 4, 5, 6 (1e-4 m^2/s, each +- 0.2): mean 5, seed-to-seed error 1/sqrt(3), the
    batch errors combined sqrt(3 x 0.2^2)/3 = 0.2/sqrt(3); strength 5, 5, 5 (+- 0.3): no scatter,
    so the error is the batch one, 0.3/sqrt(3). E 0.2, 0.3, 0.4: mean 0.3 +- 0.1/sqrt(3)."""
    from vibroflow.report.sweep_data import SweepData

    data = SweepData.read(seeded)
    pooled = {(r[FACTOR_KEY], r["method"]): r for r in data.pooled if r["status"] == "done"}
    assert set(pooled) == {(0.5, "dem"), (0.5, "lagrangian"), (1.0, "dem"), (1.0, "lagrangian")}
    dem = pooled[(0.5, "dem")]
    assert dem["n_seeds"] == 3 and dem["seeds"] == [1, 2, 3]
    assert dem["circulation_strength"] == pytest.approx(5.0e-4, rel=1e-12)
    assert dem["circulation_strength_stderr_seeds"] == pytest.approx(1e-4 / 3 ** 0.5, rel=1e-12)
    assert dem["circulation_strength_stderr_batch"] == pytest.approx(2e-5 / 3 ** 0.5, rel=1e-12)
    assert dem["circulation_strength_stderr"] == pytest.approx(1e-4 / 3 ** 0.5, rel=1e-12)
    assert dem["circulation_sense"] == "counterclockwise" and dem["sense_mean"] == 1.0
    lag = pooled[(0.5, "lagrangian")]
    assert lag["circulation_strength_stderr_seeds"] == 0.0
    assert lag["circulation_strength_stderr"] == pytest.approx(3e-5 / 3 ** 0.5, rel=1e-12)
    assert lag["E_against_dem"] == pytest.approx(0.3, rel=1e-12)
    assert lag["E_against_dem_stderr"] == pytest.approx(0.1 / 3 ** 0.5, rel=1e-12)
    assert lag["circulation_sense"] == "mixed (1 cw, 2 ccw)"
    assert lag["sense_mean"] == pytest.approx(1.0 / 3.0)
    assert lag["circulation_agrees"] is False
    # factor 1.0: seed 3 failed, so two seeds: E 0.2, 0.3 -> 0.25 +- 0.05
    lag1 = pooled[(1.0, "lagrangian")]
    assert lag1["n_seeds"] == 2 and lag1["circulation_agrees"] is True
    assert lag1["E_against_dem"] == pytest.approx(0.25, rel=1e-12)
    assert lag1["E_against_dem_stderr"] == pytest.approx(0.05, rel=1e-12)
    assert pooled[(1.0, "dem")]["circulation_strength"] == pytest.approx(4.5e-4, rel=1e-12)
    failed = [r for r in data.pooled if r["status"] != "done"]
    assert [(r[FACTOR_KEY], r["run.seed"]) for r in failed] == [(1.0, 3)]


def test_pooled_e_takes_the_larger_of_the_seeds_and_the_batches_errors():
    """E 0.3 +- 0.02 (over its batches) at one seed: no scatter, so the batches' 0.02; two seeds
    of E 0.3 each +- 0.02: no scatter, the batches' combined sqrt(2 x 0.02^2) / 2 = 0.01414;
    E 0.2 and 0.4 +- 0.02: the seeds' scatter 0.1 is the larger."""
    from vibroflow.report.sweep_pool import pool_group

    def row(E, se, seed):
        return {"method": "lagrangian", "status": "done", "point": f"p{seed}",
                "run.seed": seed, "E_against_dem": E, "E_against_dem_stderr": se,
                "circulation_strength": 1e-3, "circulation_strength_stderr": 1e-5}

    one = pool_group([row(0.3, 0.02, 1)], {"method": "lagrangian"})
    assert one["E_against_dem"] == 0.3 and one["E_against_dem_stderr"] == 0.02
    two = pool_group([row(0.3, 0.02, 1), row(0.3, 0.02, 2)], {"method": "lagrangian"})
    assert two["E_against_dem_stderr"] == pytest.approx(0.02 / 2 ** 0.5, rel=1e-12)
    apart = pool_group([row(0.2, 0.02, 1), row(0.4, 0.02, 2)], {"method": "lagrangian"})
    assert apart["E_against_dem_stderr"] == pytest.approx(0.1, rel=1e-12)


def test_seeded_sweep_report_shows_pooled_rows_and_their_limit(seeded):
    """The page: one row per factor and method with n seeds, the pooled E judged against the
    limit from the two DEM seeds at 1.0 (1.5 x their E; tub47 seeds 1 and 2); at 0.5 no DEM
    fields, so no limit there."""
    from vibroflow.report.sweep_data import SweepData
    from vibroflow.report.sweep_report import write_sweep_report

    lim = SweepData.read(seeded).limits[(1.0,)]
    assert "2 ordered pairs of this sweep's 2 seeds" in lim.source
    page = write_sweep_report(seeded).read_text(encoding="utf-8")
    rows = _cells(page)
    done = {(r[0], r[2]): r for r in rows if len(r) > 5}
    assert set(done) == {("0.5", "dem"), ("0.5", "lagrangian"), ("1", "dem"),
                         ("1", "lagrangian")}
    assert done[("0.5", "dem")][1] == "3" and done[("1", "lagrangian")][1] == "2"
    assert done[("0.5", "dem")][5].startswith("5.00 ± 0.58 (seeds ± 0.58, batch ± 0.12)")
    assert done[("0.5", "lagrangian")][6] == "0.300 ± 0.058"
    assert done[("1", "lagrangian")][6] == "0.250 ± 0.050"
    ratio = 0.25 / lim.limit
    assert done[("1", "lagrangian")][7] == f"{ratio:.2f}"
    assert "circulation agrees" in done[("1", "lagrangian")][8]
    assert "no limit known for this case: not judged" in done[("0.5", "lagrangian")][8]
    (failed,) = [r for r in rows if len(r) <= 5]
    assert failed[1:4] == ["1", "-", "failed"] and failed[4].startswith("run.seed = 3: BlowUp")
    assert "<12>" not in page


def test_seeded_sweep_report_renders_in_headless_chromium(seeded):
    from vibroflow.report.sweep_report import write_sweep_report

    point = point_name({FACTOR_KEY: 1.0, "run.seed": 3})
    with chromium(write_sweep_report(seeded), width=900) as driver:
        check_rendered(driver, 6, {point: ERROR})


def test_a_changed_case_is_judged_by_the_study_pages_rule(tmp_path):
    """verdict.preset_limit on both pages: tub47-quick at factor 1.0 as it is has the limit
    1.5 x 0.166 = 0.249 (docs/validation.md section 16); with run.duration changed it has none
    and the reason names the setting; at 0.5 no figure is known."""
    from vibroflow.report.sweep_data import SweepData

    methods = {"dem": _method(5e-4, 2e-5, "counterclockwise"),
               "lagrangian": _method(4e-4, 2e-5, "counterclockwise", 0.2, True)}
    same = SweepData.read(make_sweep(tmp_path / "a", {(0.5,): methods, (1.0,): methods},
                                     source="tub47-quick"))
    assert same.limits[(1.0,)].limit == pytest.approx(0.249, abs=1e-12)
    assert "no ensemble figure" in same.no_limit[(0.5,)]
    changed = SweepData.read(make_sweep(tmp_path / "b", {(1.0,): methods},
                                        source="tub47-quick",
                                        fixed=["run.duration=1.2"]))
    assert not changed.limits and "changes run.duration" in changed.no_limit[(1.0,)]


def test_impacts_carry_their_errors_and_wall_times_three_figures(tmp_path):
    from vibroflow.report.sweep_report import write_sweep_report

    m = _method(5e-4, 2e-5, "counterclockwise")
    m["impacts"].update(ball_ball_mean_normal_speed_stderr=0.0123,
                        ball_wall_mean_normal_speed_stderr=0.004)
    m["wall_time_s"] = 0.4644
    lag = _method(4e-4, 2e-5, "counterclockwise", 0.2, True)
    lag["wall_time_s"] = 12.34
    page = write_sweep_report(make_sweep(tmp_path / "s", {(1.0,): {"dem": m,
                                                                    "lagrangian": lag}}))
    rows = {r[1]: r for r in _cells(page.read_text(encoding="utf-8"))}
    assert rows["dem"][8] == "0.100 ± 0.012 / 0.2000 ± 0.0040"
    assert rows["lagrangian"][8] == "0.100 / 0.200"  # no error in its summary
    assert (rows["dem"][9], rows["lagrangian"][9]) == ("0.464", "12.3")


def test_unfinished_points_are_explained_by_their_status(tmp_path):
    """A pending point is 'not run yet' (it has no failed.json); a failed one names its
    failed.json; a sweep without sweep.csv does not send the reader there."""
    from vibroflow.report.sweep_report import write_sweep_report

    out = make_sweep(tmp_path / "s", {(0.5,): ERROR, (1.0,): None})
    page = " ".join(write_sweep_report(out).read_text(encoding="utf-8").split())
    pending, failed = point_name({FACTOR_KEY: 1.0}), point_name({FACTOR_KEY: 0.5})
    assert f"<b>{pending}</b>: pending: not run yet</li>" in page
    assert f"(points/{failed}/failed.json holds the error)" in page
    assert page.count("failed.json") == 1 and "sweep.csv" not in page
