"""What a continuum tub run samples, as the DEM samples its balls: the sample instants (the
DEM's phases), the sampled points or cells as the DEM's snapshots in the lab frame, their wall
contacts, floor force and shear rates, the ParaView frames written (`Samples`, carried through
a checkpoint unchanged), and the samples as the dem.h5 layout that
vibroflow.measure.summary.tub_summary reads (`samples_source`)."""
from __future__ import annotations

import math

import numba as nb
import numpy as np

from vibroflow.measure.floor_force import on_floor
from vibroflow.measure.phase_shear import PhaseShear, node_grid, phase_shear_of_snapshots
from vibroflow.tub.motion import rigid_velocity, tub_to_lab

from .stress_update import equivalent_shear_rate


def sample_times(scenario) -> tuple[np.ndarray, float, float]:
    """The DEM's sample instants (s): phases m / (P f) over the whole cycles of the window
    [duration - average_last, ...) (as vibroflow.dem.sampling.sample_steps, before its rounding to
    the DEM's step), and the window (t0, t1)."""
    run, f = scenario.run, scenario.motion.frequency
    t0 = run.duration - run.average_last
    n_cycles = int(math.floor(run.average_last * f + 1e-9))
    per = run.phases_per_cycle
    m0 = math.ceil(t0 * f * per - 1e-9)
    return (m0 + np.arange(n_cycles * per)) / (f * per), t0, t0 + n_cycles / f


@nb.njit(cache=True, inline="always")
def _point_to_lab(xp, zp, vx, vz, X, Z, th, Xd, Zd, thd, c, s, pivx, pivz, y, pos_out,
                  vel_out, p):
    """Row p of pos_out, vel_out: the lab position and velocity (3D, at y) of the tub-frame
    point (xp, zp) moving at (vx, vz) (m, m/s), the tub at pose (X, Z, th, Xd, Zd, thd) with
    c, s = cos th, sin th, through vibroflow.tub.motion."""
    lx, lz = tub_to_lab(xp, zp, X, Z, th, pivx, pivz)
    rvx, rvz = rigid_velocity(lx, lz, X, Z, Xd, Zd, thd, pivx, pivz)
    pos_out[p, 0] = lx
    pos_out[p, 1] = y
    pos_out[p, 2] = lz
    vel_out[p, 0] = rvx + c * vx - s * vz
    vel_out[p, 1] = 0.0
    vel_out[p, 2] = rvz + s * vx + c * vz


@nb.njit(cache=True)
def to_lab(x, v, pose6, pivx, pivz, pos_out, vel_out, y):
    """Lab positions and velocities (3D, y = the slice's middle) of tub-frame points (x, v) at
    the tub pose (X, Z, theta, Xdot, Zdot, thetadot), through vibroflow.tub.motion."""
    X, Z, th, Xd, Zd, thd = pose6[0], pose6[1], pose6[2], pose6[3], pose6[4], pose6[5]
    c = np.cos(th)
    s = np.sin(th)
    for p in range(x.shape[0]):
        _point_to_lab(x[p, 0], x[p, 1], v[p, 0], v[p, 1], X, Z, th, Xd, Zd, thd, c, s, pivx,
                      pivz, y, pos_out, vel_out, p)


@nb.njit(cache=True)
def dithered_cells_to_lab(xc, dx, dz, cells, v, mass, unit, dither, pose6, pivx, pivz, y, far,
                          pos_out, vel_out):
    """The Eulerian cells `cells` as pseudo-balls in the lab frame (eulerian/formulation.py):
    row p of pos_out, vel_out is `to_lab` of the cell's centre xc[p] (N, 2) (m) moved by
    (dx, dz) (m, the sample's offset) at the cell's velocity v[cells[p]] (m/s); each cell's
    dither[p] gains its mass in units (mass[cells[p]] / unit) and a cell whose dither reaches
    1/2 gives one unit and is placed there, any other is parked at `far` (3,) (m), outside
    every analysis cell."""
    X, Z, th, Xd, Zd, thd = pose6[0], pose6[1], pose6[2], pose6[3], pose6[4], pose6[5]
    c = np.cos(th)
    s = np.sin(th)
    for p in range(xc.shape[0]):
        q = cells[p]
        _point_to_lab(xc[p, 0] + dx, xc[p, 1] + dz, v[q, 0], v[q, 1], X, Z, th, Xd, Zd, thd,
                      c, s, pivx, pivz, y, pos_out, vel_out, p)
        dither[p] += mass[q] / unit
        if dither[p] >= 0.5:
            dither[p] -= 1.0
        else:
            pos_out[p, 0] = far[0]
            pos_out[p, 1] = far[1]
            pos_out[p, 2] = far[2]


