"""The DEM's own thermal balance cell by cell: the production of fluctuation energy by the
stress working on the mean flow's deformation, and its dissipation in the contacts, both
coarse-grained per volume (W/m^3) on the calibration's grid, phase-resolved and as cycle means
with batch-means errors.

Production (each snapshot's own mean flow, as the thermal temperature takes it): the snapshot
is coarse-grained alone (coarse_grain.CoarseGrainer, the calibration's kernel and grid), giving
its stress P_ab (kinetic about the snapshot's own V plus contact, walls included, compression
positive) and velocity gradient L_ab = dV_a/dx_b; the production is

    Pi = -P_ab L_ab,

what the momentum balance d(rho V_a)/dt + d_b(rho V_a V_b) = -d_b P_ab takes from the mean
flow's kinetic energy, V_a d_b P_ab = d_b(V_a P_ab) - P_ab L_ab (simple shear of a stress with
shear component -tau: tau gamma_dot).  Phase bins average the snapshots' Pi.

Dissipation: each contact's power taken out of the balls (contact_power.py: the dashpot's, the
sliding's and CDT rolling's parts, with the springs' storage rates) coarse-grained along the
contact's branch as the contact stress is (the line from the ball's centre to the other's, or
to the wall's contact point, int_0^1 W ds): the same footprint as the contact stress whose work
is the production, so that a cell's two terms are taken over the same contacts.  Over a steady
cycle the springs' storage averages out, so the cycle mean is the dissipation; a phase bin's
value also holds the storage's rate at that phase.

The walls' feed: with a wall contact's stress carried along its branch to the contact point c_w,
the momentum balance holds the wall's force f_w as a force density at c_w, so the mean flow's
energy gains f_w . V(c_w) and the fluctuation's W_w = -f_w . V(c_w): the wall's force against
the bed's coarse-grained slip and approach there (Johnson & Jackson's slip production, and the
landing), deposited at c_w with the kernel, V bilinear on the grid.  Over the bed and a steady
cycle the fluctuation energy's rate and the flux's divergence integrate to zero, so
int (Pi + W_w) = int D (tub47-quick: docs/validation.md section 29).

`ThermalBalanceGrainer` accumulates snapshots; `thermal_balance_run(run)` does a DEM run's
averaging window (its spins from dem.h5) and returns the Dataset, and the springs' stored
energy at each snapshot for the check that it averages out.
"""
from __future__ import annotations

import numpy as np
import xarray as xr
from scipy.interpolate import RegularGridInterpolator

from vibroflow.errors import InputError
from vibroflow.measure.stats import stderr_of_batches
from vibroflow.tub.geometry import geometry_of

from .coarse_grain import CoarseGrainer
from .coarse_grain_kernel import B_RHO, N_BALL_Q, deposit_balls, deposit_contacts
from .contact_power import (elastic_energy_J, pair_power_loss, rolling_reconstructable,
                            wall_power_loss)
from .dem_result import DEMResult, _to_tub_axes
from .thermal_temperature import ThermalTemperatureGrainer

#: the dissipation's parts, in the accumulator's rows
PARTS = ("normal", "tangential", "rolling")
# rows of the accumulator: the production, its contact part, the walls' feed, the pressure, then
# the dissipation's parts
_R_PROD, _R_PROD_C, _R_WALL, _R_P, _R_DISS = 0, 1, 2, 3, 4
_N_ROWS = 4 + len(PARTS)


