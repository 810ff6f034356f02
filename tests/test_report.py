"""The study report (DIR/report.html, `vibroflow report DIR`): the helpers against known
answers (the shear rate of analytic flows, impacts binned by cell against the DEM summary's own
count and mean), and the page of a tiny study (tests.conftest's study fixture, which ends with
the report stage): self-contained, every image a valid PNG/GIF, the probe table equal to
summary.json, rendered by headless Chromium with every figure loaded; bad folders are a one-line
error that writes nothing."""
from __future__ import annotations

import base64
import io
import json
import math
import os
import re
import shutil
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path

import h5py
import numpy as np
import pytest


# Debian's packages chromium and chromium-driver
CHROMIUM = Path(shutil.which("chromium") or "/usr/bin/chromium")
CHROMEDRIVER = Path(shutil.which("chromedriver") or "/usr/bin/chromedriver")


# ----------------------------------------------------------------------------------------------
# known answers

def test_mean_flow_shear_rate_of_analytic_flows():
    """gamma_dot = sqrt(2 D':D') with the 3D deviator: simple shear v_x = g z gives g, a rigid
    rotation 0, plane extension v = (e x, -e z) gives 2 e, on every cell (linear fields: the
    one-sided differences at the edges are exact too)."""
    from vibroflow.report.data import mean_flow_shear_rate

    h = 0.015
    x = np.arange(-4, 5) * h
    z = np.arange(0, 7) * h
    X, Z = np.meshgrid(x, z)  # [z, x], as field_dataset's arrays
    g, w, e = 3.0, 5.0, 2.0
    np.testing.assert_allclose(mean_flow_shear_rate(g * Z, 0 * X, h), g, rtol=1e-12)
    np.testing.assert_allclose(mean_flow_shear_rate(-w * Z, w * X, h), 0.0, atol=1e-12)
    np.testing.assert_allclose(mean_flow_shear_rate(e * X, -e * Z, h), 2 * e, rtol=1e-12)
    # cells outside the bed (NaN velocity) stay NaN; their neighbours use one-sided differences
    vx = g * Z
    vx[3, 4] = np.nan
    out = mean_flow_shear_rate(vx, 0 * X, h)
    assert np.isnan(out[3, 4])
    np.testing.assert_allclose(np.delete(out.ravel(), 3 * x.size + 4), g, rtol=1e-12)


def test_impacts_binned_by_analysis_cell():
    """Impacts land in the cell whose centre (a multiple of h) is nearest, chunks add up."""
    from vibroflow.report.data import bin_impacts

    h = 0.015
    pos = np.array([[0.001, 0.01, 0.002], [-0.007, 0.0, 0.007], [0.008, 0.0, 0.0],
                    [0.031, 0.0, 0.046]])
    speed = np.array([0.1, 0.3, 0.5, 0.7])
    cells = bin_impacts([(pos[:2], speed[:2]), (pos[2:], speed[2:])], h)
    assert cells.at(0.0, 0.0) == (pytest.approx(0.2), 2)       # first two: cell (0, 0)
    assert cells.at(0.015, 0.0) == (pytest.approx(0.5), 1)     # x = 8 mm > h/2
    assert cells.at(0.03, 0.045) == (pytest.approx(0.7), 1)
    v, n = cells.at(-0.03, 0.03)
    assert math.isnan(v) and n == 0
    assert int(cells.count.sum()) == 4
    assert math.isnan(cells.stderr_at(0.0, 0.0))  # no batches given: no error


def test_impacts_binned_by_batch_carry_the_batch_means_error():
    """Cell (0, 0) holds batch means 0.1, 0.3 and 0.5 (batches 0, 1, 2; two impacts in batch 1):
    its mean is over the impacts (0.1 + 0.2 + 0.4 + 0.5) / 4 = 0.3, its standard error the
    batch means' std / sqrt(3) = 0.2 / sqrt(3); a cell with impacts in one batch only has none.
    Without each batch in turn the cell's mean is (0.2 + 0.4 + 0.5) / 3, (0.1 + 0.5) / 2 and
    (0.1 + 0.2 + 0.4) / 3; the other cell, whose only batch is 1, has none without it."""
    from vibroflow.report.data import bin_impacts

    h = 0.015
    pos = np.array([[0.0, 0.0, 0.0], [0.001, 0.0, 0.0], [0.0, 0.0, 0.001], [0.002, 0.0, 0.0],
                    [0.03, 0.0, 0.0]])
    speed = np.array([0.1, 0.2, 0.4, 0.5, 0.9])
    batch = np.array([0, 1, 1, 2, 1])
    cells = bin_impacts([(pos[:3], speed[:3], batch[:3]), (pos[3:], speed[3:], batch[3:])], h)
    assert cells.at(0.0, 0.0) == (pytest.approx(0.3), 4)
    assert cells.stderr_at(0.0, 0.0) == pytest.approx(0.2 / math.sqrt(3.0), rel=1e-12)
    assert cells.at(0.03, 0.0) == (pytest.approx(0.9), 1)
    assert math.isnan(cells.stderr_at(0.03, 0.0))
    assert math.isnan(cells.stderr_at(0.3, 0.3))
    np.testing.assert_allclose(cells.left_out_at(0.0, 0.0), [1.1 / 3, 0.3, 0.7 / 3], rtol=1e-12)
    far = cells.left_out_at(0.03, 0.0)
    assert far[0] == pytest.approx(0.9) and math.isnan(far[1]) and far[2] == pytest.approx(0.9)
    assert cells.left_out_at(0.3, 0.3) is None