@nb.njit(cache=True)
def _add_cell_rates(index, rate, rate_sum2, rate_n2):
    """Samples.add_cell_rates_at's sums: each analysis cell's finite rates (1/s) summed in the
    points' order (np.bincount's), their mean added to rate_sum2 and 1 to rate_n2 (the maps,
    index the flat cell) where the cell holds any."""
    rate_sum = rate_sum2.reshape(rate_sum2.size)
    rate_n = rate_n2.reshape(rate_n2.size)
    size = rate_sum.shape[0]
    total = np.zeros(size)
    count = np.zeros(size, np.int64)
    for p in range(index.shape[0]):
        c = index[p]
        if c >= 0 and np.isfinite(rate[p]):
            total[c] += rate[p]
            count[c] += 1
    for c in range(size):
        if count[c] > 0:
            rate_sum[c] += total[c] / count[c]
            rate_n[c] += 1


@nb.njit(cache=True)
def _add_cell_stresses(index, volume, stress, out3):
    """Samples.add_cell_stresses_at's map: in each analysis cell the volume-weighted mean of the
    stresses (N, 4) Pa of its points of volume > 0 (m^2) and finite stress, summed in the
    points' order (np.bincount's), into out3 (nz, nx, 4; index the flat cell); cells holding
    none untouched."""
    size = out3.shape[0] * out3.shape[1]
    out = out3.reshape((size, 4))
    vol = np.zeros(size)
    total = np.zeros((size, 4))
    for p in range(index.shape[0]):
        c = index[p]
        V = volume[p]
        if c < 0 or not V > 0.0:
            continue
        if not (np.isfinite(stress[p, 0]) and np.isfinite(stress[p, 1])
                and np.isfinite(stress[p, 2]) and np.isfinite(stress[p, 3])):
            continue
        vol[c] += V
        for q in range(4):
            total[c, q] += V * stress[p, q]
    for c in range(size):
        if vol[c] > 0.0:
            for q in range(4):
                out[c, q] = total[c, q] / vol[c]


def shear_rate(L: np.ndarray) -> np.ndarray:
    """gamma_dot = sqrt(2 D':D') (1/s) of velocity gradients L (N, 4) [xx, xz, zx, zz], plane
    strain (D_yy = 0) (models.md)."""
    L = np.ascontiguousarray(L, dtype=np.float64)
    return equivalent_shear_rate(L[:, 0], L[:, 1], L[:, 2], L[:, 3])


