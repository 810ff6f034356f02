"""Coarse-grained (CG) continuum fields from DEM snapshots: models.md
"Coarse-graining" (Goldhirsch 2010; Weinhart, Thornton, Luding & Bokhove 2012, Granular Matter
14:289, "From discrete particles to continuum fields near a boundary"; MercuryCG).

Usable on any DEM result (our engine, an imported LIGGGHTS run, a synthetic test): the caller
hands over, per snapshot, the balls' positions and velocities in the tub frame and the contact
forces; `CoarseGrainer` accumulates kernel-weighted sums on a grid and `fields()` turns the
averaged sums into continuum fields.

The kernel and its deposits are in coarse_grain_kernel, the fields derived from the averaged
sums (their definitions, compression positive) in coarse_grain_fields.

Frame and grid
--------------
Everything is in the tub frame (tub47.md "Frames"): x across, z up, y along the tub; velocities
are relative to the tub, in tub axes (vibroflow.tub.motion.relative_velocity_tub_axes_np;
`snapshot_from_state` does the conversion for a live DEM state).  The fields are averaged over
y: the kernel W is two-dimensional in (x, z), normalised so that its integral over the x-z plane
is 1, and a per-unit-volume field is the kernel sum divided by the slab depth L_y
(default: the tub's length), e.g. rho(x, z) = sum_i m_i W(x - x_i, z - z_i) / L_y.
The grid is cell-centred with spacing h (default: tub47's 15 mm cells, centres on multiples of
h, as vibroflow.measure.bulk), covering the tub's cross-section (bulk.grid_extent) plus a margin
of cells wide enough to hold the kernel's support, so that no deposited mass, momentum or stress
leaves the grid (the integral identities then hold exactly).  A field value is the smoothed
field at the cell centre (a point value, not a cell average).

Averaging
---------
Time averages are averages of the *sums* (rho, P, K, grad rho, grad P, sigma_c) over the
snapshots (weighted by `weight`), from which every field is then derived: V = <P>/<rho> is the
mass-weighted (Favre) mean velocity and the kinetic stress <K> - <P><P>/<rho> counts the
fluctuation of each ball about that time-mean velocity, so it includes the local velocity's own
oscillation over the cycle.  Phase-resolved fields (`n_phases`, `phase_bin`) do the same within
each phase bin, and there the kinetic stress is the fluctuation at that phase.  With
`n_batches` >= 2 (batches of whole cycles: vibroflow.measure.stats.batches_of_whole_cycles)
every field also gets `<name>_stderr`, the batch-means standard error of the same derivation
done per batch.

Cost: one pass over the balls and the contacts per snapshot, each deposited on the cells within
the kernel's cut-off by a numba kernel (single-threaded, so results do not depend on the thread
count).  Memory: (n_batches x n_phases x 28 x n_cells) float64.
"""
from __future__ import annotations

import math

import numpy as np
import xarray as xr

from vibroflow.dem.query import ball_contacts_now
from vibroflow.dem.simulate import wall_contacts_now
from vibroflow.errors import InputError
from vibroflow.measure.bulk import grid_extent
from vibroflow.measure.stats import stderr_of_batches
from vibroflow.tub.geometry import TubGeometry
from vibroflow.tub.motion import TubMotion, lab_to_tub_np, pose_np, relative_velocity_tub_axes_np

from .coarse_grain_fields import COMPONENTS, FIELD_META, derive_fields
from .coarse_grain_kernel import (KERNELS, LUCY_CUTOFF_PER_WIDTH, N_BALL_Q, N_CONTACT_Q,
                                  deposit_balls, deposit_contacts, kernel_parameters)


D_TUB47 = 0.00635          # m, tub47's ball diameter (default kernel width d/2)
#: the most memory the fields of one coarse-graining take (bytes): tub47's calibration takes
#: tens of MB; beyond this a setting, a kernel far wider than the tub, is out of range
MAX_FIELD_BYTES = 4 * 2**30