def test_report_impacts_are_the_summarys_impacts(study):
    """The impact map counts exactly the ball-ball impacts the DEM summary averages (another
    code path: vibroflow.measure.contacts.impact_stats_chunked), with the same mean speed."""
    from vibroflow.report.data import StudyData

    _, out, summary, _ = study
    data = StudyData.read(out)
    im = summary["methods"]["dem"]["impacts"]
    cells = data.impacts
    assert int(cells.count.sum()) == im["count_by_kind"]["ball_ball"]
    mean = float(np.sum(cells.mean_speed * cells.count) / cells.count.sum())
    assert mean == pytest.approx(im["ball_ball_mean_normal_speed"], rel=1e-6)


def test_impact_distributions_are_the_summarys_impacts(study):
    """The distributions count every kind's impacts the DEM summary averages, with its mean and
    standard error (another code path: vibroflow.measure.contacts.impact_stats_chunked); the
    U's and the partitions' profiles hold all of theirs; the flags compare the summary's
    inferred and measured speeds."""
    from vibroflow.report.data import StudyData
    from vibroflow.measure.stats import jackknife_stderr
    from vibroflow.report.impact_figures import read_distributions, speed_comparisons

    _, out, summary, _ = study
    data = StudyData.read(out)
    dist, why = read_distributions(data)
    assert why is None
    im = summary["methods"]["dem"]["impacts"]
    for kind, n in im["count_by_kind"].items():
        s = dist.stats[kind]
        assert s.count == n
        if n:
            assert s.mean == pytest.approx(im["mean_normal_speed_by_kind"][kind], rel=1e-9)
            assert s.median < s.p95
    for key in ("ball_ball", "ball_wall"):
        want = im[f"{key}_mean_normal_speed_stderr"]
        if want is not None and math.isfinite(want):
            assert dist.stats[key].mean_stderr == pytest.approx(want, rel=1e-6)
    assert int(dist.u.count.sum()) == im["count_by_kind"]["ball_wall"]
    assert int(dist.partitions.count.sum()) == im["count_by_kind"]["ball_partition"]
    for row in speed_comparisons(data):
        if row["where"] == "bed mean" and row["flagged"] is not None:
            key = "ball_ball" if row["kind"] == "ball-ball" else "ball_wall"
            m = summary["methods"][row["method"]]["impacts"][f"{key}_mean_normal_speed"]
            d = im[f"{key}_mean_normal_speed"]
            assert row["flagged"] == (abs(m - d) > 0.25 * d)
            # the inferred speed's error: the run's and the calibrated relation's, independent;
            # the relation's is the straight line's prediction error at the run's shear rate,
            # worked here from calibration.toml's cell fit and the run's own summary
            own = summary["methods"][row["method"]]["impacts"]
            fit = getattr(data.calibration.impacts, key)
            rate = data.continuum_block(row["method"])["shear_rate"][
                "mean_1_s" if key == "ball_ball" else "near_wall_1_s"]
            x = data.diameter * rate
            relation = math.sqrt(fit.c0_cells_stderr_m_s ** 2 + (x * fit.c1_cells_stderr) ** 2
                                 + 2.0 * x * fit.c0_c1_cells_covariance_m_s)
            assert own[f"{key}_mean_normal_speed_relation_stderr"] == pytest.approx(
                relation, rel=1e-9)
            run = own[f"{key}_mean_normal_speed_stderr"]
            assert row["inferred_stderr"] == pytest.approx(math.hypot(run, relation), rel=1e-9)
            # the relation was calibrated on this DEM run: its covariance with the measured
            # mean, worked from calibration.toml, comes off the difference's variance
            assert fit.mean_normal_speed_m_s == pytest.approx(d, rel=1e-12)
            cov = (fit.c0_cells_measured_covariance_m2_s2
                   + x * fit.c1_cells_measured_covariance_m_s)
            q, sd = m / d, im[f"{key}_mean_normal_speed_stderr"]
            var = row["inferred_stderr"] ** 2 + (q * sd) ** 2 - 2.0 * q * cov
            assert row["relative_stderr"] == pytest.approx(math.sqrt(max(var, 0.0)) / d,
                                                           rel=1e-9)
            # the refits without each batch that the probe cells' covariance needs give back
            # the jackknife's errors they come from
            assert len(fit.c0_cells_left_out_m_s) == data.scenario.run.batches
            assert jackknife_stderr(fit.c0_cells_left_out_m_s) == pytest.approx(
                fit.c0_cells_stderr_m_s, rel=1e-9)
            assert jackknife_stderr(fit.c1_cells_left_out) == pytest.approx(
                fit.c1_cells_stderr, rel=1e-9)


