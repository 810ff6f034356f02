"""The cycle-mean shear rate of a sampled velocity field, measured the way the DEM's calibration
measures it, so that a continuum's shear rate can be put into the DEM's impact relation.

Why this exists.  The calibration fits the DEM's mean impact speed against the shear rate of the
*phase-resolved* coarse-grained velocity field (vibroflow.calibration.impacts): the velocity
relative to the tub averaged, at each phase of the cycle, over every cycle of the window and the
slice's depth, then differentiated (run_fields; add_cycle_means).  That average removes the
cycle-to-cycle fluctuation of the flow; what is left is the bed's mean shearing at that phase
(the slow roll plus the bed's periodic deformation).  A continuum's instantaneous velocity
gradient holds its own cycle-to-cycle fluctuation as well, and the mean of |gamma_dot| of a
fluctuating field is larger than |gamma_dot| of its mean (on tub47 the Lagrangian's points'
mean is 4.6 1/s where the DEM's cycle-mean field has 1.9): fed into the DEM's relation it
would predict ball-ball impacts twice as fast as the DEM's.  Measuring both on the same
definition is the like-for-like comparison (tub47.md "Impacts"; models.md "Impact velocity from
the continuum").

What it does.  `PhaseShearAccumulator` takes sampled snapshots (lab positions and velocities,
the tub's pose, a volume per sample point, the sample's phase bin and batch), converts them to
the tub frame with the shared kinematics of vibroflow.tub.motion (velocity relative to the tub,
tub axes), and deposits volume and volume-weighted velocity on the nodes of a square grid of
spacing h with bilinear (tent) weights, per (batch, phase).  `result()` forms the phase-averaged
velocity v = sum(w V v) / sum(w V) at each node, its gradient by central differences (one-sided
at the bed's edge), the plane-strain equivalent shear rate sqrt(2 D':D') of models.md (the
DEM's coarse_grain_fields.rheology with D_yy = 0), and its cycle mean weighted by the solid fraction
over the phases, as add_cycle_means weights by density.

Units: m, m/s, 1/s.  Nodes sit on multiples of h (the analysis cells' centres when h is the
analysis cell size), x from -(nxh) h to +(nxh) h, z from 0 to (nz - 1) h.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vibroflow.tub.geometry import distance_to_wall_np, geometry_of
from vibroflow.tub.motion import lab_to_tub_np, relative_velocity_tub_axes_np

from .stats import batches_of_whole_cycles, phase_bins

#: a node enters the gradient when its phase-averaged solid fraction is at least this (the
#: impact relation's own floor, calibration.impacts.impact_relations min_solid_fraction)
MIN_NODE_SOLID_FRACTION = 0.1


@dataclass
class PhaseShear:
    """Cycle-mean shear rate on the nodes, with what it was made from.

    x (nx,), z (nz,) node coordinates (m); solid_fraction (nz, nx) window mean; shear_rate (nz, nx)
    cycle mean of the phase-resolved shear rate (1/s, NaN where no material); phase_shear_rate,
    phase_solid_fraction (n_phases, nz, nx); batch_shear_rate (n_batches, nz, nx), each batch's
    own phase-resolved field's cycle mean (for standard errors of the means built on it);
    roll_shear_rate (nz, nx) the shear rate of the time-averaged field (the slow roll alone: the
    velocity averaged over every phase, then differentiated). The difference between
    shear_rate and roll_shear_rate is the bed's deformation within each cycle.
    loo_phase_shear_rate, loo_phase_solid_fraction (n_batches, n_phases, nz, nx) or None: the
    phase-resolved fields of every batch but one, batch by batch (asked for with
    `leave_one_out`: the delete-one-batch jackknife of a quantity built on the phase fields,
    vibroflow.calibration.impacts)."""
    x: np.ndarray
    z: np.ndarray
    h: float
    solid_fraction: np.ndarray
    shear_rate: np.ndarray
    phase_shear_rate: np.ndarray
    phase_solid_fraction: np.ndarray
    batch_shear_rate: np.ndarray
    batch_solid_fraction: np.ndarray
    roll_shear_rate: np.ndarray
    loo_phase_shear_rate: np.ndarray | None = None
    loo_phase_solid_fraction: np.ndarray | None = None

    def node_of(self, x: float, z: float) -> tuple[int, int]:
        """(k, i) of the node nearest to tub-frame point (x, z) (m)."""
        i = int(np.floor((x - self.x[0]) / self.h + 0.5))
        k = int(np.floor((z - self.z[0]) / self.h + 0.5))
        return k, i

    def _solid_mean(self, field: np.ndarray, solid: np.ndarray, mask) -> float:
        """Solid-fraction weighted mean of field (nz, nx) over its finite nodes with material
        in `mask` (all by default)."""
        m = np.isfinite(field) & (solid > 0)
        if mask is not None:
            m &= mask
        return float(np.sum(solid[m] * field[m]) / np.sum(solid[m])) if m.any() else float("nan")

    def roll_mean(self, mask: np.ndarray | None = None) -> float:
        """Solid-fraction weighted mean of roll_shear_rate over the nodes in `mask` (1/s)."""
        return self._solid_mean(self.roll_shear_rate, self.solid_fraction, mask)

    def weighted_mean(self, mask: np.ndarray | None = None) -> tuple[float, float]:
        """Solid-fraction weighted mean of the cycle-mean shear rate over the nodes in `mask`
        (all nodes with material by default), and its batch-means standard error (1/s)."""
        mean = self._solid_mean(self.shear_rate, self.solid_fraction, mask)
        per = [self._solid_mean(g, f, mask)
               for g, f in zip(self.batch_shear_rate, self.batch_solid_fraction)]
        per = [v for v in per if np.isfinite(v)]
        se = (float(np.std(per, ddof=1) / np.sqrt(len(per))) if len(per) >= 2
              else float("nan"))
        return mean, se


def node_grid(geometry, cell_size: float) -> tuple[float, int, int]:
    """The nodes covering a tub (the analysis cells' centres): (h m, nodes either side of
    x = 0, nodes up from z = 0), one node beyond the U's half-width and two above its rim."""
    h = float(cell_size)
    return (h, int(math.ceil(geometry.radius / h)) + 1,
            int(math.ceil(geometry.rim_height / h)) + 2)


