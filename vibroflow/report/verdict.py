"""The fields-agree limit beside every E, and a verdict in words (tub47.md "Judging a
comparison"; docs/decisions/e-limit-seeds.md).

The limit is FIELD_FACTOR (1.5) times the DEM's seed-to-seed E.  That floor is measured on the
study's own DEM seeds when it has several (its dem run and the run folders in DIR/dem-seeds/,
each a `vibroflow dem` of the same scenario with another run.seed: compare.seed_scatter, every
ordered pair, jackknife error), and taken otherwise from the ensemble figure measured for the
case (ENSEMBLE_FLOORS, the tables of docs/validation.md); the page says which.  With seeds, a
continuum's E is its mean against every seed (compare.difference_to_seeds), so that E and its
floor come from the same ensemble.

An ensemble figure judges only the case it was measured on (preset_limit, the one rule of the
study page and the sweep page): a scenario that changes a setting of the flow from its preset
(the window, the bed, the tub) is not judged, because the seeds' E is set by how many of the
roll's swings the window averages and by the bed (docs/decisions/e-limit-seeds.md "Why"), and
a figure of another case would call a flow within its own scatter "differs".
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from vibroflow.analysis.compare import (FIELD_FACTOR, difference_to_seeds,
                                        field_difference_stderr, seed_scatter)
from vibroflow.analysis.judge import read_result, run_folders
from vibroflow.errors import InputError
from vibroflow.scenario.io import load_scenario

SEEDS_DIR = "dem-seeds"

#: (case, amplitude factor) -> (seed-to-seed E, its standard error or None, seeds, where)
ENSEMBLE_FLOORS = {
    ("tub47", 1.0): (0.206, 0.026, 10, "tub47.md: mean pairwise E over ten fill seeds "
                     "(docs/decisions/e-limit-seeds.md)"),
    ("tub47", 0.5): (0.146, 0.013, 10, "docs/validation.md section 15: ten fill seeds "
                     "(tests/data/tub47-f0.5-dem-seeds)"),
    ("tub47", 1.5): (0.160, 0.012, 10, "docs/validation.md section 15: ten fill seeds "
                     "(tests/data/tub47-f1.5-dem-seeds)"),
    ("tub47-quick", 1.0): (0.166, None, 2, "docs/validation.md section 16: two fill seeds "
                           "(LIGGGHTS' CDT)"),
}

#: settings that leave the flow, and so the floor, as it is
NOT_THE_FLOW = ("run.seed", "run.checkpoint_every", "analysis.probes", "motion.amplitude_factor")

#: fewer seeds than this leave the floor low (docs/decisions/e-limit-seeds.md: it settles
#: from seven seeds on)
SETTLED_SEEDS = 7


@dataclass(frozen=True)
class ELimit:
    """The DEM's seed-to-seed E (-), its standard error (None when unknown), the seeds it
    rests on and where it comes from (words)."""

    e_seed: float
    stderr: float | None
    seeds: int
    source: str

    @property
    def limit(self) -> float:
        return FIELD_FACTOR * self.e_seed

    @property
    def caveat(self) -> str:
        if self.seeds < SETTLED_SEEDS:
            return (f"it rests on {self.seeds} seeds: likely low (the floor settles from "
                    f"{SETTLED_SEEDS} seeds on)")
        return ""


def _flat(d: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in d.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            out.update(_flat(v, key + "."))
        else:
            out[key] = v
    return out


def differs_from_preset(scenario) -> tuple[str, ...]:
    """The settings (dotted keys) in which a scenario differs from its case's preset, leaving
    out NOT_THE_FLOW; () when the case is no preset."""
    try:
        preset = load_scenario(scenario.case)
    except InputError:
        return ()
    a, b = _flat(scenario.model_dump()), _flat(preset.model_dump())
    return tuple(k for k in sorted(set(a) | set(b)) if a.get(k) != b.get(k)
                 and not any(k == n or k.startswith(n + ".") for n in NOT_THE_FLOW))


def ensemble_limit(case: str, amplitude_factor: float) -> ELimit | None:
    """The documented floor of a case at an amplitude factor (ENSEMBLE_FLOORS), or None."""
    for (c, f), (e, se, n, where) in ENSEMBLE_FLOORS.items():
        if c == case and math.isclose(f, amplitude_factor, rel_tol=1e-9):
            return ELimit(e, se, n, f"ensemble figure of {case} at amplitude factor "
                          f"{amplitude_factor:g}, {where}")
    return None


def preset_limit(scenario) -> tuple[ELimit | None, str | None]:
    """(the ensemble limit a one-seed scenario is judged by, None; or None, why there is none):
    the figure of its case at its amplitude factor, and only when the scenario changes no
    setting of the flow from that preset (the module's docstring says why)."""
    case, factor = scenario.case, float(scenario.motion.amplitude_factor)
    lim = ensemble_limit(case, factor)
    if lim is None:
        return None, (f"no ensemble figure of the DEM's seed-to-seed E is known for {case} at "
                      f"amplitude factor {factor:g} (docs/validation.md sections 15, 16)")
    differs = differs_from_preset(scenario)
    if differs:
        shown = ", ".join(differs[:6]) + (", ..." if len(differs) > 6 else "")
        return None, (f"the ensemble figure of {case} at amplitude factor {factor:g} is the "
                      f"preset's, and this case changes {shown}: the seeds' E depends on the "
                      "averaging window and the bed (docs/decisions/e-limit-seeds.md)")
    return lim, None


def seeds_limit(tables) -> ELimit:
    """The floor measured on two or more DEM runs that differ only in their fill seed."""
    sc = seed_scatter(tables)
    return ELimit(sc.mean, sc.stderr, len(tables), f"measured on the study's {len(tables)} "
                  f"DEM seeds: mean E over the {len(sc.pairs)} ordered pairs")


def verdict(e: float, limit: float | None) -> tuple[str, str]:
    """(words, css class) for a field difference E against the limit: within it, the fields
    agree; above it, how many times the limit."""
    if limit is None or not (isinstance(e, (int, float)) and math.isfinite(e)):
        return "no limit known for this case: not judged", ""
    if limit <= 0:
        return "the seeds' E is 0 (identical runs): not judged", ""
    r = e / limit
    if r <= 1.0:
        return f"{r:.2f} x the limit: within the DEM's own scatter", "ok"
    return f"{r:.2f} x the limit: the flow differs", "bad"


def study_seed_tables(data, dem_table) -> tuple[list, str | None]:
    """The study's DEM cell tables: its dem run's, then those of DIR/dem-seeds/ (same case,
    window and cell size; judge.run_folders), and a note when a seed there is unusable."""
    folder = data.out / SEEDS_DIR
    tables = [dem_table]
    if not folder.is_dir():
        return tables, None
    dem = read_result(data.out / "dem")
    for path in run_folders([folder]):
        try:
            r = read_result(path)
        except InputError as exc:
            return [dem_table], f"{SEEDS_DIR}: {exc.message}"
        if (r.case, r.window, round(r.table.cell_size, 9)) != (
                dem.case, dem.window, round(dem.table.cell_size, 9)):
            return [dem_table], (f"{path}: another case, window or cell size than the "
                                 "study's DEM: not used as a seed")
        tables.append(r.table)
    return tables, None


def e_rows(data, tables: dict) -> dict:
    """Per continuum method: E against the DEM (the study's, or the mean +- standard error
    against every seed), the limit and the verdict, and the standard error of E against the
    study's DEM over both runs' batches (analysis.compare.field_difference_stderr); plus the
    limit and its source."""
    seeds, note = study_seed_tables(data, tables["dem"])
    if len(seeds) >= 2:
        lim = seeds_limit(seeds)
    else:
        lim, why = preset_limit(data.scenario)
        if why is not None:
            note = "; ".join(n for n in (note, f"Not judged: {why}.") if n)
    rows = {}
    for name in data.continuum_methods:
        if len(seeds) >= 2:
            d = difference_to_seeds(tables[name], seeds)
            e, se = d.mean, d.stderr
        else:
            a = data.summary["methods"][name].get("against_dem") or {}
            e, se = a.get("field_difference_E"), None
        words, cls = verdict(e, lim.limit if lim else None)
        if len(seeds) >= 2:
            words += f" (E {e:.3f}" + (f" ± {se:.3f}" if se is not None else "") + (
                f" against the {len(seeds)} seeds)")
        # E against the study's DEM, its scatter over both runs' batches (the circulation
        # table): the summary's, worked out here for a folder whose summary lacks it
        against = data.summary["methods"][name].get("against_dem") or {}
        e_batches = against.get("field_difference_E_stderr")
        if e_batches is None:
            e_batches = field_difference_stderr(tables[name], tables["dem"],
                                                data.min_solid_fraction)
        rows[name] = {"E": e, "E_stderr": se, "E_batches_stderr": e_batches, "words": words,
                      "cls": cls}
    return {"limit": lim, "rows": rows, "note": note, "seeds": len(seeds)}