class Samples:
    """What the samples of the vibration have recorded so far: the points as the DEM's
    snapshots (lab position and velocity, tub pose), the wall contacts, the shear rates and the
    ParaView files written; `arrays` / `from_arrays` carry it through a checkpoint unchanged."""

    CONTACTS = {"snapshot": ((), np.int32), "particle": ((), np.int32), "fn": ((), np.float64),
                "ft": ((), np.float64), "sliding": ((), np.bool_), "arc": ((), np.float64),
                "position_tub": ((3,), np.float64)}

    def __init__(self, n_samples: int, n_points: int, n_probes: int, cell_grid=None,
                 temperature: bool = False, n_parts: int = 0):
        self.j = 0
        # with parts (part_obstacle.py): per sample the wall law's force on each part (N, over
        # the slice; x, y, z in tub axes), the reaction of its contact forces on the material,
        # and its torque about the part's centre (N m; part_obstacle.torque_on_part)
        self.n_parts = int(n_parts)
        if self.n_parts:
            self.part_force = np.full((n_samples, self.n_parts, 3), np.nan)
            self.part_torque = np.full((n_samples, self.n_parts, 3), np.nan)
        # with the granular temperature (ContinuumOptions.temperature): per sample the
        # mass-weighted mean T over the material (m^2/s^2) and, on the analysis cells, the sum
        # over samples of the mass-weighted mean T in the cell and the samples that held
        # material there
        self.temperature = bool(temperature)
        if self.temperature:
            self.temperature_all = np.full(n_samples, np.nan)
            # per sample the U wall's feed of fluctuation energy over the step ending there
            # (W/m, summed by region of the U: continuum/wall_feed.py; NaN: not measured)
            self.wall_feed = np.full((n_samples, 3), np.nan)
            if cell_grid is not None:
                h, nxh, nz = cell_grid
                self.temperature_cell_sum = np.zeros((nz, 2 * nxh + 1))
                self.temperature_cell_n = np.zeros((nz, 2 * nxh + 1))
        # the shear-rate map on the analysis cells: cell_grid = (cell size h m, cells either
        # side of x = 0, cells up from z = 0); per cell the sum over samples of the sample's
        # mean shear rate there, and the number of samples that held material there
        self.cell_grid = cell_grid
        if cell_grid is not None:
            h, nxh, nz = cell_grid
            self.rate_cell_sum = np.zeros((nz, 2 * nxh + 1))
            self.rate_cell_n = np.zeros((nz, 2 * nxh + 1))
            # per sample the material's stress in each analysis cell (Pa, [xx, zz, xz, yy],
            # tension positive: the states' layout), its points' (or cells') volume-weighted
            # mean; NaN where the cell holds none (stress_outputs.py)
            self.stress_cell = np.full((n_samples, nz, 2 * nxh + 1, 4), np.nan)
        # per sample the floor force (N over the slice): the z component, tub axes, of the U
        # wall's force on the material within measure.floor_force.FLOOR_DEG of its bottom
        self.floor_force = np.full(n_samples, np.nan)
        self.pos = np.zeros((n_samples, n_points, 3), np.float32)
        self.vel = np.zeros((n_samples, n_points, 3), np.float32)
        self.poses = np.zeros((n_samples, 6))
        self.contacts: dict[str, list] = {k: [] for k in self.CONTACTS}
        self.rate_all = np.full(n_samples, np.nan)
        self.rate_wall = np.full(n_samples, np.nan)
        self.rate_probe = np.full((n_samples, n_probes), np.nan)
        self.vtk: dict[str, list] = {"points": [], "grid": [], "tub": []}  # (t s, file name)
        self.frames = 0  # the ParaView frames before the window written (VtkOptions.every)

    def contact_arrays(self) -> dict[str, np.ndarray]:
        return {k: (np.concatenate(v) if v else np.zeros((0, *shape), dtype))
                for (k, (shape, dtype)), v in zip(self.CONTACTS.items(),
                                                  self.contacts.values())}

    def arrays(self) -> dict[str, np.ndarray]:
        j = self.j
        out = {"pos": self.pos[:j], "vel": self.vel[:j], "poses": self.poses[:j],
               "rate_all": self.rate_all, "rate_wall": self.rate_wall,
               "rate_probe": self.rate_probe, "floor_force": self.floor_force}
        out.update({"contact_" + k: v for k, v in self.contact_arrays().items()})
        if self.cell_grid is not None:
            out["rate_cell_sum"], out["rate_cell_n"] = self.rate_cell_sum, self.rate_cell_n
            out["stress_cell"] = self.stress_cell
        if self.temperature:
            out["temperature_all"] = self.temperature_all
            out["wall_feed"] = self.wall_feed
            if self.cell_grid is not None:
                out["temperature_cell_sum"] = self.temperature_cell_sum
                out["temperature_cell_n"] = self.temperature_cell_n
        if self.n_parts:
            out["part_force"] = self.part_force
            out["part_torque"] = self.part_torque
        out["vtk_frames"] = np.array(self.frames, dtype=np.int64)
        for kind, entries in self.vtk.items():
            out[f"vtk_{kind}_t"] = np.array([t for t, _ in entries], dtype=np.float64)
            out[f"vtk_{kind}_name"] = np.array([name for _, name in entries], dtype=np.str_)
        return out

    @classmethod
    def from_arrays(cls, a: dict, n_samples: int, n_points: int, n_probes: int,
                    cell_grid=None, temperature: bool = False, n_parts: int = 0) -> "Samples":
        s = cls(n_samples, n_points, n_probes, cell_grid, temperature, n_parts)
        if s.n_parts and "part_force" in a:
            s.part_force[:] = a["part_force"]
        if s.n_parts and "part_torque" in a:
            s.part_torque[:] = a["part_torque"]
        if cell_grid is not None and "rate_cell_sum" in a:
            s.rate_cell_sum[:], s.rate_cell_n[:] = a["rate_cell_sum"], a["rate_cell_n"]
        if cell_grid is not None and "stress_cell" in a:
            s.stress_cell[:] = a["stress_cell"]
        if s.temperature and "temperature_all" in a:
            s.temperature_all[:] = a["temperature_all"]
            if "wall_feed" in a:
                s.wall_feed[:] = a["wall_feed"]
            if cell_grid is not None:
                s.temperature_cell_sum[:] = a["temperature_cell_sum"]
                s.temperature_cell_n[:] = a["temperature_cell_n"]
        if "floor_force" in a:
            s.floor_force[:] = a["floor_force"]
        j = s.j = int(a["pos"].shape[0])
        s.pos[:j], s.vel[:j], s.poses[:j] = a["pos"], a["vel"], a["poses"]
        s.rate_all[:], s.rate_wall[:], s.rate_probe[:] = (a["rate_all"], a["rate_wall"],
                                                          a["rate_probe"])
        s.contacts = {k: [a["contact_" + k]] for k in cls.CONTACTS}
        s.frames = int(a["vtk_frames"]) if "vtk_frames" in a else 0
        for kind in [k for k in s.vtk if f"vtk_{k}_t" in a]:
            s.vtk[kind] = [(float(t), str(name)) for t, name in
                           zip(a[f"vtk_{kind}_t"], a[f"vtk_{kind}_name"])]
        return s

    def add_contacts(self, j: int, particle: np.ndarray, fn: np.ndarray, ft: np.ndarray,
                     state: np.ndarray, arc: np.ndarray, x: np.ndarray | None, length: float,
                     position_tub: np.ndarray | None = None) -> None:
        """Add sample j's wall contacts: the touching points' (or cells') indices, their normal
        and tangential forces per metre of thickness (N/m; times `length`, the slice L_y in m,
        they are over the slice, the DEM's unit), state (1 stick, 2 slide), arc-length
        coordinate (m) and tub-frame positions x (n, 2) (m, set at the slice's middle in y),
        or those 3D positions themselves, position_tub (n, 3) (m)."""
        c = self.contacts
        c["snapshot"].append(np.full(particle.size, j, np.int32))
        c["particle"].append(particle.astype(np.int32))
        c["fn"].append(fn * length)
        c["ft"].append(np.abs(ft) * length)
        c["sliding"].append(state == 2)
        c["arc"].append(np.array(arc, dtype=np.float64))
        if position_tub is None:
            position_tub = np.stack([x[:, 0], np.full(particle.size, 0.5 * length), x[:, 1]],
                                    axis=1)
        c["position_tub"].append(position_tub)

    def add_contact_rows(self, j: int, count: int, particle: np.ndarray, fn: np.ndarray,
                         ft: np.ndarray, sliding: np.ndarray, arc: np.ndarray,
                         position_tub: np.ndarray) -> None:
        """Add sample j's wall contacts given as the first `count` rows of arrays already in
        the contacts' units (`add_contacts`' after it has taken them over the slice: fn and
        |ft| in N, sliding bool, position_tub (n, 3) m); the rows are copied."""
        c = self.contacts
        c["snapshot"].append(np.full(count, j, np.int32))
        c["particle"].append(np.array(particle[:count], dtype=np.int32))
        c["fn"].append(np.array(fn[:count], dtype=np.float64))
        c["ft"].append(np.array(ft[:count], dtype=np.float64))
        c["sliding"].append(np.array(sliding[:count], dtype=np.bool_))
        c["arc"].append(np.array(arc[:count], dtype=np.float64))
        c["position_tub"].append(np.array(position_tub[:count], dtype=np.float64))

    def add_floor_force(self, j: int, fz: np.ndarray, x: np.ndarray, radius: float,
                        length: float) -> None:
        """Sample j's floor force: the sum of the U wall's forces' z components fz (N/m, tub
        axes) on the points (or cells) at tub-frame positions x (n, 2) (m) nearest the floor
        of a U of `radius` (m) (measure.floor_force.on_floor), over the slice's `length` (m)."""
        x = np.asarray(x, float).reshape(-1, 2)
        self.add_floor_force_of(j, np.asarray(fz, float)[on_floor(x[:, 0], x[:, 1], radius)],
                                length)

    def add_floor_force_of(self, j: int, fz_floor: np.ndarray, length: float) -> None:
        """Sample j's floor force from the z components fz_floor (N/m, tub axes) of the
        forces on the points (or cells) nearest the floor (`add_floor_force`), in their order,
        over the slice's `length` (m)."""
        self.floor_force[j] = float(np.sum(fz_floor)) * length

    def add_part_forces(self, j: int, force_on_material: np.ndarray, torque_on_part: np.ndarray,
                        length: float) -> None:
        """Sample j's forces on the parts: force_on_material (n_parts, 2) the wall law's force
        (N/m, x and z) on the material from each part, whose reaction over the slice's length
        (m) the part feels; torque_on_part (n_parts,) the reactions' torque about y (N m/m,
        part_obstacle.torque_on_part) over the same length."""
        self.part_force[j, :, 0] = -force_on_material[:, 0] * length
        self.part_force[j, :, 1] = 0.0
        self.part_force[j, :, 2] = -force_on_material[:, 1] * length
        self.part_torque[j, :, 0] = 0.0
        self.part_torque[j, :, 1] = torque_on_part * length
        self.part_torque[j, :, 2] = 0.0

    def cell_index(self, x: np.ndarray) -> np.ndarray:
        """The analysis cell (flat index iz (2 nxh + 1) + ix) of each tub-frame position x
        (N, 2) (m); -1 outside the map (int64)."""
        h, nxh, nz = self.cell_grid
        ix = np.floor(x[:, 0] / h + 0.5).astype(np.int64) + nxh
        iz = np.floor(x[:, 1] / h + 0.5).astype(np.int64)
        inside = (ix >= 0) & (ix <= 2 * nxh) & (iz >= 0) & (iz < nz)
        return np.where(inside, iz * (2 * nxh + 1) + ix, -1)

    def add_cell_rates(self, x: np.ndarray, rate: np.ndarray) -> None:
        """Add one sample's shear rates (1/s) at tub-frame positions x (N, 2) m to the map: the
        mean over the points (or cells) in each analysis cell."""
        if self.cell_grid is None:
            return
        self.add_cell_rates_at(self.cell_index(x), rate)

    def add_cell_rates_at(self, index: np.ndarray, rate: np.ndarray) -> None:
        """`add_cell_rates` of points (or cells) whose analysis cells are `index` (N,)
        (`cell_index`: a fixed mesh's, made once)."""
        if self.cell_grid is None:
            return
        _add_cell_rates(np.asarray(index, dtype=np.int64), np.asarray(rate, dtype=np.float64),
                        self.rate_cell_sum, self.rate_cell_n)

    def add_cell_stresses(self, j: int, x: np.ndarray, volume: np.ndarray,
                          stress: np.ndarray) -> None:
        """Sample j's stresses (N, 4) Pa of points (or cells) of material volumes `volume` (N,)
        m^2 at tub-frame positions x (N, 2) m on the analysis cells (`add_cell_stresses_at`)."""
        if self.cell_grid is None:
            return
        self.add_cell_stresses_at(j, self.cell_index(x), volume, stress)

    def add_cell_stresses_at(self, j: int, index: np.ndarray, volume: np.ndarray,
                             stress: np.ndarray) -> None:
        """Sample j's stress map: in each analysis cell (`cell_index`, -1 outside) the mean of
        the stresses (N, 4) of the points (or cells) in it weighted by their volumes (N,) m^2,
        the stress of the material it holds (nothing where it holds none)."""
        if self.cell_grid is None:
            return
        _add_cell_stresses(np.asarray(index, dtype=np.int64),
                           np.asarray(volume, dtype=np.float64),
                           np.ascontiguousarray(stress, dtype=np.float64).reshape(-1, 4),
                           self.stress_cell[j])

    def add_temperatures(self, j: int, x: np.ndarray, mass: np.ndarray, T: np.ndarray) -> None:
        """Add sample j's granular temperatures T (m^2/s^2) of points (or cells) of masses
        `mass` (kg/m, > 0 for material) at tub-frame positions x (N, 2) m: the mass-weighted
        mean over the material and, on the analysis cells, in each cell (nothing without the
        option)."""
        if not self.temperature:
            return
        m = np.asarray(mass, dtype=np.float64)
        T = np.asarray(T, dtype=np.float64)
        held = (m > 0) & np.isfinite(T)
        if not held.any():
            return
        self.temperature_all[j] = float(np.sum(m[held] * T[held]) / np.sum(m[held]))
        if self.cell_grid is None:
            return
        h, nxh, nz = self.cell_grid
        ix = np.floor(x[:, 0] / h + 0.5).astype(np.int64) + nxh
        iz = np.floor(x[:, 1] / h + 0.5).astype(np.int64)
        ok = held & (ix >= 0) & (ix <= 2 * nxh) & (iz >= 0) & (iz < nz)
        flat = iz[ok] * (2 * nxh + 1) + ix[ok]
        size = nz * (2 * nxh + 1)
        M = np.bincount(flat, weights=m[ok], minlength=size).reshape(nz, -1)
        E = np.bincount(flat, weights=m[ok] * T[ok], minlength=size).reshape(nz, -1)
        inside = M > 0
        self.temperature_cell_sum[inside] += E[inside] / M[inside]
        self.temperature_cell_n[inside] += 1