def near_wall_nodes(shear: "PhaseShear", radius: float) -> np.ndarray:
    """(nz, nx) mask of the nodes within a node spacing of the U wall (signed distance from
    -h/2 to h, tub.geometry): where a ball-wall contact point's nearest node lies."""
    X, Z = np.meshgrid(shear.x, shear.z)
    gap = distance_to_wall_np(X, Z, radius)
    return (gap > -0.5 * shear.h) & (gap < shear.h)


def equivalent_shear_rate_2d(lxx, lxz, lzx, lzz):
    """sqrt(2 D':D') (1/s) of a plane-strain velocity gradient (D_yy = 0), models.md; the same
    number as calibration.coarse_grain_fields.rheology gives for the 3D gradient with no y terms."""
    third = (lxx + lzz) / 3.0
    exx, ezz = lxx - third, lzz - third
    exz = 0.5 * (lxz + lzx)
    return np.sqrt(2.0 * (exx * exx + ezz * ezz + third * third + 2.0 * exz * exz))


def _gradient(f: np.ndarray, ok: np.ndarray, h: float, axis: int) -> np.ndarray:
    """Derivative of f (nz, nx) along `axis` on the nodes where ok: central differences where
    both neighbours are ok, one-sided where one is, NaN where neither (an isolated node)."""
    out = np.full(f.shape, np.nan)
    fw = np.moveaxis(f, axis, 0)
    ow = np.moveaxis(ok, axis, 0)
    res = np.moveaxis(out, axis, 0)
    lo_ok = np.zeros_like(ow)
    hi_ok = np.zeros_like(ow)
    lo_ok[1:] = ow[:-1]
    hi_ok[:-1] = ow[1:]
    lo = np.zeros_like(fw)
    hi = np.zeros_like(fw)
    lo[1:] = fw[:-1]
    hi[:-1] = fw[1:]
    both = ow & lo_ok & hi_ok
    res[both] = (hi[both] - lo[both]) / (2.0 * h)
    only_hi = ow & hi_ok & ~lo_ok
    res[only_hi] = (hi[only_hi] - fw[only_hi]) / h
    only_lo = ow & lo_ok & ~hi_ok
    res[only_lo] = (fw[only_lo] - lo[only_lo]) / h
    return out