class ThermalBalanceGrainer:
    """Accumulates the production and the dissipation of snapshots (module notes) on the grid
    of a CoarseGrainer(geometry, cell_size, kernel, width, cutoff, depth, rho_s, extent,
    diameter), in n_phases phase bins and n_batches batches; pair_mu_r the ball-ball CDT rolling
    resistance and wall_mu_r (sequence by wall slot: the U, the partitions, the planes) the
    walls' (0: no rolling loss)."""

    def __init__(self, geometry, cell_size: float, depth: float, rho_s: float, diameter: float,
                 n_phases: int, n_batches: int, pair_mu_r: float = 0.0, wall_mu_r=(0.0,),
                 kernel: str = "gaussian", width: float | None = None,
                 cutoff: float | None = None, extent=None):
        self._snap = CoarseGrainer(geometry, cell_size=float(cell_size), kernel=kernel,
                                   width=width, cutoff=cutoff, depth=float(depth), rho_s=rho_s,
                                   diameter=float(diameter), extent=extent)
        g = self._snap
        self.x, self.z, self.n_phases, self.n_batches = g.x, g.z, int(n_phases), int(n_batches)
        if self.n_phases < 1 or self.n_batches < 1:
            raise InputError(f"n_phases, n_batches = {n_phases!r}, {n_batches!r}: must be >= 1")
        self.pair_mu_r = float(pair_mu_r)
        self.wall_mu_r = np.asarray(wall_mu_r, float)
        self._acc = np.zeros((self.n_batches, self.n_phases, _N_ROWS, g.nx, g.nz))
        self._weight = np.zeros((self.n_batches, self.n_phases))
        self._scratch = np.zeros((9, g.nx, g.nz))
        self._scratch_b = np.zeros((N_BALL_Q, g.nx, g.nz))

    def add_snapshot(self, positions_tub, velocities_rel_tub, spins_rel_tub, radius, mass,
                     phase_bin: int, batch: int, contacts_i=None, contacts_j=None,
                     contact_force=None, contact_branch=None, wall_particle=None,
                     wall_force=None, wall_point=None, wall_kind=None,
                     frame_spin=(0.0, 0.0, 0.0)) -> float:
        """One snapshot, returning its contacts' total power taken out (W): positions (m) and
        velocities (m/s) in the tub frame, spins (rad/s) relative to the tub (tub axes), radii
        (m), masses (kg); the contacts as
        CoarseGrainer.add_snapshot's, wall_kind (W,) each wall contact's slot, frame_spin the
        tub's angular velocity (rad/s, tub axes); batch < 0: not used."""
        if batch < 0:
            return float("nan")
        if not (0 <= int(phase_bin) < self.n_phases) or int(batch) >= self.n_batches:
            raise InputError(f"phase_bin, batch = {phase_bin!r}, {batch!r}: must be in "
                             f"0 .. {self.n_phases - 1}, < {self.n_batches}")
        acc = self._acc[int(batch), int(phase_bin)]
        g = self._snap
        g.reset()
        g.add_snapshot(positions_tub, velocities_rel_tub, radius, mass, contacts_i, contacts_j,
                       contact_force, contact_branch, wall_particle, wall_force, wall_point)
        f = g.averaged_arrays()
        L = np.nan_to_num(f["velocity_gradient"])
        acc[_R_PROD] += -np.einsum("...ab,...ab->...", f["stress"], L)
        acc[_R_PROD_C] += -np.einsum("...ab,...ab->...", f["contact_stress"], L)
        acc[_R_P] += f["pressure"]
        pos = np.asarray(positions_tub, float)
        vel = np.asarray(velocities_rel_tub, float)
        w = np.asarray(spins_rel_tub, float)
        r = np.broadcast_to(np.asarray(radius, float), (pos.shape[0],))
        total = 0.0
        if contacts_i is not None and len(contacts_i):
            i = np.asarray(contacts_i, np.int64)
            j = np.asarray(contacts_j, np.int64)
            b = pos[i] - pos[j] if contact_branch is None else np.asarray(contact_branch, float)
            parts = pair_power_loss(b, r[i], r[j], vel[i], vel[j], w[i], w[j],
                                    np.asarray(contact_force, float), self.pair_mu_r)
            self._deposit(pos[i], b, parts, acc)
            total += float(sum(p.sum() for p in parts))
        if wall_particle is not None and len(wall_particle):
            i = np.asarray(wall_particle, np.int64)
            b = pos[i] - np.asarray(wall_point, float)
            slot = (np.zeros(i.size, np.int64) if wall_kind is None
                    else np.asarray(wall_kind, np.int64))
            mu_r = self.wall_mu_r[np.minimum(slot, self.wall_mu_r.size - 1)]
            parts = [np.zeros(i.size) for _ in PARTS]
            for s in np.unique(mu_r):
                on = mu_r == s
                for k, p in enumerate(wall_power_loss(b[on], r[i][on], vel[i][on], w[i][on],
                                                      np.asarray(wall_force, float)[on],
                                                      frame_spin, float(s))):
                    parts[k][on] = p
            self._deposit(pos[i], b, parts, acc)
            total += float(sum(p.sum() for p in parts))
            self._wall_feed(np.asarray(wall_point, float), np.asarray(wall_force, float),
                            np.nan_to_num(f["velocity"]), acc)
        self._weight[int(batch), int(phase_bin)] += 1.0
        return total

    def _wall_feed(self, point, force, V, acc):
        """The walls' feed -f_w . V(c_w) (W) at each wall contact point c_w, V the snapshot's
        coarse-grained velocity there (bilinear on the grid), deposited with the kernel."""
        g = self._snap
        at = RegularGridInterpolator((g.x, g.z), V, bounds_error=False, fill_value=None)
        xz = np.stack([np.clip(point[:, 0], g.x[0], g.x[-1]),
                       np.clip(point[:, 2], g.z[0], g.z[-1])], axis=1)
        feed = -np.einsum("ij,ij->i", force, at(xz))
        kind, amp, inv2w2, shift, rc = g._kp
        sb = self._scratch_b
        sb[...] = 0.0
        deposit_balls(point[:, 0].copy(), point[:, 2].copy(), np.ascontiguousarray(feed),
                      np.zeros(feed.size), np.zeros((feed.size, 3)), 1.0, g.i_min * g.h,
                      g.k_min * g.h, g.h, g.nx, g.nz, kind, amp, inv2w2, shift, rc, sb)
        acc[_R_WALL] += sb[B_RHO] / g.depth

    def _deposit(self, start, branch, parts, acc):
        """Each part's power (W) along each branch: f = P b / |b|^2 makes the trace of the
        deposited f (x) b the power times int W ds (coarse_grain_kernel.deposit_contacts)."""
        g = self._snap
        kind, amp, inv2w2, shift, rc = g._kp
        grid = (g.i_min * g.h, g.k_min * g.h, g.h, g.nx, g.nz)
        b = np.ascontiguousarray(branch, float)
        inv_b2 = 1.0 / np.einsum("ij,ij->i", b, b)
        for k, p in enumerate(parts):
            self._scratch[...] = 0.0
            deposit_contacts(np.ascontiguousarray(start, float), b,
                             np.ascontiguousarray((p * inv_b2)[:, None] * b), g._s_nodes,
                             g._s_weights, 1.0, *grid, kind, amp, inv2w2, shift, rc,
                             self._scratch)
            acc[_R_DISS + k] += (self._scratch[0] + self._scratch[4] + self._scratch[8]) / g.depth

    def fields(self) -> xr.Dataset:
        """production, production_contact, wall_feed, dissipation and dissipation_<part>
        (W/m^3), and the snapshots' pressure (Pa, the mean of tr(P) / 3): (phase,
        x, z) phase means and <name>_cycle_mean (x, z), the mean over the phase bins (each an
        equal share of the cycle), with <name>_cycle_mean_stderr (batch means, n_batches >= 2)."""
        if self._weight.sum() <= 0:
            raise InputError("fields(): no snapshot was added")
        w_ph = self._weight.sum(axis=0)
        if np.any(w_ph <= 0):
            raise InputError(f"phase bins {np.nonzero(w_ph <= 0)[0].tolist()} hold no snapshot")
        mean = self._acc.sum(axis=0) / w_ph[:, None, None, None]
        with np.errstate(invalid="ignore", divide="ignore"):
            per = self._acc / self._weight[:, :, None, None, None]
        names = (["production", "production_contact", "wall_feed", "pressure"]
                 + [f"dissipation_{p}" for p in PARTS])
        data = {}
        cm, cm_b = mean.mean(axis=0), np.nanmean(per, axis=1)
        for k, name in enumerate(names):
            attrs = {"units": "Pa" if name == "pressure" else "W m-3"}
            data[name] = (("phase", "x", "z"), mean[:, k], attrs)
            data[name + "_cycle_mean"] = (("x", "z"), cm[k], attrs)
            if self.n_batches >= 2:
                data[name + "_cycle_mean_stderr"] = (
                    ("x", "z"), np.asarray(stderr_of_batches(cm_b[:, k], axis=0)), attrs)
        attrs = {"units": "W m-3"}
        diss = sum(data[f"dissipation_{p}"][1] for p in PARTS)
        data["dissipation"] = (("phase", "x", "z"), diss, attrs)
        data["dissipation_cycle_mean"] = (("x", "z"), diss.mean(axis=0), attrs)
        if self.n_batches >= 2:
            d_b = np.nansum(cm_b[:, _R_DISS:], axis=1)
            data["dissipation_cycle_mean_stderr"] = (
                ("x", "z"), np.asarray(stderr_of_batches(d_b, axis=0)), attrs)
        coords = {"x": self.x, "z": self.z,
                  "phase": 2.0 * np.pi * np.arange(self.n_phases) / self.n_phases}
        g = self._snap
        return xr.Dataset(data, coords=coords, attrs={
            "kernel": g.kernel, "width_m": g.width, "cell_size_m": g.h, "depth_m": g.depth,
            "n_batches": self.n_batches,
            "production": "-P:L of each snapshot's own coarse-grained stress (kinetic about its "
                          "own velocity + contact, compression positive) and velocity gradient",
            "dissipation": "each contact's power out of the balls (dashpot, sliding, CDT "
                           "rolling, with the springs' storage rate), along its branch; the "
                           "cycle mean is the dissipation"})


