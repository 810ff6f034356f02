"""What the report shows, read from a finished study folder (`vibroflow run --out DIR`).

`StudyData.read(DIR)` validates the folder first (`vibroflow.study.results.read_summary` and
check_summary: a missing, foreign, corrupt or unfinished DIR, a summary value of the wrong type
or a verdict without the strengths it judges, is a one-line InputError naming the file and
field, and nothing is read further), then
gathers the pieces the page draws: the summary, the scenario, each method's bulk velocity field,
the stage records (cost), the calibration and the DEM's coarse-grained fields, the DEM's measured
impacts binned on the analysis cells, and any sweep results.  Optional pieces that are missing
(no fields.nc, a calibration that could not fit impacts, no sweep) or unreadable are None, with
a line in `notes` saying why, so the page states them under "Missing pieces" instead of
failing.

Units: SI (m, m/s, 1/s, s).
"""
from __future__ import annotations

import json
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from vibroflow.calibration.run_fields import read_fields
from vibroflow.continuum.shear_outputs import (impact_relation, impact_relation_errors,
                                               impact_relation_left_out)
from vibroflow.dem.walls import KIND_BALL_BALL
from vibroflow.errors import InputError
from vibroflow.io.calibration_file import Calibration, read_calibration
from vibroflow.measure.contacts import mean_by_region
from vibroflow.measure.stats import batches_of_whole_cycles, jackknife_stderr, stderr_of_batches
from vibroflow.scenario.io import dump_scenario, parse_scenario
from vibroflow.study.results import load, read_summary
from vibroflow.tub.geometry import geometry_of

DEM = "dem"
CALIBRATION = "calibration"
#: the report's own stage: its pending.json is the page being written (vibroflow.report.stage)
REPORT_STAGE = "report"
PENDING_FILE = "pending.json"
#: impacts a cell needs before its mean impact speed is drawn (a cell mean of fewer is mostly
#: noise: the speeds' spread is about their mean, so 20 impacts give a ~ 20 % standard error)
MIN_IMPACTS_PER_CELL = 20


@dataclass
class ImpactCells:
    """Mean normal approach speed (m/s) of the DEM's ball-ball impacts of the averaging window,
    by analysis cell (tub frame, cell centres x, z in m), with the impacts counted per cell and
    the mean's batch-means standard error (m/s; NaN where fewer than two batches hold an impact
    in the cell, or the impacts came without their batch) and its values with each batch of
    whole cycles left out, left_out (n_batches, cells; m/s; NaN where none is left), what the
    jackknife's covariance with another statistic of the same batches needs."""

    x: np.ndarray
    z: np.ndarray
    mean_speed: np.ndarray
    count: np.ndarray
    cell_size: float
    stderr: np.ndarray | None = None
    left_out: np.ndarray | None = None

    def _cell(self, px: float, pz: float) -> int | None:
        h = self.cell_size
        i, k = math.floor(px / h + 0.5), math.floor(pz / h + 0.5)
        hit = (np.rint(self.x / h) == i) & (np.rint(self.z / h) == k)
        return int(np.argmax(hit)) if hit.any() else None

    def at(self, px: float, pz: float) -> tuple[float, int]:
        """(mean speed m/s, count) of the cell holding the point (px, pz); (nan, 0) if none."""
        j = self._cell(px, pz)
        if j is None:
            return float("nan"), 0
        return float(self.mean_speed[j]), int(self.count[j])

    def stderr_at(self, px: float, pz: float) -> float:
        """The batch-means standard error (m/s) of the mean speed at (px, pz); NaN if none."""
        j = self._cell(px, pz)
        return math.nan if j is None or self.stderr is None else float(self.stderr[j])

    def left_out_at(self, px: float, pz: float) -> np.ndarray | None:
        """The mean speed (m/s) at (px, pz) with each batch left out, batch order; None if
        none."""
        j = self._cell(px, pz)
        return None if j is None or self.left_out is None else self.left_out[:, j]