# ----------------------------------------------------------------------------------------------
# the page

class _Page(HTMLParser):
    def __init__(self):
        super().__init__()
        self.imgs, self.links, self.tags, self.h2, self.cells = [], [], [], [], []
        self._h2 = self._td = None

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        self.tags.append(tag)
        if tag == "img":
            self.imgs.append(a.get("src", ""))
        for key in ("src", "href"):
            if key in a:
                self.links.append(a[key] or "")
        if tag == "h2":
            self._h2 = ""
        if tag == "td" and "data-probe" in a:
            self._td = [a, ""]

    def handle_data(self, d):
        if self._h2 is not None:
            self._h2 += d
        if self._td is not None:
            self._td[1] += d

    def handle_endtag(self, tag):
        if tag == "h2" and self._h2 is not None:
            self.h2.append(self._h2.strip())
            self._h2 = None
        if tag == "td" and self._td is not None:
            self.cells.append(tuple(self._td))
            self._td = None


def _cli(*args):
    env = dict(os.environ, NO_COLOR="1")
    return subprocess.run([sys.executable, "-m", "vibroflow.cli", *map(str, args)],
                          capture_output=True, text=True, env=env, stdin=subprocess.DEVNULL)


def _half_last_digit(text: str) -> float:
    """Half a unit of the last digit a number's text shows ("0.0011": 5e-5)."""
    mantissa, _, exponent = text.lower().partition("e")
    decimals = len(mantissa.partition(".")[2])
    return 0.5 * 10.0 ** (int(exponent or 0) - decimals)


