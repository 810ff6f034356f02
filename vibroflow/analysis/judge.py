"""Judging finished runs against a reference method's runs, from their folders: `vibroflow
compare` (tub47.md "Judging a comparison", over an ensemble of fill seeds).

A run folder is any method's (`vibroflow dem`, `vibroflow continuum`, an imported LIGGGHTS run,
a study's DIR/<method>): its summary.json (case, window, circulation) and bulk_velocity.csv.
The references are runs of the reference method that differ only in their fill seed.  With one
reference the floor of the field comparison, the seed-to-seed E, must be given; with two or more
it is measured on them (compare.seed_scatter: E over every ordered pair, with its jackknife
error from three runs on), and every result is compared with every reference in turn
(compare.difference_to_seeds), so that the comparison and its floor come from the same
ensemble.  One pair's E is a random number: on tub47, ten seeds' pairs range from 0.076 to
0.480 (docs/validation.md).

For each result: its circulation strength against the references' (the mean of their
strengths, with the standard error of that mean from their scatter when there are several,
else the reference's batch-means error), agreeing when within max(10 %, 2 combined standard
errors) and of the same sense; E against each reference, their mean +- standard error, and E
against the references' pooled mean field (compare.ensemble_mean, their noise averaged down:
nearer the systematic part); fields agree when the mean E is no more than 1.5 times the floor.

Several results of one method (the continuum run with the calibrations of several DEM fill
seeds, say) are also judged as one ensemble: their E's mean, standard deviation and range, and
in how many of them the strengths and the fields agree.  Why: a calibration's draw moves E by
about as much as the DEM's seeds do (docs/validation.md section 30), so with one calibration a
verdict near the limit is not a result; over several it is a count.  Each result names the DEM
run its calibration was measured on (summary.json's continuum.calibration, from the
calibration's [source]) where it has one.  An ensemble holds the runs of one method with the
same options (summary.json's continuum.options: `options_label`), so that runs with the
granular temperature on, say, are not pooled with runs without it.
"""
from __future__ import annotations

import json
import math
import re
from dataclasses import MISSING, dataclass, fields as dataclass_fields
from pathlib import Path

import numpy as np

from vibroflow.continuum.formulation import FORMULATIONS, formulation
from vibroflow.continuum.options import ContinuumOptions
from vibroflow.measure.bulk import CellTable, read_csv
from vibroflow.measure.floor_force import take_off_stderr
from vibroflow.measure.bulk_batches import BATCHES_CSV_NAME, with_batches
from vibroflow.analysis.compare import (FIELD_FACTOR, difference_to_seeds, ensemble_mean,
                                        field_difference, field_difference_stderr,
                                        fields_agree, seed_scatter, strengths_agree)
from vibroflow.errors import InputError
from vibroflow.io.atomic import json_safe, write_json_atomic


@dataclass(frozen=True)
class RunResult:
    """One finished run: its folder, case, method (a vibroflow DEM's 'dem', an imported one's
    'dem (liggghts)'), averaging window (t_start,
    t_end s), circulation (summary.json's: strength m^2/s, strength_stderr, sense), cell
    table (bulk_velocity.csv) and the bed's take-off from the floor (summary.json's "floor":
    vibroflow.measure.floor_force; a cycle fraction, NaN where the bed never leaves the floor,
    None where the run has no floor force) and, for a continuum run, the DEM run its calibration
    was measured on (None without one) and its model options (`options_label`)."""

    folder: Path
    case: str
    method: str
    window: tuple[float, float]
    circulation: dict
    table: CellTable
    take_off: float | None = None
    take_off_stderr: float = math.nan
    calibration: str | None = None
    options: str | None = None


def _natural_key(path: Path) -> list:
    """Sort key that orders seed2 before seed10 (the digits compared as numbers)."""
    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", path.name)]


def run_folders(paths) -> list[Path]:
    """The run folders that `paths` name: each path as it is, except a folder that holds no
    summary.json of its own but run folders inside (each with a summary.json), which stands
    for those, in natural order (seed1, seed2, ..., seed10): `-r tests/data/tub47-dem-seeds`
    for the ten seeds.  Why: a shell glob after a single `-r` (`-r seeds/seed*`) gives the
    option its first match only and makes the others results, a plausible but wrong
    judgement; a folder of seeds says what is meant.  Anything else is left to read_result
    (its one-line errors)."""
    out: list[Path] = []
    for p in paths:
        p = Path(p)
        if p.is_dir() and not (p / "summary.json").is_file():
            inner = sorted((c for c in p.iterdir() if c.is_dir() and (c / "summary.json")
                            .is_file()), key=_natural_key)
            if inner:
                out.extend(inner)
                continue
        out.append(p)
    return out


