"""The material point method in 2D plane strain: the state record and the step.

One step (Sulsky, Chen & Schreyer 1994 with the APIC transfers of Jiang et al. 2015; update the
stress last, "USL"):

1. boundaries add their forces on the points (boundary.py);
2. particle to grid: mass, APIC momentum, stress divergence and point forces (p2g.py);
3. grid velocity update with gravity and the frame's inertial forces, the frame's motion taken
   at mid-step (grid_update.py);
4. grid to particle: velocity, affine matrix C, velocity gradient L; move the points (g2p.py);
5. volume, density and stress of the points through the shared constitutive law
   (plasticity.py -> constitutive.py).

The steps are made by one compiled loop (fused.py, `advance`): many steps a call, parallel
over the system's fixed point chunks, so the numbers depend on `MPMSystem.chunks` and never on
the number of threads; one chunk gives the serial scatter's numbers.

Units (SI, per metre of thickness along y): positions m, velocities m/s, masses kg/m, volumes
m^2, stresses Pa [xx, zz, xz, yy] (tension positive), forces N/m.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from vibroflow.errors import InputError

from .. import fused, steps
from ..boundary import BOUNDARY_DTYPE, NO_PARTS, PartitionFriction, PartWall, Plane
from ..constitutive import ContinuumMaterial
from ..grid import Grid
from ..grid_step import chunk_bounds, grid_spec, grid_work
from ..grid_update import LabFrame
from ..state import ContinuumState
from ..temperature_balance import loop_arguments, phi_cap_of
from ..temperature_field import advance_with_temperature, point_step, pressure_Pa
from ..timestep import stable_dt
from ..wall_energy_flux import contact_terms, normal_of_force, partition_terms
from .temperature_loop import advance_temperature_kernel


class ContinuumBlowUp(RuntimeError):
    """The explicit solution left the grid or became non-finite."""


@dataclass
class MPMSystem:
    """What does not change during a run: the grid, the material, the frame (grid_update.py),
    the boundaries (boundary.py), the time step dt (s) and the number of point chunks of the
    parallel step (fused.py: the numbers depend on it, never on the number of threads; a tub
    run takes the scenario's run.force_chunks).

    no_slip_below (m, optional): a rough, no-slip floor as a grid boundary condition, the
    nodes at heights z <= no_slip_below held still after every grid update (the usual MPM
    Dirichlet condition, Sulsky et al. 1994; the no-slip base of the mu(I) column collapses
    of Lagree, Staron & Popinet 2011).  Unlike a point-wise penalty contact, which brakes only
    the row of points touching the wall and lets the next row shear past it within one cell,
    it holds the grid's velocity at the wall, so the basal shear is resolved by the grid.

    flip (-, in [0, 1]): the FLIP fraction of the points' velocity update (g2p.py): 0 is APIC
    (Jiang et al. 2015), v_p = sum_i w_ip v_i; f > 0 adds f (v_p - sum_i w_ip v_i^old), the
    part of the point's own velocity that the grid's velocity before the step did not hold
    (Brackbill & Ruppel 1986's FLIP for f = 1; the FLIP-APIC blends of Fei et al. 2021).  APIC
    replaces the point's velocity by the grid's smooth field at every step and so damps the
    grid-scale motion at every step: its results depend on the number of steps, a numerical
    viscosity that shrinks with the Courant number only by growing elsewhere (the column
    collapse's run-out, vibroflow.continuum.column; tub47-quick's circulation, 0.75 of the
    DEM's at cfl 0.3, 1.04 at cfl 0.1).  A blend near 1 keeps the momentum exactly (the FLIP
    part sums to zero over the points) and makes the results time-step converged, at the cost
    of FLIP's point noise.  Default 0, the studies' setting so far.

    transfers (integer >= 1): the APIC transfers a step makes (transfer_operator.py): the
    updated grid velocities go through the transfer pair transfers - 1 times before the
    gather, so the grid-scale damping that APIC's transfers make is transfers / dt per second,
    set apart from the step.  Default 1: the plain APIC (or FLIP-blended) step.

    axisymmetric: the section is a half-plane x = r >= 0 of a body of revolution about the z
    axis (the axisymmetric column collapses of Lube et al. 2004 and Lajeunesse et al. 2004),
    not a plane-strain slice: the points' masses and volumes are per radian (kg, m^3; a point
    of meridian area A at radius r has V = A r), the hoop stress sigma_theta is the stress's
    yy slot, the velocity gradient gains the hoop rate v_r / r (state.L has five columns;
    g2p.py), which enters the volume and the elastic predictor, and the hoop stress the radial
    force (p2g.py) -- the axisymmetric MPM of Nairn & Guilkey (2015, Int. J. Numer. Meth. Eng.
    101, 127).  The axis is a grid condition: nodes at r <= 0 have no radial velocity.  Plane
    penalty walls and the partitions are plane-strain objects (their force scales with the
    point's side sqrt(V)) and are refused here: a floor is the no-slip grid floor
    (`no_slip_below`).

    temperature (temperature_field.TemperatureModel, optional): the points carry the granular
    temperature (state.temperature) and its balance is made after every step on the grid's
    cells, its kinetic pressure added to the stress the points scatter (`advance`); None
    (default): not carried.  Plane strain only."""

    grid: Grid
    material: ContinuumMaterial
    dt: float
    frame: object = field(default_factory=LabFrame)
    boundaries: list = field(default_factory=list)
    no_slip_below: float | None = None
    chunks: int = 2
    flip: float = 0.0
    axisymmetric: bool = False
    transfers: int = 1
    temperature: object = None

    def __post_init__(self):
        if self.temperature is not None and self.axisymmetric:
            raise InputError("temperature with axisymmetric = True: the temperature's balance "
                             "is plane strain only")
        if not self.dt > 0:
            raise InputError(f"dt = {self.dt!r}: must be > 0 s")
        self.no_slip_rows = 0 if self.no_slip_below is None else \
            self.grid.rows_at_or_below(self.no_slip_below)
        self.axis_cols = 0
        if self.axisymmetric:
            if self.grid.periodic:
                raise InputError("axisymmetric = True with a periodic grid: the section must "
                                 "start at the axis r = 0, not wrap around")
            if self.boundaries:
                raise InputError(f"axisymmetric = True with boundaries "
                                 f"{[type(b).__name__ for b in self.boundaries]}: none allowed "
                                 "(the penalty walls and partitions are plane-strain; use "
                                 "no_slip_below for a floor)")
            if not self.grid.x0 <= 0.0:
                raise InputError(f"axisymmetric = True with the grid's left edge at x0 = "
                                 f"{self.grid.x0!r} m: the grid must reach the axis (x0 <= 0)")
            # node columns i with x0 + i dx <= 0 (the node on the axis included)
            self.axis_cols = int(math.floor(-self.grid.x0 / self.grid.dx + 1e-9)) + 1
        if not (isinstance(self.chunks, int) and self.chunks >= 1):
            raise InputError(f"chunks = {self.chunks!r}: must be an integer >= 1")
        if not (isinstance(self.transfers, int) and self.transfers >= 1):
            raise InputError(f"transfers = {self.transfers!r}: must be an integer >= 1 (APIC "
                             "transfers a step)")
        self.params = self.material.as_array()
        for j, b in enumerate(self.boundaries):
            b.slot = j
        # the grid and its conditions, and its work arrays reused every step: the per-chunk
        # scatter buffers, the node fields, the transfer operator's (grid_step.py)
        self.grid_spec = grid_spec(self.grid, self.no_slip_rows, self.axis_cols)
        self.work = grid_work(self.grid, self.chunks, self.transfers)


@dataclass(kw_only=True)
class MPMState(ContinuumState):
    """The material points (ContinuumState's fields over the N points) and the clock."""

    def angular_momentum(self, dx: float, origin=(0.0, 0.0)) -> float:
        """Total angular momentum about `origin` (kg m/s per m; positive turning x into z) with
        the APIC points' own spin m_p dx^2/4 (C_zx - C_xz) (Jiang et al. 2015, section 5.3)."""
        rx = self.x[:, 0] - origin[0]
        rz = self.x[:, 1] - origin[1]
        orbital = self.mass * (rx * self.v[:, 1] - rz * self.v[:, 0])
        spin = self.mass * 0.25 * dx * dx * (self.C[:, 2] - self.C[:, 1])
        return float(orbital.sum() + spin.sum())


def init_state(system: MPMSystem, x, volume, density, v=None, stress=None,
               t: float = 0.0) -> MPMState:
    """Points at x (N, 2) m with volumes (N,) m^2 and densities (N,) kg/m^3 (so masses
    density * volume), velocities v (N, 2) m/s (default 0) and stresses (N, 4) Pa (default 0)."""
    x = np.array(x, dtype=float, copy=True).reshape(-1, 2)
    n = x.shape[0]
    volume = np.broadcast_to(np.asarray(volume, dtype=float), (n,)).copy()
    density = np.broadcast_to(np.asarray(density, dtype=float), (n,)).copy()
    if np.any(volume <= 0) or np.any(density <= 0):
        raise InputError("material points: volumes and densities must be > 0")
    xmin, xmax, zmin, zmax = system.grid.inner_bounds()
    if n and (x[:, 0].min() < xmin or x[:, 0].max() > xmax or x[:, 1].min() < zmin
              or x[:, 1].max() > zmax):
        raise InputError(f"material points span x [{x[:, 0].min():.4g}, {x[:, 0].max():.4g}], "
                         f"z [{x[:, 1].min():.4g}, {x[:, 1].max():.4g}] m: must lie in the grid "
                         f"[{xmin:.4g}, {xmax:.4g}] x [{zmin:.4g}, {zmax:.4g}] m")
    vel = np.zeros((n, 2)) if v is None else np.array(v, dtype=float).reshape(n, 2)
    sig = np.zeros((n, 4)) if stress is None else np.array(stress, dtype=float).reshape(n, 4)
    if system.axisymmetric and n and not x[:, 0].min() > 0:
        raise InputError(f"material points at r = {x[:, 0].min():.4g} m: an axisymmetric "
                         "section's points must lie at r > 0")
    # an axisymmetric state's velocity gradient carries the hoop rate v_r / r as a fifth column
    ncol = 5 if system.axisymmetric else 4
    state = MPMState(x=x, v=vel, C=np.zeros((n, 4)), L=np.zeros((n, ncol)),
                     mass=volume * density, volume=volume, density=density, stress=sig,
                     gamma_dot=np.zeros(n), phase=np.ones(n, np.int8), fext=np.zeros((n, 2)),
                     history=[b.init_history(n) for b in system.boundaries], t=float(t))
    if system.temperature is not None:
        state.temperature = np.full(n, system.temperature.initial_T)
    return state


def _escaped_ids(x, v, xmin, xmax, zmin, zmax) -> np.ndarray:
    """Ids of the points outside the box or with a non-finite position or velocity."""
    with np.errstate(invalid="ignore"):
        out = ~((x[:, 0] >= xmin) & (x[:, 0] <= xmax) & (x[:, 1] >= zmin) & (x[:, 1] <= zmax))
    out |= ~np.isfinite(v).all(axis=1)
    return np.nonzero(out)[0]


def blowup_message(system: MPMSystem, state: MPMState, ids, what: str) -> str:
    """One paragraph for a ContinuumBlowUp: when, which points (ids, at most 10 named), what
    happened to them, and the likely cause, judged against the stability limits of timestep.py
    (elastic waves over dx, penalty walls) at the points' fastest finite speed."""
    ids = np.asarray(ids, dtype=np.int64)
    named = ", ".join(str(int(i)) for i in ids[:10]) + (", ..." if ids.size > 10 else "")
    mat = system.material
    dx = system.grid.dx
    speed = np.hypot(state.v[:, 0], state.v[:, 1])
    finite = speed[np.isfinite(speed)]
    v_max = float(finite.max()) if finite.size else 0.0
    side = np.sqrt(state.volume[np.isfinite(state.volume) & (state.volume > 0)])
    side_min = float(side.min()) if side.size else dx / 2
    walls = [b for b in system.boundaries if hasattr(b, "stiffness")]
    limit_elastic = stable_dt(mat, dx, side_min, (), v_max=0.0, cfl=1.0)
    limit = stable_dt(mat, dx, side_min, walls, v_max=0.0, cfl=1.0)
    k_text = ", ".join(f"{type(b).__name__} stiffness {b.stiffness:.3g} Pa/m" for b in walls)
    where = (f"t = {state.t:.6g} s (step {state.step}): material point(s) {named} "
             f"({ids.size} of {state.n}) {what}")
    numbers = (f"dt = {system.dt:.3g} s against the stability limits {limit_elastic:.3g} s "
               f"(P-wave speed {mat.p_wave_speed():.3g} m/s over dx = {dx:.3g} m) and "
               f"{limit:.3g} s with the walls" + (f" ({k_text})" if k_text else "")
               + f"; fastest finite point speed {v_max:.3g} m/s")
    if system.dt > limit:
        cause = ("likely cause: the time step is too large for the stiffness (lower the "
                 "Courant number cfl, or the wall stiffness or elastic moduli)")
    elif v_max * system.dt > 0.5 * dx:
        cause = ("likely cause: points crossing half a grid cell a step (speed x dt > dx/2): "
                 "the time step is too large for the speeds reached (lower cfl)")
    else:
        cause = ("likely cause: the wall stiffness too low to hold the bed (points pushed "
                 "through it), or an unstable stiffness / time step combination")
    return f"{where}; {numbers}; {cause}"


def pack_boundaries(boundaries) -> tuple[np.ndarray, list]:
    """The boundaries as fused.py's records (nb,) of BOUNDARY_DTYPE in their order, and the
    walls (the boundaries with a per-point history), a wall's record pointing at its row of
    the stacked histories (`_stack_history`)."""
    records = np.zeros(len(boundaries), BOUNDARY_DTYPE)
    walls = []
    for j, b in enumerate(boundaries):
        if not hasattr(b, "record"):
            raise InputError(f"boundary {type(b).__name__}: has no record() for the MPM step "
                             "(boundary.py: UWall, Plane, PartWall, PartitionFriction)")
        records[j] = b.record()
        if b.has_history:
            records[j]["hist"] = len(walls)
            walls.append(b)
    return records, walls


_HISTORY = (("xi", np.float64, ()), ("f", np.float64, (2,)), ("fn", np.float64, ()),
            ("ft", np.float64, ()), ("state", np.int8, ()))


def _stack_history(state: MPMState, walls) -> list:
    """Per history field, a (walls, N, ...) array: a view of the one wall's arrays, or a
    stacked copy of several walls' (written back by `_unstack_history`)."""
    out = []
    for name, dtype, tail in _HISTORY:
        if len(walls) == 1:
            a = state.history[walls[0].slot][name]
            out.append(a.reshape((1,) + a.shape))
        elif walls:
            out.append(np.stack([state.history[w.slot][name] for w in walls]))
        else:
            out.append(np.zeros((0, state.n) + tail, dtype))
    return out


def _unstack_history(state: MPMState, walls, stacked) -> None:
    if len(walls) > 1:
        for (name, _, _), a in zip(_HISTORY, stacked):
            for j, w in enumerate(walls):
                state.history[w.slot][name][...] = a[j]


def advance(system: MPMSystem, state: MPMState, n: int) -> None:
    """n steps (module docstring) in one compiled call (fused.py), parallel over the system's
    point chunks; raises ContinuumBlowUp naming the points and the likely cause when a point
    goes through a wall (boundary.py `lost`), leaves the grid or stops being finite.  With the
    temperature (MPMSystem.temperature), the same call carries T: each step followed by the
    temperature's balance (temperature_loop.py)."""
    n = int(n)
    if n <= 0:
        return
    _advance(system, state, n, *loop_arguments(system, state.n))


def advance_stepwise(system: MPMSystem, state: MPMState, n: int) -> None:
    """`advance` with the temperature's balance made in Python between compiled one-step calls
    (temperature_field.advance_with_temperature, `point_step`): the readable reference of the
    compiled path, to which tests hold it."""
    g = system.grid

    def balance(power, _start):
        sums = None if system.temperature.walls is None else point_wall_sums(system, state)
        pressure = None
        if system.temperature.params.sliding_coefficient > 0.0:
            pressure = np.zeros(state.n)
            pressure_Pa(state.stress, pressure)
        point_step(state.temperature, state.x, state.mass, state.volume, power, (g.x0, g.z0),
                   (g.nx, g.nz), system.dt, system.temperature, sums, pressure)

    advance_with_temperature(state, n, system.temperature,
                             lambda k, p_kin: _advance(system, state, k, p_kin), balance,
                             phi_cap=phi_cap_of(system.material), dt=system.dt,
                             wave_speed=system.material.p_wave_speed())



def point_wall_sums(system: MPMSystem, state: MPMState) -> np.ndarray:
    """The points' wall contact terms (N, 4) of the last step (wall_energy_flux.contact_terms):
    each penalty wall's contacts, the velocity relative to that wall (a UWall is at rest in
    the solver's frame, a Plane moves), contact length sqrt(V_p), and the partitions'."""
    out = np.zeros((state.n, 4))
    for b in system.boundaries:
        if isinstance(b, PartitionFriction):
            partition_terms(state.v, state.mass, state.volume, state.stress, b.friction,
                            b.length, system.dt, out)
            continue
        if not b.has_history:
            continue
        h = state.history[b.slot]
        wv = np.asarray(b.at(state.t)[1], float) if isinstance(b, Plane) else np.zeros(2)
        contact_terms(h["fn"], h["ft"], normal_of_force(h["f"], h["fn"], h["ft"]),
                      state.v - wv, state.mass, np.sqrt(state.volume), float(b.stiffness),
                      float(b.damping_ratio), system.dt, out)
    return out


def packed_parts(system: MPMSystem) -> tuple:
    """The packed parts of the system's part walls (boundary.PartWall; NO_PARTS without)."""
    return next((b.packed for b in system.boundaries if isinstance(b, PartWall)), NO_PARTS)


def _advance(system: MPMSystem, state: MPMState, n: int, p_kin, ts=None) -> None:
    """`advance`'s compiled call: n steps, the granular temperature's stress p_kin (N, 5)
    (kinetic_stress.py: Pa added to the scattered stress, then the return map's rate ratio;
    (0, 5): none); with ts (temperature_balance.TemperatureStep) the loop that computes
    p_kin and makes the balance of state.temperature after every step (temperature_loop.py)."""
    g = system.grid
    records, walls = pack_boundaries(system.boundaries)
    hist = _stack_history(state, walls)
    xmin, xmax, zmin, zmax = g.inner_bounds()
    pad = 0.0 if g.periodic else g.dx
    box = np.array([xmin - pad, xmax + pad, zmin - g.dx, zmax + g.dx])
    if system.axisymmetric:
        # a point on or across the axis r = 0 has no hoop rate v_r / r: stop there
        box[0] = 1.0e-9 * g.dx
    points = fused.Points(
        state.x, state.v, state.C, state.L, state.mass, state.volume, state.density,
        state.stress, state.gamma_dot, state.phase, state.fext,
        np.empty((state.n, 4)) if system.material.bed_viscosity > 0 or p_kin.shape[0] > 0
        else np.empty((0, 4)), p_kin)
    step = fused.MPMStep(float(system.dt), system.params, system.frame.as_array(), box,
                         chunk_bounds(state.n, system.chunks), float(system.flip))
    boundaries = fused.Boundaries(records, *hist, packed_parts(system))
    if ts is None:
        done, t, status, which = fused.advance_kernel(
            n, float(state.t), points, step, boundaries, system.grid_spec, system.work)
    else:
        done, t, status, which = advance_temperature_kernel(
            n, float(state.t), points, step, boundaries, system.grid_spec, system.work,
            state.temperature, ts, (float(g.x0), float(g.z0), int(g.nx), int(g.nz)))
    _unstack_history(state, walls, hist)
    state.t = t
    state.step += done
    if status == fused.THROUGH_WALL:
        b = system.boundaries[which]
        b._deep = 1
        b._t_last = state.t
        raise ContinuumBlowUp(blowup_message(
            system, state, b.lost(state), f"went through the {type(b).__name__} wall by more "
                                          "than their own size"))
    if status == fused.ESCAPED:
        raise ContinuumBlowUp(blowup_message(system, state, _escaped_ids(state.x, state.v, *box),
                                             "left the grid or became non-finite"))


def run_steps(system: MPMSystem, state: MPMState, n: int, callback=None) -> None:
    """n steps (`advance`); callback(state) after each if given (steps.run_steps)."""
    steps.run_steps(advance, system, state, n, callback)
