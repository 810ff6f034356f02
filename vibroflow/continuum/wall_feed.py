"""The U wall's feed of fluctuation energy into a continuum run with the granular temperature,
as the run's balance makes it, over the step that ends at a sample (docs/validation.md
section 22; models.md 5.7).

The feed of each wall-touching point or cell is the U wall's contact terms alone (the
partitions' and the parts' left out): slip production (capped by the wall friction's power),
plus the landing, less Johnson & Jackson's collision loss at the cell's phi and T
(wall_energy_flux.cell_wall_terms), in W per metre of thickness; the Lagrangian's balance cells'
feed is shared among their points by contact length.  Summed by the U's regions
(measure.floor_force.REGIONS: the floor within 30 degrees of the bottom, the arcs, the side
walls) it is one row of a sample's wall feed; measure.floor_force.wall_feed_cycle makes it W/m^2
of wall by phase.

The Eulerian's landing is measured from the step's start (its masses, velocities, densities
and scattered stresses): eulerian/wall_feed.py's `before_last_step` keeps them before the
sample's step, which the run makes on its own (tub_run: the same steps, so no number moves).
"""
from __future__ import annotations

import numpy as np

from vibroflow.measure.floor_force import REGIONS, region_of
from vibroflow.tub.geometry import point_to_arc

from .boundary import UWall
from .temperature_field import point_cells
from .wall_energy_flux import cell_wall_terms, contact_terms, normal_of_force


def cell_feed_W_m(phi, T, sums, h, model):
    """The U wall's net feed (W/m) of cells of side h (m) with solid fraction phi, T (m^2/s^2)
    (both (nx, nz)) and wall sums (nx, nz, 4): wall_energy_flux.cell_wall_terms' heating less
    the loss (3/2) rho_s phi a_w T^(3/2), times the cell's area."""
    w = model.walls
    heat, cool = cell_wall_terms(phi, T, sums, float(h), float(w.restitution),
                                 float(w.specularity), bool(w.landing),
                                 model.grid.void_solid_fraction, model.params)
    loss = 1.5 * model.params.density_kg_m3 * phi * cool * np.clip(T, 0, None) ** 1.5
    return (heat - loss) * h * h


def feed_by_region(x, feed_W_m, radius: float) -> np.ndarray:
    """(3,) the feeds feed_W_m (W/m) of points or cells at tub-frame positions x (n, 2) (m)
    summed by the U's region of their nearest wall point (REGIONS)."""
    x = np.asarray(x, float).reshape(-1, 2)
    reg = region_of(point_to_arc(x[:, 0], x[:, 1], radius), radius)
    return np.bincount(reg, np.asarray(feed_W_m, float), len(REGIONS))


class LagrangianWallFeed:
    """The U wall's feed of a Lagrangian run's points (module docstring): the points' U-wall
    sums binned to the balance's cells, each cell's feed shared among its points by contact
    length."""

    def __init__(self, system, state):
        self.system, self.state = system, state
        self.model = system.temperature
        self.wall = next(b for b in system.boundaries if isinstance(b, UWall))

    def before_last_step(self) -> None:
        """Nothing to keep: the points' contacts hold the step's terms."""

    def feed(self):
        """(x (n, 2) m, feed (n,) W/m) of the points touching the U over the step just made."""
        system, state, model, wall = self.system, self.state, self.model, self.wall
        g, h = system.grid, model.spacing_m
        nx, nz = g.nx, g.nz   # the balance's cells: temperature_field.point_step's
        hist = state.history[wall.slot]
        sums = np.zeros((state.n, 4))
        contact_terms(hist["fn"], hist["ft"], normal_of_force(hist["f"], hist["fn"], hist["ft"]),
                      state.v, state.mass, np.sqrt(state.volume), float(wall.stiffness),
                      float(wall.damping_ratio), system.dt, sums)
        idx = point_cells(state.x, g.x0, g.z0, h, (nx, nz))
        ncell = nx * nz
        M = np.bincount(idx, state.mass, ncell)
        E = np.bincount(idx, state.mass * state.temperature, ncell)
        T = np.divide(E, M, out=np.zeros(ncell), where=M > 0)
        phi = M / (model.params.density_kg_m3 * h * h)
        cs = np.stack([np.bincount(idx, sums[:, j], ncell) for j in range(4)], axis=1)
        q = cell_feed_W_m(phi.reshape(nx, nz), T.reshape(nx, nz), cs.reshape(nx, nz, 4), h,
                          model).ravel()
        touch = hist["fn"] > 0
        share = np.divide(sums[:, 0], cs[idx, 0], out=np.zeros(state.n), where=cs[idx, 0] > 0)
        return state.x[touch], (q[idx] * share)[touch]