def read_result(folder) -> RunResult:
    """The run in `folder`; an InputError (one line) when it is not a finished run."""
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(f"{folder}: no such run folder")
    summary_path, csv_path = folder / "summary.json", folder / "bulk_velocity.csv"
    for p in (summary_path, csv_path):
        if not p.is_file():
            raise InputError(f"{folder}: not a finished run (no {p.name}); give a folder of "
                             "vibroflow dem, vibroflow continuum or a study's DIR/<method>")
    try:
        s = json.loads(summary_path.read_text())
        c = s["circulation"]
        w = s["window"]
        float(w["t_start"]), float(w["t_end"])   # checked here: a one-line error if not
        strength = float(c["strength"])
    except (ValueError, KeyError, TypeError) as e:
        raise InputError(f"{summary_path}: not a run summary (no circulation or window: "
                         f"{type(e).__name__} {e})") from None
    if s.get("kind") == "vibroflow study summary":
        raise InputError(f"{folder}: a study folder; give its run folders, e.g. {folder}/dem "
                         f"or {folder}/lagrangian")
    try:
        table = read_csv(csv_path)
    except ValueError as e:
        raise InputError(f"{csv_path}: {e}") from None
    batches = folder / BATCHES_CSV_NAME
    if batches.is_file():  # the window's batches: the errors of E against one reference
        try:
            table = with_batches(table, batches)
        except ValueError as e:
            raise InputError(f"{batches}: {e}") from None
    if not math.isfinite(strength):
        raise InputError(f"{summary_path}: circulation strength {strength!r}: not a number")
    return result_from_summary(s, folder, table)


def result_from_summary(summary: dict, folder, table: CellTable) -> RunResult:
    """A RunResult of a run's summary.json contents and its cell table (read_result's last
    step; benchmarks that load runs themselves call it too)."""
    # a continuum names its method; a DEM run its code ("vibroflow", or "liggghts" imported)
    source = str(summary.get("source", "vibroflow"))
    method = summary.get("method") or ("dem" if source == "vibroflow" else f"dem ({source})")
    w = summary["window"]
    return RunResult(folder=Path(folder), case=str(summary.get("case")), method=str(method),
                     window=(float(w["t_start"]), float(w["t_end"])),
                     circulation=summary["circulation"], table=table,
                     take_off=_take_off_of(summary.get("floor")),
                     take_off_stderr=(take_off_stderr(summary["floor"])
                                      if isinstance(summary.get("floor"), dict) else math.nan),
                     calibration=_calibration_of(summary.get("continuum")),
                     options=options_label(summary.get("continuum"), str(method)))


def options_label(continuum, method: str | None = None) -> str | None:
    """A continuum summary's options (its "options" block: vibroflow.continuum.tub_run writes
    the run's ContinuumOptions) as one label, those away from the defaults of the run's
    formulation `method` (Formulation.options: transfer_cfl's is the formulation's own) and
    those without one, sorted by name, e.g. "temperature=True, transfer_cfl=0.5"; None for a
    run with no such block (a DEM run).  The calibration is no option: an ensemble's runs
    differ in it."""
    opts = continuum.get("options") if isinstance(continuum, dict) else None
    if not isinstance(opts, dict):
        return None
    if method in FORMULATIONS:
        defaults = vars(formulation(method).options())
    else:
        defaults = {f.name: f.default for f in dataclass_fields(ContinuumOptions)}
    shown = [f"{k}={v}" for k, v in sorted(opts.items())
             if k not in defaults or defaults[k] is MISSING or v != defaults[k]]
    return ", ".join(shown) or "defaults"


def _calibration_of(continuum) -> str | None:
    """The DEM run a continuum summary's calibration was measured on, or None."""
    cal = continuum.get("calibration") if isinstance(continuum, dict) else None
    run = cal.get("source_run") if isinstance(cal, dict) else None
    return str(run) if run is not None else None


