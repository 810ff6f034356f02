"""Checkpoints of a continuum run: the whole state of any formulation, what has been sampled so
far and a few numbers of the run, in one .npz file written atomically and checksummed.

A checkpoint is written with vibroflow.io.atomic (a temporary name in the run's folder, flushed
to disk, moved over the previous one with os.replace), so a run killed at any instant leaves
either the previous complete checkpoint or the new complete one.  Arrays are stored as they are
(float64 state, float32 samples), so a resumed run continues with exactly the numbers it had.

A checkpoint can still be damaged after it is written (a copy cut short, a disk error, a file
put in its place by hand): "checksum" holds the sha256 of every other entry (its name, dtype,
shape and bytes, in sorted order; `arrays_checksum`), and load_checkpoint refuses a file whose
arrays do not match it, as it refuses an empty, truncated or foreign file, with one line
(InputError) instead of a traceback or a resume from wrong numbers.

A checkpoint resumes only the run that wrote it: its meta holds the run's fingerprint
(`run_fingerprint`) and formulation, both checked by `check_resumable`.

Layout: "state/<field>" for every array field of the formulation's state record,
"state/history/<slot>/<name>" for the boundaries' per-point (or per-cell) history,
"samples/<name>" for the caller's sampling arrays, "meta" a JSON text with the clock (t, step)
and the caller's own record (fingerprint, formulation, wall time, ...), and "checksum".
"""
from __future__ import annotations

import dataclasses
import hashlib
import io
import json
import zipfile
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from vibroflow.errors import CheckpointRefused
from vibroflow.io.atomic import atomic_path
from vibroflow.io.calibration_file import Calibration
from vibroflow.io.record_diff import first_difference

from .options import ContinuumOptions, options_record

CHECKSUM_KEY = "checksum"
_ZIP_MAGIC = b"PK\x03\x04"
_ZIP_END = b"PK\x05\x06"  # the end-of-central-directory record: a whole zip file ends with it


