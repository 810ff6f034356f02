"""Results and checkpoints of a DEM run on disk (HDF5).

`ResultWriter` appends to part files as the run goes (so a 14 000-ball run with 752 snapshots
never holds them all in memory) and assembles `DIR/dem.h5` when the run is complete: a reader
never sees a half-written dem.h5.  The layout (also written by the LIGGGHTS
importer and read by vibroflow.analysis):

    /  attrs: case, n_particles, dt, frequency, scenario_toml, source
    /particles/radius (N,)
    /snapshots/time, step, phase (S,); tub_pose (S, 6) [X, Z, theta, Xdot, Zdot, thetadot];
               position, velocity, angular_velocity (S, N, 3) float32, lab frame
    /wall_contacts/snapshot, particle, wall, position_tub, arc, fn, ft, sliding, force_lab
               (C, ...): every ball-wall contact at the snapshots; position_tub is the contact
               point in the tub frame, force_lab the wall's force on the ball (N, lab axes)
    /ball_contacts/snapshot, i, j, force_lab (B, ...): every touching ball pair (i < j) at the
               snapshots, force_lab the force on i by j (N, lab axes); the branch vector
               r_i - r_j is taken from the snapshot's positions (minimum image when the tub is
               periodic).  For the coarse-grained contact stress (vibroflow.calibration).
    /impacts/time, kind, position_tub, normal_speed (M, ...)
    /series/time, kinetic_energy, max_overlap_ball, max_overlap_wall (K,)
    /part_impacts/..., /part_loads/... (only with parts in the bed, PART_UNITS): every
               ball-part impact of the window, the load on each part at the snapshots

Checkpoints hold the whole DEMState plus the number of complete result parts; on resume the
parts after those are dropped, so a resumed run writes exactly what an uninterrupted one would.

Everything a resume or a cached fill reads back is checked: a saved state carries the sha256 of
its arrays and attributes (`state_checksum`, computed from the arrays as they are written and
verified by `load_state_file`), and a checkpoint the sha256 of every part file it counts on
(`file_sha256`, verified by `ResultWriter`) with the rows each holds, so a resume reads each
part once.  A flipped bit, a truncated or an empty file is `DamagedFile`, never other numbers or
a traceback.
"""
from __future__ import annotations

import hashlib
import os
import shutil
import signal
from pathlib import Path

import h5py
import numpy as np

from ..io.atomic import atomic_path
from .neighbours import INDEX, NeighbourList
from .simulate import DEMState

_SCHEMA = {
    "snapshots": {"time": ((), "f8"), "step": ((), "i8"), "phase": ((), "f8"),
                  "tub_pose": ((6,), "f8")},
    "wall_contacts": {"snapshot": ((), "i4"), "particle": ((), "i4"), "wall": ((), "i1"),
                      "position_tub": ((3,), "f4"), "arc": ((), "f4"), "fn": ((), "f4"),
                      "ft": ((), "f4"), "sliding": ((), "?"), "force_lab": ((3,), "f4")},
    "ball_contacts": {"snapshot": ((), "i4"), "i": ((), "i4"), "j": ((), "i4"),
                      "force_lab": ((3,), "f4")},
    "impacts": {"time": ((), "f8"), "kind": ((), "i1"), "position_tub": ((3,), "f4"),
                "normal_speed": ((), "f4")},
    "series": {"time": ((), "f8"), "kinetic_energy": ((), "f8"),
               "max_overlap_ball": ((), "f8"), "max_overlap_wall": ((), "f8")},
}

# what a run with parts adds (vibroflow.dem.parts): every ball-part impact, and the load on each
# part at the snapshots
_PART_SCHEMA = {
    "part_impacts": {"time": ((), "f8"), "part": ((), "i2"), "patch": ((), "i2"),
                     "position_part": ((3,), "f4"), "normal_speed": ((), "f4"),
                     "tangential_speed": ((), "f4"), "energy": ((), "f8"), "ball": ((), "i4")},
    "part_loads": {"snapshot": ((), "i4"), "part": ((), "i2"), "force": ((3,), "f8"),
                   "torque": ((3,), "f8")},
}