def _take_off_of(floor) -> float | None:
    """The take-off phase of a summary's "floor" block: NaN where the bed never leaves the
    floor, None where there is no block."""
    if not isinstance(floor, dict):
        return None
    t = floor.get("take_off_phase")
    return math.nan if t is None else float(t)


def _se(x) -> float:
    return 0.0 if x is None or not math.isfinite(float(x)) else float(x)


def _check_alike(runs: list[RunResult]) -> None:
    """Every run of one case, window and cell size, or an InputError naming the first that is
    not (tub47.md compares results on the same cells over the same window)."""
    first = runs[0]
    for r in runs[1:]:
        for what, a, b in (("case", r.case, first.case), ("window (s)", r.window, first.window),
                           ("cell size (m)", round(r.table.cell_size, 9),
                            round(first.table.cell_size, 9))):
            if a != b:
                raise InputError(f"{r.folder}: {what} {a!r} differs from {first.folder}'s "
                                 f"{b!r}; runs are compared on the same case, window and cells")


def judge(results: list[RunResult], references: list[RunResult],
          e_seed: float | None = None) -> dict:
    """Every result against the references (module docstring).  e_seed: the seed-to-seed E to
    judge with when there is one reference (an input error with several, whose E is measured)."""
    if not results:
        raise InputError("RESULT: give at least one run folder to judge")
    if not references:
        raise InputError("--reference: give at least one run folder of the reference method")
    if e_seed is not None and not (math.isfinite(e_seed) and e_seed > 0):
        raise InputError(f"--e-seed = {e_seed!r}: must be a seed-to-seed E > 0")
    if e_seed is not None and len(references) > 1:
        raise InputError(f"--e-seed = {e_seed!r}: only with one reference run; with "
                         f"{len(references)} the seed-to-seed E is measured on them")
    _check_alike(references + results)
    for r in references[1:]:
        if r.method != references[0].method:
            raise InputError(f"--reference {r.folder}: a {r.method} run among "
                             f"{references[0].method} runs ({references[0].folder}); the "
                             "references are runs of one method that differ only in their "
                             "fill seed")
    tables = [r.table for r in references]
    n = len(references)
    strengths = np.array([float(r.circulation["strength"]) for r in references])
    ref_sense = references[0].circulation.get("sense")
    if n > 1:
        ref_strength = float(strengths.mean())
        ref_strength_se = float(strengths.std(ddof=1) / math.sqrt(n))
    else:
        ref_strength = float(strengths[0])
        ref_strength_se = _se(references[0].circulation.get("strength_stderr"))
    out: dict = {
        "references": [{"folder": str(r.folder), "method": r.method,
                        "strength": float(r.circulation["strength"]),
                        "strength_stderr": r.circulation.get("strength_stderr"),
                        "sense": r.circulation.get("sense"), **_take_off_entry(r)}
                       for r in references],
        "reference_strength": ref_strength, "reference_strength_stderr": ref_strength_se,
        "case": references[0].case, "window_s": list(references[0].window),
    }
    if n > 1:
        sc = seed_scatter(tables)
        out["floor"] = {"E_seed": sc.mean, "stderr": sc.stderr,
                        "source": f"measured: mean E over the {len(sc.pairs)} ordered pairs of "
                                  f"the {n} references",
                        "pairs": [{"a": i, "b": j, "E": e} for i, j, e in sc.pairs],
                        "each_against_mean_of_others": [
                            field_difference(t, ensemble_mean(tables[:k] + tables[k + 1:]))
                            for k, t in enumerate(tables)]}
    elif e_seed is not None:
        out["floor"] = {"E_seed": float(e_seed), "stderr": None, "source": "given (--e-seed)"}
    else:
        out["floor"] = None
    floor = out["floor"]["E_seed"] if out["floor"] else None
    out["limit"] = FIELD_FACTOR * floor if floor is not None else None
    mean_field = ensemble_mean(tables) if n > 1 else None
    out["results"] = []
    for r in results:
        c = r.circulation
        s, se = float(c["strength"]), _se(c.get("strength_stderr"))
        d = difference_to_seeds(r.table, tables)
        # one reference: E's error is its scatter over the two runs' batches
        if n > 1:
            e_se, e_se_of = d.stderr, "references"
        else:
            e_se = field_difference_stderr(r.table, tables[0])
            e_se, e_se_of = (e_se, "batches") if math.isfinite(e_se) else (None, None)
        entry = {"folder": str(r.folder), "method": r.method, "strength": s,
                 "strength_stderr": c.get("strength_stderr"), "sense": c.get("sense"),
                 **_take_off_entry(r),
                 "strength_ratio": s / ref_strength if ref_strength else None,
                 "strengths_agree": strengths_agree(s, se, ref_strength, ref_strength_se,
                                                    c.get("sense"), ref_sense),
                 "E_each": list(d.values), "E_mean": d.mean, "E_stderr": e_se,
                 "E_stderr_of": e_se_of,
                 "E_mean_field": (field_difference(r.table, mean_field)
                                  if mean_field is not None else None)}
        entry["fields_agree"] = fields_agree(d.mean, floor) if floor is not None else None
        entry["E_over_limit"] = d.mean / out["limit"] if out["limit"] else None
        if r.calibration is not None:
            entry["calibration_source_run"] = r.calibration
        if r.options is not None:
            entry["options"] = r.options
        out["results"].append(entry)
    out["ensembles"] = ensembles(out["results"], out["limit"])
    return out


