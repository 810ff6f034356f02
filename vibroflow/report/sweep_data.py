"""What the sweep report shows, read from a sweep folder (`vibroflow sweep --out DIR`): the
record (DIR/sweep.json), one row per point and method (vibroflow.study.sweep_table, from the
points' own summary.json; a failed point is one row with its error), and the fields-agree limit
on E that each point is judged against.

The limit is 1.5 x the DEM's seed-to-seed E (tub47.md "Judging a comparison"), taken

- from the sweep's own seeds when it varies `run.seed`: at each amplitude (and other varied
  value) the mean E over every ordered pair of the DEM runs that differ only in their seed
  (vibroflow.analysis.compare.seed_scatter, with its jackknife error from three seeds on);
- else by the study page's own rule (vibroflow.report.verdict.preset_limit) on each point's
  scenario: the ensemble figure of its case at its amplitude factor, when the point changes no
  setting of the flow from that preset;
- else it is unknown, and the page says why.
"""
from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import json

from vibroflow.analysis.compare import seed_scatter
from vibroflow.errors import InputError
from vibroflow.measure.bulk import read_csv
from vibroflow.report.sweep_pool import SEED_KEY, pool_seeds
from vibroflow.report.verdict import ELimit, preset_limit
from vibroflow.scenario.io import parse_scenario
from vibroflow.study.methods import METHODS
from vibroflow.study.sweep_folder import dir_lock, point_dir, read_record
from vibroflow.study.sweep_table import sweep_rows


#: `vibroflow report`'s advice for a sweep.json it cannot read (it takes no --out)
REPORT_ADVICE = ("no sweep report can be written from it; each point's folder is a study "
                 "of its own (vibroflow report DIR/points/<point>)",
                 "give a sweep folder (vibroflow sweep --out DIR)")


@dataclass
class SweepData:
    """A sweep folder's record, rows and limits.

    rows: vibroflow.study.sweep_table's rows, sorted by the varied values; pooled: the rows
    pooled over run.seed (vibroflow.report.sweep_pool; the rows themselves, each with n_seeds
    1, when the sweep keeps one seed); limits: the key of a row's group (its varied values
    without run.seed, `group_key`) -> ELimit; no_limit: the same keys -> why a group has
    none."""

    out: Path
    record: dict[str, Any]
    varied: list[str]
    rows: list[dict[str, Any]]
    limits: dict[tuple, ELimit]
    no_limit: dict[tuple, str]
    pooled: list[dict[str, Any]]

    @classmethod
    def read(cls, out) -> SweepData:
        """The sweep in `out`, read under the sweep's folder lock (a sweep writing its table
        meanwhile is waited for); an InputError (one line) for a folder that holds no sweep."""
        out = Path(out)
        if not out.is_dir():
            raise InputError(f"DIR = {str(out)!r}: no such folder; give a sweep folder "
                             "(vibroflow sweep --out DIR)")
        if not (out / "sweep.json").is_file():
            raise InputError(f"DIR = {str(out)!r}: not a sweep folder (no sweep.json)")
        with dir_lock(out):
            record = read_record(out, REPORT_ADVICE)
            assert record is not None  # sweep.json exists, read_record raised otherwise
            varied = list(record["varied"])
            rows = sweep_rows(out, record["points"], varied)
        limits, why = e_limits(out, record, rows)
        return cls(out=out, record=record, varied=varied, rows=rows, limits=limits,
                   no_limit=why, pooled=pool_seeds(rows, varied))

    def limit_of(self, row: dict[str, Any]) -> ELimit | None:
        return self.limits.get(group_key(row, self.varied))

    @property
    def seeds_pooled(self) -> bool:
        """Whether the sweep varies run.seed (its rows are pooled over the seeds)."""
        return SEED_KEY in self.varied

    @property
    def shown(self) -> list[str]:
        """The varied keys a pooled row carries: every one but run.seed."""
        return [k for k in self.varied if k != SEED_KEY]

    @property
    def failed(self) -> list[dict[str, Any]]:
        """The rows of points that did not finish (failed, running or pending)."""
        return [r for r in self.rows if r["status"] != "done"]


def group_key(row: dict[str, Any], varied: list[str]) -> tuple:
    """A row's varied values without its seed: the points whose DEMs differ only in the seed."""
    return tuple(row.get(k) for k in varied if k != SEED_KEY)


def e_limits(out: Path, record: dict, rows: list[dict]) -> tuple[dict, dict]:
    """(limits, why none) by group: see the module's docstring."""
    varied = list(record["varied"])
    if SEED_KEY in varied:
        return _measured(out, record, rows)
    limits, why = {}, {}
    for r in rows:
        key = group_key(r, varied)
        if key in limits or key in why:
            continue
        try:
            lim, reason = preset_limit(point_scenario(record, r))
        except InputError as exc:
            lim, reason = None, f"its scenario does not load ({exc.message})"
        if lim is None:
            why[key] = str(reason)
        else:
            limits[key] = lim
    return limits, why


def point_scenario(record: dict, row: dict[str, Any]):
    """A point's scenario: the sweep's base with the row's varied scenario fields (the base
    holds the fixed settings and leaves the varied keys out)."""
    sets = [f"{k}={json.dumps(row.get(k))}" for k in record["varied"]
            if k.split(".")[0] not in METHODS]
    return parse_scenario(record["base"]["scenario"], sets)


def _measured(out: Path, record: dict, rows: list[dict]) -> tuple[dict, str | None]:
    varied = list(record["varied"])
    cell = float(record["base"]["scenario"]["analysis"]["cell_size"])
    phi = float(record["base"]["scenario"]["analysis"]["min_solid_fraction"])
    tables = defaultdict(list)
    for r in rows:
        if r["status"] == "done" and r["method"] == "dem":
            path = point_dir(out, r["point"]) / "dem" / "bulk_velocity.csv"
            if path.is_file():
                tables[group_key(r, varied)].append(read_csv(path, cell_size=cell))
    limits, why = {}, {}
    for r in rows:
        key = group_key(r, varied)
        ts = tables.get(key, [])
        if len(ts) >= 2 and key not in limits:
            sc = seed_scatter(ts, phi)
            limits[key] = ELimit(sc.mean, sc.stderr, len(ts),
                                 f"measured: mean E over the {len(sc.pairs)} ordered pairs of "
                                 f"this sweep's {len(ts)} seeds")
        elif len(ts) < 2:
            why[key] = f"fewer than two finished DEM seeds here ({len(ts)})"
    return limits, why


def point_report(out: Path, name: str) -> str | None:
    """The point's own report page relative to the sweep folder, when it has one."""
    rel = f"points/{name}/report.html"
    return rel if (Path(out) / rel).is_file() else None


def created(record: dict) -> str:
    return str(record.get("updated") or record.get("created") or "")


def describe(record: dict) -> str:
    """One line: the source scenario, the varied keys and the fixed settings."""
    fixed = record.get("fixed_settings") or []
    return (f"{record.get('source', '?')}, varied: {', '.join(record['varied'])}"
            + (f"; fixed: {' '.join(fixed)}" if fixed else "")
            + f"; {len(record['points'])} point(s)")
