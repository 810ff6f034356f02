"""Checkpoints of a continuum run: the whole material-point state, what has been sampled so far
and a few numbers of the run, in one .npz file written atomically.

A checkpoint is written to a temporary name in the run's folder, flushed to disk and moved over
the previous one with os.replace, so a run killed at any instant leaves either the previous
complete checkpoint or the new complete one.  Arrays are stored as they are (float64 state,
float32 samples), so a resumed run continues with exactly the numbers it had.

Layout: "state/<field>" for the MPMState arrays, "state/history/<slot>/<name>" for the boundaries'
per-point history, "samples/<name>" for the caller's sampling arrays, and "meta" a JSON text with
the clock (t, step) and the caller's own record (fingerprint, wall time, ...).
"""
from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from .mpm import MPMState

_STATE_ARRAYS = ("x", "v", "C", "L", "mass", "volume", "density", "stress", "gamma_dot",
                 "phase", "fext")


def save_checkpoint(path, state: MPMState, samples: dict[str, np.ndarray], meta: dict) -> None:
    """Write state, samples (name -> array) and meta (JSON-able) to path atomically."""
    path = Path(path)
    arrays = {f"state/{name}": getattr(state, name) for name in _STATE_ARRAYS}
    for slot, hist in enumerate(state.history):
        for name, a in hist.items():
            arrays[f"state/history/{slot}/{name}"] = a
    for name, a in samples.items():
        arrays[f"samples/{name}"] = np.asarray(a)
    record = {"t": state.t, "step": state.step, "history_slots": len(state.history),
              **meta}
    arrays["meta"] = np.array(json.dumps(record))
    tmp = path.with_name(f".tmp{os.getpid()}-" + path.name)
    try:
        with open(tmp, "wb") as f:
            np.savez(f, **arrays)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def load_checkpoint(path) -> tuple[MPMState, dict[str, np.ndarray], dict]:
    """(state, samples, meta) of a checkpoint written by save_checkpoint."""
    with np.load(Path(path), allow_pickle=False) as f:
        meta = json.loads(str(f["meta"]))
        fields = {name: f[f"state/{name}"].copy() for name in _STATE_ARRAYS}
        history: list[dict] = [{} for _ in range(int(meta["history_slots"]))]
        samples = {}
        for key in f.files:
            parts = key.split("/")
            if parts[:2] == ["state", "history"]:
                history[int(parts[2])][parts[3]] = f[key].copy()
            elif parts[0] == "samples":
                samples[parts[1]] = f[key].copy()
    state = MPMState(history=history, t=float(meta["t"]), step=int(meta["step"]), **fields)
    return state, samples, meta