def ensembles(entries: list[dict], limit: float | None) -> list[dict]:
    """Each method and options (the entries' "options") with two or more of the judged
    `entries` (judge's "results"), as one ensemble: method, options (None for a DEM's), n;
    E_mean, E_sd (the runs' mean E: their mean and standard deviation, ddof 1), E_min, E_max;
    E_mean_over_limit; the strength ratios' range; strengths_agree and fields_agree, how many
    of the n agree (fields None without a floor); the runs' folders and calibrations' DEM runs
    (None where a run names none)."""
    out = []
    keys = list(dict.fromkeys((e["method"], e.get("options")) for e in entries))
    for m, options in keys:
        group = [e for e in entries if (e["method"], e.get("options")) == (m, options)]
        if len(group) < 2:
            continue
        E = np.array([e["E_mean"] for e in group])
        ratios = [e["strength_ratio"] for e in group if e["strength_ratio"] is not None]
        fields = [e["fields_agree"] for e in group]
        out.append({
            "method": m, "options": options, "n": len(group),
            "folders": [e["folder"] for e in group],
            "calibration_source_runs": [e.get("calibration_source_run") for e in group],
            "E_mean": float(E.mean()), "E_sd": float(E.std(ddof=1)),
            "E_min": float(E.min()), "E_max": float(E.max()),
            "E_mean_over_limit": float(E.mean()) / limit if limit else None,
            "strength_ratio_min": min(ratios) if ratios else None,
            "strength_ratio_max": max(ratios) if ratios else None,
            "strengths_agree": sum(bool(e["strengths_agree"]) for e in group),
            "fields_agree": None if any(f is None for f in fields) else sum(fields)})
    return out


def _take_off_entry(r: RunResult) -> dict:
    if r.take_off is None:
        return {}
    se = r.take_off_stderr
    return {"take_off_phase": r.take_off,
            "take_off_phase_stderr": se if math.isfinite(se) else None}


def _take_off(r: dict) -> str:
    """', take-off t f X' of a run's judgement entry (measure.floor_force), or ', never
    leaves the floor'; '' where its run has no floor force (a run of another version)."""
    if "take_off_phase" not in r:
        return ""
    t = r["take_off_phase"]
    if t is None or not math.isfinite(float(t)):
        return ", never leaves the floor"
    se = r.get("take_off_phase_stderr")
    return f", leaves the floor at t f {_pm(float(t), se)}"


def _pm(v, se, fmt="{:.3f}") -> str:
    return fmt.format(v) + ("" if se is None else " +- " + fmt.format(se))