def test_report_is_self_contained_and_shows_the_summary(study):
    from PIL import Image

    from vibroflow.report.animation import MAX_FRAMES
    from vibroflow.report.html import SECTIONS

    _, out, summary, _ = study
    assert json.loads((out / "report" / "stage.json").read_text())["stage"] == "report"
    before = (out / "report.html").stat().st_mtime_ns
    r = _cli("report", out)  # the command rewrites the page the pipeline's stage wrote
    assert r.returncode == 0, r.stderr
    assert (out / "report.html").stat().st_mtime_ns != before
    assert not [p for p in out.rglob("*") if ".tmp" in p.name]  # written atomically
    page = _Page()
    page.feed((out / "report.html").read_text(encoding="utf-8"))
    assert page.h2[:len(SECTIONS)] == list(SECTIONS.values())
    text = (out / "report.html").read_text(encoding="utf-8")
    for name in ("lagrangian", "eulerian"):  # the study's continua carry no temperature
        assert f"{name} ran without the granular temperature" in text
    assert "script" not in page.tags and "link" not in page.tags
    assert not [u for u in page.links if re.match(r"\s*(https?:)?//", u, re.I)]
    gifs = []
    for src in page.imgs:
        m = re.fullmatch(r"data:image/(png|gif);base64,([A-Za-z0-9+/=]+)", src)
        assert m, src[:60]
        raw = base64.b64decode(m.group(2), validate=True)
        with Image.open(io.BytesIO(raw)) as im:
            im.verify()
        with Image.open(io.BytesIO(raw)) as im:
            assert im.format == m.group(1).upper() and im.width > 0 and im.height > 0
            if im.format == "GIF":
                assert 300 <= im.width <= 500
                gifs.append(im.n_frames)
    # velocity, shear, impacts, wall friction, mu(I), the animation
    assert len(page.imgs) >= 6
    with h5py.File(out / "dem" / "dem.h5", "r") as f:
        snaps = f["snapshots/time"].shape[0]
    assert gifs == [min(MAX_FRAMES, snaps)]  # one animation, a frame per snapshot
    assert (out / "report" / "dem_slice.gif").stat().st_size < 3e6
    # the probe table holds summary.json's numbers (exact in data-value, rounded in the text)
    methods = summary["methods"]
    seen = 0
    for attrs, text in page.cells:
        name, probe, q = attrs["data-method"], attrs["data-probe"], attrs["data-q"]
        if q in ("vx", "vz"):
            want = methods[name]["probes"][probe][q]
            se = methods[name]["probes"][probe][q + "_stderr"]
        else:
            d = methods[name]["against_dem"]["probe_differences_m_s"][probe]
            want, se = d[q], d[q + "_stderr"]
            # two independent runs: the difference's error is their errors in quadrature
            a, b = methods[name]["probes"][probe], methods["dem"]["probes"][probe]
            v = q[1:]
            if se is not None:
                assert se == pytest.approx(math.hypot(a[v + "_stderr"], b[v + "_stderr"]),
                                           rel=1e-12)
        assert float(attrs["data-value"]) == want
        shown = text.split("±")[0].strip()
        # rounded to the error's place (report.numbers) or to four figures without an error
        assert float(shown) == pytest.approx(want, rel=1e-3, abs=_half_last_digit(shown))
        if se is not None and math.isfinite(se):
            assert float(attrs["data-stderr"]) == se
        seen += 1
    n_probes = len(methods["dem"]["probes"])
    assert seen == n_probes * (2 + 4 * (len(methods) - 1))
    assert "No sweep in this folder" in (out / "report.html").read_text()
    # the continua's profiles and turnover times carry batch-means standard errors over the
    # same batches as the DEM's (their bulk_velocity_batches.csv)
    html = (out / "report.html").read_text(encoding="utf-8")
    flat = " ".join(html.split())
    assert "no error bars (no batches" not in flat
    assert f"batches of whole cycles ({', '.join(methods)}: the DEM's from" in flat
    turnover = {re.search(r'data-method="(\w+)"', tag).group(1): tag for tag in
                re.findall(r"<td[^>]*turnover_s[^>]*>", html)}
    assert set(turnover) == set(methods)
    timed = [name for name, tag in turnover.items()
             if math.isfinite(float(re.search(r'data-value="([^"]*)"', tag).group(1)))]
    assert "dem" in timed and set(timed) - {"dem"}  # a continuum with a roll's core
    for name in timed:
        se = re.search(r'data-stderr="([^"]*)"', turnover[name])
        assert se and math.isfinite(float(se.group(1))) and float(se.group(1)) >= 0, name
    # the DEM's bulk_velocity_batches.csv holds its snapshots' batches: the table rebuilt from
    # dem.h5 (cell_tables.dem_batch_table) has the file's cells and batch means, and E's error
    # over the two runs' batches is the same from either
    from vibroflow.analysis.compare import field_difference_stderr
    from vibroflow.report.cell_tables import csv_table, dem_batch_table
    from vibroflow.report.data import StudyData
    data = StudyData.read(out)
    filed, rebuilt = csv_table(data, "dem"), dem_batch_table(data)
    assert filed.n_batches == rebuilt.n_batches == data.scenario.run.batches
    assert np.array_equal(filed.ix, rebuilt.ix) and np.array_equal(filed.iz, rebuilt.iz)
    for key in ("batch_vx", "batch_vz", "batch_phi"):
        np.testing.assert_allclose(getattr(filed, key), getattr(rebuilt, key), rtol=1e-6,
                                   atol=1e-12, equal_nan=True, err_msg=key)
    table = re.search(r'<table class="circulation">(.*?)</table>', html, re.S).group(1)
    for name in [n for n in methods if n != "dem"]:
        row = re.search(rf"<tr><td[^>]*>{name}</td>(.*?)</tr>", table, re.S).group(1)
        shown = float(re.findall(r'data-stderr="([^"]*)"', row)[1])  # strength's, then E's
        want = summary["methods"][name]["against_dem"]["field_difference_E_stderr"]
        assert want > 0 and shown == pytest.approx(want, rel=1e-9), name
        cont = csv_table(data, name)
        assert field_difference_stderr(cont, rebuilt, data.min_solid_fraction) == \
            pytest.approx(want, rel=1e-4), name
    # the difference table's rms carries its error over both runs' batches; the max none
    for name in [n for n in methods if n != "dem"]:
        rms = re.search(rf'<td[^>]*data-method="{name}"[^>]*data-q="rms_dv"[^>]*>', html) or \
            re.search(rf'<td[^>]*data-q="rms_dv"[^>]*data-method="{name}"[^>]*>', html)
        se = re.search(r'data-stderr="([^"]*)"', rms.group(0))
        assert se and 0 < float(se.group(1)) < float(
            re.search(r'data-value="([^"]*)"', rms.group(0)).group(1)), name


