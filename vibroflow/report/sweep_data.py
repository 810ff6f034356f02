"""What the sweep report shows, read from a sweep folder (`vibroflow sweep --out DIR`): the
record (DIR/sweep.json), one row per point and method (vibroflow.study.sweep_table, from the
points' own summary.json; a failed point is one row with its error), and the fields-agree limit
on E that each point is judged against.

The limit is 1.5 x the DEM's seed-to-seed E (tub47.md "Judging a comparison"), taken

- from the sweep's own seeds when it varies `run.seed`: at each amplitude (and other varied
  value) the mean E over every ordered pair of the DEM runs that differ only in their seed
  (vibroflow.analysis.compare.seed_scatter, with its jackknife error from three seeds on);
- else from tub47.md's ensemble figure, when the sweep is of the preset that figure belongs to
  with no scenario field of its own changed (only the amplitude factor and the continuum
  options): ten seeds of tub47 at factor 1.0 (docs/decisions/e-limit-seeds.md);
- else it is unknown, and the page says why.
"""
from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from vibroflow.analysis.compare import FIELD_FACTOR, seed_scatter
from vibroflow.errors import InputError
from vibroflow.measure.bulk import read_csv
from vibroflow.report.sweep_pool import SEED_KEY, pool_seeds
from vibroflow.study.methods import METHODS
from vibroflow.study.pipeline import split_settings
from vibroflow.study.sweep_folder import dir_lock, point_dir, read_record
from vibroflow.study.sweep_points import FACTOR_KEY
from vibroflow.study.sweep_table import sweep_rows


@dataclass(frozen=True)
class ELimit:
    """The fields-agree limit on E (-): FIELD_FACTOR x the DEM's seed-to-seed E (E_seed, with
    its standard error when known) and where that floor comes from."""

    E_seed: float
    stderr: float | None
    source: str

    @property
    def limit(self) -> float:
        return FIELD_FACTOR * self.E_seed


#: tub47.md's ensemble floors by preset: the mean pairwise E of the DEM over fill seeds
ENSEMBLE = {
    "tub47": ELimit(0.206, 0.026, "tub47.md: mean E over the 90 ordered pairs of ten fill seeds "
                                  "of tub47 at amplitude factor 1.0 "
                                  "(docs/decisions/e-limit-seeds.md)"),
    "tub47-quick": ELimit(0.166, None, "two fill seeds of tub47-quick at amplitude factor 1.0 "
                                       "(docs/validation.md)"),
}


@dataclass
class SweepData:
    """A sweep folder's record, rows and limits.

    rows: vibroflow.study.sweep_table's rows, sorted by the varied values; pooled: the rows
    pooled over run.seed (vibroflow.report.sweep_pool; the rows themselves, each with n_seeds
    1, when the sweep keeps one seed); limits: the key of a row's group (its varied values
    without run.seed, `group_key`) -> ELimit, or one ELimit for every group under None;
    no_limit: why there is none (when limits is empty)."""

    out: Path
    record: dict[str, Any]
    varied: list[str]
    rows: list[dict[str, Any]]
    limits: dict[tuple | None, ELimit]
    no_limit: str | None
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
            record = read_record(out)
            assert record is not None  # sweep.json exists, read_record raised otherwise
            varied = list(record["varied"])
            rows = sweep_rows(out, record["points"], varied)
        limits, why = e_limits(out, record, rows)
        return cls(out=out, record=record, varied=varied, rows=rows, limits=limits,
                   no_limit=why, pooled=pool_seeds(rows, varied))

    def limit_of(self, row: dict[str, Any]) -> ELimit | None:
        if None in self.limits:
            return self.limits[None]
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


def e_limits(out: Path, record: dict, rows: list[dict]) -> tuple[dict, str | None]:
    """(limits, why none): see the module's docstring."""
    varied = list(record["varied"])
    if SEED_KEY in varied:
        return _measured(out, record, rows)
    source = str(record.get("source", ""))
    scenario_sets, _ = split_settings(record.get("fixed_settings") or [])
    own = [k for k in varied if k != FACTOR_KEY and k.split(".")[0] not in METHODS]
    if source not in ENSEMBLE:
        return {}, (f"the DEM's seed-to-seed E of {source!r} is unknown: sweep run.seed "
                    "(--vary run.seed=1,2,3) to measure it")
    if scenario_sets or own:
        changed = ", ".join([s.partition("=")[0] for s in scenario_sets] + own)
        return {}, (f"tub47.md's seed-to-seed E belongs to {source} as it is, and this sweep "
                    f"changes {changed}: sweep run.seed (--vary run.seed=1,2,3) to measure it")
    return {None: ENSEMBLE[source]}, None


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
    limits = {}
    for key, ts in tables.items():
        if len(ts) >= 2:
            sc = seed_scatter(ts, phi)
            limits[key] = ELimit(sc.mean, sc.stderr,
                                 f"measured: mean E over the {len(sc.pairs)} ordered pairs of "
                                 f"this sweep's {len(ts)} seeds")
    if not limits:
        return {}, "fewer than two finished seeds at every point: no seed-to-seed E"
    return limits, None


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
