"""The stages of a study: what each depends on, what it runs, what it leaves in DIR.

A `Stage` is a small record: its name (its folder DIR/<name>), the JSON-ready inputs that fix
its result (`inputs(study)`: scenario fields and options), its upstream stages (their hashes
join its own), its outputs (paths under DIR that must exist for a kept result), a cost estimate
for the time left, and `run(study, resume)` returning a JSON-ready result record.  Making the
list is `stages_of(study)`: one stage per registered continuum method.
"""
from __future__ import annotations

import dataclasses
import json
import math
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from vibroflow import __version__
from vibroflow.analysis.compare import field_difference, field_difference_stderr, strengths_agree
from vibroflow.calibration.calibrate import calibrate
from vibroflow.continuum.options import options_record
from vibroflow.dem.fingerprint import scenario_record
from vibroflow.dem.run import run_dem
# write_json_atomic is imported from here by the study's other modules
from vibroflow.io.atomic import write_json_atomic
from vibroflow.io.calibration_file import CALIBRATION_FILE, read_calibration
from vibroflow.io.calibration_source import check_calibration_source
from vibroflow.io.vtk_frame import VtkOptions, has_vtk
from vibroflow.measure.bulk import read_csv
from vibroflow.measure.bulk_batches import BATCHES_CSV_NAME, with_batches
from vibroflow.study.methods import ContinuumMethod

DEM = "dem"
CALIBRATION = "calibration"
COMPARISON = "comparison"
SUMMARY_NAME = "summary.json"
#: DEM particle-steps per wall second assumed for the first estimate of the time left
ASSUMED_RATE = 2.0e6


def scenario_inputs(scenario) -> dict:
    """The scenario's fields that fix a continuum's numbers (all but run.checkpoint_every); the
    DEM stage's are fewer (dem.fingerprint.scenario_record: no run.force_chunks either)."""
    s = scenario.model_dump(mode="json")
    s.get("run", {}).pop("checkpoint_every", None)
    return s


@dataclass
class Study:
    """What the stages share: the output folder, the scenario, the options, the progress flag,
    and (filled as stages finish or are kept) each stage's record and hash."""

    out: Path
    scenario: Any
    methods: list[tuple[ContinuumMethod, Any]]  # (method, its options)
    shear_cell: bool = False
    progress: bool = False
    #: the ParaView files the DEM and the continuum stages write (None: none)
    vtk: VtkOptions | None = None
    records: dict[str, dict] = dataclasses.field(default_factory=dict)

    def folder(self, name: str) -> Path:
        return self.out / name


@dataclass
class Stage:
    name: str
    inputs: Callable[[Study], dict]
    run: Callable[[Study, bool], dict]
    upstream: tuple[str, ...] = ()
    outputs: tuple[str, ...] = ()
    #: wall seconds the stage is expected to take (a light stage: about a second), None where
    #: there is no basis for a number
    estimate: Callable[[Study], float | None] = lambda study: 1.0
    #: whether the stage's folder holds what this study asks beyond its inputs (the ParaView
    #: files of study.vtk, which change no number and so no hash); False: it runs again
    ready: Callable[[Study], bool] = lambda study: True


# ----------------------------------------------------------------------------------------------
# DEM

def _dem_cost(study: Study) -> float:
    s = study.scenario
    n = s.fill.count if s.fill is not None else len(s.particles or [])
    t = s.run.duration + (s.fill.settle_time if s.fill is not None else 0.0)
    return n * t / s.run.dt / ASSUMED_RATE


def _run_dem(study: Study, resume: bool) -> dict:
    summary = run_dem(study.scenario, out_dir=study.folder(DEM), resume=resume,
                      progress=study.progress, vtk=study.vtk)
    return {"summary": f"{DEM}/summary.json", "wall_time_s": summary["wall_time_s"]}


def dem_stage() -> Stage:
    return Stage(DEM, inputs=lambda st: {"scenario": scenario_record(st.scenario)},
                 run=_run_dem, outputs=(f"{DEM}/summary.json", f"{DEM}/bulk_velocity.csv",
                                        f"{DEM}/dem.h5"),
                 estimate=_dem_cost, ready=lambda st: has_vtk(st.folder(DEM) / "vtk", st.vtk))


# ----------------------------------------------------------------------------------------------
# calibration: its files (calibration.toml, fields.nc, pictures) in its own folder DIR/calibration

