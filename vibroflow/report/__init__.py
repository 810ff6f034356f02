"""The study report: DIR/report.html of a finished `vibroflow run --out DIR` (also
`vibroflow report DIR`), one self-contained page (images inline, no external link) showing
side by side for the DEM and each continuum method the velocity field, the probes with their
errors, the circulation verdicts, the shear-rate and impact-speed maps, the wall friction, the
mu(I) fit, any sweep, the cost and the scenario, with an animation of the DEM slice.

    data.py       what the page shows, read from the study folder (validated first)
    figures.py    the side-by-side figures (PNG bytes)
    animation.py  the DEM slice over the last cycles (GIF, DIR/report/dem_slice.gif)
    engineer.py   the engineer's sections: the E limit and verdict (verdict.py), difference
                  maps (flow_maps.py), profiles (profiles.py), Gamma, turnover time and
                  kinetic energy (bed_state.py), binned mu(I) (mu_i_bins.py), on the methods'
                  cell tables (cell_tables.py)
    html.py       the page
"""
from __future__ import annotations

from pathlib import Path

from vibroflow.io.atomic import write_text_atomic
from vibroflow.io.folder_lock import folder_lock
from vibroflow.report.animation import write_slice_gif
from vibroflow.report.data import StudyData
from vibroflow.report.html import render
from vibroflow.study.folder import check_study_dir

REPORT_NAME = "report.html"
REPORT_DIR = "report"
GIF_NAME = "dem_slice.gif"


def write_report(study_dir) -> Path:
    """Write DIR/report.html (and DIR/report/dem_slice.gif) for the finished study in
    study_dir; returns the page's path.  A missing, foreign, corrupt or unfinished folder is an
    InputError (one line) and nothing is written.  Both files are written atomically."""
    out = Path(study_dir)
    if not out.is_dir():  # a missing folder or a file, before the lock would make a folder
        check_study_dir(out, must_exist=True)
    # held while the page is made: a study rerun writing the folder meanwhile would change
    # what the page shows under it (a folder another command holds is refused first)
    with folder_lock(out, "vibroflow report", field="DIR"):
        check_study_dir(out, must_exist=True)
        return _write(out, StudyData.read(out))  # validated before anything is written


def _write(out: Path, data) -> Path:
    gif, why = None, None
    dem_dir = out / "dem"
    if (dem_dir / "dem.h5").is_file():
        try:
            gif = write_slice_gif(dem_dir, out / REPORT_DIR / GIF_NAME)
        except ValueError as exc:
            why = str(exc)
    else:
        why = "no dem/dem.h5 in the study"
    text = render(data, gif, why)
    return write_text_atomic(out / REPORT_NAME, text)


__all__ = ["write_report", "REPORT_NAME", "GIF_NAME"]
