"""The continuum's ParaView files, out/vtk/, in the frame the run asks for (io.vtk_frame: the
tub's by default, the lab's on request), the DEM's frames' counterpart (dem.paraview):

    points_NNNNN.vtu   the material points (material point method): velocity relative to the
                       tub and lab velocity (m/s), radius_m (half the side of the point's
                       square), pressure_Pa, shear_rate_per_s, solid_fraction, state
    grid_NNNNN.vtr     the grid fields of fields.py in the tub frame (a rectilinear grid), or
    grid_NNNNN.vts     in the lab frame (a structured grid: the nodes turned with the tub):
                       velocity_relative_m_per_s, velocity_lab_m_per_s, solid_fraction,
                       density_kg_per_m3, pressure_Pa, shear_rate_per_s
    tub.vtu            the tub's surface (tub frame), or in the lab frame
    tub_NNNNN.vtu      the surface moved by the tub's motion at each sample, and tub.pvd
    parts.vtu          with parts: the outline of each part's section at the slice's middle
                       (line cells, cell data "part" the part's index; tub frame), or in the
                       lab frame parts_NNNNN.vtu at each sample, as tub_NNNNN.vtu
    points_early_NNNNN.vtu, grid_early_NNNNN.vt[rs], tub_early_NNNNN.vtu
                       with VtkOptions.every: the same every `every` seconds from `start` up
                       to the averaging window, written as the run passes them
    points.pvd, grid.pvd   the collections, in time order; vtk.json the options
                       (io.vtk_frame.write_vtk_record)

Each file's field data holds its time (s) and the tub's pose then.  The solver's velocity is
relative to the tub, in tub axes (grid_update.py); the lab velocity adds the tub's rigid
velocity at the point (io.vtk_frame.relative_to_frame).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from pyevtk.hl import gridToVTK

from vibroflow.io.vtk import (atomic_vtk, frame_field_data, write_points_vtu,
                              write_section_lines, write_tub_surface)
from vibroflow.io.vtk_frame import VtkOptions, relative_to_frame
from vibroflow.tub.geometry import geometry_of

from .files import VTK_DIR
from .grid import Grid
from .part_obstacle import continuum_parts, section_segments


class ContinuumVtk:
    """Writes a continuum run's ParaView files (module docstring) into out/vtk; each writer
    appends (t s, file name) to samples.vtk[kind]; `tag` names the frame (files.sample_tag,
    files.early_tag)."""

    def __init__(self, scenario, out: Path, options: VtkOptions, pivot, kinds: tuple[str, ...]):
        self.options, self.pivot = options, (float(pivot[0]), float(pivot[1]))
        self.geo = geometry_of(scenario)
        self.y = 0.5 * self.geo.length
        self.dir = Path(out) / VTK_DIR
        self.lab = options.frame == "lab"
        self.kinds = kinds + (("tub",) if self.lab else ())
        self.dir.mkdir(parents=True, exist_ok=True)
        self.outlines = [section_segments(p, self.y) for p in continuum_parts(scenario)]
        if not self.lab:
            write_tub_surface(self.dir / "tub.vtu", self.geo)
            if self.outlines:
                write_section_lines(self.dir / "parts.vtu", self.outlines, self.y)

    def tub(self, tag: str, t: float, pose6, samples) -> None:
        """The tub's surface at frame `tag` (lab frame only: in the tub frame it stands
        still)."""
        if self.lab:
            name = f"tub_{tag}.vtu"
            write_tub_surface(self.dir / name, self.geo, pose6=pose6, pivot=self.pivot,
                              time_s=t)
            samples.vtk["tub"].append((t, name))
            if self.outlines:
                write_section_lines(self.dir / f"parts_{tag}.vtu", self.outlines, self.y,
                                    pose6=pose6, pivot=self.pivot, time_s=t)

    def points(self, tag: str, t: float, pose6, x, v, radius, extra: dict, samples) -> None:
        """Material points at tub-frame x (N, 2) m with velocities v (N, 2) m/s relative to the
        tub, half-sides radius (N,) m, and more point arrays `extra` (named with units)."""
        n = x.shape[0]
        pos_tub = np.stack([x[:, 0], np.full(n, self.y), x[:, 1]], axis=1)
        vel_rel = np.stack([v[:, 0], np.zeros(n), v[:, 1]], axis=1)
        pos, fields = relative_to_frame(self.options.frame, pos_tub, vel_rel, pose6, self.pivot)
        fields["radius_m"] = np.asarray(radius, dtype=float)
        fields.update(extra)
        name = f"points_{tag}.vtu"
        write_points_vtu(self.dir / name, pos, fields, frame_field_data(t, pose6))
        samples.vtk["points"].append((t, name))

    def grid(self, tag: str, t: float, pose6, grid: Grid, fields: dict, samples) -> None:
        """The grid fields (fields.grid_fields) at frame `tag`."""
        xs, zs = grid.node_x(), grid.node_z()
        X, Z = np.meshgrid(xs, zs, indexing="ij")  # (nx, nz)
        nodes = np.stack([X, np.full(X.shape, self.y), Z], axis=-1)
        vel = fields["velocity"]
        vel3 = np.stack([vel[:, :, 0], np.zeros(X.shape), vel[:, :, 1]], axis=-1)
        pos, velocities = relative_to_frame(self.options.frame, nodes, vel3, pose6, self.pivot)

        def c(a):  # (nx, nz) -> contiguous (nx, 1, nz)
            return np.ascontiguousarray(np.asarray(a, dtype=np.float64)[:, None, :])

        data = {name: (c(a[..., 0]), c(a[..., 1]), c(a[..., 2]))
                for name, a in velocities.items()}
        data["solid_fraction"] = c(fields["solid_fraction"])
        data["density_kg_per_m3"] = c(fields["density"])
        data["pressure_Pa"] = c(fields["pressure"])
        data["shear_rate_per_s"] = c(fields["shear_rate"])
        fd = {k: np.atleast_1d(np.float64(val)) for k, val in frame_field_data(t, pose6).items()}
        if self.lab:
            name, suffix = f"grid_{tag}.vts", ".vts"
            coords = (c(pos[..., 0]), c(pos[..., 1]), c(pos[..., 2]))
        else:
            name, suffix = f"grid_{tag}.vtr", ".vtr"
            coords = (np.ascontiguousarray(xs, dtype=np.float64), np.array([self.y]),
                      np.ascontiguousarray(zs, dtype=np.float64))
        atomic_vtk(self.dir / name, lambda base: gridToVTK(base, *coords, pointData=data,
                                                           fieldData=fd), suffix=suffix)
        samples.vtk["grid"].append((t, name))