def arrays_checksum(arrays: dict[str, np.ndarray]) -> str:
    """sha256 (hex) of the named arrays: each one's name, dtype, shape and bytes, in sorted
    name order (the checksum entry itself left out)."""
    h = hashlib.sha256()
    for name in sorted(arrays):
        if name == CHECKSUM_KEY:
            continue
        a = np.ascontiguousarray(arrays[name])
        h.update(f"{name}\0{a.dtype.str}\0{a.shape}\0".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def save_checkpoint(path, state, samples: dict[str, np.ndarray], meta: dict) -> None:
    """Write state (a formulation's state record: its array fields, its history, t and step),
    samples (name -> array) and meta (JSON-able) to path atomically, with the arrays'
    checksum."""
    path = Path(path)
    arrays = {f"state/{f.name}": getattr(state, f.name) for f in dataclasses.fields(state)
              if isinstance(getattr(state, f.name), np.ndarray)}
    for slot, hist in enumerate(state.history):
        for name, a in hist.items():
            arrays[f"state/history/{slot}/{name}"] = a
    for name, a in samples.items():
        arrays[f"samples/{name}"] = np.asarray(a)
    record = {"t": state.t, "step": state.step, "history_slots": len(state.history),
              **meta}
    arrays["meta"] = np.array(json.dumps(record))
    arrays[CHECKSUM_KEY] = np.array(arrays_checksum(arrays))
    with atomic_path(path) as tmp:  # its name ends with ".npz": savez adds no suffix
        np.savez(tmp, **arrays)


class DamagedCheckpoint(CheckpointRefused):
    """A checkpoint file that cannot be resumed from: `why` is "empty", "truncated", "not a
    checkpoint", "checksum mismatch" or "unreadable: ..."."""

    def __init__(self, path: Path, why: str):
        self.path, self.why = Path(path), why
        super().__init__(f"--resume: {path} is damaged ({why})")


def _read_arrays(path: Path) -> dict[str, np.ndarray]:
    """Every entry of the checkpoint at path, checked against its checksum; DamagedCheckpoint
    when the file is empty, cut short, not a checkpoint or does not match its checksum."""
    data = path.read_bytes()
    if not data:
        raise DamagedCheckpoint(path, "empty")
    if not data.startswith(_ZIP_MAGIC):
        raise DamagedCheckpoint(path, "not a checkpoint")
    end = data.rfind(_ZIP_END, max(0, len(data) - (65536 + 22)))
    if end < 0 or len(data) - end < 22:  # no whole end record (22 bytes): cut short
        raise DamagedCheckpoint(path, "truncated")
    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as f:
            arrays = {key: f[key].copy() for key in f.files}
    except zipfile.BadZipFile as e:
        # zipfile checks each entry's CRC-32: a flipped byte in the data is caught here
        raise DamagedCheckpoint(path, "checksum mismatch" if "CRC" in str(e) else
                                f"unreadable: {' '.join(str(e).split())[:80]}") from None
    except (ValueError, OSError, EOFError, KeyError) as e:
        raise DamagedCheckpoint(path, f"unreadable: {' '.join(str(e).split())[:80]}") from None
    if CHECKSUM_KEY not in arrays or "meta" not in arrays:
        raise DamagedCheckpoint(path, "not a checkpoint")
    if str(arrays[CHECKSUM_KEY]) != arrays_checksum(arrays):
        raise DamagedCheckpoint(path, "checksum mismatch")
    return arrays


def load_checkpoint(path) -> tuple[SimpleNamespace, dict[str, np.ndarray], dict]:
    """(saved, samples, meta) of a checkpoint written by save_checkpoint: saved holds the
    state's arrays by field name, its history, t and step, from which the formulation makes its
    state (Formulation.restore); DamagedCheckpoint (an InputError, one line) when the file is
    empty, truncated, not a checkpoint or fails its checksum."""
    path = Path(path)
    arrays = _read_arrays(path)
    try:
        meta = json.loads(str(arrays["meta"]))
        fields = {}
        history: list[dict] = [{} for _ in range(int(meta["history_slots"]))]
        samples = {}
        for key, a in arrays.items():
            parts = key.split("/")
            if parts[:2] == ["state", "history"]:
                history[int(parts[2])][parts[3]] = a
            elif parts[0] == "state":
                fields[parts[1]] = a
            elif parts[0] == "samples":
                samples[parts[1]] = a
        if "x" not in fields:
            raise KeyError("state/x")
        saved = SimpleNamespace(history=history, t=float(meta["t"]), step=int(meta["step"]),
                                **fields)
    except (KeyError, IndexError, ValueError, TypeError) as e:
        # a checksummed file of another layout: not one of these checkpoints
        raise DamagedCheckpoint(path, f"not a checkpoint: {type(e).__name__} "
                                f"{' '.join(str(e).split())[:60]}") from None
    return saved, samples, meta


def run_record(scenario, calibration: Calibration | None, options: ContinuumOptions,
               vtk) -> dict:
    """Everything that fixes a run's numbers, as plain JSON tables: the scenario but for
    run.checkpoint_every, the calibration, the options, vtk (io.vtk_frame.VtkOptions or
    None)."""
    s = scenario.model_dump(mode="json")
    s.get("run", {}).pop("checkpoint_every", None)
    cal = calibration.to_toml_dict() if calibration is not None else None
    record = {"scenario": s, "calibration": cal, "options": options_record(options),
              "vtk": bool(vtk), **({"vtk_options": vtk.record()} if vtk else {})}
    return json.loads(json.dumps(record, sort_keys=True, default=str))


def run_fingerprint(scenario, calibration: Calibration | None, options: ContinuumOptions,
                    vtk) -> str:
    """A hash of run_record: a checkpoint resumes only the run that wrote it (with its
    formulation, `check_resumable`)."""
    text = json.dumps(run_record(scenario, calibration, options, vtk), sort_keys=True,
                      default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def check_resumable(path, meta: dict, fingerprint: str, method: str,
                    record: dict | None = None) -> None:
    """CheckpointRefused (one line) unless the checkpoint at path, of record `meta`, was written
    by a run of this fingerprint (run_fingerprint) and formulation `method`; the line names the
    method, or the first field of the run's record (run_record) that differs."""
    if meta.get("method") != method:
        raise CheckpointRefused(f"--resume: {path} is the checkpoint of another method "
                                f"(method = {meta.get('method')} there, {method} now)")
    if meta.get("fingerprint") != fingerprint:
        diff = first_difference(meta.get("record"), record) if record is not None else \
            "another scenario, calibration or options"
        raise CheckpointRefused(f"--resume: {path} is the checkpoint of another run ({diff})")
