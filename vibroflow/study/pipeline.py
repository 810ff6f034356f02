"""Running a study's stages with kept results (see the package notes).

A stage is kept when DIR/<stage>/stage.json exists, holds the hash of the stage's inputs now,
and its outputs exist.  Otherwise it runs: DIR/<stage>/pending.json first records the hash it
runs for; an interrupted stage found again with the same hash resumes (the DEM and the
continuum from their checkpoints), one with another hash starts afresh in an emptied folder.
stage.json is written atomically and last, so a killed stage never looks finished.
"""
from __future__ import annotations

import hashlib
import json
import shutil
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from vibroflow import __version__
from vibroflow.errors import CheckpointRefused, InputError, Interrupted
from vibroflow.io.folder_lock import folder_lock
from vibroflow.io.vtk_frame import VtkOptions
from vibroflow.progress import format_duration
from vibroflow.scenario.checks import require_tub_mode
from vibroflow.scenario.io import parse_value
from vibroflow.study.folder import KIND, STUDY_FILE, check_study_dir, read_json
from vibroflow.study.methods import METHODS, method
from vibroflow.study.results import read_summary
from vibroflow.study.stages import Stage, Study, stages_of, write_json_atomic

STAGE_FILE = "stage.json"
PENDING_FILE = "pending.json"


def split_settings(settings: list[str] | None) -> tuple[list[str], dict[str, dict[str, Any]]]:
    """--set KEY=VALUE settings split into the scenario's overrides and each method's options
    (keys that start with a registered method's name: lagrangian.dx=0.004)."""
    scenario: list[str] = []
    options: dict[str, dict[str, Any]] = {name: {} for name in METHODS}
    for item in settings or []:
        key, sep, value = item.partition("=")
        head, dot, rest = key.strip().partition(".")
        if head in METHODS and dot:
            if not sep or not rest:
                raise InputError(f"--set {item!r}: must be {head}.OPTION=VALUE")
            options[head][rest] = parse_value(value)  # as a scenario field's: bare text too
        else:
            scenario.append(item)
    return scenario, options