def test_report_renders_in_headless_chromium(study):
    if not (CHROMIUM.exists() and CHROMEDRIVER.exists()):
        pytest.skip("headless Chromium needs the Debian packages chromium and chromium-driver "
                    f"({CHROMIUM}, {CHROMEDRIVER})")
    webdriver = pytest.importorskip("selenium.webdriver", reason="selenium not installed "
                                    "(pip install -e '.[test]')")
    from selenium.webdriver.chrome.service import Service

    from vibroflow.report.html import SECTIONS

    _, out, _, _ = study
    opts = webdriver.ChromeOptions()
    opts.binary_location = str(CHROMIUM)
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                "--window-size=1400,1000"):
        opts.add_argument(arg)
    driver = webdriver.Chrome(service=Service(str(CHROMEDRIVER)), options=opts)
    try:
        driver.set_page_load_timeout(60)
        driver.get((out / "report.html").resolve().as_uri())
        # driver.get returned before the load event on the CI machine (large embedded images):
        # wait for it, as a reader's browser would, up to the page-load timeout
        from selenium.webdriver.support.ui import WebDriverWait
        WebDriverWait(driver, 60, poll_frequency=0.2).until(
            lambda d: d.execute_script("return document.readyState") == "complete")
        imgs = driver.execute_script(
            "return Array.from(document.images).map(i => [i.alt, i.complete, i.naturalWidth,"
            " i.naturalHeight])")
        assert len(imgs) >= 6
        bad = [i for i in imgs if not (i[1] and i[2] > 0 and i[3] > 0)]
        assert not bad, bad
        heads = driver.execute_script(
            "return Array.from(document.querySelectorAll('h2')).map(h => h.textContent.trim())")
        assert heads[:len(SECTIONS)] == list(SECTIONS.values())
        # impact speed distributions: histograms and the wall map drawn, the statistics table,
        # and the flags (red where a continuum's inferred speed is off by more than a quarter)
        sec = driver.execute_script(
            "const s = document.getElementById('impact_distributions');"
            "return [Array.from(s.querySelectorAll('img')).map(i => [i.alt, i.naturalWidth]),"
            " s.querySelectorAll('table.impact-stats tr').length,"
            " Array.from(s.querySelectorAll('td[data-flag]')).map(c => [c.dataset.flag,"
            " c.textContent, getComputedStyle(c).color])]")
        imgs, stat_rows, flags = sec
        assert [a for a, _ in imgs] == ["impact-speed histograms",
                                        "ball-wall impacts along the U"]
        assert all(w > 0 for _, w in imgs)
        assert stat_rows >= 3  # the head, ball-ball and at least one wall kind
        for flag, text, colour in flags:
            if flag == "true":
                assert "FLAG" in text and colour == "rgb(180, 35, 24)"  # .bad
            elif flag == "false":
                assert "within a quarter" in text
        if flags:
            said = driver.execute_script(
                "return document.getElementById('impact-flag-count').textContent")
            n_true = sum(f == "true" for f, _, _ in flags)
            n_compared = sum(f in ("true", "false") for f, _, _ in flags)
            assert " ".join(said.split()).startswith(f"{n_true} of {n_compared} inferred")
        # the engineer's sections: every figure drawn, the E limit and a verdict beside E
        for sid in ("differences", "profiles", "bed", "rheology_bins"):
            assert driver.execute_script(
                f"const i = document.querySelector('#{sid} img'); "
                "return i !== null && i.complete && i.naturalWidth > 0"), sid

        def text(sid):
            return driver.execute_script(f"return document.getElementById('{sid}').innerText")
        # the study's short window changes the preset's flow: its E limit is none, and said
        assert "E limit" in text("circulation") and "not judged" in text("circulation")
        assert "Γ = A_z ω² / g" in text("bed") and "turnover time (s)" in text("bed")
        assert "mean mu ± standard error" in text("rheology_bins")
    finally:
        driver.quit()