def bin_impacts(chunks, cell_size: float) -> ImpactCells:
    """Mean speed and count per square cell of side cell_size (m) centred on its multiples
    (the analysis cells of tub47.md "Bulk velocity"), from an iterable of (position_tub (M, 3)
    m, normal_speed (M,) m/s[, batch (M,)]) chunks of impacts (a tub47 run holds tens of
    millions: they are never all in memory).  The per-chunk means are
    vibroflow.measure.contacts.mean_by_region.  With each impact's batch of whole cycles
    (measure.stats.batches_of_whole_cycles), each cell's mean also gets its batch-means
    standard error over the batches that hold an impact there (measure.stats.stderr_of_batches)."""
    h = float(cell_size)
    # (ix, iz, batch) -> [count, sum of speeds]; batch -1 for impacts without one
    acc: dict[tuple[int, int, int], list[float]] = {}
    batched = True
    for chunk in chunks:
        pos, speed = chunk[0], chunk[1]
        batch = chunk[2] if len(chunk) > 2 else None
        batched = batched and batch is not None
        parts = [(-1, pos, speed)] if batch is None else [
            (int(b), pos[batch == b], speed[batch == b]) for b in np.unique(batch)]
        for b, p, v in parts:
            x, z, cnt, mean = mean_by_region(p, v, h)
            for xi, zi, c, m in zip(np.rint(x / h).astype(int), np.rint(z / h).astype(int),
                                    cnt, mean):
                a = acc.setdefault((int(xi), int(zi), b), [0.0, 0.0])
                a[0] += float(c)
                a[1] += float(c) * float(m)
    keys = sorted({k[:2] for k in acc})
    col = {k: j for j, k in enumerate(keys)}
    row = {b: i for i, b in enumerate(sorted({k[2] for k in acc}))}
    counts = np.zeros((len(row), len(keys)))
    sums = np.zeros((len(row), len(keys)))
    for (xi, zi, b), (c, tot) in acc.items():
        counts[row[b], col[(xi, zi)]] = c
        sums[row[b], col[(xi, zi)]] = tot
    count = counts.sum(axis=0).astype(np.int64)
    total = sums.sum(axis=0)
    x = np.array([k[0] for k in keys], dtype=float) * h
    z = np.array([k[1] for k in keys], dtype=float) * h
    stderr = left_out = None
    if batched and keys:
        with np.errstate(invalid="ignore", divide="ignore"):
            means = np.where(counts > 0, sums / counts, np.nan)
            # a batch with no impact anywhere has no row: the rows are batches 0, 1, ... only
            # when every batch holds one
            if sorted(row) == list(range(len(row))):
                rest = count[None, :] - counts
                left_out = np.where(rest > 0, (total[None, :] - sums) / rest, np.nan)
        stderr = np.asarray(stderr_of_batches(means, axis=0), dtype=float).reshape(len(keys))
    return ImpactCells(x, z, total / np.maximum(count, 1), count, h, stderr, left_out)


def mean_flow_shear_rate(vx: np.ndarray, vz: np.ndarray, h: float) -> np.ndarray:
    """Shear rate gamma_dot = sqrt(2 D':D') (1/s) of a plane velocity field (vx, vz) (m/s) given
    on a square grid of spacing h (m), arrays indexed [z, x] (NaN outside the bed).

    D is the symmetric part of the in-plane velocity gradient (central differences, one-sided
    at the bed's edge; NaN where a cell has no neighbour along an axis), D_yy = 0 (plane flow),
    and D' = D - tr(D)/3 I its deviator in 3D, the definition of the DEM's coarse-grained
    shear rate (vibroflow.calibration.coarse_grain_fields), so simple shear v_x = g z gives g and a
    rigid rotation 0.
    """
    vx = np.asarray(vx, dtype=float)
    vz = np.asarray(vz, dtype=float)

    def grad(a, axis):
        out = np.full(a.shape, np.nan)
        n = a.shape[axis]
        if n < 2:
            return out
        a_m = np.moveaxis(a, axis, 0)
        o = np.moveaxis(out, axis, 0)
        central = (a_m[2:] - a_m[:-2]) / (2.0 * h)
        fwd = (a_m[1:] - a_m[:-1]) / h
        o[1:-1] = central
        # where a central difference lacks a side, the one-sided difference on the other
        o[1:-1] = np.where(np.isnan(o[1:-1]), fwd[1:], o[1:-1])
        o[1:-1] = np.where(np.isnan(o[1:-1]), fwd[:-1], o[1:-1])
        o[0] = fwd[0]
        o[-1] = fwd[-1]
        return out

    dvx_dx, dvx_dz = grad(vx, 1), grad(vx, 0)
    dvz_dx, dvz_dz = grad(vz, 1), grad(vz, 0)
    dxx, dzz = dvx_dx, dvz_dz
    dxz = 0.5 * (dvx_dz + dvz_dx)
    tr3 = (dxx + dzz) / 3.0
    dd = (dxx - tr3) ** 2 + (dzz - tr3) ** 2 + tr3**2 + 2.0 * dxz**2
    g = np.sqrt(2.0 * dd)
    return np.where(np.isfinite(vx) & np.isfinite(vz), g, np.nan)