def calibration_file(study: Study) -> Path:
    """The study's calibration.toml, which its continuum stages run with."""
    return study.folder(CALIBRATION) / CALIBRATION_FILE


def _run_calibration(study: Study, resume: bool) -> dict:
    cal = calibrate(study.folder(DEM), shear_cell=study.shear_cell, progress=study.progress,
                    cyclic=True, dilatancy=needs_dilatancy(study),
                    out=study.folder(CALIBRATION))
    r = cal.rheology
    return {"calibration": f"{CALIBRATION}/{CALIBRATION_FILE}",
            "rheology": {"mu_s": r.mu_s, "mu_2": r.mu_2, "I_0": r.I_0, "source": r.source}}


def needs_dilatancy(study: Study) -> bool:
    """Whether a method runs with the dilatancy option, so the calibration must measure K_dil
    (calibration/dilatancy.py)."""
    # the compaction option's excess packing is referred to the dilatancy cell's steady one
    return any(bool(getattr(opts, "dilatancy", False)) or bool(getattr(opts, "compaction", False))
               for _, opts in study.methods)


def _calibration_inputs(study: Study) -> dict:
    # cyclic: the continuum's shear modulus is the cyclic secant one (calibrate.py step 5);
    # "dilatancy" only when measured, so that studies without it keep their hashes
    inputs = {"shear_cell": bool(study.shear_cell), "cyclic_shear_modulus": True}
    if needs_dilatancy(study):
        inputs["dilatancy"] = True
    return inputs


def calibration_stage() -> Stage:
    return Stage(CALIBRATION, inputs=_calibration_inputs,
                 run=_run_calibration, upstream=(DEM,),
                 outputs=(f"{CALIBRATION}/{CALIBRATION_FILE}",),
                 estimate=lambda st: 0.15 * _dem_cost(st) + 5.0
                 + (600.0 if st.shear_cell else 0.0) + (60.0 if needs_dilatancy(st) else 0.0))


# ----------------------------------------------------------------------------------------------
# continuum methods

def continuum_stage(method: ContinuumMethod, options) -> Stage:
    def inputs(study: Study) -> dict:
        opts = options_record(options)
        # the options class's LATER_OPTIONS are left out at their defaults, so that a stage
        # hashed without them keeps its hash
        defaults = {f.name: f.default for f in dataclasses.fields(options)}
        for name in getattr(options, "LATER_OPTIONS", ()):
            if opts.get(name) == defaults.get(name):
                opts.pop(name, None)
        return {"scenario": scenario_inputs(study.scenario), "options": opts}

    def run(study: Study, resume: bool) -> dict:
        path = calibration_file(study)
        cal = read_calibration(path)
        # the study's own DEM made it, so it matches unless the folder was changed by hand
        warning = check_calibration_source(cal, study.scenario, where=str(path))
        if warning:
            sys.stderr.write(warning + "\n")
        summary = method.run(study.scenario, study.folder(method.name), cal, options,
                             study.progress, resume, study.vtk)
        return {"summary": f"{method.name}/summary.json",
                "wall_time_s": summary["wall_time_s"]}

    return Stage(method.name, inputs=inputs, run=run, upstream=(CALIBRATION,),
                 outputs=(f"{method.name}/summary.json", f"{method.name}/bulk_velocity.csv"),
                 estimate=_continuum_cost,
                 ready=lambda st: has_vtk(st.folder(method.name) / "vtk", st.vtk))


def _continuum_cost(study: Study) -> float | None:
    """None: a continuum's cost follows neither the DEM's nor the case's size in a known way
    (on tub47-quick a fraction of a second to a minute, with the method and its options), so
    the first run of a stage is not estimated; the study estimates a later run from its last
    wall time (pipeline._previous_wall)."""
    return None


# ----------------------------------------------------------------------------------------------
# comparison: DIR/summary.json

def _finite(x) -> float | None:
    return float(x) if x is not None and math.isfinite(float(x)) else None


def _method_entry(summary: dict, folder: str) -> dict:
    return {"probes": summary["probes"], "circulation": summary["circulation"],
            "impacts": summary["impacts"], "wall_time_s": summary["wall_time_s"],
            "n_particles": summary.get("n_particles"),
            "bulk_velocity_csv": f"{folder}/bulk_velocity.csv"}