def rolling_resistances(scenario):
    """(ball-ball mu_r, [U wall, partition, partition] mu_r, left_out) of a tub scenario's CDT
    laws; a law whose rolling moment dem.h5 does not determine (EPSD) gets 0 and is named in
    left_out."""
    def law(a, b):
        for c in scenario.contacts:
            if set(c.pair) == {a, b}:
                return c
        return None
    ball = scenario.fill.material
    left_out = []

    def mu(a, b):
        c = law(a, b)
        if c is None or c.rolling_model == "none":
            return 0.0
        if not rolling_reconstructable(c.rolling_model):
            left_out.append(f"{a}-{b} ({c.rolling_model})")
            return 0.0
        return float(c.rolling_friction)
    part = mu(ball, scenario.tub.partition_material)
    return mu(ball, ball), [mu(ball, scenario.tub.wall_material), part, part], left_out


def thermal_balance_run(run, n_batches: int | None = None, thermal: bool = True):
    """The production and dissipation Dataset (ThermalBalanceGrainer.fields) of a DEM run's
    averaging window on the calibration's grid (a third of the analysis cell, kernel d/2), with,
    when `thermal`, the thermal temperature's phase-resolved and cycle-mean fields and the solid
    fraction (thermal_temperature.py) on the same grid, and the springs' stored energy
    "elastic_energy" (J) at each snapshot of the window (linear laws; NaN otherwise).
    run: a DEMResult, a run directory or a dem.h5 path."""
    own = not isinstance(run, DEMResult)
    res = DEMResult.open(run) if own else run
    try:
        if not res.has_ball_contacts:
            raise InputError(f"{res.path}: no ball contacts stored (run the DEM with them)")
        sc = res.scenario
        geometry = geometry_of(sc)
        nb = int(sc.run.batches if n_batches is None else n_batches)
        n_ph = int(sc.run.phases_per_cycle)
        pair_mu_r, wall_mu_r, left_out = rolling_resistances(sc)
        common = dict(cell_size=float(sc.analysis.cell_size / 3.0), depth=float(sc.tub.length),
                      rho_s=res.solid_density, diameter=res.diameter, n_phases=n_ph,
                      n_batches=nb)
        bal = ThermalBalanceGrainer(geometry, pair_mu_r=pair_mu_r, wall_mu_r=wall_mu_r,
                                    **common)
        th = ThermalTemperatureGrainer(geometry, **common) if thermal else None
        springs = _springs(sc)
        batch, used, ph = res.window_snapshots(nb, n_ph)
        spins = res.file["snapshots/angular_velocity"]
        energy = np.full(used.size, np.nan)
        power = np.full(used.size, np.nan)
        for k, (s, snap) in enumerate(res.iter_snapshots(used)):
            _X, _Z, th_, _Xd, _Zd, thd = (float(v) for v in snap["pose"])
            w = spins[s].astype(np.float64)
            w[:, 1] += thd        # the tub's spin is (0, -theta_dot, 0) (dem/walls.py)
            w = _to_tub_axes(w, th_)
            keys = ("positions_tub", "velocities_rel_tub", "radius", "mass", "contacts_i",
                    "contacts_j", "contact_force", "contact_branch", "wall_particle",
                    "wall_force", "wall_point")
            args = {key: snap[key] for key in keys if key in snap}
            power[k] = bal.add_snapshot(spins_rel_tub=w, phase_bin=int(ph[s]), batch=int(batch[s]),
                             wall_kind=snap.get("wall_kind"), frame_spin=(0.0, -thd, 0.0),
                             **args)
            if th is not None:
                th.add_snapshot(phase_bin=int(ph[s]), batch=int(batch[s]), **args)
            if springs is not None:
                energy[k] = _stored(snap, springs)
        ds = bal.fields()
        if th is not None:
            phase, cycle = th.fields()
            ds = xr.merge([ds, phase.drop_vars("phase", errors="ignore")
                           .assign_coords(phase=ds.phase), cycle], compat="override")
            sf = th.energy_flux_fields()["solid_fraction"]
            ds["solid_fraction"] = (("phase", "x", "z"), np.asarray(sf.values))
        ds["elastic_energy"] = (("snapshot",), energy, {"units": "J"})
        ds["contact_power"] = (("snapshot",), power, {
            "units": "W", "long_name": "all contacts' power out of the balls"})
        ds["snapshot_time"] = (("snapshot",), res.times[used], {"units": "s"})
        ds.attrs["rolling_left_out"] = ", ".join(left_out) or "none"
        return ds
    finally:
        if own:
            res.close()