@dataclass
class StudyData:
    """A finished study, as the report reads it (see the module notes)."""

    out: Path
    summary: dict
    scenario: Any
    scenario_toml: str | None
    fields: dict                      # method -> xarray Dataset of bulk_velocity.csv (z, x)
    stages: dict                      # stage name -> its stage.json record
    calibration: Calibration | None
    dem_fields: Any | None            # the DEM's time-averaged coarse-grained fields (fields.nc)
    impacts: ImpactCells | None       # the DEM's measured ball-ball impacts by cell
    sweep_table: Path | None
    sweep_images: list[Path]
    notes: dict = field(default_factory=dict)

    @property
    def methods(self) -> list[str]:
        """The DEM first, then the continuum methods in the summary's order."""
        names = list(self.summary["methods"])
        return [DEM] + [n for n in names if n != DEM] if DEM in names else names

    @property
    def continuum_methods(self) -> list[str]:
        return [n for n in self.methods if n != DEM]

    @property
    def geometry(self):
        return geometry_of(self.scenario)

    @property
    def min_solid_fraction(self) -> float:
        return float(self.scenario.analysis.min_solid_fraction)

    @property
    def diameter(self) -> float:
        return float(self.scenario.fill.diameter)

    # ------------------------------------------------------------------------------------------
    @classmethod
    def read(cls, out) -> "StudyData":
        """Read the study in `out` (InputError, one line, for a missing, foreign, corrupt or
        unfinished folder)."""
        out = Path(out)
        # the summary's values before the tables: a corrupt one is named, not drawn
        summary = read_summary(out)
        check_finished(out)
        check_summary(out / "summary.json", summary)
        loaded = load(out)  # validates DIR (study.folder.check_study_dir) and every method's
        # bulk velocity table
        fields = loaded.pop("fields")
        summary = loaded
        for name in summary["methods"]:
            s = out / name / "summary.json"
            if s.is_file():
                try:
                    own = json.loads(s.read_text())
                except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
                    raise InputError(f"{s}: corrupt summary ({type(exc).__name__})") from None
                check_method_summary(s, own)
        notes: dict[str, str] = {}
        scenario, text = _scenario(out)
        stages = {}
        for rec_path in sorted(out.glob("*/stage.json")):
            try:
                rec = json.loads(rec_path.read_text())
            except (OSError, UnicodeDecodeError, json.JSONDecodeError):
                notes[f"stage {rec_path.parent.name}"] = "corrupt stage.json"
                continue
            if isinstance(rec, dict) and "stage" in rec:
                stages[str(rec["stage"])] = rec
        calibration = _optional(out / CALIBRATION / "calibration.toml", read_calibration, notes,
                                "calibration", f"no {CALIBRATION}/calibration.toml in the study")
        dem_fields = _optional(out / CALIBRATION / "fields.nc", _read_dem_fields, notes,
                               "dem_fields", f"no {CALIBRATION}/fields.nc (the calibration's "
                               "coarse-grained DEM fields)")
        impacts = None
        if scenario is not None:
            impacts, why = _dem_impacts(out / DEM / "dem.h5", scenario)
            if why:
                notes["impacts"] = why
        table, images = _sweep(out)
        return cls(out=out, summary=summary, scenario=scenario, scenario_toml=text,
                   fields=fields, stages=stages, calibration=calibration,
                   dem_fields=dem_fields, impacts=impacts, sweep_table=table,
                   sweep_images=images, notes=notes)

    # ------------------------------------------------------------------------------------------
    def impact_fit(self, kind: str = "ball_ball") -> dict | None:
        """The calibrated v = c0 + c1 d gamma_dot of `kind` (calibration.toml [impacts.KIND])
        that the continuum runs use (continuum.shear_outputs.impact_relation: the one fitted on the
        continuum's measure of the shear rate when the calibration has it), or None when the
        calibration has none with finite coefficients; with c0_stderr (m/s), c1_stderr and
        covariance (of c0 and c1, m/s), the fit's errors (NaN where the calibration holds
        none); left_out, (c0s, c1s) with each batch of its DEM run left out, or None; and
        measured_mean (m/s), the mean speed its DEM run measured, by which that run is known."""
        impacts = self.calibration.impacts if self.calibration is not None else None
        rel = getattr(impacts, kind) if impacts is not None else None
        c0, c1, which = impact_relation(rel)
        if c0 is None:
            return None
        se0, se1, cov = impact_relation_errors(rel)
        return {"c0": c0, "c1": c1, "which": which, "c0_stderr": se0, "c1_stderr": se1,
                "covariance": cov, "left_out": impact_relation_left_out(rel),
                "measured_mean": rel.mean_normal_speed_m_s}

    def method_dir(self, name: str) -> Path:
        """The folder of a method's run: that of its bulk_velocity.csv as the study's summary
        names it (NAME/ by default)."""
        entry = self.summary["methods"].get(name, {})
        return self.out / Path(entry.get("bulk_velocity_csv", f"{name}/bulk_velocity.csv")).parent

    def method_summary(self, name: str) -> dict:
        """A method's own summary.json, beside its bulk_velocity.csv ({} if unreadable)."""
        try:
            s = json.loads((self.method_dir(name) / "summary.json").read_text())
        except (OSError, UnicodeDecodeError, json.JSONDecodeError):
            return {}
        return s if isinstance(s, dict) else {}

    def _summary_block(self, name: str, key: str) -> dict:
        block = self.method_summary(name).get(key)
        return block if isinstance(block, dict) else {}

    def continuum_block(self, name: str) -> dict:
        """The `continuum` block of a continuum method's own summary.json ({} if none)."""
        return self._summary_block(name, "continuum")

    def floor(self, name: str) -> dict:
        """The "floor" block (measure.floor_force: the floor's force over the cycle and the
        take-off) of a method's own summary.json ({} if none)."""
        return self._summary_block(name, "floor")

    def continuum_shear_map(self, name: str, column: str = "shear_rate"):
        """A continuum method's map on the analysis cells from its shear_rate.csv (continuum
        run.write_shear_rate_csv): (x (m), z (m), values (z, x) with NaN where no material),
        column "shear_rate" (1/s, cycle mean) or "impact_ball_ball" (m/s, inferred); None when
        the run wrote no map or the column is empty."""
        path = self.method_dir(name) / "shear_rate.csv"
        try:
            lines = path.read_text().splitlines()
        except (OSError, UnicodeDecodeError):
            return None
        if len(lines) < 2:
            return None
        head = lines[0].split(",")
        if column not in head or "x" not in head or "z" not in head:
            return None
        ci, xi, zi = head.index(column), head.index("x"), head.index("z")
        rows = []
        for line in lines[1:]:
            parts = line.split(",")
            try:
                rows.append((float(parts[xi]), float(parts[zi]),
                             float(parts[ci]) if parts[ci] else float("nan")))
            except (ValueError, IndexError):
                return None
        a = np.asarray(rows, dtype=float)
        if not np.isfinite(a[:, 2]).any():
            return None
        h = float(self.scenario.analysis.cell_size)
        ix = np.rint(a[:, 0] / h).astype(int)
        iz = np.rint(a[:, 1] / h).astype(int)
        grid = np.full((iz.max() - iz.min() + 1, ix.max() - ix.min() + 1), np.nan)
        grid[iz - iz.min(), ix - ix.min()] = a[:, 2]
        return (np.arange(ix.min(), ix.max() + 1) * h, np.arange(iz.min(), iz.max() + 1) * h,
                grid)

    def dem_shear_rate_at(self, px: float, pz: float) -> tuple[float, float]:
        """The DEM's cycle-mean shear rate (1/s) in the analysis cell holding (px, pz), the
        mass-weighted mean of fields.nc's grid points inside that cell, and its delete-one-batch
        jackknife standard error: the same mean of each batch-left-out map
        (shear_rate_cycle_mean_leave_one_out, calibration.run_fields.add_cycle_mean_errors),
        under the window's weights.  (NaN, NaN) without fields; the error NaN for a fields.nc
        without the left-out maps."""
        nan = float("nan")
        ds = self.dem_fields
        if ds is None:
            return nan, nan
        name = "shear_rate_cycle_mean" if "shear_rate_cycle_mean" in ds else "shear_rate"
        h = float(self.scenario.analysis.cell_size)
        cx, cz = math.floor(px / h + 0.5) * h, math.floor(pz / h + 0.5) * h
        x = ds["x"].values
        z = ds["z"].values
        tol = 1e-9
        sx = (x >= cx - 0.5 * h - tol) & (x < cx + 0.5 * h - tol)
        sz = (z >= cz - 0.5 * h - tol) & (z < cz + 0.5 * h - tol)
        g = ds[name].values[np.ix_(sx, sz)]
        w = ds["density"].values[np.ix_(sx, sz)]
        ok = np.isfinite(g) & (w > 0)
        if not ok.any():
            return nan, nan
        value = float(np.sum(g[ok] * w[ok]) / np.sum(w[ok]))
        loo_name = "shear_rate_cycle_mean_leave_one_out"
        if name != "shear_rate_cycle_mean" or loo_name not in ds:
            return value, nan
        loo = ds[loo_name].transpose("batch", "x", "z").values[:, sx][:, :, sz]
        left_out = [np.sum(b[ok] * w[ok]) / np.sum(w[ok]) for b in loo]
        return value, jackknife_stderr(left_out)


