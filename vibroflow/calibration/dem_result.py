"""A DEM result on disk (DIR/dem.h5, written by vibroflow.dem or by the LIGGGHTS importer) read
back as the inputs of the calibration: the scenario it ran, its averaging window and its batches,
and per snapshot the balls and contacts in the tub frame (what
vibroflow.calibration.coarse_grain.CoarseGrainer.add_snapshot takes).

Frames: dem.h5 keeps ball states and contact forces in the lab frame with the tub's pose per
snapshot (vibroflow.dem.output); everything handed out here is in the tub frame, tub axes, with
velocities relative to the tub (tub47.md "Bulk velocity"), so a result from any code is analysed
the same way.
"""
from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from vibroflow.errors import InputError
from vibroflow.measure.stats import batches_of_whole_cycles, phase_bins
from vibroflow.scenario.io import parse_scenario
from vibroflow.tub.motion import lab_to_tub_np, relative_velocity_tub_axes_np

DEM_FILE = "dem.h5"


def _rows_by_snapshot(snapshot_column: np.ndarray, n_snapshots: int) -> np.ndarray:
    """Row offsets (S+1,) of each snapshot in a group whose rows were appended snapshot by
    snapshot (the `snapshot` column is non-decreasing)."""
    return np.searchsorted(snapshot_column, np.arange(n_snapshots + 1), side="left")


def _stored_scenario(f: h5py.File, path: Path) -> dict:
    """The raw scenario (TOML tables) stored in dem.h5's attribute scenario_toml."""
    text = f.attrs.get("scenario_toml")
    if text is None:
        raise InputError(f"{path}: no scenario_toml attribute: give the scenario")
    if isinstance(text, bytes):
        text = text.decode()
    try:
        return tomllib.loads(str(text))
    except tomllib.TOMLDecodeError as e:
        raise InputError(f"{path}: its stored scenario is malformed TOML ({e})") from None


def run_scenario(run: str | Path, overrides=(), field: str = "RUN_DIR"):
    """The scenario the DEM run in RUN (a run directory holding dem.h5, or the file) ran, with
    `key=value` overrides on top; InputError (one line naming `field`) when there is none."""
    p = Path(run)
    path = p / DEM_FILE if p.is_dir() else p
    if not path.is_file():
        raise InputError(f"{field} = {str(run)!r}: no {DEM_FILE} there (run `vibroflow dem` "
                         f"or `vibroflow import liggghts` first)")
    try:
        with h5py.File(path, "r") as f:
            raw = _stored_scenario(f, path)
    except OSError as e:
        raise InputError(f"{path}: not a readable HDF5 file ({e})") from None
    return parse_scenario(raw, overrides)