@pytest.mark.slow
def test_report_of_a_bad_folder_is_a_one_line_error(tmp_path):
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("mine\n")
    corrupt = tmp_path / "corrupt"
    corrupt.mkdir()
    (corrupt / "study.json").write_text(json.dumps({"kind": "vibroflow study"}))
    (corrupt / "summary.json").write_text("{not json")
    unfinished = tmp_path / "unfinished"
    unfinished.mkdir()
    (unfinished / "study.json").write_text(json.dumps({"kind": "vibroflow study"}))
    missing = tmp_path / "missing"
    # valid JSON that is not a study's summary
    odd = tmp_path / "odd"
    odd.mkdir()
    (odd / "study.json").write_text(json.dumps({"kind": "vibroflow study"}))
    (odd / "summary.json").write_text(json.dumps({"methods": {"dem": {"probes": 3}}}))
    for folder in (foreign, corrupt, unfinished, missing, odd):
        before = sorted(p.name for p in folder.iterdir()) if folder.exists() else None
        r = _cli("report", folder)
        assert r.returncode == 2, (folder, r.stderr)
        assert r.stderr.startswith("error: ") and r.stderr.count("\n") == 1, r.stderr
        assert "Traceback" not in r.stderr
        assert str(folder) in r.stderr  # the line names the folder (or its file)
        after = sorted(p.name for p in folder.iterdir()) if folder.exists() else None
        assert after == before  # nothing written
    assert not missing.exists()


def test_missing_pieces_are_stated_and_a_sweep_point_shows_its_sweep(study, tmp_path):  # noqa: E501
    """Optional pieces missing (no dem.h5: no animation, no measured impacts; no fields.nc; no
    calibration pictures) are stated in the page, not a crash; a study that is a point of a
    sweep (SWEEP/points/NAME, `vibroflow sweep`) shows the sweep's plots and table."""
    from PIL import Image

    from vibroflow.report import write_report

    _, out, _, _ = study
    sweep = tmp_path / "sweep"
    copy = sweep / "points" / "factor-1"
    shutil.copytree(out, copy, ignore=shutil.ignore_patterns("dem.h5", "fields.nc", "*.png",
                                                             "report*"))
    (sweep / "sweep.json").write_text(json.dumps({"kind": "vibroflow sweep"}))
    (sweep / "sweep.csv").write_text("point,method,circulation_strength\n"
                                     "factor-1,dem,0.00073\nfactor-1,lagrangian,0.0017\n")
    (sweep / "plots").mkdir()
    Image.new("RGB", (40, 30), "white").save(sweep / "plots" / "sweep_circulation.png")
    page = write_report(copy).read_text(encoding="utf-8")
    assert "No animation" in page
    assert "No measured impact distributions: no dem/dem.h5" in page
    assert "mu_I.png is missing" in page
    assert "no calibration/fields.nc" in page
    assert "No binned mu(I): no calibration/fields.nc" in page
    assert "records no kinetic energy" in page
    assert "the DEM result holds no impacts" not in page and "no measured impacts" in page
    assert not (copy / "report" / "dem_slice.gif").exists()
    assert "No sweep in this folder" not in page
    # a point's page links to its sweep's own page, the one the sweep keeps up to date
    assert 'class="sweep-point"' in page and 'href="../../report.html"' in page
    assert "<b>factor-1</b>" in page and '<td class="l">factor-1</td>' not in page


def test_the_e_limit_is_measured_on_the_studys_dem_seeds(study, tmp_path):
    """A second DEM seed in DIR/dem-seeds/ whose velocities are 1.1 times the study's DEM's:
    tub47.md's E(a, b) = sqrt(sum phi |v_a - v_b|^2 / sum phi) / (sum phi |v_b| / sum phi) is
    0.1 R / 1.1 one way and 0.1 R the other, R = rms |v| / mean |v| (phi-weighted, cells with
    phi >= 0.3); the seed-to-seed E is their mean, the limit 1.5 times that, and the page says
    it was measured."""
    from vibroflow.report import write_report

    _, out, _, _ = study
    copy = tmp_path / "run"
    shutil.copytree(out, copy, ignore=shutil.ignore_patterns("*.png", "report*"))
    seed = copy / "dem-seeds" / "seed2"
    seed.mkdir(parents=True)
    shutil.copy(out / "dem" / "summary.json", seed / "summary.json")
    lines = (out / "dem" / "bulk_velocity.csv").read_text().splitlines()
    head = lines[0].split(",")
    ix, iz = head.index("vx"), head.index("vz")
    rows = [lines[0]]
    w, sp = [], []
    for line in lines[1:]:
        p = line.split(",")
        phi = float(p[head.index("solid_fraction")])
        if phi >= 0.3:
            w.append(phi)
            sp.append(math.hypot(float(p[ix]), float(p[iz])))
        p[ix], p[iz] = repr(1.1 * float(p[ix])), repr(1.1 * float(p[iz]))
        rows.append(",".join(p))
    (seed / "bulk_velocity.csv").write_text("\n".join(rows) + "\n")
    page = write_report(copy).read_text(encoding="utf-8")
    w, sp = np.array(w), np.array(sp)
    R = math.sqrt(np.sum(w * sp**2) / np.sum(w)) / (np.sum(w * sp) / np.sum(w))
    want = 1.5 * 0.5 * (0.1 * R / 1.1 + 0.1 * R)
    limits = re.findall(r'data-q="E_limit" data-value="([^"]+)"', page)
    assert limits and all(float(v) == pytest.approx(want, rel=1e-6) for v in limits)
    assert "measured on the study&#39;s 2 DEM seeds" in page


