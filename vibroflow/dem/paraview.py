"""The DEM's ParaView files, DIR/vtk/, in one frame (vibroflow.io.vtk_frame: the tub's by
default, the lab's on request):

    snapshot_NNNNN.vtu    the balls at each snapshot of the averaging window (from dem.h5)
    early_NNNNN.vtu       with VtkOptions.every: the balls every `every` seconds from `start`
                          up to the window, written as the run passes them (not in dem.h5)
    snapshots.pvd         all of them in time order, for ParaView
    tub.vtu               the tub's surface (tub frame), or in the lab frame
    tub_<ball file>.vtu   the surface moved by the tub's motion at each frame's instant, and
    tub.pvd               their collection
    part_<name>.vtu       each part's surface with its impact map from DIR/parts.nc
                          (vibroflow.io.part_vtk), at rest where the frame is the part's own
                          (a tub-fixed part in the tub frame, a lab-fixed one in the lab's)
    part_<name>_<ball file>.vtu  otherwise the surface carried by the tub's motion to each
    part_<name>.pvd       frame's instant, and their collection
    vtk.json              the options they were written with (io.vtk_frame.VtkOptions)

Each ball file holds the velocity relative to the tub and the lab velocity (m/s), the angular
velocities (rad/s), the radius (m) and the id; its field data the time (s) and the tub's pose.
"""
from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

from ..io.vtk_frame import VtkOptions, extra_frame_steps, pose_at, write_vtk_record
from ..tub.geometry import geometry_of
from ..io.parts_file import read_parts as read_parts_nc
from ..tub.motion import TubMotion
from ..tub.parts import parts_of
from .part_output import PARTS_NC

VTK_DIR = "vtk"


def early_name(k: int) -> str:
    return f"early_{k:05d}.vtu"


def snapshot_name(s: int) -> str:
    return f"snapshot_{s:05d}.vtu"


def _pivot(scenario) -> tuple[float, float]:
    return float(scenario.motion.pivot[0]), float(scenario.motion.pivot[1])


class EarlyFrames:
    """The frames before the averaging window (VtkOptions.every), written as the run passes
    their steps: `steps` (vibration steps, increasing) and `write(k, state)`."""

    def __init__(self, scenario, options: VtkOptions | None, dt: float, window_start: float,
                 out_dir: Path):
        self.scenario, self.options, self.dt = scenario, options, dt
        self.steps = (extra_frame_steps(options, dt, window_start)
                      if options is not None and not scenario.explicit
                      else np.zeros(0, np.int64))
        self.vdir = Path(out_dir) / VTK_DIR
        self.motion = TubMotion.of_scenario(scenario)
        self.geometry = geometry_of(scenario) if scenario.tub is not None else None

    def write(self, k: int, t: float, pos, vel, omg, radius) -> None:
        """Frame k at time t (s) of the balls (lab: m, m/s, rad/s)."""
        from ..io import vtk as V  # pyevtk is loaded only when VTK output is asked for

        self.vdir.mkdir(exist_ok=True)
        pose6 = pose_at(self.motion, t)
        name = early_name(k)
        V.write_ball_frame(self.vdir / name, self.options.frame, pos, vel, omg, radius, pose6,
                           _pivot(self.scenario), t)
        if self.options.frame == "lab" and self.geometry is not None:
            V.write_tub_surface(self.vdir / f"tub_{name}", self.geometry, pose6=pose6,
                                pivot=_pivot(self.scenario), time_s=t)


def write_vtk(h5path: Path, out_dir: Path, scenario, options: VtkOptions,
              early: EarlyFrames | None = None) -> None:
    """DIR/vtk/ (module docstring): the window's snapshots from dem.h5 in options.frame, the
    early frames the run wrote (those on disk), their .pvd collection, the tub's surface."""
    from ..io import vtk as V  # pyevtk is loaded only when VTK output is asked for

    vdir = out_dir / VTK_DIR
    vdir.mkdir(exist_ok=True)
    pivot = _pivot(scenario)
    geometry = geometry_of(scenario) if scenario.tub is not None else None
    lab = options.frame == "lab"
    entries, surfaces, poses_of = [], [], {}
    motion = TubMotion.of_scenario(scenario)
    if early is not None:
        for k, step in enumerate(early.steps):
            name = early_name(k)
            if (vdir / name).is_file():
                t = float(step) * early.dt
                entries.append((t, name))
                poses_of[name] = pose_at(motion, t)
                if lab and geometry is not None:
                    surfaces.append((t, f"tub_{name}"))
    with h5py.File(h5path, "r") as f:
        radius = f["particles/radius"][()]
        times = f["snapshots/time"][()]
        poses = f["snapshots/tub_pose"][()]
        for s in range(times.shape[0]):
            name, t = snapshot_name(s), float(times[s])
            V.write_ball_frame(vdir / name, options.frame, f["snapshots/position"][s],
                               f["snapshots/velocity"][s], f["snapshots/angular_velocity"][s],
                               radius, poses[s], pivot, t)
            entries.append((t, name))
            poses_of[name] = poses[s]
            if lab and geometry is not None:
                V.write_tub_surface(vdir / f"tub_{name}", geometry, pose6=poses[s], pivot=pivot,
                                    time_s=t)
                surfaces.append((t, f"tub_{name}"))
    V.write_pvd(vdir / "snapshots.pvd", sorted(entries))
    if geometry is not None and lab:
        V.write_pvd(vdir / "tub.pvd", sorted(surfaces))
    elif geometry is not None:
        V.write_tub_surface(vdir / "tub.vtu", geometry)
    frames = [(t, name, poses_of[name]) for t, name in sorted(entries)]
    _write_parts(out_dir, vdir, scenario, options.frame, frames, pivot)
    write_vtk_record(vdir, options)


def _write_parts(out_dir: Path, vdir: Path, scenario, frame: str, frames, pivot) -> None:
    """Each part's surface with its impact map (when DIR/parts.nc is there): part_<name>.vtu
    where `frame` is the part's own, else one file per frame (t s, ball file, pose) carried by
    the tub's motion and part_<name>.pvd (module docstring)."""
    nc = out_dir / PARTS_NC
    if not scenario.parts or not nc.is_file() or scenario.tub is None:
        return
    from ..io import vtk as V
    from ..io.part_vtk import MAP_FIELDS, write_part_surface

    ds = read_parts_nc(nc)
    for k, part in enumerate(parts_of(scenario)):
        maps = {var: ds[var][k].values for var in MAP_FIELDS.values()}
        base = f"part_{part.name}"
        if part.frame == frame:
            write_part_surface(vdir / f"{base}.vtu", part, scenario.tub.length, maps)
            continue
        for t, name, pose6 in frames:
            write_part_surface(vdir / f"{base}_{name}", part, scenario.tub.length, maps,
                               pose6=pose6, pivot=pivot, time_s=t)
        V.write_pvd(vdir / f"{base}.pvd", [(t, f"{base}_{name}") for t, name, _ in frames])
