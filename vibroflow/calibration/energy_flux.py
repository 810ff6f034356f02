"""The coarse-grained flux of fluctuation energy q (W/m^2) and the gradient of the granular
temperature, from DEM snapshots: what Fourier's law q = -kappa grad T is fitted to
(vibroflow.calibration.conductivity).

Definitions (Babic 1997, Physica A 242, 333; Goldhirsch 2003, Chaos 13, 657; the kernel W,
grid, depth L_y and averaging of vibroflow.calibration.coarse_grain), with c_i = v_i - V(r) the
fluctuation velocity of ball i about the coarse-grained velocity V = P / rho at the field point:

* kinetic flux q_k(r) = sum_i m_i c_i (c_i . c_i) / 2 W(r - r_i) / L_y.  With the sums
  Q_a = sum m v_a |v|^2 W, K_ab = sum m v_a v_b W, rho and P (per volume) it is
      q_k,a = [Q_a - 2 K_ab V_b - V_a tr K + 2 rho V_a |V|^2] / 2
  exactly, so it is derived from averaged sums as the kinetic stress is, and a field
  phase-resolved over the cycle counts the fluctuation about that phase's mean velocity;
* collisional flux q_c(r) = sum_contacts [f_ij . (c_i + c_j) / 2] r_ij int_0^1 W(r - r_i +
  s r_ij) ds / L_y, f_ij the force on i by j and r_ij = r_i - r_j, each pair once.  It follows
  from the energy balance: sum_i v_i . f_i W_i splits into the divergence of this flux and the
  contacts' local work f_ij . (v_i - v_j) (W_i + W_j) / 2 (the collisional loss), using
  W_i - W_j = -div(r_ij int W ds).  With E_b = sum (f . (v_i + v_j) / 2) r_b int W ds and the
  contact stress sigma_c (compression positive, coarse_grain_fields) q_c,b = E_b - V_a
  sigma_c,ab.  A wall contact (the wall at rest in the tub frame) delivers f . v_i at its
  contact point, carried along the branch r_i - contact point: its term is (f . c_i) b int W ds,
  with the wall's load in sigma_c as the contact stress has it;
* temperature T = (tr K - P . V) / (3 rho) and its gradient exactly from the kernel gradients:
  with G_b = sum m |v|^2 dW/dx_b, grad T = (grad A - 3 T grad rho) / (3 rho),
  grad_b A = G_b - 2 P_a dP_a/dx_b / rho + |P|^2 d rho/dx_b / rho^2;
* solid fraction gradient grad phi = grad rho / rho_s (one grain density), what the
  density-gradient term of the heat flux is driven by (conductivity.py).

`EnergyFluxGrainer` is a CoarseGrainer (its fields are the same, bit for bit) that deposits
these sums as well, with the same compiled deposits: the balls' with m |v|^2 as the mass gives
tr K, G and Q; the contacts' with the force (f . v_bar, 0, 0) gives E.  `energy_flux_fields`
returns them phase-resolved or time-averaged, with batch-means errors and the per-batch values
the conductivity fit's standard error is taken from.
"""
from __future__ import annotations

import numpy as np
import xarray as xr

from vibroflow.errors import InputError
from vibroflow.measure.stats import stderr_of_batches

from .coarse_grain import CoarseGrainer
from .coarse_grain_kernel import (B_DP, B_DRHO, B_K, B_P, B_RHO, B_VOL, deposit_balls,
                                  deposit_contacts)

# rows of the extra ball sums: tr K, G_x, G_z, Q_x, Q_y, Q_z
X_TRK, X_G, X_Q = 0, 1, 3
N_EXTRA_BALL = 6
N_EXTRA_CONTACT = 3      # E_x, E_y, E_z