def _study_with_parts(out: Path, new: Path) -> Path:
    """A view of the study `out` in `new` (links to its files, its method and report folders
    real) with a synthetic parts.nc (tests.test_report_parts) in dem/ and lagrangian/, of a
    part whose name needs escaping."""
    from tests.test_report_parts import synthetic_parts
    from vibroflow.io.parts_file import write_parts

    new.mkdir()
    for p in out.iterdir():
        if p.is_dir() and p.name in ("dem", "lagrangian", "eulerian", "report"):
            (new / p.name).mkdir()
            for q in p.iterdir():
                (new / p.name / q.name).symlink_to(q.resolve())
        elif p.name != "report.html":
            (new / p.name).symlink_to(p.resolve())
    for method, speed in (("dem", 0.2), ("lagrangian", 0.25)):
        write_parts(new / method / "parts.nc", synthetic_parts(method, "bar<&>", speed))
    return new


@pytest.mark.slow
def test_report_has_a_section_per_part_with_its_name_escaped(study, tmp_path):
    """The tiny study with parts.nc in two of its methods' folders: one section per part after
    the fixed ones, its name escaped, the table's values the files' (data-value), the missing
    Eulerian file said; rendered by headless Chromium with its figures drawn."""
    from vibroflow.report.html import SECTIONS

    _, out, _, _ = study
    new = _study_with_parts(out, tmp_path / "study")
    r = _cli("report", new)
    assert r.returncode == 0, r.stderr
    html = (new / "report.html").read_text(encoding="utf-8")
    page = _Page()
    page.feed(html)
    assert page.h2[:len(SECTIONS)] == list(SECTIONS.values())
    assert "Part bar<&>" in page.h2
    assert "bar&lt;&amp;&gt;" in html and "bar<&>" not in html
    assert "eulerian: no parts.nc" in html
    values = re.findall(r'<table class="part-patches">.*?</table>', html, re.S)[0]
    first = re.findall(r'data-value="([^"]*)"', values.split("</tr>")[1])
    # area, DEM 0.2, lagrangian 0.25, difference 0.05, DEM rate 1e4, energy flux 3
    assert [float(v) for v in first] == pytest.approx(
        [2 * math.pi * 0.0125 / 36 * 0.019, 0.2, 0.25, 0.05, 1e4, 3.0])
    if not (CHROMIUM.exists() and CHROMEDRIVER.exists()):
        return
    webdriver = pytest.importorskip("selenium.webdriver")
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = str(CHROMIUM)
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage"):
        opts.add_argument(arg)
    driver = webdriver.Chrome(service=Service(str(CHROMEDRIVER)), options=opts)
    try:
        driver.set_page_load_timeout(60)
        driver.get((new / "report.html").resolve().as_uri())
        from selenium.webdriver.support.ui import WebDriverWait
        WebDriverWait(driver, 60, poll_frequency=0.2).until(
            lambda d: d.execute_script("return document.readyState") == "complete")
        imgs = driver.execute_script(
            "const s = document.getElementById('part-1');"
            "return [s.querySelector('h2').textContent,"
            " Array.from(s.querySelectorAll('img')).map(i => [i.complete, i.naturalWidth])]")
        assert imgs[0] == "Part bar<&>"
        assert len(imgs[1]) == 2 and all(c and w > 0 for c, w in imgs[1])
    finally:
        driver.quit()


def _floor_cells(html: str) -> dict:
    """The floor section's take-off cells: method -> data-value."""
    sec = re.search(r'<section id="floor">.*?</section>', html, re.S).group(0)
    table = re.search(r'<table class="floor">.*?</table>', sec, re.S).group(0)
    rows = re.findall(r"<tr>(.*?)</tr>", table, re.S)[1:]
    out = {}
    for row in rows:
        cells = re.findall(r"<td([^>]*)>(.*?)</td>", row, re.S)
        out[cells[0][1]] = re.search(r'data-value="([^"]*)"', cells[1][0]).group(1)
    return out


