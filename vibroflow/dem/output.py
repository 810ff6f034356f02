"""Results and checkpoints of a DEM run on disk (HDF5).

`ResultWriter` appends to `DIR/dem.h5.partial` as the run goes (so a 14 000-ball run with 752
snapshots never holds them all in memory) and renames it to `DIR/dem.h5` when the run is
complete: a reader never sees a half-written dem.h5.  The layout (also written by the LIGGGHTS
importer and read by vibroflow.analysis):

    /  attrs: case, n_particles, dt, frequency, scenario_toml, source
    /particles/radius (N,)
    /snapshots/time, step, phase (S,); tub_pose (S, 6) [X, Z, theta, Xdot, Zdot, thetadot];
               position, velocity, angular_velocity (S, N, 3) float32, lab frame
    /wall_contacts/snapshot, particle, wall, position_tub, arc, fn, ft, sliding (C, ...)
    /impacts/time, kind, position_tub, normal_speed (M, ...)
    /series/time, kinetic_energy, max_overlap_ball, max_overlap_wall (K,)

Checkpoints (`save_checkpoint` / `load_checkpoint`) hold the whole DEMState plus the number of
rows of each result dataset written so far; on resume the partial file is cut back to those
counts, so a resumed run writes exactly what an uninterrupted one would.
"""
from __future__ import annotations

import os
from pathlib import Path

import h5py
import numpy as np

from .neighbours import NeighbourList
from .simulate import DEMState

_SCHEMA = {
    "snapshots": {"time": ((), "f8"), "step": ((), "i8"), "phase": ((), "f8"),
                  "tub_pose": ((6,), "f8")},
    "wall_contacts": {"snapshot": ((), "i4"), "particle": ((), "i4"), "wall": ((), "i1"),
                      "position_tub": ((3,), "f4"), "arc": ((), "f4"), "fn": ((), "f4"),
                      "ft": ((), "f4"), "sliding": ((), "?")},
    "impacts": {"time": ((), "f8"), "kind": ((), "i1"), "position_tub": ((3,), "f4"),
                "normal_speed": ((), "f4")},
    "series": {"time": ((), "f8"), "kinetic_energy": ((), "f8"),
               "max_overlap_ball": ((), "f8"), "max_overlap_wall": ((), "f8")},
}


class ResultWriter:
    """Appends result rows to DIR/dem.h5.partial; `finish` moves it to DIR/dem.h5."""

    def __init__(self, out_dir: Path, n_particles: int, attrs: dict, radius: np.ndarray,
                 counts: dict | None = None):
        self.final = Path(out_dir) / "dem.h5"
        self.partial = Path(out_dir) / "dem.h5.partial"
        n = n_particles
        if counts is not None and self.partial.exists():
            self.f = h5py.File(self.partial, "a")
            for key, count in counts.items():
                group, name = key.split("/")
                ds = self.f[group][name]
                ds.resize(count, axis=0)
            self.f.flush()
            return
        self.f = h5py.File(self.partial, "w")
        for k, v in attrs.items():
            self.f.attrs[k] = v
        self.f.create_dataset("particles/radius", data=radius)
        for group, fields in _SCHEMA.items():
            for name, (shape, dtype) in fields.items():
                # impacts run to millions of rows: lzf keeps the file small at little cost
                self.f.create_dataset(f"{group}/{name}", shape=(0, *shape),
                                      maxshape=(None, *shape), dtype=dtype,
                                      chunks=(16384, *shape),
                                      compression="lzf" if group == "impacts" else None)
        for name in ("position", "velocity", "angular_velocity"):
            self.f.create_dataset(f"snapshots/{name}", shape=(0, n, 3), maxshape=(None, n, 3),
                                  dtype="f4", chunks=(1, n, 3))

    def append(self, group: str, **columns) -> None:
        rows = None
        for name, values in columns.items():
            values = np.asarray(values)
            ds = self.f[group][name]
            if rows is None:
                rows = values.shape[0]
            old = ds.shape[0]
            ds.resize(old + rows, axis=0)
            ds[old:] = values

    def counts(self) -> dict:
        return {f"{g}/{name}": self.f[g][name].shape[0]
                for g in ("snapshots", "wall_contacts", "impacts", "series")
                for name in self.f[g]}

    def flush(self) -> None:
        self.f.flush()

    def finish(self) -> Path:
        self.f.close()
        os.replace(self.partial, self.final)
        return self.final

    def close(self) -> None:
        try:
            self.f.close()
        except Exception:
            pass


_STATE_ARRAYS = ("pos", "vel", "omg", "force", "torque", "radius", "mass", "mat", "ref_tub",
                 "wall_hist", "wall_flag", "wall_fn", "wall_ft", "wall_slide", "wall_point",
                 "wall_arc")


def write_state(group: h5py.Group, state: DEMState) -> None:
    for name in _STATE_ARRAYS:
        group.create_dataset(name, data=getattr(state, name))
    nl = group.create_group("neighbours")
    for name in ("start", "nbr", "hist", "flag"):
        nl.create_dataset(name, data=getattr(state.nl, name))
    nl.attrs["skin"] = state.nl.skin
    nl.attrs["periodic_length"] = state.nl.periodic_length
    nl.attrs["builds"] = state.nl.builds
    group.attrs["step"] = state.step
    group.attrs["time_origin_step"] = state.time_origin_step
    group.attrs["vibrating"] = state.vibrating


def read_state(group: h5py.Group) -> DEMState:
    arrays = {name: group[name][()] for name in _STATE_ARRAYS}
    g = group["neighbours"]
    nl = NeighbourList(float(g.attrs["skin"]), float(g.attrs["periodic_length"]))
    nl.start, nl.nbr, nl.hist, nl.flag = (g["start"][()], g["nbr"][()], g["hist"][()],
                                          g["flag"][()])
    nl.builds = int(g.attrs["builds"])
    return DEMState(step=int(group.attrs["step"]),
                    time_origin_step=int(group.attrs["time_origin_step"]), nl=nl,
                    vibrating=bool(group.attrs["vibrating"]), **arrays)


def save_state_file(path: Path, state: DEMState, attrs: dict | None = None) -> None:
    """Write a state to an HDF5 file atomically (temp file, then rename)."""
    path = Path(path)
    tmp = path.with_name(path.name + f".tmp{os.getpid()}")
    with h5py.File(tmp, "w") as f:
        write_state(f.create_group("state"), state)
        for k, v in (attrs or {}).items():
            f.attrs[k] = v
    os.replace(tmp, path)


def load_state_file(path: Path) -> tuple[DEMState, dict]:
    with h5py.File(path, "r") as f:
        return read_state(f["state"]), dict(f.attrs)
