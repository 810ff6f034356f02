"""The Eulerian continuum in 2D plane strain: the state record and the step.

Why this design.  A coupled-Eulerian-Lagrangian operator split (Benson 1992; as Abaqus/CEL and
the Eulerian hydrocodes do), with the material point method's own pieces as the Lagrangian step:

1. Lagrangian step on the fixed mesh (lagrangian_step.py): the nodes of the solver's grid carry
   the momentum; the mesh's cells (mesh.py, side dx/2: 2 x 2 fixed integration points per
   element of quadratic B-splines) carry mass, stress and the APIC affine velocity; forces,
   the frame's inertial forces, the wall and the stress update are the Lagrangian
   formulation's kernels (p2g, grid_update, g2p, constitutive, boundary), so the two
   formulations differ only in what an Eulerian method must do differently.  Quadratic
   B-splines at 2 x 2 points a cell are fully integrated: bilinear elements with one point
   would need an hourglass control, these do not.
2. Remap (advection.py): the material moved by v dt is transported back onto the fixed cells by
   a conservative, limited second-order finite-volume scheme: the mass exactly (to round-off),
   velocity, affine matrix and stress mass-weighted (the stress advection that the rate form of
   the elasto-plastic law needs in a fixed mesh).

Volume fraction.  Each cell carries its mass m and its material's density rho (transported
with the mass, like the stress); its volume fraction f = min(1, m / (rho h^2)) is the share of
the cell the material fills, the volume of fluid of coupled Eulerian-Lagrangian codes.  The
material and the empty space above it are told apart by it, and it is computed from the
transported mass, so it moves without losing mass.  A partly filled cell at the free surface
carries the stress of its material on the volume f h^2 = m / rho it fills (the material
point's m_p / rho_p).  In every cell the material expands with the cell down to the critical
density rho_c (unloading), the rest of the growth opening the cell's empty part, and is
compressed by it once that empty part has closed (lagrangian_step.void_first).  Material that
has opened a void sits a hair below rho_c: disconnected (stress-free, Dunatunga & Kamrin 2015)
until it is compacted again, while a half-filled surface cell at or above rho_c, still
pressed, is not: the two states that a density alone would confuse.

Rheology: the elastic part is kept (the shared elasto-visco-plastic law, not a regularised
visco-plastic mu(I)): the same constitutive module as the Lagrangian formulation, so that the
two formulations can be compared as formulations, and the elastic stress is what carries the
bed's weight at rest and its impacts on the wall, which a purely visco-plastic law of Barker &
Gray (2017) would have to regularise.  Its rate form in a fixed mesh needs the stress advected,
step 2.

Units (SI, per metre of thickness along y): positions m, velocities m/s, masses kg/m, volumes
m^2, stresses Pa [xx, zz, xz, yy] (tension positive), forces N/m.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numba as nb
import numpy as np

from vibroflow.errors import InputError
from vibroflow.threads import cores_free

from .. import steps
from ..constitutive import ContinuumMaterial
from ..grid_step import grid_spec, grid_work
from ..grid_update import LabFrame
from ..mpm.solver import ContinuumBlowUp
from ..state import ContinuumState
from ..temperature_balance import loop_arguments, phi_cap_of
from ..temperature_field import advance_with_temperature, cell_step, pressure_Pa
from . import fused, temperature_loop
from .advection import remap_serial, remap_work
from .remap_rows import rows_work
from .lagrangian_step import fill_limit, material_fraction
from .mesh import EulerianMesh
from .column_gather import gather_work
from .column_scatter import scatter_work
from .operator_build import empty_tables, operator_tables, operator_work
from .transfer import WeightTables, node_row_columns
from .wall import MeshWall, empty_history

#: number of intensive fields transported with the mass: v (2), C (4), stress (4), density
NQ = 11

#: meshes of fewer cells step on one thread (the serial loop, fused.advance_kernel_serial,
#: whose numbers are the parallel loop's) unless numba's threads fit on the cores that other
#: processes leave free (vibroflow.threads.cores_free) and the mesh has FREE_PARALLEL_FROM
#: cells or more.  A step holds seven parallel loops, each a launch and a barrier: on the
#: shared two-core machine, with another process busy, a barrier waited for the scheduler
#: (tub47's whole run took 17.0 s on two threads against 10.7 s on one, and single steps up to
#: 40 ms); with the cores free, and the threads spinning at their barriers (threads.SPIN_FREE),
#: tub47's mesh (1 376 cells) steps 1.4 - 1.5 x faster on two threads than on one
#: (docs/validation.md, section 18)
SERIAL_BELOW = 10_000
#: the smallest mesh that takes the parallel loop on free cores: the gain is measured on
#: tub47's 1 376 cells, and smaller meshes (the tests' columns) keep the serial loop
FREE_PARALLEL_FROM = 1_000
#: the loop with T keeping no step's start (temperature_loop.StepStart of 0 cells)
NO_STEP_START = temperature_loop.step_start(0)


@dataclass
class EulerianSystem:
    """What does not change during a run: the mesh, the material, the time step dt (s), the
    frame (grid_update.LabFrame or TubFrame), the wall (wall.MeshWall or None), the
    partitions' friction (boundary.PartitionFriction or None) and an optional rough floor.

    no_slip_below (m, optional): a rough, no-slip floor as a grid boundary condition, the
    solver grid's nodes at heights z <= no_slip_below held still after every grid update, as
    the Lagrangian formulation's (mpm.MPMSystem.no_slip_below; the no-slip base of Lagree,
    Staron & Popinet 2011).  The mesh's wall still carries the normal load; the nodes held
    still make the cells next to the floor stick to it, where the wall's Coulomb friction acts
    only on the row of cells touching it.

    serial_below: a mesh of fewer cells steps on one thread, unless the cores are free for
    numba's threads (`parallel_loop`, SERIAL_BELOW); chunks: the cells' scatter chunks
    (fused.py), which alone fix the numbers.

    transfers (integer >= 1): the APIC transfers a step makes, as the Lagrangian formulation's
    (mpm.MPMSystem.transfers, vibroflow.continuum.transfer_operator).  Default 1.

    axisymmetric: the section is the half-plane x = r >= 0 of a body of revolution about the
    z axis, as the Lagrangian formulation's (mpm.MPMSystem.axisymmetric: the cylindrical
    column collapses of Lube et al. 2004 and Lajeunesse et al. 2004).  The mesh must start at
    the axis (xmin = 0) and not be periodic; its wall must not include the axis, which is a
    grid condition (the nodes at r <= 0 have no radial velocity) and a closed face of zero
    area.  Masses, volumes and forces are per radian: a cell of side h holds h^2 r
    (cell_weight, r its centre's radius), a face sweeps h r (the remap's weights,
    advection.remap_work), the wall's contact scales with r (wall.wall_forces), the stress
    divergence gains the hoop term -V sigma_theta w / r (column_scatter.scatter_columns) and the
    velocity gradient the hoop rate (face_velocity.match_divergence; L (N, 5)).

    temperature (temperature_field.TemperatureModel, optional): the cells carry the granular
    temperature (state.temperature), remapped with their mass, its balance made after every
    step on the cells, its kinetic pressure added to the stress they scatter (`advance`);
    None (default): not carried.  Plane strain only."""

    mesh: EulerianMesh
    material: ContinuumMaterial
    dt: float
    frame: object = field(default_factory=LabFrame)
    wall: MeshWall | None = None
    partitions: object = None
    chunks: int = 2
    no_slip_below: float | None = None
    serial_below: int = SERIAL_BELOW
    transfers: int = 1
    axisymmetric: bool = False
    temperature: object = None

    def __post_init__(self):
        if not self.dt > 0:
            raise InputError(f"dt = {self.dt!r}: must be > 0 s")
        self.no_slip_rows = 0 if self.no_slip_below is None else \
            self.mesh.grid.rows_at_or_below(self.no_slip_below)
        if not (isinstance(self.chunks, int) and self.chunks >= 1):
            raise InputError(f"chunks = {self.chunks!r}: must be an integer >= 1")
        if not (isinstance(self.serial_below, int) and self.serial_below >= 0):
            raise InputError(f"serial_below = {self.serial_below!r}: must be an integer >= 0")
        if not (isinstance(self.transfers, int) and self.transfers >= 1):
            raise InputError(f"transfers = {self.transfers!r}: must be an integer >= 1 (APIC "
                             "transfers a step)")
        if self.temperature is not None and self.axisymmetric:
            raise InputError("temperature with axisymmetric = True: the temperature's balance "
                             "is plane strain only")
        m = self.mesh
        self.params = self.material.as_array()
        self.x = m.centres()
        self.cell_weight = np.ones(m.n)
        self.inv_r = np.zeros(m.n)
        self.axis_cols = 0
        radius = None
        if self.axisymmetric:
            if m.periodic:
                raise InputError("axisymmetric = True with a periodic mesh: the section must "
                                 "start at the axis r = 0, not wrap around")
            if abs(m.xmin) > 1e-12 * m.h:
                raise InputError(f"axisymmetric = True with the mesh's left edge at xmin = "
                                 f"{m.xmin!r} m: the mesh must start at the axis (xmin = 0)")
            if np.any(m.wall & (self.x[:, 0] < m.h) & (m.normal[:, 0] > 0.5)):
                raise InputError("axisymmetric = True with a wall along the axis: the axis is "
                                 "a grid condition, not a wall (mesh.EulerianMesh.box with "
                                 "axis=True)")
            self.cell_weight = self.x[:, 0].copy()
            self.inv_r = 1.0 / self.x[:, 0]
            g = m.grid
            self.axis_cols = int(math.floor(-g.x0 / g.dx + 1e-9)) + 1
            radius = (m.xmin + (np.arange(m.ncx) + 0.5) * m.h, m.xmin + np.arange(m.ncx + 1) * m.h)
        self.density = np.zeros(m.n)
        self.wall_cells = np.nonzero(m.wall)[0].astype(np.int64)
        self.ux = np.zeros((m.ncx + 1, m.ncz))
        self.uz = np.zeros((m.ncx, m.ncz + 1))
        # the whole mesh's remap work (advection.remap; the compiled loop's remap runs on the
        # rows that can hold material, remap_rows.py, with its own)
        self.remap_work = remap_work(m.open_x, m.open_z, NQ, radius)
        # the B-spline weights of the fixed cell centres and face midpoints (transfer.py), as
        # the tuple the compiled loop takes
        t = WeightTables.of_mesh(m, self.x)
        self.tables = (t.cx, t.cz, t.fx, t.fz)
        # and, with more than one transfer a step, the tables of the cells' transfer operator
        # and its work arrays (operator_build.py)
        g = m.grid
        many = self.transfers > 1
        op = operator_tables(t.cx, t.cz, g.dx) if many else empty_tables()
        op_work = operator_work(m.ncx, g.nx, g.nz) if many else operator_work(0, 0, 0)
        # fused.py's records of the mesh and of its work arrays (the end-of-step density, the
        # cells holding material), and the grid's (grid_step.py: its conditions, the
        # per-chunk scatter buffers, the node fields, the transfer operator's buffers)
        self.mesh_record = fused.MeshRecord(float(m.h), m.open_x, m.open_z, m.normal,
                                            self.tables, self.cell_weight, self.inv_r,
                                            node_row_columns(t.cx, g.nx, g.periodic), op)
        self.cell_work = fused.CellWork(self.ux, self.uz,
                                        rows_work(m.open_x, m.open_z, NQ, radius),
                                        np.zeros(m.n), scatter_work(m.ncx, g.nz),
                                        gather_work(g.nx, m.ncz), *op_work)
        self.grid_spec = grid_spec(m.grid, self.no_slip_rows, self.axis_cols)
        self.work = grid_work(m.grid, 0, self.transfers)
        # the temperature's own remap (one field, after the step's: `advance`)
        self.temperature_work = None if self.temperature is None else \
            remap_work(m.open_x, m.open_z, 1, radius)


@dataclass(kw_only=True)
class EulerianState(ContinuumState):
    """The fields on the mesh's cells (ContinuumState's fields over the N cells, p = i * ncz +
    k, x their fixed centres) and the clock, with frac (N,) the material fraction, volume (N,)
    the material's volume m^2 and density (N,) its density kg/m^3 at the end of the last step;
    history: [the wall's per-cell arrays (wall.empty_history)]; mass0: the initial total mass
    (kg/m); mass_error_max: the largest |M - M0| / M0 seen."""

    frac: np.ndarray
    mass0: float = 0.0
    mass_error_max: float = 0.0

    @property
    def wall(self) -> dict:
        return self.history[0]

    def total_mass(self) -> float:
        return float(self.mass.sum())

    def mass_error(self) -> float:
        """(M - M0) / M0 (-)."""
        return (self.total_mass() - self.mass0) / self.mass0 if self.mass0 > 0 else 0.0


def init_state(system: EulerianSystem, mass, density=None, v=None, stress=None,
               t: float = 0.0):
    """A state with cell masses (N,) kg/m (zero outside the mesh's domain), material densities
    (N,) kg/m^3 (default the critical density), velocities (N, 2) m/s and stresses (N, 4) Pa
    (default 0)."""
    mesh = system.mesh
    n = mesh.n
    mass = np.array(mass, dtype=float).reshape(n)
    if np.any(mass < 0) or not np.all(np.isfinite(mass)):
        raise InputError("cell masses: must be finite and >= 0")
    if np.any(mass[~mesh.inside] > 0):
        raise InputError("cell masses: material in cells outside the container")
    vel = np.zeros((n, 2)) if v is None else np.array(v, dtype=float).reshape(n, 2)
    sig = np.zeros((n, 4)) if stress is None else np.array(stress, dtype=float).reshape(n, 4)
    rho = np.full(n, system.material.critical_density) if density is None else \
        np.broadcast_to(np.asarray(density, dtype=float), (n,)).copy()
    if np.any(rho <= 0):
        raise InputError("cell densities: must be > 0 kg/m^3")
    fill_limit(mass, rho, system.mesh.h, system.cell_weight)
    # an axisymmetric section's velocity gradient carries the hoop rate as a fifth column
    st = EulerianState(x=system.x.copy(), mass=mass, v=vel, C=np.zeros((n, 4)),
                       L=np.zeros((n, 5 if system.axisymmetric else 4)), stress=sig,
                       gamma_dot=np.zeros(n),
                       phase=np.ones(n, np.int8), frac=np.zeros(n), volume=np.zeros(n),
                       density=rho, fext=np.zeros((n, 2)),
                       history=[empty_history(n)], t=float(t))
    st.mass0 = st.total_mass()
    if system.temperature is not None:
        st.temperature = np.where(mass > 0, system.temperature.initial_T, 0.0)
    material_fraction(st.mass, st.density, mesh.h, system.cell_weight, st.frac, st.volume)
    return st


def state_from_checkpoint(system: EulerianSystem, saved, meta: dict) -> EulerianState:
    """The state stored by checkpoint.save_checkpoint (its MPMState record and meta)."""
    st = EulerianState(x=saved.x, mass=saved.mass, v=saved.v, C=saved.C, L=saved.L,
                       stress=saved.stress, gamma_dot=saved.gamma_dot, phase=saved.phase,
                       frac=np.zeros(saved.mass.shape[0]), volume=saved.volume,
                       density=saved.density, fext=saved.fext, history=saved.history,
                       mass0=float(meta["mass0"]), mass_error_max=float(meta["mass_error_max"]),
                       t=saved.t, step=saved.step,
                       temperature=getattr(saved, "temperature", None))
    material_fraction(st.mass, st.density, system.mesh.h, system.cell_weight, st.frac,
                      st.volume)
    return st


def _blowup(system, state, ids, what):
    ids = np.asarray(ids)
    named = ", ".join(str(int(i)) for i in ids[:10]) + (", ..." if ids.size > 10 else "")
    xs = system.x[ids[:3]] if ids.size else np.zeros((0, 2))
    where = "; ".join(f"({a:.4g}, {b:.4g}) m" for a, b in xs)
    speed = np.hypot(state.v[:, 0], state.v[:, 1])
    finite = speed[np.isfinite(speed)]
    vmax = float(finite.max()) if finite.size else 0.0
    return ContinuumBlowUp(
        f"t = {state.t:.6g} s (step {state.step}): cell(s) {named} ({ids.size} of {state.n}; "
        f"at {where}) {what}; dt = {system.dt:.3g} s, cell side {system.mesh.h:.3g} m, "
        f"fastest finite speed {vmax:.3g} m/s (advective Courant number "
        f"{vmax * system.dt / system.mesh.h:.3g}); likely cause: the time step too large for "
        "the stiffness or the speeds reached (lower cfl), or the wall stiffness too low")


def advance(system: EulerianSystem, state: EulerianState, n: int, keep=None) -> None:
    """n steps of system.dt (the Lagrangian step, then the remap: module docstring) in one
    compiled call (fused.py); raises mpm.ContinuumBlowUp when a cell's mass goes negative or
    its velocity non-finite.  With the temperature (EulerianSystem.temperature), the same call
    carries T: each step followed by the temperature's remap with the step's mass fluxes and
    its balance on the cells (temperature_loop.py), and `keep` (temperature_loop.StepStart of
    the state's cells) receives the start of the call's last step."""
    n = int(n)
    if n <= 0:
        return
    args = loop_arguments(system, state.n)
    if keep is not None and len(args) < 2:
        raise ValueError("keep: the start of a step is kept by the loop with the temperature")
    _advance(system, state, n, *args, keep=keep)



def advance_stepwise(system: EulerianSystem, state: EulerianState, n: int) -> None:
    """`advance` with the temperature's remap and balance made in Python between compiled
    one-step calls (temperature_field.advance_with_temperature, `cell_step`): the readable
    reference of the compiled path, to which tests hold it."""
    model = system.temperature
    mesh = system.mesh
    shape = (mesh.ncx, mesh.ncz)
    h = mesh.h
    periodic = system.grid_spec[3]

    def start(s_kin):
        return (state.mass.reshape(shape).copy(), state.v.copy(), state.density.copy(),
                state.stress + s_kin[:, :4])

    def balance(power, before):
        m_start, v_start, rho_start, sigma_start = before
        # the start's masses for the landing: the remap below moves m_start in place
        landing_start = (m_start.ravel().copy(), v_start, rho_start, sigma_start) \
            if model.walls is not None and model.walls.landing else None
        # T carried with the mass: the same transport of the step's start mass by the same
        # face velocities as the kernel's remap
        T = state.temperature.reshape((1,) + shape)
        remap_serial(m_start, T, system.ux, system.uz, h, system.dt, periodic,
                     system.temperature_work)
        full = state.density > 0.0
        frac = np.minimum(1.0, np.divide(state.mass, state.density * h * h,
                                         out=np.zeros(state.n), where=full))
        phi = state.mass / (model.params.density_kg_m3 * h * h)
        sums = None if model.walls is None else \
            cell_wall_sums(system, state, landing_start)
        pressure = None
        if model.params.sliding_coefficient > 0.0:
            pressure = np.zeros(state.n)
            pressure_Pa(state.stress, pressure)
            pressure = (pressure * frac).reshape(shape)
        state.temperature[:] = cell_step(T[0], phi.reshape(shape), (power * frac).reshape(shape),
                                         system.dt, model,
                                         None if sums is None else sums.reshape(shape + (4,)),
                                         pressure).ravel()

    advance_with_temperature(state, n, model,
                             lambda k, p_kin: _advance(system, state, k, p_kin), balance, start,
                             phi_cap=phi_cap_of(system.material), dt=system.dt,
                             wave_speed=system.material.p_wave_speed(), cells=h)


def cell_wall_sums(system: EulerianSystem, state: EulerianState, start=None) -> np.ndarray:
    """The cells' wall contact terms (N, 4) of the last step (wall_energy_flux.contact_terms):
    the wall layer's contacts (the wall at rest on the mesh, its inward normal the mesh's,
    contact length fill h as wall.wall_forces takes it) and the partitions'.  The landing
    column is not the dashpot's c v_n^2: the wall layer's material is held by its closed
    faces, not by the dashpot, so its normal velocity is no approach (fed with c v_n^2,
    tub47-quick's side-wall cells heat without bound).  With start = (mass (N,) kg/m, v (N, 2)
    m/s, density (N,) kg/m^3, the stress the step scatters (N, 4) Pa: the elastic-plastic plus
    the temperature's) the cells' at the step's start, it is the landing measured: the
    normal kinetic energy the step took from the wall cells that approached the wall
    (wall_energy_flux.landing_terms) and the momentum exchange that stopped the material where
    voids close: the pairs' across the open faces (compaction_landing.compaction_terms), or
    with the walls' `columns` (wall_energy_flux.WallEnergy) along each column each open z
    face's impulse that no stress carries on its mean relative velocity (column_landing.py,
    from the step's grid: face_impulse.py) and the pairs' across the x faces; without, none.
    The compiled loop's own definition (temperature_loop.cell_wall_sums), on the state and
    the grid's work arrays as the last step left them."""
    out = np.zeros((state.n, 4))
    landing = start is not None
    if not landing:
        start = (state.mass, state.v, state.density, state.stress)
    temperature_loop.cell_wall_sums(
        _boundaries(system, state), system.mesh_record, system.grid_spec, system.work,
        system.frame.as_array(), state.t - 0.5 * system.dt, state.mass, state.v, state.volume,
        state.stress, state.fext, float(system.material.critical_density), float(system.dt),
        *(np.ascontiguousarray(a, dtype=float) for a in start), landing,
        bool(landing and system.temperature.walls.columns), out)
    return out


def _boundaries(system: EulerianSystem, state: EulerianState):
    """The wall's and the partitions' fused.MeshBoundaries record over the state's wall
    history."""
    w = system.wall
    hist = state.wall
    pf = system.partitions
    return fused.MeshBoundaries(
        w is not None, system.wall_cells, hist["delta"], hist["xi"], hist["fn"], hist["ft"],
        hist["state"], *((float(w.stiffness), float(w.tangential_stiffness),
                          float(w.damping_ratio), float(w.friction))
                         if w is not None else (0.0, 0.0, 0.0, 0.0)),
        pf is not None, *((float(pf.friction), float(pf.length)) if pf is not None
                          else (0.0, 1.0)))


def parallel_loop(cells: int, threads: int, serial_below: int = SERIAL_BELOW) -> bool:
    """Whether a mesh of `cells` cells steps in numba's parallel loops on `threads` threads
    (SERIAL_BELOW, FREE_PARALLEL_FROM); either loop gives the same numbers."""
    if threads <= 1:
        return False
    if cells >= serial_below:
        return True
    return cells >= FREE_PARALLEL_FROM and cores_free(threads)


def _advance(system: EulerianSystem, state: EulerianState, n: int, p_kin, ts=None,
             keep=None) -> None:
    """`advance`'s compiled call: n steps, the granular temperature's stress p_kin (N, 5)
    (kinetic_stress.py: Pa added to the scattered stress, then the return map's rate ratio;
    (0, 5): none); with ts (temperature_balance.TemperatureStep) the loop that computes p_kin
    and makes the balance of state.temperature after every step (temperature_loop.py), keep
    (temperature_loop.StepStart) receiving its last step's start."""
    mesh = system.mesh
    mat = system.material
    # the loop without numba's parallel loops on one thread (their launches cost time even
    # then) and on a small mesh on a busy machine (SERIAL_BELOW)
    parallel = parallel_loop(mesh.n, nb.get_num_threads(), system.serial_below)
    kernel = fused.advance_kernel if parallel else fused.advance_kernel_serial
    cells = fused.Cells(state.mass, state.v, state.C, state.L, state.stress, state.gamma_dot,
                        state.phase, state.frac, state.volume, state.density, state.fext,
                        np.empty((state.n, 4)) if mat.bed_viscosity > 0 or p_kin.shape[0] > 0
                        else np.empty((0, 4)), p_kin)
    step = fused.CellStep(float(system.dt), system.params, system.frame.as_array(),
                          float(mat.critical_density), float(state.mass0), int(system.chunks))
    boundaries = _boundaries(system, state)
    args = (n, float(state.t), float(state.mass_error_max), cells, step, system.mesh_record,
            boundaries, system.grid_spec, system.work, system.cell_work)
    if ts is None:
        done, t, status, lowest, err_max = kernel(*args)
    else:
        t_kernel = temperature_loop.advance_temperature_kernel if parallel else \
            temperature_loop.advance_temperature_kernel_serial
        done, t, status, lowest, err_max = t_kernel(
            *args, state.temperature, ts, system.temperature_work,
            NO_STEP_START if keep is None else keep)
    state.t = t
    state.step += done
    state.mass_error_max = err_max
    if status == fused.NEGATIVE_MASS:
        bad = np.nonzero(~(state.mass >= -1e-9 * mat.critical_density * mesh.h**2))[0]
        raise _blowup(system, state, bad, "lost more mass than they held (negative mass)")
    if status == fused.NON_FINITE:
        raise _blowup(system, state, np.nonzero(~np.isfinite(state.v).all(axis=1))[0],
                      "reached a non-finite velocity")


def run_steps(system: EulerianSystem, state: EulerianState, n: int, callback=None) -> None:
    """n steps (`advance`); callback(state) after each if given (steps.run_steps)."""
    steps.run_steps(advance, system, state, n, callback)