def test_the_floor_section_shows_each_runs_take_off(study):
    """The section "The floor over the cycle": a plot and each method's take-off, the value of
    its own summary.json's "floor" block (measure.floor_force) and floor.csv beside it."""
    _, out, summary, _ = study
    html = (out / "report.html").read_text(encoding="utf-8")
    cells = _floor_cells(html)
    assert set(cells) == set(summary["methods"])
    for name, value in cells.items():
        floor = json.loads((out / name / "summary.json").read_text())["floor"]
        want = floor["take_off_phase"]
        assert (value == "nan") if want is None else float(value) == want
        assert (out / name / "floor.csv").is_file()
    assert 'alt="floor force over the cycle"' in html


def test_the_stress_section_shows_where_each_bed_sits_against_its_yield(study):
    """The section "Stress by height and phase": a row for the DEM (the calibration's
    phase-resolved fields.nc) and each continuum (its stress.csv), whose share of dense cells
    at or above the calibrated mu_s and lowest / highest thirds by phase are
    analysis.stress_state's of those files; every continuum's friction is that of a stress
    within its law's yield cone (mu <= mu_2 where its points were return-mapped)."""
    import math

    from vibroflow.analysis.stress_state import (batch_errors, continuum_points, dem_points,
                                                 height_phase_table, share_at_yield)
    from vibroflow.calibration.run_fields import read_fields
    from vibroflow.io.calibration_file import read_calibration
    from vibroflow.rounding import plus_minus

    scenario, out, summary, _ = study
    html = (out / "report.html").read_text(encoding="utf-8")
    sec = re.search(r'<section id="stress">.*?</section>', html, re.S).group(0)
    table = re.search(r'<table class="stress">.*?</table>', sec, re.S).group(0)
    rows = {}
    for row in re.findall(r"<tr>(.*?)</tr>", table, re.S)[1:]:
        cells = re.findall(r"<td([^>]*)>(.*?)</td>", row, re.S)
        rows[cells[0][1]] = cells
    assert set(rows) == set(summary["methods"])
    mu_s = read_calibration(out / "calibration" / "calibration.toml").rheology.mu_s
    for name, cells in rows.items():
        pts = dem_points(read_fields(out / "calibration" / "fields.nc", phase_resolved=True)) \
            if name == "dem" else continuum_points(out / name / "stress.csv")
        share = float(re.search(r'data-value="([^"]*)"', cells[4][0]).group(1))
        assert share / 100.0 == pytest.approx(share_at_yield(pts, mu_s), rel=1e-12)
        assert float(re.search(r'data-value="([^"]*)"', cells[1][0]).group(1)) == pts["mu"].size
        # every method's batches reach the table: the DEM's in fields.nc, a continuum's in its
        # stress_batches.csv
        se = batch_errors(pts, mu_s)
        assert se is not None and pts["batch_mu"].shape == (scenario.run.batches,
                                                           pts["mu"].size), name
        for col, key in ((2, "median_mu"), (3, "median_pressure")):
            shown = float(re.search(r'data-stderr="([^"]*)"', cells[col][0]).group(1))
            assert shown == pytest.approx(se[key], rel=1e-12) and shown > 0, (name, key)
        by_phase = {r["phase"]: r for r in height_phase_table(pts)["rows"]}
        for k in range(scenario.run.phases_per_cycle):
            r = by_phase.get(k)
            lo, hi = se["thirds"].get(k, (math.nan, math.nan))
            want = "n/a" if r is None else (f"{plus_minus(r['mu_low'], lo, '.3f')} / "
                                            f"{plus_minus(r['mu_high'], hi, '.3f')}")
            assert cells[5 + k][1] == want
    for name in summary["methods"]:
        if name != "dem":
            mat = json.loads((out / name / "summary.json").read_text())["continuum"]["material"]
            mu = continuum_points(out / name / "stress.csv")["mu"]
            assert math.isfinite(mat["mu_2"]) and mu.size > 0
            if name == "lagrangian":
                assert mu.max() <= mat["mu_2"] * (1.0 + 1e-9)


@pytest.mark.slow
def test_the_floor_section_escapes_the_method_names(study):
    """A method named with HTML's special characters appears escaped in the floor section."""
    import dataclasses

    from vibroflow.report.data import StudyData
    from vibroflow.report.html import render

    _, out, _, _ = study
    data = StudyData.read(out)
    methods = dict(data.summary["methods"])
    methods["lag<&>"] = methods["lagrangian"]
    fields = dict(data.fields, **{"lag<&>": data.fields["lagrangian"]})
    data = dataclasses.replace(data, summary=dict(data.summary, methods=methods), fields=fields)
    html = render(data)
    cells = _floor_cells(html)
    assert "lag&lt;&amp;&gt;" in cells and cells["lag&lt;&amp;&gt;"] == cells["lagrangian"]
    assert "lag<&>" not in html
