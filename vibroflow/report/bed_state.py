"""The state of the bed as an engineer reads it: the peak tub acceleration Gamma, the turnover
time of the roll, and the bed's kinetic energy against time (is the flow steady?).

Gamma (tub47.md "Tub motion"): the peak vertical acceleration over gravity,
Gamma = A_z omega^2 / g, with A_z the vertical amplitude (times the amplitude factor) and
omega = 2 pi f; beside it the horizontal A_x omega^2 / g and the peak magnitude of the whole
rigid motion's acceleration at the bottom of the U (tub point (0, 0)),
a = (X'', Z'') + theta'' (-r_z, r_x) - theta'^2 r, r the point from the pivot (the turn
counterclockwise in x-z, tub/motion.py), over one cycle.

Turnover time (docs/models.md "Turnover time of the roll"): T = 2 pi / Omega_roll with
Omega_roll = <zeta> / 2 the mean angular velocity of the roll's core, zeta = dvz/dx - dvx/dz
the vorticity of the time-averaged bulk velocity (central differences on the analysis cells,
on cells whose four neighbours hold bed), averaged over the core: the bed cells (solid fraction
>= min_solid_fraction) where the stream function (measure.circulation) is at least CORE of its
extreme, of the same sign.  A solid-body rotation at Omega has zeta = 2 Omega everywhere, so
T = 2 pi / Omega, one revolution.  With batches, T of each batch (on the whole window's core)
gives its batch-means standard error.

Kinetic energy: the DEM's series/kinetic_energy (J, the balls' translation and spin in the lab
frame, written every few steps) averaged over blocks of whole vibration cycles about 0.1 s
long (the vibration's own energy swings within a cycle, not from one block to the next).
Steady: the means of the averaging window's first and second halves (each with its
batch-means standard error over half the run's batches of whole cycles) differ by no more than
max(STEADY_REL of their mean, 2 combined standard errors).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import h5py
import numpy as np

from vibroflow.io.pictures import pyplot
from vibroflow.measure.bulk import CellTable
from vibroflow.measure.circulation import stream_function
from vibroflow.measure.stats import (batch_means, batches_of_whole_cycles,
                                     cycles_in_window, stderr_of_batches)
from vibroflow.report.figures import png_bytes
from vibroflow.tub.motion import TubMotion

#: the roll's core: where psi is at least this fraction of its extreme
CORE = 0.5
#: length (s) of the blocks of whole cycles the kinetic energy is averaged over in its plot
BLOCK_S = 0.1
#: relative change of the cycle-mean kinetic energy within the window still called steady
STEADY_REL = 0.05


def gamma(motion: TubMotion, g: float, points: int = 720) -> dict:
    """Peak accelerations of the tub over gravity g (m/s^2), module docstring: "vertical"
    A_z omega^2 / g (Gamma), "horizontal" A_x omega^2 / g, "bottom_of_u" the peak |a| at tub
    point (0, 0) / g."""
    w = motion.omega
    t = np.arange(points) / (points * motion.frequency)

    def h(a, ph):  # s, s', s'' of s = a [sin(w t + ph) - sin(ph)]
        return (a * (np.sin(w * t + ph) - np.sin(ph)), a * w * np.cos(w * t + ph),
                -a * w * w * np.sin(w * t + ph))

    _, _, xdd = h(motion.amplitude_x, motion.phase_x)
    _, _, zdd = h(motion.amplitude_z, motion.phase_z)
    th, thd, thdd = h(motion.amplitude_theta, motion.phase_theta)
    px, pz = 0.0 - motion.pivot_x, 0.0 - motion.pivot_z
    rx = np.cos(th) * px - np.sin(th) * pz
    rz = np.sin(th) * px + np.cos(th) * pz
    ax = xdd - thdd * rz - thd**2 * rx
    az = zdd + thdd * rx - thd**2 * rz
    return {"vertical": motion.amplitude_z * w * w / g,
            "horizontal": motion.amplitude_x * w * w / g,
            "bottom_of_u": float(np.max(np.hypot(ax, az))) / g}


def _vorticity(vx: np.ndarray, vz: np.ndarray, h: float) -> np.ndarray:
    """zeta = dvz/dx - dvx/dz (1/s) of (nz, nx) fields by central differences; NaN on the
    grid's edge and where a neighbour is NaN."""
    zeta = np.full(vx.shape, np.nan)
    zeta[1:-1, 1:-1] = ((vz[1:-1, 2:] - vz[1:-1, :-2]) - (vx[2:, 1:-1] - vx[:-2, 1:-1])) / (
        2.0 * h)
    return zeta