#: every dataset's "units" (SI; "1" for a count, an index or a flag) and "long_name" attributes
UNITS = {
    "particles/radius": ("m", "ball radius"),
    "snapshots/time": ("s", "time since the vibration started"),
    "snapshots/step": ("1", "steps since the vibration started"),
    "snapshots/phase": ("1", "phase of the vibration cycle, as a fraction of the cycle"),
    "snapshots/tub_pose": ("m, m, rad, m/s, m/s, rad/s",
                           "tub pose X, Z, theta and their rates (tub47.md, Tub motion)"),
    "snapshots/position": ("m", "ball centre, lab frame"),
    "snapshots/velocity": ("m/s", "ball velocity, lab frame"),
    "snapshots/angular_velocity": ("rad/s", "ball angular velocity, lab frame"),
    "wall_contacts/snapshot": ("1", "snapshot index"),
    "wall_contacts/particle": ("1", "ball index"),
    "wall_contacts/wall": ("1", "wall: 0 the U, 1 and 2 the partitions, 3 and up the planes"),
    "wall_contacts/position_tub": ("m", "contact point, tub frame"),
    "wall_contacts/arc": ("m", "arc length of the contact point along the U's profile"),
    "wall_contacts/fn": ("N", "normal force on the ball"),
    "wall_contacts/ft": ("N", "magnitude of the tangential force on the ball"),
    "wall_contacts/sliding": ("1", "true where the tangential force is at the Coulomb limit"),
    "wall_contacts/force_lab": ("N", "force of the wall on the ball, lab axes"),
    "ball_contacts/snapshot": ("1", "snapshot index"),
    "ball_contacts/i": ("1", "first ball index (i < j)"),
    "ball_contacts/j": ("1", "second ball index"),
    "ball_contacts/force_lab": ("N", "force on ball i by ball j, lab axes"),
    "impacts/time": ("s", "time of the contact's first step"),
    "impacts/kind": ("1", "0 ball-ball, 1 ball-U, 2 ball-partition, 3 ball-plane"),
    "impacts/position_tub": ("m", "contact point, tub frame"),
    "impacts/normal_speed": ("m/s", "normal approach speed at the first step of the contact"),
    "series/time": ("s", "time since the vibration started"),
    "series/kinetic_energy": ("J", "kinetic energy of the balls, spin included, lab frame"),
    "series/max_overlap_ball": ("m", "largest ball-ball overlap since the previous row"),
    "series/max_overlap_wall": ("m", "largest ball-wall overlap since the previous row"),
}

#: the same for a run with parts in the bed
PART_UNITS = {
    "part_impacts/time": ("s", "time of the ball-part contact's first step"),
    "part_impacts/part": ("1", "part index, in the scenario's order"),
    "part_impacts/patch": ("1", "surface patch of the part (vibroflow.tub.parts.patch_layout)"),
    "part_impacts/position_part": ("m", "contact point from the part's centre, part frame"),
    "part_impacts/normal_speed": ("m/s", "normal approach speed relative to the part"),
    "part_impacts/tangential_speed": ("m/s", "tangential slip speed relative to the part"),
    "part_impacts/energy": ("J", "impact energy 0.5 m v_n^2"),
    "part_impacts/ball": ("1", "ball index"),
    "part_loads/snapshot": ("1", "snapshot index"),
    "part_loads/part": ("1", "part index, in the scenario's order"),
    "part_loads/force": ("N", "force of the balls on the part, part frame axes"),
    "part_loads/torque": ("N m", "torque of the balls about the part's centre, part frame axes"),
}

# groups of millions of rows: lzf keeps the file small at little cost
_COMPRESSED = ("impacts", "ball_contacts")

_COPY_ROWS = 1_000_000

