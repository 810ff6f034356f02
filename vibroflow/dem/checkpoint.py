"""The checkpoint of a DEM run (DIR/checkpoint.h5) and what `--resume` finds in DIR: a finished
run, or a checkpoint to go on from, checked against the scenario (vibroflow.dem.fingerprint),
its own checksum and those of the result parts it counts on (vibroflow.dem.output).  What the
folder holds at each instant of a run is in vibroflow.dem.run's docstring.
"""
from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np

from ..errors import START_AFRESH, CheckpointRefused, InputError
from ..run_clock import RunClock
from ..io.record_diff import first_difference
from .interrupts import fault_after_checkpoint
from .output import DamagedFile, ResultWriter, load_state_file, save_state_file
from .simulate import DEMState, DEMSystem, overlap_maxima, set_overlap_maxima
from .step import ASSEMBLY

CHECKPOINT_NAME = "checkpoint.h5"
SUMMARY_NAME = "summary.json"


def refuse(path, what: str) -> CheckpointRefused:
    return CheckpointRefused(f"--resume: {path} {what}")


def finished_summary(out_dir: Path, fingerprint: str, record: dict) -> dict | None:
    """The summary of a finished run in out_dir (summary.json and dem.h5 there), or None;
    InputError when it is another scenario's run."""
    summary_path, h5 = out_dir / SUMMARY_NAME, out_dir / "dem.h5"
    if not (summary_path.is_file() and h5.is_file()):
        return None
    try:
        summary = json.loads(summary_path.read_text())
        with h5py.File(h5, "r") as f:
            there_fp = f.attrs.get("fingerprint")
            there = f.attrs.get("scenario_json")
    except (OSError, ValueError):
        return None  # not a whole result: the checkpoint, if any, decides
    if there_fp != fingerprint:
        diff = first_difference(json.loads(there) if there else None, record)
        raise InputError(f"--resume: {out_dir} holds the finished run of another scenario "
                         f"({diff}); {START_AFRESH}")
    return summary


def resume_checkpoint(scenario, out_dir: Path, system: DEMSystem, clock: RunClock,
                      fingerprint: str, record: dict):
    """(system, state, settle_info, writer) of the run in out_dir/checkpoint.h5, its
    fingerprint, checksum and parts checked (CheckpointRefused when it cannot be resumed)."""
    ckpt = out_dir / CHECKPOINT_NAME
    try:
        state, attrs = load_state_file(ckpt)
    except DamagedFile as exc:
        raise refuse(ckpt, f"is damaged ({exc.reason})") from None
    if attrs.get("fingerprint") != fingerprint:
        there = attrs.get("scenario_json")
        diff = first_difference(json.loads(there) if there else None, record)
        raise refuse(ckpt, f"is the checkpoint of another scenario ({diff})")
    if attrs.get("assembly") != ASSEMBLY:
        raise refuse(ckpt, f"was written by another force assembly ({attrs.get('assembly')}; "
                     f"this vibroflow's: {ASSEMBLY}), whose numbers differ; {START_AFRESH}")
    settle_info = json.loads(attrs["settle_info"])
    try:
        writer = ResultWriter(out_dir, state.n, {}, state.radius,
                              parts_done=int(attrs["parts_done"]),
                              part_hashes=json.loads(attrs["parts_sha256"]),
                              meta_hash=str(attrs["meta_sha256"]),
                              rows_done=json.loads(attrs.get("rows_done", "null")),
                              parts=bool(scenario.parts))
    except DamagedFile as exc:
        raise refuse(exc.path, f"is damaged ({exc.reason}), a part {ckpt.name} counts on") \
            from None
    clock.resume_from(float(attrs["wall_time_s"]))
    if attrs.get("diag") and json.loads(attrs["diag"]) is not None:
        set_overlap_maxima(system, state, np.array(json.loads(attrs["diag"])))
    return system, state, settle_info, writer


def write_checkpoint(path: Path, state: DEMState, writer: ResultWriter, system: DEMSystem,
                     settle_info: dict, wall: float, fingerprint: str,
                     record: dict) -> None:
    """The state, the count of complete result parts with their checksums, and the scenario's
    fingerprint, to DIR/checkpoint.h5 (atomically, with a checksum of its own)."""
    parts_done = writer.rotate()
    # the overlap maxima since the last series row travel too, so the series is exact
    diag = overlap_maxima(state)
    save_state_file(path, state, {"parts_done": parts_done,
                                  "assembly": ASSEMBLY, "wall_time_s": wall,
                                  "settle_info": json.dumps(settle_info),
                                  "diag": json.dumps(diag.tolist() if diag is not None
                                                     else None),
                                  "fingerprint": fingerprint,
                                  "scenario_json": json.dumps(record, sort_keys=True,
                                                              default=str),
                                  "parts_sha256": json.dumps(writer.part_hashes),
                                  "meta_sha256": writer.meta_hash,
                                  "rows_done": json.dumps(writer.rows_done)})
    fault_after_checkpoint()
