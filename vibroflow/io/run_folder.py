"""Whose results a folder holds, so that a fresh run replaces only its own command's.

A fresh `vibroflow dem`, `vibroflow continuum` or `vibroflow import liggghts` removes the files
of an earlier run of the same command in its --out folder before it writes its own (so that no
summary.json outlives the run it belongs to).  Those are plain names (summary.json, floor.csv,
vtk/): in a folder that holds another command's results, a study, a sweep or the user's own
files, removing them would destroy what the command did not write.  `claim_for_fresh_run`
refuses such a folder in one line before anything is removed; a new or empty folder, a folder
of the same command's run and a folder of other files that the run does not replace are the
run's to write.  `folder_owner` says whose results a folder holds (`vibroflow export liggghts`
writes its deck only where it names none).

What says whose a folder is: a study's or a sweep's record (study.json, sweep.json), the
"source" of its summary.json (the DEM's "vibroflow", the continuum's "vibroflow continuum", a
LIGGGHTS import's "liggghts"), and, where a run stopped before its summary, its checkpoint and
the files only that command writes (the DEM's dem.h5 and dem.h5.partial, checkpoint.h5; the
continuum's checkpoint.npz).
"""
from __future__ import annotations

import json
from pathlib import Path

from vibroflow.errors import InputError

#: a study's record (vibroflow.study.folder) and a sweep's (vibroflow.study.sweep_folder)
STUDY_FILE = "study.json"
SWEEP_FILE = "sweep.json"
SUMMARY = "summary.json"

#: each command that runs into a folder: the "source" its summary.json carries, and the files
#: only a run of it writes (which say whose the folder is while a run has no summary yet)
COMMANDS = {
    "dem": ("vibroflow", ("dem.h5", "dem.h5.partial", "checkpoint.h5")),
    "continuum": ("vibroflow continuum", ("checkpoint.npz",)),
    "import liggghts": ("liggghts", ()),
}
_SOURCES = {"vibroflow": "a `vibroflow dem` run",
            "vibroflow continuum": "a `vibroflow continuum` run",
            "liggghts": "a LIGGGHTS import (`vibroflow import liggghts`)"}


def folder_owner(out: Path) -> str | None:
    """What the folder's results are, in words, or None where nothing says."""
    if (out / STUDY_FILE).exists():
        return f"a study ({STUDY_FILE}, `vibroflow run`)"
    if (out / SWEEP_FILE).exists():
        return f"a sweep ({SWEEP_FILE}, `vibroflow sweep`)"
    summary = out / SUMMARY
    if summary.exists():
        try:
            source = json.loads(summary.read_text()).get("source")
        except (OSError, UnicodeDecodeError, json.JSONDecodeError, AttributeError):
            source = None
        return _SOURCES.get(source, f"a {SUMMARY} that no vibroflow run wrote")
    for source, own in COMMANDS.values():
        if any((out / name).exists() for name in own):
            return _SOURCES[source]
    return None


#: what a run's ParaView folder holds (vibroflow.io.vtk): a folder of these alone is a run's
#: frames, left by a run that stopped (a blow-up removes its results but not its frames)
PARAVIEW_SUFFIXES = (".vtu", ".vtp", ".vts", ".vtr", ".vti", ".vtm", ".pvd", ".pvtu", ".vtk")


def _frames_only(path: Path) -> bool:
    return path.is_dir() and all(p.is_dir() or p.suffix in PARAVIEW_SUFFIXES
                                 or p.name.startswith(".") for p in path.rglob("*"))


def claim_for_fresh_run(out: Path, command: str, replaces, field: str = "--out") -> None:
    """InputError (one line) unless a fresh run of `command` (a key of COMMANDS) may remove
    the files `replaces` (names in out) of an earlier run: out holds none of them, or they are
    a run of the same command's (module docstring).  Called before anything is removed."""
    out = Path(out)
    if not out.is_dir():
        return
    source, _own = COMMANDS[command]
    owner = folder_owner(out)
    if owner == _SOURCES[source]:
        return
    present = sorted(name for name in replaces
                     if (out / name).exists() and not _frames_only(out / name))
    if owner is None and not present:
        return
    whose = f"the results of {owner}" if owner is not None else "files that no vibroflow " \
        f"{command} run wrote there"
    names = f" ({', '.join(present)})" if present else ""
    raise InputError(f"{field} = {str(out)!r}: holds {whose}{names}; a fresh `vibroflow "
                     f"{command}` replaces only its own runs' files: give another {field}")
