"""The study's last stage: DIR/report.html and the DEM animation in DIR/report/.

The study pipeline (vibroflow.study) sits below the report, so it cannot name this stage
itself: the commands that run a study (`vibroflow run`, `vibroflow sweep`) hand it over as an
extra stage, `run_study(..., extra_stages=[report_stage()])`.
"""
from __future__ import annotations

from vibroflow.report import GIF_NAME, write_report
from vibroflow.study.stages import COMPARISON, Stage, Study

REPORT = "report"


def _run_report(study: Study, resume: bool) -> dict:
    path = write_report(study.out)
    gif = study.folder(REPORT) / GIF_NAME
    return {"report": path.name,
            "animation": f"{REPORT}/{GIF_NAME}" if gif.is_file() else None}


def report_stage() -> Stage:
    """The report stage: after the comparison, no input of its own, about 20 s."""
    return Stage(REPORT, inputs=lambda st: {}, run=_run_report, upstream=(COMPARISON,),
                 outputs=("report.html",), estimate=lambda st: 20.0)