def cell_grid_of(geo, cell_size: float) -> tuple[float, int, int]:
    """The analysis cells covering a tub (see Samples): (h m, cells either side, cells up);
    the nodes of analysis.phase_shear.node_grid, so the two maps are the same cells."""
    return node_grid(geo, cell_size)


def samples_source(scenario, samples: Samples, times: np.ndarray, radius: np.ndarray) -> dict:
    """The samples as the dem.h5 layout that analysis.summary.tub_summary reads: snapshots of
    "balls" of the given radii (m), the wall contacts on the tub's U."""
    source = {"attrs": {"frequency": scenario.motion.frequency},
              "snapshots/time": times, "snapshots/position": samples.pos,
              "snapshots/velocity": samples.vel, "snapshots/tub_pose": samples.poses,
              "particles/radius": radius}
    if times.size:
        source.update({"wall_contacts/" + k: v for k, v in samples.contact_arrays().items()})
        source["wall_contacts/wall"] = np.zeros(source["wall_contacts/fn"].size, np.int8)
    return source


def phase_shear_of_samples(scenario, samples: Samples, times: np.ndarray,
                           radius: np.ndarray) -> PhaseShear:
    """The cycle-mean shear rate of the run's phase-resolved velocity field on the analysis
    cells' centres (analysis.phase_shear.phase_shear_of_snapshots, as the DEM calibration
    measures it): each sampled point standing for the solid volume of a ball of its `radius`
    (m)."""
    j = min(samples.j, times.size)
    return phase_shear_of_snapshots(scenario, samples.pos[:j], samples.vel[:j],
                                    samples.poses[:j],
                                    4.0 / 3.0 * math.pi * np.asarray(radius, float) ** 3,
                                    times[:j])