def _springs(sc):
    """(k_n, k_t) of the ball-ball law and of each wall slot's (the U, the partitions), N/m;
    None when a law is not linear (its stored energy is not k delta^2 / 2)."""
    def law(a, b):
        for c in sc.contacts:
            if set(c.pair) == {a, b}:
                if c.model != "linear":
                    return None
                return float(c.k_n), float(c.k_n * c.k_t_over_k_n)
        return (np.nan, np.nan)
    ball = sc.fill.material
    laws = [law(ball, ball), law(ball, sc.tub.wall_material),
            law(ball, sc.tub.partition_material)]
    return None if any(v is None for v in laws) else laws


def _stored(snap, springs):
    """The springs' stored energy of one snapshot (J; contact_power.elastic_energy_J)."""
    r = np.broadcast_to(np.asarray(snap["radius"], float), (snap["positions_tub"].shape[0],))
    e = 0.0
    if "contacts_i" in snap and len(snap["contacts_i"]):
        i, j = snap["contacts_i"], snap["contacts_j"]
        e += elastic_energy_J(snap["contact_branch"], r[i] + r[j], snap["contact_force"],
                              *springs[0])
    if "wall_particle" in snap and len(snap["wall_particle"]):
        i = snap["wall_particle"]
        b = snap["positions_tub"][i] - snap["wall_point"]
        kind = np.minimum(snap.get("wall_kind", np.zeros(i.size, np.int64)), 2)
        for k in np.unique(kind):
            on = kind == k
            e += elastic_energy_J(b[on], r[i][on], snap["wall_force"][on], *springs[int(k)])
    return e