def _grid(table: CellTable, vx, vz, i0, k0, shape):
    g = np.full((2, *shape), np.nan)
    g[0][table.iz - k0, table.ix - i0] = vx
    g[1][table.iz - k0, table.ix - i0] = vz
    return g[0], g[1]


@dataclass(frozen=True)
class Turnover:
    """Turnover time T (s) and its batch-means standard error (NaN without batches), the core's
    mean vorticity (1/s), its number of cells and the vorticity's batch-means standard error
    (1/s, NaN without batches)."""

    time_s: float
    stderr_s: float
    mean_vorticity_1_s: float
    cells: int
    mean_vorticity_stderr_1_s: float = math.nan


def turnover_time(table: CellTable, min_solid_fraction: float) -> Turnover:
    """The roll's turnover time of a cell table (module docstring)."""
    h = table.cell_size
    xg, zg, psi, _, _ = stream_function(table.x, table.z, table.solid_fraction, table.vx,
                                        table.vz, h)
    i0, k0 = int(round(xg[0] / h)), int(round(zg[0] / h))
    shape = psi.shape
    phi = np.zeros(shape)
    phi[table.iz - k0, table.ix - i0] = table.solid_fraction
    bed = phi >= min_solid_fraction
    ext = psi.flat[int(np.argmax(np.abs(psi)))]
    core = bed & (psi * np.sign(ext) >= CORE * abs(ext)) if ext != 0 else np.zeros(shape, bool)

    def mean_zeta(vx, vz):
        vx, vz = _grid(table, vx, vz, i0, k0, shape)
        zeta = _vorticity(np.where(bed, vx, np.nan), np.where(bed, vz, np.nan), h)[core]
        return float(np.nanmean(zeta)) if np.isfinite(zeta).any() else float("nan"), int(
            np.isfinite(zeta).sum())

    z, n = mean_zeta(table.vx, table.vz)
    T = 4.0 * math.pi / abs(z) if math.isfinite(z) and z != 0 else float("nan")
    se = z_se = float("nan")
    if table.batch_vx is not None and table.n_batches >= 2:
        zb = np.array([mean_zeta(table.batch_vx[b], table.batch_vz[b])[0]
                       for b in range(table.n_batches)])
        tb = [4.0 * math.pi / abs(v) if math.isfinite(v) and v != 0 else np.nan for v in zb]
        se = float(stderr_of_batches(np.asarray(tb)))
        z_se = float(stderr_of_batches(zb))
    return Turnover(T, se, z, n, z_se)


@dataclass(frozen=True)
class KineticEnergy:
    """The DEM's kinetic energy: the series (time s, energy J), its block means (cycle_time s
    at each block's middle, cycle_mean J; cycle_means), the window (t_start, t_end s), the
    window's mean and batch-means standard error (J), the two halves' (mean, stderr) (J),
    whether the flow is steady, and the halves' whole cycles (start, end s)."""

    time: np.ndarray
    energy: np.ndarray
    cycle_time: np.ndarray
    cycle_mean: np.ndarray
    window: tuple[float, float]
    mean: float
    stderr: float
    halves: tuple[tuple[float, float], tuple[float, float]]
    steady: bool
    half_spans: tuple[tuple[float, float], tuple[float, float]] = ((math.nan,) * 2,) * 2