# ----------------------------------------------------------------------------------------------
# the folder's checks: what the page shows must be what the study computed

def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _bad(path: Path, where: str, value, want: str) -> InputError:
    return InputError(f"{path}: {where} is {json.dumps(value)}, not {want} (corrupt summary)")


def _numbers(path: Path, block, where: str, keys, integer: bool = False) -> None:
    """Each of `keys` in the dict `block` is a number or null (a NaN, written as null by
    io.atomic.json_safe) when present."""
    for k in keys:
        v = block.get(k)
        if v is not None and not (_is_number(v) and (not integer or float(v).is_integer())):
            raise _bad(path, f"{where}.{k}", v, "an integer" if integer else "a number")


def _table(path: Path, block, where: str, required: bool = False) -> dict:
    if block is None and not required:
        return {}
    if not isinstance(block, dict):
        raise _bad(path, where, block, "a table")
    return block


def check_summary(path: Path, summary: dict) -> None:
    """The study summary's values the page shows have their types (numbers or null, a verdict
    true, false or null), and every verdict has the strengths it judges: an InputError naming
    the file and the field otherwise."""
    methods = summary["methods"]
    dem = methods.get(DEM) if isinstance(methods.get(DEM), dict) else {}
    for name, m in methods.items():
        w = f"methods.{name}"
        m = _table(path, m, w, required=True)
        for probe, q in _table(path, m.get("probes"), f"{w}.probes", required=True).items():
            _numbers(path, _table(path, q, f"{w}.probes.{probe}", required=True),
                     f"{w}.probes.{probe}", ("vx", "vz", "vx_stderr", "vz_stderr",
                                             "solid_fraction", "solid_fraction_stderr"))
        c = _table(path, m.get("circulation"), f"{w}.circulation", required=True)
        _numbers(path, c, f"{w}.circulation", ("strength", "strength_stderr"))
        if c.get("sense") is not None and not isinstance(c["sense"], str):
            raise _bad(path, f"{w}.circulation.sense", c["sense"], "a word")
        im = _table(path, m.get("impacts"), f"{w}.impacts")
        _numbers(path, im, f"{w}.impacts", [f"{k}_mean_normal_speed{e}" for k in
                                            ("ball_ball", "ball_wall") for e in ("", "_stderr")])
        _numbers(path, im, f"{w}.impacts", ("count",), integer=True)
        _numbers(path, m, w, ("wall_time_s",))
        a = _table(path, m.get("against_dem"), f"{w}.against_dem")
        _numbers(path, a, f"{w}.against_dem", ("field_difference_E", "field_difference_E_stderr",
                                               "circulation_strength",
                                               "dem_circulation_strength", "cost_ratio"))
        for probe, d in _table(path, a.get("probe_differences_m_s"),
                               f"{w}.against_dem.probe_differences_m_s").items():
            _numbers(path, _table(path, d, f"{w}.against_dem.probe_differences_m_s.{probe}",
                                  required=True),
                     f"{w}.against_dem.probe_differences_m_s.{probe}",
                     ("dvx", "dvz", "dvx_stderr", "dvz_stderr"))
        verdict = a.get("circulation_agrees")
        if verdict is not None and not isinstance(verdict, bool):
            raise _bad(path, f"{w}.against_dem.circulation_agrees", verdict, "true or false")
        if isinstance(verdict, bool):  # a verdict stands on both strengths
            for who, block in ((w, c), (f"methods.{DEM}", (dem or {}).get("circulation"))):
                v = (block or {}).get("strength") if isinstance(block, dict) else None
                if not (_is_number(v) and math.isfinite(v)):
                    raise InputError(
                        f"{path}: {w}.against_dem.circulation_agrees is "
                        f"{json.dumps(verdict)} without a strength to judge "
                        f"({who}.circulation.strength is {json.dumps(v)}) (corrupt summary)")


