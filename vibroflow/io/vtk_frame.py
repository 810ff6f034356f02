"""The frame of the ParaView files: what `--vtk-frame`, `--vtk-every` and `--vtk-from` ask for,
and the change of frame of the balls' (or material points') fields and of the tub's surface.

Two frames (tub47.md "Frames", vibroflow.tub.motion):

* "tub" (the default): the tub stands still, x across, y along, z up, origin at the lowest point
  of the inner surface; a ball's velocity relative to the tub is the roll the averages measure
  (0.05 m/s on tub47), no longer hidden under the tub's vibration (0.44 m/s).
* "lab": the tub moves by its rigid motion, p_lab = P + Rot(theta) (p - P) + (X, Z).

Every vector field is written in the axes of the chosen frame: in the tub frame a lab velocity
v is written as Rot(-theta) v, in the lab frame a velocity relative to the tub u (tub axes) as
Rot(theta) u.  The relative velocity is v minus the tub's rigid velocity at the ball's centre
(tub.motion.relative_velocity_tub_axes_np), the relative angular velocity w - w_tub with
w_tub = (0, -theta_dot, 0).  The names carry the SI unit (FIELD_UNITS).

This module needs no VTK writer, so that the options can be checked before a run starts.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vibroflow.errors import InputError
from vibroflow.io.atomic import write_json_atomic
from vibroflow.tub.motion import TubMotion, lab_to_tub_np, pose_np, relative_velocity_tub_axes_np

FRAMES = ("tub", "lab")

#: the point arrays of a ball snapshot, each with its unit (SI)
FIELD_UNITS = {
    "velocity_relative_m_per_s": "m/s",
    "velocity_lab_m_per_s": "m/s",
    "angular_velocity_rad_per_s": "rad/s",
    "angular_velocity_relative_rad_per_s": "rad/s",
    "radius_m": "m",
    "id": "1",
}


@dataclass(frozen=True)
class VtkOptions:
    """What ParaView output a run writes.

    frame: "tub" or "lab" (module docstring).  every (s): also a frame of the balls (the
    continuum's points and grid fields) every `every` seconds of the vibration from `start` (s)
    up to the averaging window, whose snapshots are always written; None: the window's
    snapshots alone.
    """

    frame: str = "tub"
    every: float | None = None
    start: float = 0.0

    def __post_init__(self):
        if self.frame not in FRAMES:
            raise InputError(f"--vtk-frame = {self.frame!r}: must be tub or lab")
        if self.every is not None and not (math.isfinite(self.every) and self.every > 0):
            raise InputError(f"--vtk-every = {self.every!r}: must be a time > 0 s")
        if not (math.isfinite(self.start) and self.start >= 0):
            raise InputError(f"--vtk-from = {self.start!r}: must be a time >= 0 s")

    def record(self) -> dict:
        """JSON-ready record (for a stage's inputs or a checkpoint's fingerprint)."""
        return {"frame": self.frame, "every": self.every, "start": self.start}


def vtk_options(vtk) -> VtkOptions | None:
    """None when no ParaView output is asked for; True is VtkOptions() (the tub frame, the
    window's snapshots)."""
    if vtk is None or vtk is False:
        return None
    return VtkOptions() if vtk is True else vtk


def cli_vtk_options(vtk: bool, frame: str | None, every: float | None,
                    start: float | None) -> VtkOptions | None:
    """The options of the command-line flags; a frame option without --vtk is an input error."""
    given = [(name, value) for name, value in (("--vtk-frame", frame), ("--vtk-every", every),
                                                ("--vtk-from", start)) if value is not None]
    if not vtk:
        if given:
            name, value = given[0]
            raise InputError(f"{name} = {value!r}: needs --vtk")
        return None
    if start is not None and every is None:
        raise InputError(f"--vtk-from = {start!r}: needs --vtk-every (the time between frames)")
    return VtkOptions(frame=frame or "tub", every=every, start=start or 0.0)


def check_vtk_window(options: VtkOptions | None, scenario) -> None:
    """InputError (one line) when --vtk-from asks for frames from a time at or after the
    averaging window's start (run.duration - run.average_last of the vibration), where the
    frames `every` gives end: the run would write none of them."""
    if options is None or options.every is None:
        return
    window = float(scenario.run.duration - scenario.run.average_last)
    if options.start >= window:
        raise InputError(f"--vtk-from = {options.start!r}: the frames of --vtk-every run up to "
                         f"the averaging window, which starts at t = {window:g} s "
                         "(run.duration - run.average_last); give an earlier time")


def extra_frame_steps(options: VtkOptions | None, dt: float, window_start: float) -> np.ndarray:
    """Vibration steps of the frames before the averaging window: t = start + k every < the
    window's start (s), rounded to the nearest step; empty unless `every` is given."""
    if options is None or options.every is None:
        return np.zeros(0, np.int64)
    n = math.ceil((window_start - options.start) / options.every - 1e-9)
    if n <= 0:
        return np.zeros(0, np.int64)
    times = options.start + options.every * np.arange(n)
    return np.unique(np.round(times / dt).astype(np.int64))


def _rotate(v, theta):
    """Rot(theta) on the (x, z) components of vectors (..., 3); y unchanged."""
    v = np.asarray(v, dtype=float)
    c, s = np.cos(theta), np.sin(theta)
    out = np.array(v, dtype=float, copy=True)
    out[..., 0] = c * v[..., 0] - s * v[..., 2]
    out[..., 2] = s * v[..., 0] + c * v[..., 2]
    return out


def pose_at(motion: TubMotion, t: float) -> np.ndarray:
    """The tub's pose [X m, Z m, theta rad, Xdot m/s, Zdot m/s, thetadot rad/s] at t (s)."""
    p = pose_np(motion, t)
    return np.array([float(p[k]) for k in ("X", "Z", "theta", "Xdot", "Zdot", "thetadot")])


def ball_frame(frame: str, pos_lab, vel_lab, omg_lab, pose6, pivot) -> tuple[np.ndarray, dict]:
    """Positions (N, 3) m and the vector point arrays of balls given in the lab (positions m,
    velocities m/s, angular velocities rad/s, (N, 3)) at the tub's pose `pose6` (pose_at), in
    `frame` (module docstring): velocity_relative_m_per_s, velocity_lab_m_per_s,
    angular_velocity_rad_per_s, angular_velocity_relative_rad_per_s."""
    X, Z, th, Xd, Zd, thd = (float(a) for a in pose6[:6])
    pivot = (float(pivot[0]), float(pivot[1]))
    rel = relative_velocity_tub_axes_np(pos_lab, vel_lab, X, Z, th, Xd, Zd, thd, pivot)
    omg_rel = np.array(omg_lab, dtype=float, copy=True)
    omg_rel[..., 1] += thd  # w - w_tub, w_tub = (0, -theta_dot, 0)
    if frame == "tub":
        pos = lab_to_tub_np(pos_lab, X, Z, th, pivot)
        fields = {"velocity_relative_m_per_s": rel,
                  "velocity_lab_m_per_s": _rotate(vel_lab, -th),
                  "angular_velocity_rad_per_s": _rotate(omg_lab, -th),
                  "angular_velocity_relative_rad_per_s": _rotate(omg_rel, -th)}
    else:
        pos = np.asarray(pos_lab, dtype=float)
        fields = {"velocity_relative_m_per_s": _rotate(rel, th),
                  "velocity_lab_m_per_s": np.asarray(vel_lab, dtype=float),
                  "angular_velocity_rad_per_s": np.asarray(omg_lab, dtype=float),
                  "angular_velocity_relative_rad_per_s": omg_rel}
    return pos, fields


def tub_to_lab_points(points, pose6, pivot) -> np.ndarray:
    """Lab positions (..., 3) m of tub-frame points at the pose `pose6` (pose_at)."""
    X, Z, th = (float(a) for a in pose6[:3])
    p = np.asarray(points, dtype=float)
    out = np.array(p, dtype=float, copy=True)
    c, s = math.cos(th), math.sin(th)
    rx, rz = p[..., 0] - pivot[0], p[..., 2] - pivot[1]
    out[..., 0] = pivot[0] + c * rx - s * rz + X
    out[..., 2] = pivot[1] + s * rx + c * rz + Z
    return out


def relative_to_frame(frame: str, pos_tub, vel_rel, pose6, pivot) -> tuple[np.ndarray, dict]:
    """Positions (N, 3) m and velocity arrays of material given in the tub frame (positions,
    velocity relative to the tub in tub axes, m/s): the continuum's points.  The lab velocity
    adds the tub's rigid velocity at the point, (Xdot - thetadot r_z, Zdot + thetadot r_x)."""
    X, Z, th, Xd, Zd, thd = (float(a) for a in pose6[:6])
    pos_tub = np.asarray(pos_tub, dtype=float)
    vel_rel = np.asarray(vel_rel, dtype=float)
    pos_lab = tub_to_lab_points(pos_tub, pose6, pivot)
    rx, rz = pos_lab[..., 0] - X - pivot[0], pos_lab[..., 2] - Z - pivot[1]
    vel_lab = _rotate(vel_rel, th)
    vel_lab[..., 0] += Xd - thd * rz
    vel_lab[..., 2] += Zd + thd * rx
    if frame == "tub":
        return pos_tub, {"velocity_relative_m_per_s": vel_rel,
                         "velocity_lab_m_per_s": _rotate(vel_lab, -th)}
    return pos_lab, {"velocity_relative_m_per_s": _rotate(vel_rel, th),
                     "velocity_lab_m_per_s": vel_lab}


#: the record of the options a folder's ParaView files were written with, beside them
RECORD_NAME = "vtk.json"


def write_vtk_record(vtk_dir: Path, options: VtkOptions) -> None:
    """Record, last, the options the ParaView files of vtk_dir were written with."""
    write_json_atomic(Path(vtk_dir) / RECORD_NAME, options.record())


def has_vtk(vtk_dir: Path, options: VtkOptions | None) -> bool:
    """True when no ParaView output is asked for, or vtk_dir holds the files of `options`."""
    if options is None:
        return True
    try:
        return json.loads((Path(vtk_dir) / RECORD_NAME).read_text()) == options.record()
    except (OSError, ValueError):
        return False