def cycle_means(time, values, frequency: float, block_s: float = BLOCK_S):
    """Means of a series over consecutive blocks of whole vibration cycles, each
    max(1, round(block_s f)) cycles long, from t = 0, the last one the whole cycles left (fewer
    when they do not fill it): (middle times s, means).  Blocks of several
    cycles because the series is sampled on the solver's clock, not in step with the cycle: one
    cycle's mean aliases (its few samples catch the impacts' peaks or miss them)."""
    per = max(1, int(round(block_s * frequency)))
    cycle = np.floor(np.asarray(time) * frequency + 1e-6).astype(np.int64)
    n_cycles = int(np.floor(float(np.max(time)) * frequency + 1e-6))
    n = -(-n_cycles // per)  # the last block holds the whole cycles left, fewer than per
    block = cycle // per
    keep = (cycle >= 0) & (cycle < n_cycles)
    cnt = np.bincount(block[keep], minlength=n)
    tot = np.bincount(block[keep], np.asarray(values, dtype=float)[keep], minlength=n)
    ok = cnt > 0
    start = np.arange(n) * per
    end = np.minimum(start + per, n_cycles)
    return (0.5 * (start + end)[ok] / frequency, tot[ok] / cnt[ok])


def is_steady(halves) -> bool:
    """The halves' means agree within max(STEADY_REL of their mean, 2 combined errors)."""
    (m1, s1), (m2, s2) = halves
    tol = max(STEADY_REL * 0.5 * abs(m1 + m2), 2.0 * math.hypot(np.nan_to_num(s1),
                                                                 np.nan_to_num(s2)))
    return bool(abs(m2 - m1) <= tol)


def kinetic_energy(time, energy, t_start: float, t_end: float, frequency: float,
                   n_batches: int) -> KineticEnergy:
    """The kinetic-energy record of a series over the averaging window (module docstring)."""
    time, energy = np.asarray(time, dtype=float), np.asarray(energy, dtype=float)
    b = batches_of_whole_cycles(time, t_start, t_end, frequency, n_batches)
    mean, se = batch_means(energy, b, n_batches)
    half = max(n_batches // 2, 2)
    mid = t_start + math.floor((t_end - t_start) * frequency / 2 + 1e-6) / frequency
    halves, spans = [], []
    for a, z in ((t_start, mid), (mid, t_end)):
        halves.append(batch_means(energy, batches_of_whole_cycles(time, a, z, frequency, half),
                                  half))
        spans.append((a, a + cycles_in_window(a, z, frequency) / frequency))
    ct, cm = cycle_means(time, energy, frequency)
    return KineticEnergy(time, energy, ct, cm, (t_start, t_end), float(mean), float(se),
                         tuple(halves), is_steady(halves), tuple(spans))


def dem_kinetic_energy(h5_path, scenario) -> KineticEnergy | None:
    """The DEM's kinetic energy (dem.h5 series/kinetic_energy), None when it has none."""
    run = scenario.run
    try:
        with h5py.File(h5_path, "r") as f:
            if "series/kinetic_energy" not in f:
                return None
            t, e = f["series/time"][:], f["series/kinetic_energy"][:]
    except (OSError, KeyError):
        return None
    try:
        return kinetic_energy(t, e, run.duration - run.average_last, run.duration,
                              float(scenario.motion.frequency), int(run.batches))
    except ValueError:
        return None


def kinetic_energy_figure(ke: KineticEnergy) -> bytes:
    """The series, its whole-cycle means and the window's two halves' means, against time."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(11, 3.8), layout="constrained")
    ax.plot(ke.time, ke.energy, color="0.75", lw=0.5, label="kinetic energy (lab frame)")
    ax.plot(ke.cycle_time, ke.cycle_mean, "o-", ms=2.5, lw=1.0, color="C0",
            label=f"mean over blocks of whole cycles, about {BLOCK_S:g} s (the last: the "
            "cycles left)")
    ax.axvspan(*ke.window, color="C2", alpha=0.12, label="averaging window")
    for (m, s), (a, z) in zip(ke.halves, ke.half_spans):
        # at the middle of the half's own whole cycles, the bar across them
        ax.errorbar(0.5 * (a + z), m, xerr=0.5 * (z - a), yerr=np.nan_to_num(s), fmt="s",
                    color="C3", capsize=4, ms=6)
    ax.plot([], [], "s", color="C3", label="half-window means ± standard error, across "
            "the half's whole cycles")
    ax.set_xlabel("time since the vibration started (s)")
    ax.set_ylabel("kinetic energy of the balls (J)")
    ax.set_ylim(bottom=0.0)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper left")
    ax.set_title("the bed's kinetic energy: " + ("steady over the window" if ke.steady else
                                                  "not steady over the window"), fontsize=10)
    return png_bytes(fig)