def check_method_summary(path: Path, summary) -> None:
    """A method's own summary.json: the blocks the page reads (floor, wall_contacts, the
    continuum's probes, wall_feed) hold numbers or null where it reads numbers."""
    if not isinstance(summary, dict):
        raise _bad(path, "the summary", summary, "a table")
    f = _table(path, summary.get("floor"), "floor")
    _numbers(path, f, "floor", ("take_off_phase", "cycle_mean_over_weight",
                                "cycle_mean_over_weight_stderr"))
    for k in ("take_off_phase_batches", "force_over_weight"):
        v = f.get(k)
        if v is not None and not (isinstance(v, list) and all(
                x is None or _is_number(x) for x in v)):
            raise _bad(path, f"floor.{k}", v, "a list of numbers")
    _numbers(path, _table(path, summary.get("wall_contacts"), "wall_contacts"),
             "wall_contacts", [k + e for k in ("ratio_of_sums", "mean_ft_over_fn",
                                              "sliding_fraction") for e in ("", "_stderr")])
    c = _table(path, summary.get("continuum"), "continuum")
    for probe, q in _table(path, c.get("probes"), "continuum.probes").items():
        _numbers(path, _table(path, q, f"continuum.probes.{probe}", required=True),
                 f"continuum.probes.{probe}", ("shear_rate_1_s", "shear_rate_1_s_stderr"))
    wf = _table(path, summary.get("wall_feed"), "wall_feed")
    _numbers(path, wf, "wall_feed", ("u_wall_W_m2", "u_wall_W_m2_stderr"))
    for k in ("by_region_W_m2", "by_region_W_m2_stderr"):
        regions = _table(path, wf.get(k), f"wall_feed.{k}")
        _numbers(path, regions, f"wall_feed.{k}", list(regions))