def phase_field_shear_rate(vol: np.ndarray, mom_x: np.ndarray, mom_z: np.ndarray,
                           node_volume: float, h: float,
                           min_solid_fraction: float = MIN_NODE_SOLID_FRACTION):
    """Shear rate (1/s) of phase-averaged fields: vol, mom_x, mom_z (n_phases, nz, nx) the sums
    of tent weight x volume and of tent weight x volume x velocity, node_volume the node's
    volume times the number of samples per phase (so vol / node_volume is the solid fraction).
    Returns (phase shear rate (n_phases, nz, nx), phase solid fraction, cycle mean (nz, nx),
    cycle-mean solid fraction)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        phi = vol / node_volume[:, None, None]
        vx = np.where(vol > 0, mom_x / vol, np.nan)
        vz = np.where(vol > 0, mom_z / vol, np.nan)
    rate = np.full(vol.shape, np.nan)
    for p in range(vol.shape[0]):
        ok = phi[p] >= min_solid_fraction
        lxx = _gradient(vx[p], ok, h, 1)
        lxz = _gradient(vx[p], ok, h, 0)
        lzx = _gradient(vz[p], ok, h, 1)
        lzz = _gradient(vz[p], ok, h, 0)
        rate[p] = np.where(ok, equivalent_shear_rate_2d(lxx, lxz, lzx, lzz), np.nan)
    w = np.where(np.isfinite(rate), phi, 0.0)
    wsum = w.sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        cycle = np.where(wsum > 0, np.nansum(w * np.nan_to_num(rate), axis=0) / wsum, np.nan)
    return rate, phi, cycle, phi.mean(axis=0)


class PhaseShearAccumulator:
    """Streaming accumulator of the phase-resolved velocity field on square nodes (module
    docstring).

    h : node spacing (m); nxh : nodes either side of x = 0; nz : nodes up from z = 0; length :
    the slice's thickness L_y (m), so a node's volume is h^2 L_y; n_phases, n_batches : the
    sampling phases a cycle and the batches of whole cycles; pivot : the tub's rotation pivot
    (x, z) in the tub frame (m)."""

    def __init__(self, h: float, nxh: int, nz: int, length: float, n_phases: int,
                 n_batches: int, pivot=(0.0, -0.10)):
        if not h > 0 or not length > 0:
            raise ValueError(f"h = {h}, length = {length}: must be > 0 m")
        if n_phases < 1 or n_batches < 1:
            raise ValueError(f"n_phases = {n_phases}, n_batches = {n_batches}: must be >= 1")
        self.h, self.nxh, self.nz, self.length = float(h), int(nxh), int(nz), float(length)
        self.nx = 2 * self.nxh + 1
        self.n_phases, self.n_batches = int(n_phases), int(n_batches)
        self.pivot = (float(pivot[0]), float(pivot[1]))
        shape = (self.n_batches, self.n_phases, self.nz, self.nx)
        self.vol = np.zeros(shape)
        self.mom_x = np.zeros(shape)
        self.mom_z = np.zeros(shape)
        self.samples = np.zeros((self.n_batches, self.n_phases), np.int64)

    def add(self, positions, velocities, tub_pose, volume, phase: int, batch: int) -> None:
        """One sample: positions, velocities (N, 3) lab frame (m, m/s); tub_pose (6,) X, Z,
        theta, Xdot, Zdot, thetadot; volume (N,) the solid volume (m^3) each point stands for
        (points far outside the grid, e.g. the Eulerian's parked ones, are ignored); phase,
        batch the sample's phase bin and batch (batch < 0: not in the window)."""
        if batch < 0 or batch >= self.n_batches:
            return
        X, Z, th, Xd, Zd, thd = (float(c) for c in tub_pose)
        pos = np.asarray(positions, float)
        p = lab_to_tub_np(pos, X, Z, th, self.pivot)
        v = relative_velocity_tub_axes_np(pos, np.asarray(velocities, float), X, Z, th, Xd, Zd,
                                          thd, self.pivot)
        fx = p[:, 0] / self.h + self.nxh
        fz = p[:, 2] / self.h
        i0 = np.floor(fx).astype(np.int64)
        k0 = np.floor(fz).astype(np.int64)
        tx, tz = fx - i0, fz - k0
        vol = np.asarray(volume, float)
        size = self.nz * self.nx
        acc_v = np.zeros(size)
        acc_x = np.zeros(size)
        acc_z = np.zeros(size)
        for di, wi in ((0, 1.0 - tx), (1, tx)):
            for dk, wk in ((0, 1.0 - tz), (1, tz)):
                i, k = i0 + di, k0 + dk
                ok = (i >= 0) & (i < self.nx) & (k >= 0) & (k < self.nz)
                w = (wi * wk * vol)[ok]
                flat = k[ok] * self.nx + i[ok]
                acc_v += np.bincount(flat, weights=w, minlength=size)
                acc_x += np.bincount(flat, weights=w * v[ok, 0], minlength=size)
                acc_z += np.bincount(flat, weights=w * v[ok, 2], minlength=size)
        self.vol[batch, phase] += acc_v.reshape(self.nz, self.nx)
        self.mom_x[batch, phase] += acc_x.reshape(self.nz, self.nx)
        self.mom_z[batch, phase] += acc_z.reshape(self.nz, self.nx)
        self.samples[batch, phase] += 1

    def result(self, min_solid_fraction: float = MIN_NODE_SOLID_FRACTION,
               leave_one_out: bool = False) -> PhaseShear:
        """The cycle-mean shear-rate field of everything added, and of each batch alone; with
        `leave_one_out`, also the phase fields of every batch but one, batch by batch."""
        node = self.h * self.h * self.length
        n_all = self.samples.sum(axis=0)
        rate, phase_phi, cycle, phi = phase_field_shear_rate(
            self.vol.sum(axis=0), self.mom_x.sum(axis=0), self.mom_z.sum(axis=0),
            node * np.maximum(n_all, 1), self.h, min_solid_fraction)
        b_rate = np.full((self.n_batches, self.nz, self.nx), np.nan)
        b_phi = np.zeros((self.n_batches, self.nz, self.nx))
        for b in range(self.n_batches):
            if self.samples[b].sum() == 0:
                continue
            _, _, b_rate[b], b_phi[b] = phase_field_shear_rate(
                self.vol[b], self.mom_x[b], self.mom_z[b],
                node * np.maximum(self.samples[b], 1), self.h, min_solid_fraction)
        total = self.vol.sum(axis=(0, 1))[None]
        _, _, roll, _ = phase_field_shear_rate(
            total, self.mom_x.sum(axis=(0, 1))[None], self.mom_z.sum(axis=(0, 1))[None],
            np.array([node * max(int(n_all.sum()), 1)]), self.h, min_solid_fraction)
        loo_rate = loo_phi = None
        if leave_one_out and self.n_batches >= 2:
            loo_rate = np.full((self.n_batches,) + rate.shape, np.nan)
            loo_phi = np.zeros((self.n_batches,) + rate.shape)
            for b in range(self.n_batches):
                keep = np.arange(self.n_batches) != b
                n_keep = self.samples[keep].sum(axis=0)
                if n_keep.sum() == 0:
                    continue
                loo_rate[b], loo_phi[b], _, _ = phase_field_shear_rate(
                    self.vol[keep].sum(axis=0), self.mom_x[keep].sum(axis=0),
                    self.mom_z[keep].sum(axis=0), node * np.maximum(n_keep, 1), self.h,
                    min_solid_fraction)
        x = (np.arange(self.nx) - self.nxh) * self.h
        z = np.arange(self.nz) * self.h
        return PhaseShear(x=x, z=z, h=self.h, solid_fraction=phi, shear_rate=cycle,
                          phase_shear_rate=rate, phase_solid_fraction=phase_phi,
                          batch_shear_rate=b_rate,
                          batch_solid_fraction=b_phi, roll_shear_rate=roll,
                          loo_phase_shear_rate=loo_rate, loo_phase_solid_fraction=loo_phi)


def phase_shear_of_snapshots(scenario, positions, velocities, poses, volume, times,
                             cell_size: float | None = None,
                             min_solid_fraction: float = MIN_NODE_SOLID_FRACTION,
                             leave_one_out: bool = False) -> PhaseShear:
    """The PhaseShear of a run's snapshots in its averaging window, on the nodes of node_grid
    (the analysis cells' centres by default): positions, velocities (S, N, 3) lab frame (arrays
    or h5py datasets, read a snapshot at a time), poses (S, 6), volume (N,) the solid volume
    (m^3) each body stands for, times (S,) s.  Binned by the scenario's sampling phases and by
    its batches of whole cycles (`leave_one_out`: PhaseShear.loo_*).  The DEM calibration and
    both continuum drivers call this."""
    geo = geometry_of(scenario)
    h, nxh, nz = node_grid(geo, cell_size or float(scenario.analysis.cell_size))
    run, motion = scenario.run, scenario.motion
    acc = PhaseShearAccumulator(h, nxh, nz, geo.length, run.phases_per_cycle, run.batches,
                                tuple(motion.pivot))
    times = np.asarray(times, float)
    batch = batches_of_whole_cycles(times, run.duration - run.average_last, run.duration,
                                    motion.frequency, run.batches)
    phase = phase_bins(times, motion.frequency, run.phases_per_cycle)
    poses = np.asarray(poses, float)
    for j in np.nonzero(batch >= 0)[0]:
        acc.add(positions[j], velocities[j], poses[j], volume, int(phase[j]), int(batch[j]))
    return acc.result(min_solid_fraction, leave_one_out)