def compare(study: Study) -> dict:
    """The study's summary: every method's probes, circulation, impacts and wall time; each
    continuum method's field difference E against the DEM, circulation verdict (tub47.md
    "Judging a comparison"), probe differences and cost ratio."""
    out = study.out
    sc = study.scenario
    h = sc.analysis.cell_size
    dem = json.loads((out / DEM / "summary.json").read_text())
    dem_table = _with_batches(read_csv(out / DEM / "bulk_velocity.csv", cell_size=h), out / DEM)
    methods = {DEM: _method_entry(dem, DEM)}
    dc = dem["circulation"]
    for m, _ in study.methods:
        s = json.loads((out / m.name / "summary.json").read_text())
        entry = _method_entry(s, m.name)
        table = _with_batches(read_csv(out / m.name / "bulk_velocity.csv", cell_size=h),
                              out / m.name)
        try:
            E = field_difference(table, dem_table, sc.analysis.min_solid_fraction)
            E_note = None
            E_se = _finite(field_difference_stderr(table, dem_table,
                                                   sc.analysis.min_solid_fraction))
        except ValueError as exc:
            E, E_note, E_se = None, str(exc), None
        c = s["circulation"]
        agree = strengths_agree(c["strength"], _nan(c.get("strength_stderr")),
                                dc["strength"], _nan(dc.get("strength_stderr")),
                                c.get("sense"), dc.get("sense"))
        probes = {}
        for name, p in s["probes"].items():
            q = dem["probes"].get(name)
            if q is not None:
                # two independent runs: their batch-means errors add in quadrature
                probes[name] = {
                    k: _finite(_nan(p[v]) - _nan(q[v])) for k, v in (("dvx", "vx"),
                                                                      ("dvz", "vz"))}
                probes[name].update({
                    k + "_stderr": _finite(math.hypot(_nan(p.get(v + "_stderr")),
                                                      _nan(q.get(v + "_stderr"))))
                    for k, v in (("dvx", "vx"), ("dvz", "vz"))})
        entry["against_dem"] = {
            "field_difference_E": E, "field_difference_E_stderr": E_se,
            "field_difference_note": E_note,
            "min_solid_fraction": sc.analysis.min_solid_fraction,
            "circulation_strength": c["strength"], "dem_circulation_strength": dc["strength"],
            "circulation_agrees": agree,
            "probe_differences_m_s": probes,
            "cost_ratio": (s["wall_time_s"] / dem["wall_time_s"]
                           if dem["wall_time_s"] > 0 else None),
        }
        methods[m.name] = entry
    return {"kind": "vibroflow study summary", "vibroflow_version": __version__,
            "case": sc.case, "units": "SI (m, m/s, m^2/s, s)",
            "reference": DEM, "methods": methods}


def _with_batches(table, folder: Path):
    """The table with the batches its run wrote beside it (measure.bulk_batches), or as it is
    without a readable batches' file: then E has no error."""
    path = folder / BATCHES_CSV_NAME
    if not path.is_file():
        return table
    try:
        return with_batches(table, path)
    except (OSError, ValueError):
        return table


def _nan(x) -> float:
    return float("nan") if x is None else float(x)


def _run_comparison(study: Study, resume: bool) -> dict:
    summary = compare(study)
    write_json_atomic(study.out / SUMMARY_NAME, summary)
    return {"summary": SUMMARY_NAME,
            "E": {k: v["against_dem"]["field_difference_E"]
                  for k, v in summary["methods"].items() if "against_dem" in v}}


def comparison_stage(study: Study) -> Stage:
    names = tuple(m.name for m, _ in study.methods)
    return Stage(COMPARISON,
                 inputs=lambda st: {"methods": list(names),
                                    "min_solid_fraction": st.scenario.analysis.min_solid_fraction,
                                    "cell_size": st.scenario.analysis.cell_size},
                 run=_run_comparison, upstream=(DEM, *names), outputs=(SUMMARY_NAME,))


def stages_of(study: Study, extra: Sequence[Stage] = ()) -> list[Stage]:
    """The study's stages in order: DEM, calibration, each continuum method, comparison, then
    `extra`, the stages of the layers above that finish a study (its report:
    vibroflow.report.stage), given by the caller since the study cannot import them."""
    return [dem_stage(), calibration_stage(),
            *(continuum_stage(m, o) for m, o in study.methods), comparison_stage(study),
            *extra]