class CoarseGrainer:
    """Streaming coarse-graining on a grid of the tub frame's x-z plane (see the module notes).

    Parameters
    ----------
    geometry : TubGeometry or None. Its cross-section sets the grid (bulk.grid_extent) and its
        length the default depth.  None needs `extent` and `depth`.
    cell_size : grid spacing h (m), default 0.015 (tub47's cells); any h > 0 (finer for
        profiles); cell centres are multiples of h.
    kernel : "gaussian" or "lucy".
    width : w (m), the kernel's standard deviation per axis; default d/2 with d = `diameter`.
    cutoff : Gaussian cut-off c / w (default 3); not allowed for "lucy" (c = 3.35 w).
    depth : slab depth L_y (m) that turns x-z kernel sums into per-volume fields; default the
        geometry's length.
    rho_s : solid density (kg/m^3) for the inertial number; default: the mass over the volume of
        the balls added.
    extent : (x_min, x_max, z_min, z_max) (m) of the region the grid must cover, instead of the
        geometry's cross-section.
    margin : extra cells on each side (default: enough to hold the kernel's support, so that
        nothing deposited leaves the grid).
    n_phases : number of phase bins for phase-resolved fields (None: time averages only).
    n_batches : batches of whole cycles for standard errors (1: none).
    quadrature : Gauss-Legendre points of the contact line integral (default 4).
    diameter : ball diameter d (m) for the default width and the inertial number (default
        tub47's 6.35 mm).
    """

    def __init__(self, geometry: TubGeometry | None = None, cell_size: float = 0.015,
                 kernel: str = "gaussian", width: float | None = None,
                 cutoff: float | None = None, depth: float | None = None,
                 rho_s: float | None = None, *, extent=None, margin: int | None = None,
                 n_phases: int | None = None, n_batches: int = 1, quadrature: int = 4,
                 diameter: float = D_TUB47):
        if not (cell_size > 0 and math.isfinite(cell_size)):
            raise InputError(f"cell_size = {cell_size!r}: must be a finite length > 0 m")
        if kernel not in KERNELS:
            raise InputError(f"kernel = {kernel!r}: must be one of {', '.join(KERNELS)}")
        if not (diameter > 0):
            raise InputError(f"diameter = {diameter!r}: must be > 0 m")
        if width is None:
            width = 0.5 * diameter
        if not (width > 0 and math.isfinite(width)):
            raise InputError(f"width = {width!r}: must be a finite length > 0 m")
        if kernel == "lucy" and cutoff is not None:
            raise InputError(f"cutoff = {cutoff!r}: not allowed with kernel = 'lucy' (its "
                             f"support is fixed at {LUCY_CUTOFF_PER_WIDTH:.3f} width)")
        if cutoff is not None and not (cutoff >= 1.0 and math.isfinite(cutoff)):
            raise InputError(f"cutoff = {cutoff!r}: must be a finite number >= 1 (widths)")
        if geometry is None and (extent is None or depth is None):
            raise InputError("geometry = None: give extent = (x_min, x_max, z_min, z_max) and "
                             "depth instead")
        if depth is None:
            depth = float(geometry.length)
        if not (depth > 0 and math.isfinite(depth)):
            raise InputError(f"depth = {depth!r}: must be a finite length > 0 m")
        if rho_s is not None and not (rho_s > 0):
            raise InputError(f"rho_s = {rho_s!r}: must be > 0 kg/m^3")
        if n_phases is not None and int(n_phases) < 1:
            raise InputError(f"n_phases = {n_phases!r}: must be at least 1 (or None)")
        if int(n_batches) < 1:
            raise InputError(f"n_batches = {n_batches!r}: must be at least 1")
        if int(quadrature) < 1:
            raise InputError(f"quadrature = {quadrature!r}: must be at least 1 point")
        self.kernel = kernel
        self.width = float(width)
        self.cutoff = (3.0 if cutoff is None else float(cutoff)) if kernel == "gaussian" \
            else LUCY_CUTOFF_PER_WIDTH
        self._kp = kernel_parameters(kernel, self.width, cutoff)
        self.cutoff_radius = self._kp[4]
        self.h = float(cell_size)
        self.depth = float(depth)
        self.rho_s = None if rho_s is None else float(rho_s)
        self.diameter = float(diameter)
        if extent is None:
            i0, i1, k0, k1 = grid_extent(geometry, self.h)
        else:
            xa, xb, za, zb = (float(v) for v in extent)
            if not (xb > xa and zb > za):
                raise InputError(f"extent = {tuple(extent)!r}: must be (x_min, x_max, z_min, "
                                 f"z_max) with x_max > x_min and z_max > z_min (m)")
            i0, i1 = int(np.ceil(xa / self.h - 0.5)), int(np.floor(xb / self.h + 0.5))
            k0, k1 = int(np.ceil(za / self.h - 0.5)), int(np.floor(zb / self.h + 0.5))
        if margin is None:
            margin = int(math.ceil(self.cutoff_radius / self.h))
        if int(margin) < 0:
            raise InputError(f"margin = {margin!r}: must be >= 0 cells")
        margin = int(margin)
        self.i_min, self.i_max = i0 - margin, i1 + margin
        self.k_min, self.k_max = k0 - margin, k1 + margin
        self.nx = self.i_max - self.i_min + 1
        self.nz = self.k_max - self.k_min + 1
        nph = 1 if n_phases is None else int(n_phases)
        size = 8.0 * int(n_batches) * nph * (N_BALL_Q + N_CONTACT_Q) * self.nx * self.nz
        if size > MAX_FIELD_BYTES:
            raise InputError(f"width = {self.width!r} m, cell_size = {self.h!r} m: the "
                             f"coarse-grained fields over {self.nx} x {self.nz} cells (the "
                             f"kernel's reach included) take {size / 2**30:.3g} GiB; at most "
                             f"{MAX_FIELD_BYTES / 2**30:g} GiB (a narrower kernel or larger "
                             "cells)")
        self.x = np.arange(self.i_min, self.i_max + 1) * self.h
        self.z = np.arange(self.k_min, self.k_max + 1) * self.h
        self.n_phases = None if n_phases is None else int(n_phases)
        self.n_batches = int(n_batches)
        nph = self.n_phases or 1
        self._ball = np.zeros((self.n_batches, nph, N_BALL_Q, self.nx, self.nz))
        self._cont = np.zeros((self.n_batches, nph, N_CONTACT_Q, self.nx, self.nz))
        self._weight = np.zeros((self.n_batches, nph))
        self._snapshots = 0
        self._mass = 0.0
        self._volume = 0.0
        self._batch_phase_cache: dict[str, dict] = {}  # gradient -> per-batch phase fields
        nodes, weights = np.polynomial.legendre.leggauss(int(quadrature))
        self._s_nodes = 0.5 * (nodes + 1.0)
        self._s_weights = 0.5 * weights

    # ------------------------------------------------------------------------------------------
    def add_snapshot(self, positions_tub, velocities_rel_tub, radius, mass,
                     contacts_i=None, contacts_j=None, contact_force=None, contact_branch=None,
                     wall_particle=None, wall_force=None, wall_point=None, weight: float = 1.0,
                     phase_bin: int | None = None, batch: int = 0) -> None:
        """Accumulate one snapshot.

        positions_tub : (N, 3) ball centres in the tub frame (m).
        velocities_rel_tub : (N, 3) velocities relative to the tub, tub axes (m/s).
        radius, mass : (N,) (m, kg), or scalars.
        contacts_i, contacts_j : (C,) ball indices of each touching pair, each pair once.
        contact_force : (C, 3) force on i by j, tub axes (N).
        contact_branch : (C, 3) r_i - r_j (m; minimum image if periodic); default computed
            from the positions (then contacts_j is needed).
        wall_particle : (W,) ball of each wall contact; wall_force : (W, 3) the wall's force on
            the ball, tub axes (N); wall_point : (W, 3) contact point, tub frame (m).
        weight : the snapshot's weight in the averages (>= 0).
        phase_bin : phase bin 0 .. n_phases-1 (required when n_phases is set; see
            vibroflow.measure.stats.phase_bins).
        batch : batch of whole cycles 0 .. n_batches-1; negative: the snapshot is skipped
            (as stats.batches_of_whole_cycles marks samples outside the window).
        """
        if batch < 0:
            return
        if batch >= self.n_batches:
            raise InputError(f"batch = {batch!r}: must be < n_batches = {self.n_batches}")
        if self.n_phases is None:
            if phase_bin not in (None, 0):
                raise InputError(f"phase_bin = {phase_bin!r}: this CoarseGrainer has no phase "
                                 f"bins (give n_phases)")
            ph = 0
        else:
            if phase_bin is None or not (0 <= int(phase_bin) < self.n_phases):
                raise InputError(f"phase_bin = {phase_bin!r}: must be 0 .. {self.n_phases - 1}")
            ph = int(phase_bin)
        if not (weight >= 0 and math.isfinite(weight)):
            raise InputError(f"weight = {weight!r}: must be a finite number >= 0")
        pos = np.ascontiguousarray(positions_tub, dtype=np.float64)
        vel = np.ascontiguousarray(velocities_rel_tub, dtype=np.float64)
        n = pos.shape[0]
        if pos.shape != (n, 3) or vel.shape != (n, 3):
            raise InputError(f"positions_tub, velocities_rel_tub have shapes {pos.shape}, "
                             f"{vel.shape}: must both be (N, 3)")
        r = np.broadcast_to(np.asarray(radius, dtype=np.float64), (n,))
        m = np.ascontiguousarray(np.broadcast_to(np.asarray(mass, dtype=np.float64), (n,)))
        vol = np.ascontiguousarray(4.0 / 3.0 * math.pi * r**3)
        kind, amp, inv2w2, shift, rc = self._kp
        grid = (self.i_min * self.h, self.k_min * self.h, self.h, self.nx, self.nz)
        deposit_balls(pos[:, 0].copy(), pos[:, 2].copy(), m, vol, vel, float(weight), *grid,
                      kind, amp, inv2w2, shift, rc, self._ball[batch, ph])
        if contacts_i is not None and len(contacts_i):
            ci = np.asarray(contacts_i, dtype=np.int64)
            f = np.ascontiguousarray(contact_force, dtype=np.float64).reshape(-1, 3)
            if contact_branch is None:
                if contacts_j is None:
                    raise InputError("contact_branch = None: give contact_branch or contacts_j")
                b = pos[ci] - pos[np.asarray(contacts_j, dtype=np.int64)]
            else:
                b = np.ascontiguousarray(contact_branch, dtype=np.float64).reshape(-1, 3)
            if f.shape[0] != ci.size or b.shape[0] != ci.size:
                raise InputError(f"contact_force, contact_branch have {f.shape[0]}, "
                                 f"{b.shape[0]} rows: must have one per contact ({ci.size})")
            deposit_contacts(pos[ci], b, f, self._s_nodes, self._s_weights, float(weight),
                             *grid, kind, amp, inv2w2, shift, rc, self._cont[batch, ph])
        if wall_particle is not None and len(wall_particle):
            wi = np.asarray(wall_particle, dtype=np.int64)
            wf = np.ascontiguousarray(wall_force, dtype=np.float64).reshape(-1, 3)
            wp = np.asarray(wall_point, dtype=np.float64).reshape(-1, 3)
            if wf.shape[0] != wi.size or wp.shape[0] != wi.size:
                raise InputError(f"wall_force, wall_point have {wf.shape[0]}, {wp.shape[0]} "
                                 f"rows: must have one per wall contact ({wi.size})")
            start = pos[wi]
            deposit_contacts(start, start - wp, wf, self._s_nodes, self._s_weights,
                             float(weight), *grid, kind, amp, inv2w2, shift, rc,
                             self._cont[batch, ph])
        self._weight[batch, ph] += weight
        self._snapshots += 1
        self._batch_phase_cache.clear()
        self._mass += float(m.sum())
        self._volume += float(vol.sum())

    def reset(self) -> None:
        """Forget every snapshot added: the same grid and kernel, empty (one grid serves a
        snapshot at a time, as a local mean's or a snapshot's own fields need)."""
        self._ball[...] = 0.0
        self._cont[...] = 0.0
        self._weight[...] = 0.0
        self._snapshots = 0
        self._mass = 0.0
        self._volume = 0.0
        self._batch_phase_cache.clear()

    def averaged_arrays(self, gradient: str = "kernel") -> dict:
        """The time-averaged fields over every snapshot added as plain arrays (nx, nz, ...)
        (coarse_grain_fields.derive_fields' dict), without errors or coordinates."""
        if self._weight.sum() <= 0:
            raise InputError("averaged_arrays(): no snapshot with positive weight was added")
        return self._fields_of(self._ball.sum(axis=(0, 1)), self._cont.sum(axis=(0, 1)),
                               self._weight.sum(), gradient)

    def batch_phase_arrays(self, names, gradient: str = "kernel") -> dict:
        """Each batch's phase-resolved fields `names` as plain arrays (n_batches, n_phases, nx,
        nz, ...), the derivation `fields(phase_resolved=True)` does per batch for its standard
        errors; NaN where a batch has no snapshot of that phase."""
        if self.n_phases is None:
            raise InputError("batch_phase_arrays(): this CoarseGrainer has no phase bins (give "
                             "n_phases)")
        per_batch = self._batch_phase_fields(gradient)
        return {name: per_batch[name] for name in names}

    def leave_one_out_phase_arrays(self, names, gradient: str = "kernel") -> dict:
        """The phase-resolved fields `names` of every batch but one, as plain arrays
        (n_batches, n_phases, nx, nz, ...): row b derived from the sums of the other batches,
        as `fields(phase_resolved=True)` derives the pooled fields from all of them (so row b
        is the field the delete-one-batch jackknife refits on; measure.stats.jackknife_stderr).
        NaN where the other batches hold no snapshot of that phase."""
        if self.n_phases is None:
            raise InputError("leave_one_out_phase_arrays(): this CoarseGrainer has no phase "
                             "bins (give n_phases)")
        ball = self._ball.sum(axis=0, keepdims=True) - self._ball
        cont = self._cont.sum(axis=0, keepdims=True) - self._cont
        weight = self._weight.sum(axis=0, keepdims=True) - self._weight
        derived = self._fields_of(ball, cont, weight, gradient)
        return {name: derived[name] for name in names}

    def _batch_phase_fields(self, gradient: str) -> dict:
        """Each batch's phase-resolved fields, derived once per gradient until the next snapshot:
        `fields(phase_resolved=True)`'s standard errors and batch_phase_arrays share them."""
        if gradient not in self._batch_phase_cache:
            derived = self._fields_of(self._ball, self._cont, self._weight, gradient)
            for arr in derived.values():
                arr.setflags(write=False)  # shared by every caller until the next snapshot
            self._batch_phase_cache[gradient] = derived
        return self._batch_phase_cache[gradient]

    # ------------------------------------------------------------------------------------------
    @property
    def n_snapshots(self) -> int:
        return self._snapshots

    def solid_density(self) -> float:
        """rho_s (kg/m^3): as given, else the mass over the volume of the balls added."""
        if self.rho_s is not None:
            return self.rho_s
        return self._mass / self._volume if self._volume > 0 else float("nan")

    def _fields_of(self, ball, cont, weight, gradient):
        with np.errstate(invalid="ignore", divide="ignore"):
            inv = np.where(weight > 0, 1.0 / np.where(weight > 0, weight, 1.0), np.nan)
        ball = ball * inv[..., None, None, None]
        cont = cont * inv[..., None, None, None]
        return derive_fields(ball, cont, self.depth, self.solid_density(), self.diameter, gradient,
                       self.h)

    def fields(self, phase_resolved: bool = False, gradient: str = "kernel",
               stderr: bool | None = None, as_xarray: bool | None = None):
        """The averaged fields.

        phase_resolved : False: time averages over every snapshot added, dims (x, z, ...);
            True: one average per phase bin, dims (phase, x, z, ...), phase in rad.
        gradient : "kernel" (exact CG velocity gradient, default) or "grid" (central
            differences of V on the grid).
        stderr : add `<name>_stderr` (batch means) for every field; default when n_batches >= 2.
        as_xarray : return an xarray.Dataset (default) or, with False, a dict
            {"coords": {...}, "attrs": {...}, name: (dims, array, attrs)}.

        Vectors have a last dim `i`, tensors `i`, `j` (coordinates "x", "y", "z").  Where no
        mass reaches a point the velocity, its gradient and the temperature are NaN and the
        kinetic stress is zero (the stress is then the contact stress alone).
        """
        if gradient not in ("kernel", "grid"):
            raise InputError(f"gradient = {gradient!r}: must be 'kernel' or 'grid'")
        if self._weight.sum() <= 0:
            raise InputError("fields(): no snapshot with positive weight was added")
        if phase_resolved and self.n_phases is None:
            raise InputError("phase_resolved = True: this CoarseGrainer has no phase bins "
                             "(give n_phases)")
        if stderr is None:
            stderr = self.n_batches >= 2
        if phase_resolved:
            main = self._fields_of(self._ball.sum(axis=0), self._cont.sum(axis=0),
                                   self._weight.sum(axis=0), gradient)
            per_batch = self._batch_phase_fields(gradient) if stderr else None
            lead = ("phase",)
        else:
            main = self._fields_of(self._ball.sum(axis=(0, 1)), self._cont.sum(axis=(0, 1)),
                                   self._weight.sum(), gradient)
            per_batch = self._fields_of(self._ball.sum(axis=1), self._cont.sum(axis=1),
                                        self._weight.sum(axis=1), gradient) if stderr else None
            lead = ()
        coords = {"x": self.x, "z": self.z, "i": COMPONENTS, "j": COMPONENTS}
        if phase_resolved:
            coords["phase"] = 2.0 * np.pi * np.arange(self.n_phases) / self.n_phases
        attrs = {
            "kernel": self.kernel, "width_m": self.width, "cutoff_widths": self.cutoff,
            "cutoff_radius_m": self.cutoff_radius, "cell_size_m": self.h,
            "depth_m": self.depth, "rho_s_kg_m3": self.solid_density(),
            "diameter_m": self.diameter, "n_snapshots": self._snapshots,
            "n_batches": self.n_batches, "sign_convention": "compression positive",
            "frame": "tub frame; velocities relative to the tub, tub axes; averaged over y",
            "averaging": "averages of kernel sums over snapshots, then derived",
            "gradient": gradient,
        }
        out = {}
        for name, arr in main.items():
            extra = ("i", "j")[:arr.ndim - len(lead) - 2]
            dims = lead + ("x", "z") + extra
            unit, desc = FIELD_META[name]
            out[name] = (dims, arr, {"units": unit, "long_name": desc})
            if per_batch is not None:
                se = stderr_of_batches(per_batch[name], axis=0)
                out[name + "_stderr"] = (dims, np.asarray(se),
                                         {"units": unit,
                                          "long_name": f"batch-means standard error of {name}"})
        if as_xarray is None or as_xarray:
            ds = xr.Dataset({k: v for k, v in out.items()}, coords=coords, attrs=attrs)
            ds["x"].attrs["units"] = "m"
            ds["z"].attrs["units"] = "m"
            if phase_resolved:
                ds["phase"].attrs.update(units="rad", long_name="phase of the vibration cycle")
            return ds
        return {"coords": coords, "attrs": attrs, **out}