class EnergyFluxGrainer(CoarseGrainer):
    """A CoarseGrainer that also accumulates the fluctuation-energy flux and the exact
    temperature gradient (module notes); same parameters."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        lead = self._ball.shape[:2]
        self._xball = np.zeros(lead + (N_EXTRA_BALL, self.nx, self.nz))
        self._xcont = np.zeros(lead + (N_EXTRA_CONTACT, self.nx, self.nz))
        self._scratch_b = np.zeros((19, self.nx, self.nz))
        self._scratch_c = np.zeros((9, self.nx, self.nz))

    def add_snapshot(self, positions_tub, velocities_rel_tub, radius, mass,
                     contacts_i=None, contacts_j=None, contact_force=None, contact_branch=None,
                     wall_particle=None, wall_force=None, wall_point=None, weight: float = 1.0,
                     phase_bin: int | None = None, batch: int = 0) -> None:
        """CoarseGrainer.add_snapshot (same arguments), plus the energy-flux sums."""
        before = self._snapshots
        super().add_snapshot(positions_tub, velocities_rel_tub, radius, mass, contacts_i,
                             contacts_j, contact_force, contact_branch, wall_particle,
                             wall_force, wall_point, weight, phase_bin, batch)
        if self._snapshots == before:       # skipped (batch < 0)
            return
        ph = 0 if self.n_phases is None else int(phase_bin)
        pos = np.ascontiguousarray(positions_tub, dtype=np.float64)
        vel = np.ascontiguousarray(velocities_rel_tub, dtype=np.float64)
        n = pos.shape[0]
        m = np.broadcast_to(np.asarray(mass, dtype=np.float64), (n,))
        v2 = np.einsum("ij,ij->i", vel, vel)
        kind, amp, inv2w2, shift, rc = self._kp
        grid = (self.i_min * self.h, self.k_min * self.h, self.h, self.nx, self.nz)
        sb = self._scratch_b
        sb[...] = 0.0
        # mass m |v|^2: the density row is tr K, its gradient G, the momentum Q
        deposit_balls(pos[:, 0].copy(), pos[:, 2].copy(), np.ascontiguousarray(m * v2),
                      np.zeros(n), vel, float(weight), *grid, kind, amp, inv2w2, shift, rc, sb)
        xb = self._xball[batch, ph]
        xb[X_TRK] += sb[B_RHO]
        xb[X_G:X_G + 2] += sb[B_DRHO:B_DRHO + 2]
        xb[X_Q:X_Q + 3] += sb[B_P:B_P + 3]
        sc = self._scratch_c
        sc[...] = 0.0
        deposited = False
        if contacts_i is not None and len(contacts_i):
            if contacts_j is None:
                raise InputError("contacts_j = None: the energy flux needs both balls of each "
                                 "contact (their velocities)")
            ci = np.asarray(contacts_i, dtype=np.int64)
            cj = np.asarray(contacts_j, dtype=np.int64)
            f = np.ascontiguousarray(contact_force, dtype=np.float64).reshape(-1, 3)
            b = (pos[ci] - pos[cj] if contact_branch is None else
                 np.ascontiguousarray(contact_branch, dtype=np.float64).reshape(-1, 3))
            power = np.einsum("ij,ij->i", f, 0.5 * (vel[ci] + vel[cj]))
            self._deposit_power(pos[ci], b, power, weight, grid, sc)
            deposited = True
        if wall_particle is not None and len(wall_particle):
            wi = np.asarray(wall_particle, dtype=np.int64)
            wf = np.ascontiguousarray(wall_force, dtype=np.float64).reshape(-1, 3)
            wp = np.asarray(wall_point, dtype=np.float64).reshape(-1, 3)
            start = pos[wi]
            self._deposit_power(start, start - wp, np.einsum("ij,ij->i", wf, vel[wi]), weight,
                                grid, sc)
            deposited = True
        if deposited:
            self._xcont[batch, ph] += sc[0:3]

    def _deposit_power(self, start, branch, power, weight, grid, out):
        """(power, 0, 0) (x) branch along each branch: rows 0..2 of out get power * b."""
        kind, amp, inv2w2, shift, rc = self._kp
        f = np.zeros((power.size, 3))
        f[:, 0] = power
        deposit_contacts(np.ascontiguousarray(start), np.ascontiguousarray(branch), f,
                         self._s_nodes, self._s_weights, float(weight), *grid, kind, amp,
                         inv2w2, shift, rc, out)

    # ------------------------------------------------------------------------------------------
    def _flux_of(self, ball, cont, xball, xcont, weight):
        """Flux fields from the summed accumulators (..., rows, nx, nz) and weights (...)."""
        with np.errstate(invalid="ignore", divide="ignore"):
            inv_w = np.where(weight > 0, 1.0 / np.where(weight > 0, weight, 1.0), np.nan)
        s = inv_w[..., None, None] / self.depth

        def rows(a, r0, r1):   # rows r0..r1-1 as a last axis, per volume
            return np.moveaxis(a[..., r0:r1, :, :] * s[..., None, :, :], -3, -1)

        rho = ball[..., B_RHO, :, :] * s
        P = rows(ball, B_P, B_P + 3)
        dP = rows(ball, B_DP, B_DP + 6).reshape(rho.shape + (3, 2))
        drho = rows(ball, B_DRHO, B_DRHO + 2)
        K = np.zeros(rho.shape + (3, 3))
        for q, (a, b) in enumerate(((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))):
            K[..., a, b] = K[..., b, a] = ball[..., B_K + q, :, :] * s
        sig_c = rows(cont, 0, 9).reshape(rho.shape + (3, 3))
        trK = xball[..., X_TRK, :, :] * s
        G = rows(xball, X_G, X_G + 2)
        Q = rows(xball, X_Q, X_Q + 3)
        E = rows(xcont, 0, 3)
        with np.errstate(invalid="ignore", divide="ignore"):
            inv = np.where(rho > 0, 1.0 / np.where(rho > 0, rho, 1.0), np.nan)
            V = P * inv[..., None]
            V2 = np.einsum("...a,...a->...", V, V)
            A = trK - np.einsum("...a,...a->...", P, V)
            T = A * inv / 3.0
            gradA = (G - 2.0 * np.einsum("...a,...ab->...b", P, dP) * inv[..., None]
                     + (V2 * rho)[..., None] * drho * inv[..., None])
            gradT = (gradA - 3.0 * T[..., None] * drho) * inv[..., None] / 3.0
            qk = 0.5 * (Q - 2.0 * np.einsum("...ab,...b->...a", K, V)
                        - V * trK[..., None] + 2.0 * (rho * V2)[..., None] * V)
        Vf = np.nan_to_num(V)
        qc = E - np.einsum("...a,...ab->...b", Vf, sig_c)
        qk = np.where((rho > 0)[..., None], qk, 0.0)
        rho_s = self.solid_density()
        return {"solid_fraction": ball[..., B_VOL, :, :] * s,
                "solid_fraction_gradient": drho / rho_s, "velocity": V, "temperature": T,
                "temperature_gradient": gradT, "kinetic_energy_flux": qk,
                "collisional_energy_flux": qc, "energy_flux": qk + qc}

    def energy_flux_fields(self, phase_resolved: bool = True) -> xr.Dataset:
        """Dataset of solid_fraction (-), its gradient solid_fraction_gradient (1/m, last dim
        k = x, z), velocity V (m/s, the tub frame's, last dim i), temperature (m^2/s^2),
        temperature_gradient (m/s^2, last dim k), kinetic_, collisional_ and energy_flux (W/m^2, last dim i = x, y,
        z), dims (phase,) x, z; each with <name>_stderr (batch means, when n_batches >= 2) and
        <name>_batches (leading dim batch: the field of each batch alone)."""
        if self._weight.sum() <= 0:
            raise InputError("energy_flux_fields(): no snapshot with positive weight was added")
        if phase_resolved and self.n_phases is None:
            raise InputError("phase_resolved = True: this grainer has no phase bins "
                             "(give n_phases)")
        acc = (self._ball, self._cont, self._xball, self._xcont)
        if phase_resolved:
            main = self._flux_of(*(a.sum(axis=0) for a in acc), self._weight.sum(axis=0))
            per = self._flux_of(*acc, self._weight)
            lead = ("phase",)
        else:
            main = self._flux_of(*(a.sum(axis=(0, 1)) for a in acc), self._weight.sum())
            per = self._flux_of(*(a.sum(axis=1) for a in acc), self._weight.sum(axis=1))
            lead = ()
        units = {"solid_fraction": "1", "solid_fraction_gradient": "m-1", "velocity": "m s-1",
                 "temperature": "m2 s-2", "temperature_gradient": "m s-2"}
        data = {}
        for name, arr in main.items():
            extra = (("k",) if name.endswith("_gradient") else ("i",)) \
                if arr.ndim > len(lead) + 2 else ()
            dims = lead + ("x", "z") + extra
            u = units.get(name, "W m-2")
            data[name] = (dims, arr, {"units": u})
            data[name + "_batches"] = (("batch",) + dims, per[name], {"units": u})
            if self.n_batches >= 2:
                data[name + "_stderr"] = (dims, np.asarray(stderr_of_batches(per[name], axis=0)),
                                          {"units": u, "long_name": f"batch-means standard "
                                                                    f"error of {name}"})
        coords = {"x": self.x, "z": self.z, "i": ["x", "y", "z"], "k": ["x", "z"]}
        if phase_resolved:
            coords["phase"] = 2.0 * np.pi * np.arange(self.n_phases) / self.n_phases
        attrs = {"kernel": self.kernel, "width_m": self.width, "cell_size_m": self.h,
                 "depth_m": self.depth, "rho_s_kg_m3": self.solid_density(),
                 "diameter_m": self.diameter, "n_batches": self.n_batches,
                 "definition": "fluctuation-energy flux, kinetic + collisional (Babic 1997; "
                               "Goldhirsch 2003), tub frame"}
        return xr.Dataset(data, coords=coords, attrs=attrs)
