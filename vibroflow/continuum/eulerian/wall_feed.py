"""The U wall's feed of fluctuation energy into an Eulerian run with the granular temperature,
over the step that ends at a sample (continuum/wall_feed.py; docs/validation.md section 22):
the step's start kept before it (`before_last_step`) or by the compiled loop that makes it
(`last_step_start`, solver.advance's keep), the wall layer's contact terms of the U alone (the
partitions off) from the run's own cell_wall_sums after it."""
from __future__ import annotations

import numpy as np

from ..kinetic_stress import KINETIC_COLUMNS
from ..temperature_balance import kinetic_stress_of_cells, temperature_step
from ..wall_feed import cell_feed_W_m
from . import solver as eulerian
from . import temperature_loop


class EulerianWallFeed:
    """The U wall's feed of an Eulerian run's wall-layer cells (module docstring)."""

    def __init__(self, system, state, wall_cells=None):
        self.system, self.state = system, state
        self.model = model = system.temperature
        self.ts = temperature_step(model, system.material.critical_density
                                   / system.material.solid_density, system.dt,
                                   system.material.p_wave_speed())
        self.p_kin = np.zeros((state.n, KINETIC_COLUMNS))
        self.cells = system.wall_cells if wall_cells is None else np.asarray(wall_cells)
        self.start = None

    def before_last_step(self) -> None:
        """Keep the step's start (the landing's reference) before the sample's step."""
        s = self.state
        kinetic_stress_of_cells(s.density, s.mass, self.system.mesh.h, s.temperature, s.L, s.stress, s.gamma_dot,
                                s.phase, self.ts, self.p_kin)
        self.start = (s.mass.copy(), s.v.copy(), s.density.copy(), s.stress + self.p_kin[:, :4])

    def last_step_start(self) -> temperature_loop.StepStart:
        """Buffers for solver.advance's keep: the compiled loop fills them with the start of
        its call's last step, the landing's reference (what `before_last_step` keeps)."""
        keep = temperature_loop.step_start(self.state.n)
        self.start = tuple(keep)
        return keep

    def feed(self):
        """(x (n, 2) m, feed (n,) W/m) of the wall layer's cells over the step just made."""
        system, state, model = self.system, self.state, self.model
        mesh, cells, h = system.mesh, self.cells, system.mesh.h
        sums = np.zeros((state.n, 4))
        # the U wall's contacts alone: the partitions off (fused.MeshBoundaries)
        bnd = eulerian._boundaries(system, state)._replace(partitions_on=False)
        temperature_loop.cell_wall_sums(
            bnd, system.mesh_record, system.grid_spec, system.work, system.frame.as_array(),
            state.t - 0.5 * system.dt, state.mass, state.v, state.volume, state.stress,
            state.fext, float(system.material.critical_density), float(system.dt),
            *(np.ascontiguousarray(a, dtype=float) for a in self.start), True,
            bool(model.walls.columns), sums)
        only = np.zeros_like(sums)
        only[cells] = sums[cells]
        shape = (mesh.ncx, mesh.ncz)
        phi = (state.mass / (model.params.density_kg_m3 * h * h)).reshape(shape)
        q = cell_feed_W_m(phi, state.temperature.reshape(shape), only.reshape(shape + (4,)),
                          h, model).ravel()
        return system.x[cells], q[cells]