# ----------------------------------------------------------------------------------------------

def snapshot_from_state(system, state, contacts: bool = True) -> dict:
    """add_snapshot keyword arguments for a live DEM state (vibroflow.dem.simulate):
    positions in the tub frame, velocities relative to the tub in tub axes, ball-ball contacts
    (vibroflow.dem.query.ball_contacts_now) and wall contacts
    (vibroflow.dem.simulate.wall_contacts_now), forces and branches turned into tub axes.

    The tub's pose is the system's motion at the state's time (at rest unless the state is
    vibrating); wall contact points are in the tub frame (wall_contacts_now).
    """
    motion = system.motion if state.vibrating else TubMotion.still()
    pivot = (motion.pivot_x, motion.pivot_z)
    pz = pose_np(motion, state.time(system.dt))
    X, Z, th = float(pz["X"]), float(pz["Z"]), float(pz["theta"])
    Xd, Zd, thd = float(pz["Xdot"]), float(pz["Zdot"]), float(pz["thetadot"])

    def axes(v):  # a lab vector in tub axes: the rotation alone (no translation, pivot 0)
        return lab_to_tub_np(v, 0.0, 0.0, th, (0.0, 0.0))

    out = {
        "positions_tub": lab_to_tub_np(state.pos, X, Z, th, pivot),
        "velocities_rel_tub": relative_velocity_tub_axes_np(state.pos, state.vel, X, Z, th, Xd,
                                                            Zd, thd, pivot),
        "radius": state.radius.copy(), "mass": state.mass.copy(),
    }
    if contacts:
        bc = ball_contacts_now(system, state)
        out.update(contacts_i=bc["i"], contacts_j=bc["j"], contact_force=axes(bc["force"]),
                   contact_branch=axes(bc["branch"]))
        wc = wall_contacts_now(system, state)
        out.update(wall_particle=wc["particle"], wall_force=axes(wc["force"]),
                   wall_point=wc["point_tub"])
    return out
