"""The Lees-Edwards periodic box of spheres as plain-Python orchestration: the DEM variant of the
shear cell and of the elastic tests (vibroflow.calibration's protocols drive it).  It owns the
state, rebuilds the neighbour list carrying the contact histories over, and runs the compiled
step (vibroflow.dem.periodic_step) of the box (vibroflow.dem.lees_edwards).
"""
from __future__ import annotations

import math

import numpy as np

from .lees_edwards import B_LZ, build_le_list, wrap
from .neighbours import INDEX, transfer_history
from .periodic_step import (BLOWUP, C_CUT, C_DAMPING, C_GAIN, C_MAX_OVERLAP, C_MODE, C_PRESSURE,
                            C_RATE_MAX, C_SKIN, MODE_FIXED, MODE_Z, N_CTRL, N_Q, N_STATE,
                            R_EX, R_EY, R_EZ, R_GAMMA, REBUILD, S_BUILD_STRAIN, S_BLOCK,
                            S_MAX_OVERLAP, S_NSAMPLE, S_TIME, advance, pair_forces)
from .records import Box, BoxBalls, Pairs


def random_fill(n: int, radius: np.ndarray, lengths, rng: np.random.Generator,
                max_tries: int = 100_000) -> np.ndarray:
    """Random sequential addition of n non-overlapping spheres in a periodic box (positions, m).

    Each ball is drawn uniformly until it overlaps none already placed (minimum image); fine up
    to solid fractions of about 0.3 (the random sequential addition limit is 0.38)."""
    lengths = np.asarray(lengths, float)
    pos = np.empty((n, 3))
    for i in range(n):
        for _ in range(max_tries):
            x = rng.random(3) * lengths
            d = pos[:i] - x
            d -= lengths * np.rint(d / lengths)
            if i == 0 or np.all((d * d).sum(axis=1) >= (radius[:i] + radius[i]) ** 2):
                pos[i] = x
                break
        else:
            raise RuntimeError(f"random fill: no room for ball {i} of {n} after {max_tries} "
                               f"tries")
    return pos