_PARTICLE_FIELDS = ("position", "velocity", "angular_velocity")


class DamagedFile(Exception):
    """A file a run reads back (checkpoint, result part, cached fill) is unreadable or fails its
    checksum; `reason` says how in a few words ("checksum mismatch", "truncated", ...)."""

    def __init__(self, path: Path, reason: str):
        super().__init__(f"{path}: {reason}")
        self.path = Path(path)
        self.reason = reason


def fault_kill_at(phase: str) -> None:
    """Fault injection for the tests of the end of a run: with VIBROFLOW_FAULT_KILL_AT=<phase>
    in the environment the process SIGKILLs itself when it reaches that phase (a power cut at a
    known instant).  Phases, in the order a run passes them: "final-checkpoint" (the state at
    the end is on disk, the last rows not yet written), "assembling" (DIR/dem.h5.partial holds
    the first part only), "assembled" (dem.h5 in place, parts and checkpoint kept), "summary"
    (summary.json written, checkpoint and parts kept), "checkpoint-removed" (parts kept)."""
    if os.environ.get("VIBROFLOW_FAULT_KILL_AT") == phase:
        os.kill(os.getpid(), signal.SIGKILL)


def file_sha256(path: Path) -> str:
    """sha256 of a file's bytes (read in 1 MiB blocks: parts of a tub47 run are large)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _damage(path: Path, exc: BaseException) -> str:
    """A few words on why h5py could not read `path`."""
    try:
        size = Path(path).stat().st_size
    except OSError:
        return "missing"
    if size == 0:
        return "empty"
    text = str(exc).lower()
    if "signature" in text:
        return "not an HDF5 file"
    if "truncat" in text or "eof" in text or "end of file" in text:
        return "truncated"
    if isinstance(exc, KeyError):
        return f"incomplete ({exc})"
    return f"unreadable ({' '.join(str(exc).split())[:80]})"


class ResultWriter:
    """Appends result rows as a run goes; `finish` assembles DIR/dem.h5.

    Rows go to numbered part files in DIR/dem.parts/.  At each checkpoint the current part is
    closed (`rotate`) and never touched again, so a run killed at any instant leaves complete,
    readable parts up to its last checkpoint (an HDF5 file open for writing is not crash-safe);
    on resume the parts after the checkpoint's are deleted.  `finish` copies the parts into
    DIR/dem.h5.partial and renames it to DIR/dem.h5, so a reader never sees a half-written
    dem.h5.
    """

    def __init__(self, out_dir: Path, n_particles: int, attrs: dict, radius: np.ndarray,
                 parts_done: int | None = None, part_hashes: list[str] | None = None,
                 meta_hash: str | None = None, rows_done: dict[str, int] | None = None,
                 parts: bool = False):
        """A fresh writer (parts_done None: DIR/dem.parts made anew with meta.h5), or one that
        goes on after `parts_done` complete parts (resume).  On resume, `part_hashes` (the
        sha256 of each complete part) and `meta_hash` (of meta.h5), as the checkpoint recorded
        them, are verified: DamagedFile when a part is missing or changed; `rows_done` (the
        rows of each dataset in those parts, `rows_done` of the checkpoint's writer) is taken
        as recorded, the checksums vouching for the parts.  `parts`: the run has parts in the
        bed (the part_impacts and part_loads groups)."""
        self.schema = {**_SCHEMA, **(_PART_SCHEMA if parts else {})}
        self.out_dir = Path(out_dir)
        self.final = self.out_dir / "dem.h5"
        self.partial = self.out_dir / "dem.h5.partial"
        self.parts_dir = self.out_dir / "dem.parts"
        self.n = n_particles
        self.attrs = dict(attrs)
        self.radius = np.asarray(radius)
        if parts_done is None:
            shutil.rmtree(self.parts_dir, ignore_errors=True)
            self.parts_dir.mkdir(parents=True)
            self.index = 0
            with h5py.File(self.parts_dir / "meta.h5", "w") as f:
                for k, v in self.attrs.items():
                    f.attrs[k] = v
                f.create_dataset("particles/radius", data=self.radius)
            self.meta_hash = file_sha256(self.parts_dir / "meta.h5")
            self.part_hashes: list[str] = []
        else:
            self.index = parts_done
            self._verify(parts_done, part_hashes, meta_hash)
            self.meta_hash = meta_hash
            self.part_hashes = list(part_hashes or [])[:parts_done]
            for p in self.parts_dir.glob("part_*.h5"):
                if int(p.stem.split("_")[1]) >= parts_done:
                    p.unlink()
        self.rows_done = {key: 0 for key in self._keys()}
        if parts_done is not None:
            if rows_done is None or set(rows_done) != set(self.rows_done):
                raise DamagedFile(self.parts_dir, "no row counts in the checkpoint")
            self.rows_done = {key: int(rows_done[key]) for key in self.rows_done}
        self.f = self._open_part()

    def _verify(self, parts_done: int, part_hashes: list[str] | None,
                meta_hash: str | None) -> None:
        """Check meta.h5 and the complete parts against the checkpoint's checksums (without
        them, as in a checkpoint of an older vibroflow, nothing can vouch for the parts)."""
        files = [(self.parts_dir / "meta.h5", meta_hash)]
        hashes = list(part_hashes or [])
        files += [(self._part(k), hashes[k] if k < len(hashes) else None)
                  for k in range(parts_done)]
        for path, expected in files:
            if not path.is_file():
                raise DamagedFile(path, "missing")
            if expected is None:
                raise DamagedFile(path, "no checksum in the checkpoint")
            if file_sha256(path) != expected:
                raise DamagedFile(path, "checksum mismatch")

    def _keys(self):
        keys = [f"{g}/{name}" for g, fields in self.schema.items() for name in fields]
        return keys + [f"snapshots/{name}" for name in _PARTICLE_FIELDS]

    def _part(self, k: int) -> Path:
        return self.parts_dir / f"part_{k:05d}.h5"

    def _open_part(self) -> h5py.File:
        f = h5py.File(self._part(self.index), "w")
        for group, fields in self.schema.items():
            for name, (shape, dtype) in fields.items():
                f.create_dataset(f"{group}/{name}", shape=(0, *shape), maxshape=(None, *shape),
                                 dtype=dtype, chunks=(16384, *shape),
                                 compression="lzf" if group in _COMPRESSED else None)
        for name in _PARTICLE_FIELDS:
            f.create_dataset(f"snapshots/{name}", shape=(0, self.n, 3),
                             maxshape=(None, self.n, 3), dtype="f4", chunks=(1, self.n, 3))
        return f

    def append(self, group: str, **columns) -> None:
        for name, values in columns.items():
            values = np.asarray(values)
            ds = self.f[group][name]
            old = ds.shape[0]
            ds.resize(old + values.shape[0], axis=0)
            ds[old:] = values

    def rows(self, key: str) -> int:
        """Rows written so far under `key` ("snapshots/time", ...), all parts together."""
        return self.rows_done[key] + self.f[key].shape[0]

    def rotate(self) -> int:
        """Close the current part (it is complete from now on) and start the next; returns the
        number of complete parts, which a checkpoint records."""
        for key in self.rows_done:
            self.rows_done[key] += self.f[key].shape[0]
        self.f.close()
        self.part_hashes.append(file_sha256(self._part(self.index)))
        self.index += 1
        self.f = self._open_part()
        return self.index

    def finish(self, keep_parts: bool = False) -> Path:
        """Assemble the parts into DIR/dem.h5 (atomically) and remove them, unless keep_parts:
        a run keeps them until its summary is written and its checkpoint removed, so that a
        kill at any instant of its end leaves a folder --resume completes (`remove_parts`)."""
        self.f.close()
        parts = [self._part(k) for k in range(self.index + 1)]
        with h5py.File(self.partial, "w") as out:
            with h5py.File(self.parts_dir / "meta.h5", "r") as meta:
                for k, v in meta.attrs.items():
                    out.attrs[k] = v
                out.create_dataset("particles/radius", data=meta["particles/radius"][()])
            totals = {key: 0 for key in self._keys()}
            for p in parts:
                with h5py.File(p, "r") as f:
                    for key in totals:
                        totals[key] += f[key].shape[0]
            with h5py.File(parts[0], "r") as f0:
                for key, total in totals.items():
                    src = f0[key]
                    chunks = (1, self.n, 3) if key.split("/")[1] in _PARTICLE_FIELDS else True
                    out.create_dataset(key, shape=(total, *src.shape[1:]), dtype=src.dtype,
                                       chunks=chunks if total else None,
                                       compression="lzf" if key.split("/")[0] in _COMPRESSED
                                       and total else None)
            units_of = {**UNITS, **(PART_UNITS if "part_impacts" in self.schema else {})}
            for key, (units, long_name) in units_of.items():
                out[key].attrs["units"] = units
                out[key].attrs["long_name"] = long_name
            offsets = {key: 0 for key in totals}
            for p in parts:
                with h5py.File(p, "r") as f:
                    for key in totals:
                        m = f[key].shape[0]
                        # copied in slices: a part of a tub47 run holds millions of impacts
                        step = _COPY_ROWS if key.split("/")[1] not in _PARTICLE_FIELDS else 16
                        for a in range(0, m, step):
                            b = min(m, a + step)
                            out[key][offsets[key] + a:offsets[key] + b] = f[key][a:b]
                        offsets[key] += m
                if p == parts[0]:
                    out.flush()
                    fault_kill_at("assembling")
        os.replace(self.partial, self.final)
        if not keep_parts:
            self.remove_parts()
        return self.final

    def remove_parts(self) -> None:
        """Remove DIR/dem.parts (the last step of a run's end)."""
        shutil.rmtree(self.parts_dir, ignore_errors=True)

    def close(self) -> None:
        try:
            self.f.close()
        except Exception:
            pass

    def discard(self) -> None:
        """Remove everything written (a run that blew up has no result)."""
        self.close()
        shutil.rmtree(self.parts_dir, ignore_errors=True)
        self.partial.unlink(missing_ok=True)


_STATE_ARRAYS = ("pos", "vel", "omg", "force", "torque", "radius", "mass", "mat", "ref_tub",
                 "wall_hist", "wall_flag", "wall_fn", "wall_ft", "wall_slide", "wall_point",
                 "wall_force",
                 "wall_arc")


def _state_nodes(state: DEMState, attrs: dict) -> dict[str, tuple[np.ndarray | None, dict]]:
    """A state file's tree as it is written: node name ("" the root) -> (the dataset's array,
    or None for a group; the node's attributes)."""
    nl = state.nl
    nodes = {"": (None, dict(attrs)),
             "state": (None, {"step": state.step, "time_origin_step": state.time_origin_step,
                              "vibrating": state.vibrating}),
             "state/neighbours": (None, {"skin": nl.skin, "periodic_length": nl.periodic_length,
                                         "builds": nl.builds})}
    for name in _STATE_ARRAYS:
        nodes[f"state/{name}"] = (getattr(state, name), {})
    if state.part_key is not None and state.part_key.shape[1] > 0:
        # only a run with parts has them: the files of one without are as they were
        for name in _PART_ARRAYS:
            nodes[f"state/{name}"] = (getattr(state, name), {})
    for name in ("start", "nbr", "hist", "flag"):
        nodes[f"state/neighbours/{name}"] = (getattr(nl, name), {})
    return nodes


_PART_ARRAYS = ("part_hist", "part_key", "part_load")


def read_state(group: h5py.Group) -> DEMState:
    arrays = {name: group[name][()] for name in _STATE_ARRAYS}
    arrays.update({name: group[name][()] for name in _PART_ARRAYS if name in group})
    g = group["neighbours"]
    nl = NeighbourList(float(g.attrs["skin"]), float(g.attrs["periodic_length"]))
    nl.start, nl.nbr, nl.hist, nl.flag = (g["start"][()], np.asarray(g["nbr"][()], INDEX),
                                          g["hist"][()], g["flag"][()])
    nl.builds = int(g.attrs["builds"])
    return DEMState(step=int(group.attrs["step"]),
                    time_origin_step=int(group.attrs["time_origin_step"]), nl=nl,
                    vibrating=bool(group.attrs["vibrating"]), **arrays)


def _attr_bytes(value) -> bytes:
    """An attribute value as bytes for the checksum, the same written or read back (h5py
    returns str for str, numpy scalars for numbers)."""
    if isinstance(value, bytes):
        return value
    if isinstance(value, str):
        return value.encode("utf-8")
    a = np.asarray(value)
    return a.dtype.str.encode() + repr(a.shape).encode() + a.tobytes()


def _nodes_checksum(nodes: dict[str, tuple[np.ndarray | None, dict]]) -> str:
    """sha256 of every dataset (name, dtype, shape, bytes) and every attribute (name, value)
    of a state file's tree (`_state_nodes`), but the root's "checksum" attribute itself."""
    h = hashlib.sha256()
    for name in sorted(nodes):
        data, attrs = nodes[name]
        h.update(b"\0node\0" + name.encode())
        if data is not None:
            data = np.ascontiguousarray(data)
            h.update(data.dtype.str.encode() + repr(data.shape).encode())
            h.update(data.tobytes())
        for key in sorted(attrs):
            if name == "" and key == "checksum":
                continue
            h.update(b"\0attr\0" + key.encode() + b"\0" + _attr_bytes(attrs[key]))
    return h.hexdigest()


def state_checksum(f: h5py.File) -> str:
    """The checksum of an open state file as read back (load_state_file checks it against the
    one save_state_file computed from the arrays it wrote)."""
    names: list[str] = []
    f.visit(names.append)
    nodes = {"": (None, dict(f.attrs))}
    for name in names:
        obj = f[name]
        nodes[name] = (obj[()] if isinstance(obj, h5py.Dataset) else None, dict(obj.attrs))
    return _nodes_checksum(nodes)


def save_state_file(path: Path, state: DEMState, attrs: dict | None = None) -> None:
    """Write a state to an HDF5 file atomically (vibroflow.io.atomic), with the sha256 of its
    contents (computed from the arrays written, not read back) in the root attribute
    "checksum"."""
    nodes = _state_nodes(state, attrs or {})
    with atomic_path(path) as tmp, h5py.File(tmp, "w") as f:
        for name in sorted(nodes):
            data, node_attrs = nodes[name]
            obj = f if name == "" else (f.create_group(name) if data is None
                                        else f.create_dataset(name, data=data))
            for k, v in node_attrs.items():
                obj.attrs[k] = v
        f.attrs["checksum"] = _nodes_checksum(nodes)


def load_state_file(path: Path) -> tuple[DEMState, dict]:
    """(state, root attributes) of a file of save_state_file; DamagedFile when it is not
    readable (empty, truncated, not HDF5, a dataset missing) or fails its checksum."""
    path = Path(path)
    try:
        with h5py.File(path, "r") as f:
            stored = f.attrs.get("checksum")
            if stored is None:
                raise DamagedFile(path, "no checksum")
            if state_checksum(f) != stored:
                raise DamagedFile(path, "checksum mismatch")
            state = read_state(f["state"])
            attrs = {k: v for k, v in f.attrs.items() if k != "checksum"}
    except DamagedFile:
        raise
    except (OSError, KeyError, ValueError, TypeError, RuntimeError) as exc:
        raise DamagedFile(path, _damage(path, exc)) from None
    return state, attrs