def check_finished(out: Path) -> None:
    """No stage of the study is under way or was interrupted (DIR/<stage>/pending.json, the
    study pipeline's mark until its stage.json is written): an InputError otherwise.  The
    report's own stage is the page being written."""
    for pending in sorted(out.glob(f"*/{PENDING_FILE}")):
        stage = pending.parent.name
        if stage != REPORT_STAGE:
            raise InputError(f"{pending}: the study has not finished (its {stage} stage is "
                             f"under way or was interrupted); run `vibroflow run ... --out "
                             f"{out}` to finish it")


def _optional(path: Path, read, notes: dict[str, str], key: str, missing: str):
    """read(path) of an optional piece, or None with notes[key] saying why: `missing` when the
    file is not there, the InputError's line when it cannot be read."""
    if not path.is_file():
        notes[key] = missing
        return None
    try:
        return read(path)
    except InputError as exc:
        notes[key] = exc.message
        return None


def _read_dem_fields(path: Path):
    # imported here: xarray is slow to import, and a study without fields.nc reads none

    return read_fields(path)


def _scenario(out: Path):
    """The study's scenario and its TOML text (as `vibroflow scenario show` prints it): dem.h5's
    scenario_toml attribute, else the DEM stage record's inputs."""
    h5 = out / DEM / "dem.h5"
    if h5.is_file():
        try:
            with h5py.File(h5, "r") as f:
                text = f.attrs.get("scenario_toml")
            if isinstance(text, bytes):
                text = text.decode()
            if text:
                return parse_scenario(tomllib.loads(str(text))), str(text)
        except (OSError, ValueError, tomllib.TOMLDecodeError):
            pass
    try:
        rec = json.loads((out / DEM / "stage.json").read_text())
        s = parse_scenario(rec["inputs"]["scenario"])
        return s, dump_scenario(s)
    except (OSError, ValueError, KeyError, TypeError):
        raise InputError(f"DIR = {str(out)!r}: the study's scenario is unreadable (no "
                         f"{DEM}/dem.h5 scenario_toml and no {DEM}/stage.json inputs)") from None