class PeriodicBox:
    """State of a Lees-Edwards periodic box of spheres and its stepping (see module notes).

    pos (m), radius (m), mass (kg) per ball; `par` the contact-law row (laws.pair_table) of the
    ball-ball pair; `lengths` the box (m); `dt` (s); `skin` (m).  Positions are wrapped in."""

    def __init__(self, pos, radius, mass, par, lengths, dt: float, skin: float,
                 max_overlap: float):
        n = len(pos)
        self.pos = np.array(pos, float)
        self.radius = np.asarray(radius, float).copy()
        self.mass = np.asarray(mass, float).copy()
        self.inertia = 0.4 * self.mass * self.radius**2
        self.par = np.asarray(par, float).copy()
        self.vel = np.zeros((n, 3))
        self.omg = np.zeros((n, 3))
        self.force = np.zeros((n, 3))
        self.torque = np.zeros((n, 3))
        self.box = np.array([*map(float, lengths), 0.0])
        self.rates = np.zeros(4)
        self.state = np.zeros(N_STATE)
        self.disp = np.zeros((n, 3))
        self.image = np.zeros((n, 3), np.int64)
        self.degree = np.zeros(n, np.int64)
        self.virial = np.zeros((3, 3))
        self.acc = np.zeros(N_Q)
        self.dt = float(dt)
        self.skin = float(skin)
        self.cut = 2.0 * float(self.radius.max()) + self.skin
        self.max_overlap = float(max_overlap)
        self.start = np.zeros(n + 1, np.int64)
        self.nbr = np.zeros(0, INDEX)
        self.hist = np.zeros((0, 6))
        self.flag = np.zeros(0, np.uint8)
        self.builds = 0
        wrap(self.pos, self.vel, self.image, self.box, 0.0)
        self.rebuild()
        self.evaluate()

    # -- geometry ------------------------------------------------------------------------------
    @property
    def n(self) -> int:
        return self.pos.shape[0]

    @property
    def volume(self) -> float:
        return float(self.box[0] * self.box[1] * self.box[2])

    @property
    def solid_fraction(self) -> float:
        return float((4.0 / 3.0 * np.pi * self.radius**3).sum() / self.volume)

    @property
    def table(self) -> np.ndarray:
        """The contact-law row as the pair kernel's (1, 1, N_PARAMS) table (a view of `par`)."""
        return self.par.reshape(1, 1, -1)

    def rebuild(self) -> None:
        """New neighbour list (history carried over) from the current positions."""
        dims = np.floor(self.box[:3] / self.cut).astype(np.int64)
        if dims.min() < 3:
            raise ValueError(f"periodic box {self.box[:3]} m is less than three cut-offs "
                             f"({self.cut:.4g} m) across: too few balls")
        wrap(self.pos, self.vel, self.image, self.box, self.rates[R_GAMMA])
        start, nbr = build_le_list(self.pos, self.radius, self.box, self.skin, dims)
        if self.nbr.shape[0]:
            hist, flag = transfer_history(self.start, self.nbr, self.hist, self.flag, start,
                                          nbr)
        else:
            hist = np.zeros((nbr.shape[0], 6))
            flag = np.zeros(nbr.shape[0], np.uint8)
        self.start, self.nbr, self.hist, self.flag = start, nbr, hist, flag
        self.disp[:] = 0.0
        self.state[S_BUILD_STRAIN] = 0.0
        self.builds += 1

    def evaluate(self) -> tuple[int, float]:
        """Forces, torques and virial at the current state without advancing contact histories
        (LAMMPS' setup).  Returns (contacts, largest overlap)."""
        return pair_forces(self._balls(), self._pairs(), self._cell(np.zeros(N_CTRL)), 0.0)

    # -- velocities of the mean flow -------------------------------------------------------------
    def set_shear_rate(self, gamma_dot: float) -> None:
        """Change the imposed shear rate (1/s), re-profiling the balls' velocities: v_x keeps its
        fluctuation about the mean flow, which becomes gamma_dot (z - L_z/2), and the spin w_y
        keeps its fluctuation about the flow's half vorticity gamma_dot / 2."""
        old = self.rates[R_GAMMA]
        self.vel[:, 0] += (gamma_dot - old) * (self.pos[:, 2] - 0.5 * self.box[B_LZ])
        self.omg[:, 1] += 0.5 * (gamma_dot - old)
        self.rates[R_GAMMA] = float(gamma_dot)

    def unwrapped_momentum(self) -> np.ndarray:
        """Momentum of the unwrapped balls (kg m/s): sum m (v + image_z gamma_dot L_z x); the pair
        forces conserve it (at constant L_z and gamma_dot)."""
        v = self.vel.copy()
        v[:, 0] += self.image[:, 2] * self.rates[R_GAMMA] * self.box[B_LZ]
        return (self.mass[:, None] * v).sum(axis=0)

    # -- the kernels' records (vibroflow.dem.records) of the current arrays ---------------------
    def _balls(self) -> BoxBalls:
        return BoxBalls(self.pos, self.vel, self.omg, self.force, self.torque, self.radius,
                        self.mass, self.inertia, self.disp, self.image, self.degree)

    def _pairs(self) -> Pairs:
        """The neighbour list, one force-assembly chunk."""
        return Pairs(self.start, self.nbr, self.hist, self.flag,
                     np.array([0, self.n], np.int64))

    def _cell(self, ctrl: np.ndarray) -> Box:
        return Box(self.box, self.rates, ctrl, self.state, self.virial, self.acc, self.table)

    # -- stepping --------------------------------------------------------------------------------
    def run(self, n_steps: int, mode: int = MODE_FIXED, pressure: float = 0.0,
            gain: float = 0.0, rate_max: float = math.inf, damping: float = 0.0,
            dilation=(0.0, 0.0, 0.0), sample_every: int = 100, stop=None) -> np.ndarray:
        """Advance n_steps; returns the samples (rows of Q_* columns, one per `sample_every`
        steps).  mode: MODE_FIXED (box rates as set in `self.rates`), MODE_Z (sigma_zz = pressure)
        or MODE_ISO (tr sigma / 3 = pressure), with the control law of the module notes:
        eps_dot = clip((sigma_c - p) gain, +-rate_max), gain = 1 / (K_ref t_b) (1/(Pa s)).
        `stop(samples_so_far)`, checked every ten samples, may end the run early.
        Raises FloatingPointError when the box blows up."""
        ctrl = np.zeros(N_CTRL)
        ctrl[C_MODE] = mode
        ctrl[C_PRESSURE] = pressure
        ctrl[C_GAIN] = gain
        ctrl[C_RATE_MAX] = rate_max
        ctrl[C_DAMPING] = damping
        ctrl[C_SKIN] = self.skin
        ctrl[C_CUT] = self.cut
        ctrl[C_MAX_OVERLAP] = self.max_overlap
        if mode == MODE_FIXED:
            self.rates[R_EX:R_EZ + 1] = np.asarray(dilation, float)
        elif mode == MODE_Z:
            self.rates[R_EX] = self.rates[R_EY] = 0.0
        samples = np.zeros((n_steps // sample_every + 1, N_Q))
        self.state[S_NSAMPLE] = 0.0
        self.state[S_BLOCK] = 0.0
        self.acc[:] = 0.0
        done = 0
        chunk = 20_000 if stop is None else 10 * sample_every
        balls, cell = self._balls(), self._cell(ctrl)
        while done < n_steps:
            todo = min(n_steps - done, chunk)
            status, steps = advance(todo, self.dt, sample_every, balls, self._pairs(), cell,
                                    samples)
            done += steps
            if status == BLOWUP:
                raise FloatingPointError(
                    f"periodic box blew up at t = {self.state[S_TIME]:.4g} s (largest overlap "
                    f"{self.state[S_MAX_OVERLAP]:.3g} m)")
            if status == REBUILD:
                self.rebuild()
            k = min(int(self.state[S_NSAMPLE]), samples.shape[0])
            if stop is not None and stop(samples[:k]):
                break
        return samples[:min(int(self.state[S_NSAMPLE]), samples.shape[0])]

    def copy(self) -> "PeriodicBox":
        """An independent copy of the whole state (to branch experiments from one packing)."""
        new = object.__new__(PeriodicBox)
        for k, v in self.__dict__.items():
            setattr(new, k, v.copy() if isinstance(v, np.ndarray) else v)
        return new