def format_judgement(j: dict) -> str:
    """The judgement as the lines `vibroflow compare` prints."""
    refs = j["references"]
    lines = [f"{j['case']}, window {j['window_s'][0]:g} - {j['window_s'][1]:g} s; "
             f"{len(refs)} reference run(s):"]
    for k, r in enumerate(refs):
        lines.append(f"  [{k}] {r['folder']} ({r['method']}): circulation {r['sense']} "
                     f"{_pm(r['strength'], r['strength_stderr'], '{:.4e}')} m^2/s"
                     f"{_take_off(r)}")
    f = j["floor"]
    if f is None:
        lines.append("seed-to-seed E: unknown (one reference and no --e-seed): the fields "
                     "cannot be judged")
    else:
        lines.append(f"seed-to-seed E {_pm(f['E_seed'], f['stderr'])} ({f['source']}); "
                     f"fields agree when E <= {j['limit']:.3f}")
        if "pairs" in f:
            n = len(refs)
            E = {(p["a"], p["b"]): p["E"] for p in f["pairs"]}
            lines.append("  E(row, column), the column the reference:")
            lines.append("        " + "".join(f"{f'[{b}]':>8}" for b in range(n)))
            for a in range(n):
                lines.append(f"  {f'[{a}]':>6}" + "".join(
                    f"{E[(a, b)]:8.3f}" if a != b else f"{'':>8}" for b in range(n)))
            lines.append("  each against the mean field of the others: "
                         + ", ".join(f"{e:.3f}" for e in f["each_against_mean_of_others"]))
        if "note" in f:
            lines.append(f"  ({f['note']})")
    for r in j["results"]:
        lines.append(f"{r['folder']} ({r['method']}):")
        lines.append(f"  circulation {r['sense']} "
                     f"{_pm(r['strength'], r['strength_stderr'], '{:.4e}')} m^2/s, "
                     f"{r['strength_ratio']:.3f} of the references' "
                     f"{_pm(j['reference_strength'], j['reference_strength_stderr'], '{:.4e}')}"
                     f": strengths agree: {'yes' if r['strengths_agree'] else 'no'}")
        each = ", ".join(f"{e:.3f}" for e in r["E_each"])
        if len(r["E_each"]) == 1:
            line = (f"  E against the reference {_pm(r['E_mean'], r['E_stderr'])}"
                    + (" (its scatter over the two runs' batches)"
                       if r["E_stderr"] is not None else ""))
        else:
            line = f"  E against each reference {each}: mean {_pm(r['E_mean'], r['E_stderr'])}"
        if r["E_mean_field"] is not None:
            line += f"; against their mean field {r['E_mean_field']:.3f}"
        lines.append(line)
        verdict = {True: "yes", False: "no", None: "cannot say"}[r["fields_agree"]]
        ratio = f" ({r['E_over_limit']:.2f} of the limit)" if r["E_over_limit"] else ""
        lines.append(f"  fields agree: {verdict}{ratio}")
        if "take_off_phase" in r:
            lines.append(f"  bed{_take_off(r)[1:]}")
        if "options" in r:
            lines.append(f"  options: {r['options']}")
        if "calibration_source_run" in r:
            lines.append(f"  calibrated on {r['calibration_source_run']}")
    for g in j.get("ensembles", []):
        lines.extend(_ensemble_lines(g))
    return "\n".join(lines)


def _ensemble_lines(g: dict) -> list[str]:
    """The lines of one method's ensemble (`ensembles`)."""
    n = g["n"]
    cals = [c for c in g["calibration_source_runs"] if c is not None]
    if not cals:
        over = f"its {n} runs"
    elif len(set(cals)) == len(cals) == n:
        over = f"its {n} runs, each calibrated on another DEM run"
    else:
        over = f"its {n} runs, on {len(set(cals))} calibration(s) named"
    options = f" ({g['options']})" if g.get("options") else ""
    lines = [f"{g['method']}{options} over {over}:"]
    line = (f"  E {g['E_mean']:.3f} (sd {g['E_sd']:.3f}, {g['E_min']:.3f} - {g['E_max']:.3f})")
    if g["E_mean_over_limit"] is not None:
        line += f", {g['E_mean_over_limit']:.2f} of the limit"
    lines.append(line)
    if g["strength_ratio_min"] is not None:
        lines.append(f"  strength {g['strength_ratio_min']:.3f} - {g['strength_ratio_max']:.3f}"
                     f" of the references'; strengths agree in {g['strengths_agree']} of {n}")
    fa = g["fields_agree"]
    lines.append(f"  fields agree in {fa} of {n}" if fa is not None
                 else "  fields agree: cannot say (no seed-to-seed E)")
    return lines


def is_judgement(path) -> bool:
    """Whether the file at path is a judgement that write_judgement wrote (its references and
    its floor), so that --json replaces only one of those."""
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return False
    return isinstance(data, dict) and "references" in data and "floor" in data


def write_judgement(j: dict, path) -> None:
    """The judgement as JSON, written atomically."""
    write_json_atomic(path, json_safe(j))