def _dem_impacts(h5: Path, scenario, chunk: int = 2_000_000):
    """The DEM's ball-ball impacts of the averaging window's whole cycles (the impacts its
    summary averages: vibroflow.measure.stats.batches_of_whole_cycles) by analysis cell."""
    if not h5.is_file():
        return None, f"no {DEM}/dem.h5: no measured impacts"

    run = scenario.run
    t0, t1 = run.duration - run.average_last, run.duration
    f_hz = float(scenario.motion.frequency)

    def chunks(f):
        n = f["impacts/time"].shape[0]
        for a in range(0, n, chunk):
            b = min(n, a + chunk)
            t = f["impacts/time"][a:b]
            batch = batches_of_whole_cycles(t, t0, t1, f_hz, int(run.batches))
            use = (batch >= 0) & (f["impacts/kind"][a:b] == KIND_BALL_BALL)
            yield (f["impacts/position_tub"][a:b][use], f["impacts/normal_speed"][a:b][use],
                   batch[use])

    try:
        with h5py.File(h5, "r") as f:
            if "impacts/time" not in f or f["impacts/time"].shape[0] == 0:
                return None, ("the DEM result holds no impacts (a LIGGGHTS import does not "
                              "report them)")
            return bin_impacts(chunks(f), float(scenario.analysis.cell_size)), None
    except (OSError, KeyError, ValueError) as exc:
        return None, f"{h5}: impacts unreadable ({type(exc).__name__})"


def _sweep(out: Path) -> tuple[Path | None, list[Path]]:
    """A sweep's table and plots (vibroflow sweep: sweep.csv, plots/sweep_*.png) in the study
    folder, or in the sweep folder holding it as one of its points (SWEEP/points/NAME)."""
    places = [out]
    parent = out.parent.parent
    if out.parent.name == "points" and (parent / "sweep.json").is_file():
        try:
            kind = json.loads((parent / "sweep.json").read_text()).get("kind")
        except (OSError, UnicodeDecodeError, json.JSONDecodeError, AttributeError):
            kind = None
        if kind == "vibroflow sweep":
            places.append(parent)
    for place in places:
        table = place / "sweep.csv"
        images = sorted({*place.glob("sweep*.png"), *place.glob("plots/sweep*.png")})
        if table.is_file() or images:
            return (table if table.is_file() else None), images
    return None, []