@dataclass
class DEMResult:
    """An open dem.h5 with its scenario.  Use as a context manager (closes the file)."""

    path: Path
    file: h5py.File
    scenario: object
    source: str

    # ------------------------------------------------------------------------------------------
    @classmethod
    def open(cls, run: str | Path, scenario=None) -> "DEMResult":
        """Open RUN (a run directory holding dem.h5, or the file itself).

        scenario: the Scenario the run used; default: the one stored in dem.h5 (attribute
        scenario_toml, written by `vibroflow dem` and by the LIGGGHTS importer).
        Raises InputError (one line) for a missing, unreadable or foreign file.
        """
        p = Path(run)
        path = p / DEM_FILE if p.is_dir() else p
        if not path.is_file():
            raise InputError(f"RUN_DIR = {str(run)!r}: no {DEM_FILE} there (run `vibroflow dem` "
                             f"or `vibroflow import liggghts` first)")
        try:
            f = h5py.File(path, "r")
        except OSError as e:
            raise InputError(f"{path}: not a readable HDF5 file ({e})") from None
        try:
            for key in ("snapshots/time", "snapshots/position", "snapshots/velocity",
                        "snapshots/tub_pose", "particles/radius"):
                if key not in f:
                    raise InputError(f"{path}: no /{key}: not a vibroflow DEM result")
            if scenario is None:
                scenario = parse_scenario(_stored_scenario(f, path))
            if scenario.tub is None:
                raise InputError(f"{path}: the run's scenario has no tub (explicit mode): "
                                 f"calibration needs a tub run")
        except BaseException:
            f.close()
            raise
        return cls(path=path, file=f, scenario=scenario,
                   source=str(f.attrs.get("source", "vibroflow")))

    def close(self) -> None:
        self.file.close()

    def __enter__(self) -> "DEMResult":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # ------------------------------------------------------------------------------------------
    @property
    def n_particles(self) -> int:
        return int(self.file["particles/radius"].shape[0])

    @property
    def times(self) -> np.ndarray:
        return self.file["snapshots/time"][()]

    @property
    def radius(self) -> np.ndarray:
        return self.file["particles/radius"][()].astype(np.float64)

    @property
    def mass(self) -> np.ndarray:
        rho = self.scenario.materials[self.scenario.fill.material].density
        return 4.0 / 3.0 * math.pi * self.radius**3 * rho

    @property
    def solid_density(self) -> float:
        """rho_s (kg/m^3) of the fill material."""
        return float(self.scenario.materials[self.scenario.fill.material].density)

    @property
    def diameter(self) -> float:
        return float(2.0 * self.radius.mean())

    @property
    def pivot(self) -> tuple[float, float]:
        m = self.scenario.motion
        return (float(m.pivot[0]), float(m.pivot[1]))

    def window(self) -> tuple[float, float]:
        """The averaging window [t_start, t_end) (s) of the scenario."""
        run = self.scenario.run
        return float(run.duration - run.average_last), float(run.duration)

    def batches(self, n_batches: int | None = None) -> np.ndarray:
        """Batch of whole cycles (0 .. n_batches-1, default run.batches, or -1 outside the
        window) of each snapshot (vibroflow.measure.stats.batches_of_whole_cycles)."""
        t0, t1 = self.window()
        n = int(self.scenario.run.batches if n_batches is None else n_batches)
        return batches_of_whole_cycles(self.times, t0, t1, float(self.scenario.motion.frequency),
                                       n)

    def window_snapshots(self, n_batches: int | None = None, n_phases: int = 8):
        """(batch, used, phase) of the averaging window: each snapshot's batch (`batches`), the
        indices of the snapshots in the window, and each snapshot's phase bin of n_phases a
        cycle.  InputError when the window holds no snapshot."""
        batch = self.batches(n_batches)
        used = np.nonzero(batch >= 0)[0]
        if used.size == 0:
            t0, t1 = self.window()
            raise InputError(f"{self.path}: no snapshot in the averaging window [{t0}, {t1}) s")
        return batch, used, phase_bins(self.times, float(self.scenario.motion.frequency), n_phases)

    def has(self, key: str) -> bool:
        return key in self.file and self.file[key].shape[0] > 0

    @property
    def has_ball_contacts(self) -> bool:
        """True when the file holds ball-ball contact forces (vibroflow >= 0.2 runs, LIGGGHTS
        imports of decks that dump them).  An import of an older deck has the group but no
        rows: no ball contacts, its contact stress is then the wall part only."""
        return self.has("ball_contacts/i")

    @property
    def has_wall_forces(self) -> bool:
        """True when the wall contacts' force vectors are stored (and there are some)."""
        return self.has("wall_contacts/force_lab")

    # ------------------------------------------------------------------------------------------
    def iter_snapshots(self, indices=None, contacts: bool = True, wall_contacts: bool = True):
        """Yield (index, snapshot dict) for the snapshots `indices` (default: all), the dict
        holding add_snapshot's keyword arguments: positions_tub, velocities_rel_tub, radius, mass,
        and when `contacts` (and stored) contacts_i, contacts_j, contact_force, contact_branch
        (tub axes), and, unless wall_contacts is False, wall_particle, wall_force (tub axes),
        wall_point (tub frame); plus `time` (s) and `pose` (X, Z, theta, Xdot, Zdot,
        thetadot)."""
        f = self.file
        n_snap = f["snapshots/time"].shape[0]
        idx = np.arange(n_snap) if indices is None else np.asarray(indices, dtype=np.int64)
        times = f["snapshots/time"][()]
        poses = f["snapshots/tub_pose"][()]
        radius = self.radius
        mass = self.mass
        pivot = self.pivot
        tub = self.scenario.tub
        period = float(tub.length) if tub.periodic else 0.0
        bc_rows = wc_rows = None
        if contacts and self.has_ball_contacts:
            bc_rows = _rows_by_snapshot(f["ball_contacts/snapshot"][()], n_snap)
        if contacts and wall_contacts and self.has_wall_forces:
            wc_rows = _rows_by_snapshot(f["wall_contacts/snapshot"][()], n_snap)
        for s in idx:
            s = int(s)
            X, Z, th, Xd, Zd, thd = (float(v) for v in poses[s])
            pos = f["snapshots/position"][s].astype(np.float64)
            vel = f["snapshots/velocity"][s].astype(np.float64)
            out = {
                "time": float(times[s]), "pose": poses[s],
                "positions_tub": lab_to_tub_np(pos, X, Z, th, pivot),
                "velocities_rel_tub": relative_velocity_tub_axes_np(pos, vel, X, Z, th, Xd, Zd,
                                                                    thd, pivot),
                "radius": radius, "mass": mass,
            }
            if bc_rows is not None:
                a, b = int(bc_rows[s]), int(bc_rows[s + 1])
                i = f["ball_contacts/i"][a:b].astype(np.int64)
                j = f["ball_contacts/j"][a:b].astype(np.int64)
                force = f["ball_contacts/force_lab"][a:b].astype(np.float64)
                branch = pos[i] - pos[j]
                if period > 0.0:  # minimum image along the periodic length (y)
                    branch[:, 1] -= period * np.round(branch[:, 1] / period)
                out.update(contacts_i=i, contacts_j=j,
                           contact_force=_to_tub_axes(force, th),
                           contact_branch=_to_tub_axes(branch, th))
            if wc_rows is not None:
                a, b = int(wc_rows[s]), int(wc_rows[s + 1])
                out.update(wall_particle=f["wall_contacts/particle"][a:b].astype(np.int64),
                           wall_force=_to_tub_axes(
                               f["wall_contacts/force_lab"][a:b].astype(np.float64), th),
                           wall_point=f["wall_contacts/position_tub"][a:b].astype(np.float64),
                           wall_kind=f["wall_contacts/wall"][a:b].astype(np.int64))
            yield s, out


def _to_tub_axes(v: np.ndarray, theta: float) -> np.ndarray:
    """A lab-axes vector field (..., 3) in tub axes: the rotation by -theta alone."""
    return lab_to_tub_np(v, 0.0, 0.0, theta, (0.0, 0.0))