def stage_hash(stage: Stage, study: Study, hashes: dict[str, str]) -> str:
    """The hash of a stage's inputs, its upstream stages' hashes and the vibroflow version."""
    text = json.dumps({"stage": stage.name, "inputs": stage.inputs(study),
                       "upstream": {u: hashes[u] for u in stage.upstream},
                       "vibroflow_version": __version__}, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def _kept(study: Study, stage: Stage, h: str) -> dict | None:
    path = study.folder(stage.name) / STAGE_FILE
    if not path.exists():
        return None
    record = read_json(path, "stage record")
    if record.get("hash") != h:
        return None
    if not all((study.out / p).exists() for p in stage.outputs) or not stage.ready(study):
        return None
    return record


def _previous_wall(study: Study, stage: Stage) -> float | None:
    path = study.folder(stage.name) / STAGE_FILE
    try:
        return float(json.loads(path.read_text())["wall_time_s"])
    except (OSError, ValueError, KeyError, TypeError):
        return None


def _run_stage(study: Study, stage: Stage, h: str) -> dict:
    folder = study.folder(stage.name)
    pending = folder / PENDING_FILE
    resume = pending.exists() and read_json(pending, "stage record").get("hash") == h
    if not resume and folder.exists():
        shutil.rmtree(folder)  # another run's leftovers: start afresh
    folder.mkdir(parents=True, exist_ok=True)
    (folder / STAGE_FILE).unlink(missing_ok=True)
    for p in stage.outputs:
        target = study.out / p
        if target.is_file() and target.suffix == ".json":
            target.unlink()  # a result that would look complete before the stage ends
    write_json_atomic(pending, {"stage": stage.name, "hash": h})
    t0 = time.perf_counter()
    try:
        result = stage.run(study, resume)
    except Interrupted as exc:
        raise _stage_interrupted(study, stage, exc.where) from None
    except KeyboardInterrupt:
        raise _stage_interrupted(study, stage, "") from None
    except CheckpointRefused as exc:
        if not resume:
            raise
        # a damaged or foreign checkpoint of a stage the study resumes by itself
        raise CheckpointRefused(exc.reason, f"remove {folder} to run the {stage.name} stage "
                                            "afresh") from None
    wall = time.perf_counter() - t0
    record = {"stage": stage.name, "hash": h, "vibroflow_version": __version__,
              "upstream": {u: study.records[u]["hash"] for u in stage.upstream},
              "inputs": stage.inputs(study), "resumed": resume, "wall_time_s": wall,
              "finished": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "result": result}
    write_json_atomic(folder / STAGE_FILE, record)  # last: the stage is finished
    pending.unlink(missing_ok=True)
    return record


def _stage_interrupted(study: Study, stage: Stage, where: str) -> Interrupted:
    """The study's line for a stage stopped by Ctrl-C: pending.json stays, so the same command
    again resumes the stage from its checkpoint; of the stage's own line only where it stopped
    ("at t = ...", "while settling"): its advice is for its own command."""
    at = f" {where}" if where else ""
    return Interrupted(f"interrupted in the study's {stage.name} stage{at}; run the same "
                       f"command again to go on from there (out: {study.out})")


def _about(estimate: float | None) -> str:
    if estimate is None:
        return "no estimate yet (its first run here)"
    return f"about {format_duration(estimate)}"


def _time_left(rest: Sequence[Stage], kept: dict, estimates: dict, measured: set,
               scale: float) -> str:
    """The time left of the stages still to run: their estimates, the model's scaled by how
    the finished stages the model estimated compared with it (`scale`), a stage's own wall
    time on this folder's previous run (`measured`) as it is: a stage rerun with other options
    says nothing of the machine's pace; the stages without an estimate are named, not
    guessed."""
    to_run = [s.name for s in rest if kept[s.name] is None]
    left = sum(estimates[s] * (1.0 if s in measured else scale)
               for s in to_run if estimates[s] is not None)
    unknown = [s for s in to_run if estimates[s] is None]
    text = f"time left ~ {format_duration(left)}"
    if unknown:
        text += f" + the {', '.join(unknown)} stage{'s' if len(unknown) > 1 else ''} (not " \
                "estimated yet)"
    return text


def run_study(scenario, out: Path, settings: dict[str, dict[str, Any]] | None = None,
              shear_cell: bool = False, progress: bool = False,
              echo: Callable[[str], None] | None = print,
              extra_stages: Sequence[Stage] = (), vtk: VtkOptions | None = None) -> dict:
    """Run (or bring up to date) the study of `scenario` in `out`; returns the summary.

    settings: method name -> its options (`--set lagrangian.dx=0.004` gives
    {"lagrangian": {"dx": 0.004}}); echo: where the one line per stage goes (None: nowhere);
    extra_stages: stages after the comparison from the layers above the study (the report:
    `vibroflow.report.stage.report_stage()`); vtk: the ParaView files of the DEM and of each
    continuum (io.vtk_frame.VtkOptions; None: none); a stage kept without them runs again.
    """
    out = Path(out)
    check_study_dir(out)
    settings = settings or {}
    methods = []  # every input checked before the folder is made
    for name in METHODS:
        m = method(name)
        methods.append((m, m.make_options(settings.get(name, {}))))
    require_tub_mode(scenario, "a study")
    for m, _ in methods:
        m.check(scenario)
    with folder_lock(out, "vibroflow run", field="DIR"):
        check_study_dir(out)  # again under the lock: another command may have written it
        return _run_study(scenario, out, methods, shear_cell, progress, echo, extra_stages, vtk)


def _run_study(scenario, out: Path, methods: list, shear_cell: bool, progress: bool,
               echo: Callable[[str], None] | None, extra_stages: Sequence[Stage],
               vtk: VtkOptions | None = None) -> dict:
    out.mkdir(parents=True, exist_ok=True)
    if not (out / STUDY_FILE).exists():
        write_json_atomic(out / STUDY_FILE, {"kind": KIND, "vibroflow_version": __version__,
                                             "case": scenario.case})
    study = Study(out=out, scenario=scenario, methods=methods, shear_cell=shear_cell,
                  progress=progress, vtk=vtk)
    stages = stages_of(study, extra_stages)
    hashes: dict[str, str] = {}
    for s in stages:  # a hash depends on the upstream hashes only, not on their results
        hashes[s.name] = stage_hash(s, study, hashes)
    kept = {s.name: _kept(study, s, hashes[s.name]) for s in stages}
    previous = {s.name: _previous_wall(study, s) for s in stages}
    measured = {name for name, wall in previous.items() if wall}
    estimates = {s.name: (previous[s.name] or s.estimate(study)) for s in stages}
    spent_est = spent_real = 0.0
    n = len(stages)
    for i, stage in enumerate(stages, 1):
        h = hashes[stage.name]
        record = kept[stage.name]
        if record is not None and any(kept[u] is None for u in stage.upstream):
            record = kept[stage.name] = None  # an upstream stage ran: its outputs are new
        if record is not None:
            what = "up to date, kept"
            spent = 0.0
        else:
            if echo is not None:  # said when it starts: a stage may take minutes
                echo(f"[{i}/{n}] {stage.name:<12} running, {_about(estimates[stage.name])}")
            record = _run_stage(study, stage, h)
            spent = record["wall_time_s"]
            what = f"done in {format_duration(spent)}" + (" (resumed)" if record["resumed"] else "")
            if estimates[stage.name] is not None and stage.name not in measured:
                spent_est += estimates[stage.name]
                spent_real += spent
        study.records[stage.name] = record
        scale = min(5.0, max(0.2, spent_real / spent_est)) if spent_est > 0 else 1.0
        if echo is not None:
            echo(f"[{i}/{n}] {stage.name:<12} {what}; "
                 f"{_time_left(stages[i:], kept, estimates, measured, scale)}")

    return read_summary(out)
