"""The U floor's force over the vibration cycle and the bed's take-off, the same for every
method (docs/validation.md section 22, "The floor over the cycle").

The floor is the U wall within FLOOR_DEG (30 degrees) of its bottom: arc positions |s| <= R
pi / 6 (tub.geometry.point_to_arc).  At each sample the floor force F_z (N) is the sum over
the wall's contacts there of the z component, in the tub's axes, of the wall's force on the
material: the DEM's sampled ball-wall contacts (dem.h5 /wall_contacts/force_lab, lab axes,
rotated by the tub's angle theta: F_z = -sin(theta) F_X + cos(theta) F_Z), a continuum's
penalty force on its points or wall-layer cells.  Over the bed's weight M |g| it is binned by
the samples' phase of the cycle, t f mod 1, at the run's P sampled phases k / P, each phase's
mean over the window's whole cycles carrying its batch-means standard error (stats.py).

The take-off phase is where that force first falls to TAKE_OFF_LEVEL of the weight after its
maximum (layer_profiles.take_off_phase, section 23's definition), on the sampled phases k / P
(not the bins' centres (k + 1/2) / P that take_off_phase assumes): a block resting on a floor
shaken at Gamma = A omega^2 / g leaves it at sin(psi) = 1 / Gamma.  NaN (None in JSON) where the
force never falls that low: the bed never leaves the floor.

The regions of the U (REGIONS: the floor, the arcs to 90 degrees, the side walls) also split a
run's wall feed of fluctuation energy (`region_of`, `region_lengths`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from vibroflow.io.atomic import write_text_atomic
from vibroflow.tub.geometry import point_to_arc

from .layer_profiles import TAKE_OFF_LEVEL, take_off_phase
from .stats import batches_of_whole_cycles, phase_bins, phase_stderr

FLOOR_CSV_NAME = "floor.csv"
#: the floor: the U within this angle (degrees) of its bottom, either side
FLOOR_DEG = 30.0
#: the U's regions, by index of region_of
REGIONS = ("floor", "arcs", "side walls")
#: floor.csv's columns and their units (SI; "1": a number)
FLOOR_COLUMNS = {"phase": "1", "force_over_weight": "1", "force_over_weight_stderr": "1",
                 "samples": "1"}


def region_of(s, radius: float) -> np.ndarray:
    """Region index (REGIONS) of arc positions s (m) on a U of `radius` (m)."""
    a = np.abs(np.asarray(s, float))
    return np.where(a <= radius * math.radians(FLOOR_DEG), 0,
                    np.where(a <= 0.5 * math.pi * radius, 1, 2))


def region_lengths(radius: float, wall_height: float) -> np.ndarray:
    """Arc length (m) of each region (REGIONS) on both sides of a U of `radius` (m) whose side
    walls rise to `wall_height` (m) above its bottom."""
    floor = 2 * radius * math.radians(FLOOR_DEG)
    return np.array([floor, math.pi * radius - floor, 2 * (wall_height - radius)])


def on_floor(x, z, radius: float) -> np.ndarray:
    """True where the tub-frame point (x, z) (m) is nearest the floor of a U of `radius` (m)."""
    return region_of(point_to_arc(x, z, radius), radius) == 0


def tub_z(force_lab, theta) -> np.ndarray:
    """The z component in the tub's axes (N) of lab-frame forces (n, 3) (N; x, y, z) at the
    tub's angles theta (n,) (rad, the tub pose's third entry)."""
    f = np.asarray(force_lab, float)
    th = np.asarray(theta, float)
    return -np.sin(th) * f[:, 0] + np.cos(th) * f[:, 2]


def floor_force_of_contacts(snapshot, wall, position_tub, force_lab, theta, n_samples: int,
                            radius: float, u_wall: int = 0) -> np.ndarray:
    """(n_samples,) the floor force F_z (N) at each sample from sampled ball-wall contacts
    (dem.h5 /wall_contacts: the sample index, the wall (u_wall = the U), the contact point in
    the tub frame (n, 3) m, the wall's force on the ball (n, 3) N in lab axes), theta (rad)
    the tub's angle at each sample; 0 at a sample with no floor contact."""
    snap = np.asarray(snapshot, np.int64)
    pos = np.asarray(position_tub, float).reshape(-1, 3)
    th = np.asarray(theta, float)
    keep = (np.asarray(wall) == u_wall) & (snap >= 0) & (snap < n_samples)
    keep &= on_floor(pos[:, 0], pos[:, 2], radius)
    fz = tub_z(np.asarray(force_lab, float).reshape(-1, 3)[keep], th[snap[keep]])
    return np.bincount(snap[keep], fz, n_samples)


@dataclass
class FloorCycle:
    """The floor force over the cycle (module docstring): at the sampled phases k / P, its
    mean over the bed's weight and batch-means standard error and the samples behind each;
    the take-off phase (cycle fraction; NaN: none) of the mean and of each batch; the cycle
    mean over the weight; the weight (N)."""

    phase: np.ndarray
    force_over_weight: np.ndarray
    stderr: np.ndarray
    samples: np.ndarray
    take_off: float
    take_off_batches: list = field(default_factory=list)
    cycle_mean: float = math.nan
    cycle_mean_stderr: float = math.nan
    weight_N: float = math.nan

    def as_dict(self) -> dict:
        """The summary's "floor" block (JSON-ready apart from NaN: json_safe)."""
        return {
            "take_off_phase": self.take_off,
            "take_off_phase_batches": list(self.take_off_batches),
            "force_over_weight": self.force_over_weight.tolist(),
            "force_over_weight_stderr": self.stderr.tolist(),
            "phases": self.phase.tolist(),
            "cycle_mean_over_weight": self.cycle_mean,
            "cycle_mean_over_weight_stderr": self.cycle_mean_stderr,
            "weight_N": self.weight_N, "csv": FLOOR_CSV_NAME,
            "definition": (f"z component, tub axes, of the U wall's force on the bed within "
                           f"{FLOOR_DEG:g} degrees of its bottom, over the bed's weight, by "
                           "phase t f mod 1; take-off: where it first falls to "
                           f"{TAKE_OFF_LEVEL:g} of the weight after its maximum (cycle "
                           "fraction; null: never)"),
        }


def take_off_stderr(floor: dict) -> float:
    """The batch-means standard error (cycles) of a summary "floor" block's take-off, a phase:
    its batches' take-offs about the run's on the circle (stats.phase_stderr); NaN unless
    every batch leaves the floor (a batch that never does has no phase to average)."""
    b = floor.get("take_off_phase_batches") or []
    off = floor.get("take_off_phase")
    if (len(b) < 2 or not isinstance(off, (int, float))
            or any(not isinstance(v, (int, float)) or not math.isfinite(v) for v in b)):
        return math.nan
    return float(phase_stderr(np.asarray(b, dtype=float), float(off)))


def sampled_take_off(force_over_weight, per: int) -> float:
    """take_off_phase of a force sampled at the phases k / per (module docstring)."""
    return float(np.mod(take_off_phase(force_over_weight) - 0.5 / per, 1.0))


def floor_cycle(force_N, times, t_start: float, t_end: float, frequency: float, per: int,
                n_batches: int, weight_N: float) -> FloorCycle:
    """The FloorCycle of floor forces force_N (S,) (N) sampled at times (S,) (s, the tub's
    clock) over the window [t_start, t_end) of whole cycles at `frequency` (Hz), binned to the
    `per` phases k / per, n_batches batches of whole cycles, over the weight weight_N (N).
    Samples with a non-finite force are left out; without weight (no gravity) there is no
    ratio, and every phase is NaN."""
    with np.errstate(invalid="ignore", divide="ignore"):
        f = np.asarray(force_N, float) / float(weight_N)
    t = np.asarray(times, float)
    batch = batches_of_whole_cycles(t, t_start, t_end, frequency, n_batches)
    k = phase_bins(t, frequency, per)
    use = (batch >= 0) & np.isfinite(f)
    key = batch[use] * per + k[use]
    sums = np.bincount(key, f[use], n_batches * per).reshape(n_batches, per)
    cnt = np.bincount(key, minlength=n_batches * per).reshape(n_batches, per)
    with np.errstate(invalid="ignore", divide="ignore"):
        by_batch = sums / cnt                       # (batch, phase)
        mean = sums.sum(0) / cnt.sum(0)
        whole = sums.sum(1) / cnt.sum(1)            # each batch's cycle mean
    full = np.all(cnt > 0, axis=0)
    se = np.full(per, np.nan)
    if n_batches >= 2:
        se[full] = by_batch[:, full].std(axis=0, ddof=1) / math.sqrt(n_batches)
    cycle_se = (float(whole.std(ddof=1) / math.sqrt(n_batches))
                if n_batches >= 2 and np.all(np.isfinite(whole)) else math.nan)
    total = cnt.sum()
    return FloorCycle(
        phase=np.arange(per) / per, force_over_weight=mean, stderr=se, samples=cnt.sum(0),
        take_off=sampled_take_off(mean, per),
        take_off_batches=[sampled_take_off(b, per) for b in by_batch],
        cycle_mean=float(f[use].sum() / total) if total else math.nan,
        cycle_mean_stderr=cycle_se, weight_N=float(weight_N))


def write_floor_csv(path, cycle: FloorCycle) -> None:
    """floor.csv, atomically (FLOOR_COLUMNS): each sampled phase (cycle fraction t f mod 1),
    the floor force over the bed's weight there, its batch-means standard error and the
    samples behind it (empty where not measured)."""
    def num(v):
        return repr(float(v)) if np.isfinite(v) else ""

    lines = [",".join(FLOOR_COLUMNS)]
    for p, m, e, n in zip(cycle.phase, cycle.force_over_weight, cycle.stderr, cycle.samples):
        lines.append(f"{num(p)},{num(m)},{num(e)},{int(n)}")
    write_text_atomic(path, "\n".join(lines) + "\n")


def read_floor_csv(path) -> dict[str, np.ndarray]:
    """floor.csv's columns (FLOOR_COLUMNS) as arrays (NaN where empty)."""
    rows = [line.split(",") for line in open(path).read().splitlines()[1:] if line]
    cols = list(FLOOR_COLUMNS)
    return {c: np.array([float(r[i]) if r[i] else math.nan for r in rows])
            for i, c in enumerate(cols)}


def dem_floor_cycle(src, scenario, weight_N: float) -> FloorCycle | None:
    """The FloorCycle of a DEM run's dem.h5 (an open h5py File or a dict keyed like it:
    /snapshots/time, tub_pose, /wall_contacts with force_lab) over the scenario's averaging
    window and batches; None where the file holds no contacts' forces."""
    w = src.get("wall_contacts") if hasattr(src, "get") else None
    if w is None or "force_lab" not in w:
        return None
    times = np.asarray(src["snapshots/time"][()], float)
    theta = np.asarray(src["snapshots/tub_pose"][()], float)[:, 2]
    geo_radius = float(scenario.tub.radius)
    force = floor_force_of_contacts(w["snapshot"][()], w["wall"][()], w["position_tub"][()],
                                    w["force_lab"][()], theta, times.size, geo_radius)
    run = scenario.run
    return floor_cycle(force, times, run.duration - run.average_last, run.duration,
                       scenario.motion.frequency, int(run.phases_per_cycle), int(run.batches),
                       weight_N)


def weight_of(gravity, mass_kg: float) -> float:
    """The weight (N) of mass_kg (kg) under the gravity vector (m/s^2)."""
    return float(np.linalg.norm(np.asarray(gravity, float))) * float(mass_kg)


WALL_FEED_CSV_NAME = "wall_feed.csv"


def _region_key(name: str) -> str:
    return name.replace(" ", "_")


@dataclass
class WallFeedCycle:
    """The U wall's feed of fluctuation energy (W/m^2 of wall) by region (REGIONS) and over the
    whole U, its cycle mean and at each sampled phase k / P, each with its batch-means standard
    error (NaN where it cannot be estimated)."""

    phase: np.ndarray
    by_phase: np.ndarray          # (P, 3)
    by_phase_stderr: np.ndarray   # (P, 3)
    u_by_phase: np.ndarray        # (P,)
    u_by_phase_stderr: np.ndarray
    by_region: np.ndarray         # (3,)
    by_region_stderr: np.ndarray
    u_wall: float
    u_wall_stderr: float
    samples: np.ndarray           # (P,)

    def as_dict(self) -> dict:
        """The summary's "wall_feed" block (json_safe for NaN)."""
        return {
            "u_wall_W_m2": self.u_wall, "u_wall_W_m2_stderr": self.u_wall_stderr,
            "by_region_W_m2": {r: float(v) for r, v in zip(REGIONS, self.by_region)},
            "by_region_W_m2_stderr": {r: float(v) for r, v in
                                      zip(REGIONS, self.by_region_stderr)},
            "u_wall_by_phase_W_m2": self.u_by_phase.tolist(),
            "u_wall_by_phase_W_m2_stderr": self.u_by_phase_stderr.tolist(),
            "phases": self.phase.tolist(), "csv": WALL_FEED_CSV_NAME,
            "definition": ("the U wall's feed of fluctuation energy into the granular "
                           "temperature over the step ending at each sample (slip production "
                           "capped by the wall friction's power, plus the landing, less the "
                           "collision loss), by region of the U (floor: within "
                           f"{FLOOR_DEG:g} degrees of the bottom; arcs: to 90 degrees; side "
                           "walls) over the region's arc length, W/m^2 of wall"),
        }


def _se(by_batch, axis=0):
    """Batch-means standard error over `axis`, NaN unless every batch is finite (>= 2)."""
    a = np.asarray(by_batch, float)
    n = a.shape[axis]
    if n < 2:
        return np.full(np.delete(a.shape, axis), np.nan)
    se = a.std(axis=axis, ddof=1) / math.sqrt(n)
    return np.where(np.all(np.isfinite(a), axis=axis), se, np.nan)


def wall_feed_cycle(feed_W_m, times, t_start: float, t_end: float, frequency: float, per: int,
                    n_batches: int, lengths) -> WallFeedCycle:
    """The WallFeedCycle of per-sample feeds feed_W_m (S, 3) (W per metre of thickness, summed
    over each region of the U) sampled at times (S,) (s) over the window [t_start, t_end) at
    `frequency` (Hz), binned to the `per` phases k / per, n_batches batches of whole cycles,
    over the regions' arc lengths `lengths` (3,) m (region_lengths).  Samples with a
    non-finite feed are left out."""
    q = np.asarray(feed_W_m, float).reshape(-1, len(REGIONS))
    L = np.asarray(lengths, float)
    t = np.asarray(times, float)
    batch = batches_of_whole_cycles(t, t_start, t_end, frequency, n_batches)
    k = phase_bins(t, frequency, per)
    use = (batch >= 0) & np.all(np.isfinite(q), axis=1)
    key = batch[use] * per + k[use]
    cnt = np.bincount(key, minlength=n_batches * per).reshape(n_batches, per)
    sums = np.stack([np.bincount(key, q[use, r], n_batches * per) for r in range(len(REGIONS))],
                    axis=1).reshape(n_batches, per, len(REGIONS))
    with np.errstate(invalid="ignore", divide="ignore"):
        pb = sums / cnt[:, :, None] / L                           # (batch, phase, region)
        ub = sums.sum(2) / cnt / L.sum()                          # (batch, phase)
        rb = sums.sum(1) / cnt.sum(1)[:, None] / L                # (batch, region)
        wb = sums.sum((1, 2)) / cnt.sum(1) / L.sum()              # (batch,)
        n_all = cnt.sum(0)
        by_phase = sums.sum(0) / n_all[:, None] / L
        u_phase = sums.sum((0, 2)) / n_all / L.sum()
        by_region = sums.sum((0, 1)) / cnt.sum() / L
        u_wall = float(sums.sum() / cnt.sum() / L.sum())
    return WallFeedCycle(
        phase=np.arange(per) / per, by_phase=by_phase, by_phase_stderr=_se(pb),
        u_by_phase=u_phase, u_by_phase_stderr=_se(ub), by_region=by_region,
        by_region_stderr=_se(rb), u_wall=u_wall, u_wall_stderr=float(_se(wb)),
        samples=n_all)


def write_wall_feed_csv(path, cycle: WallFeedCycle) -> None:
    """wall_feed.csv, atomically: each sampled phase (cycle fraction t f mod 1), the feed of
    each region of the U and of the whole U (W/m^2 of wall) with their batch-means standard
    errors, and the samples behind them (empty where not measured or not known)."""
    def num(v):
        return repr(float(v)) if np.isfinite(v) else ""

    head = ["phase"]
    for r in REGIONS:
        head += [f"{_region_key(r)}_W_m2", f"{_region_key(r)}_W_m2_stderr"]
    head += ["u_wall_W_m2", "u_wall_W_m2_stderr", "samples"]
    lines = [",".join(head)]
    for i, p in enumerate(cycle.phase):
        row = [num(p)]
        for r in range(len(REGIONS)):
            row += [num(cycle.by_phase[i, r]), num(cycle.by_phase_stderr[i, r])]
        n = cycle.samples[i]
        row += [num(cycle.u_by_phase[i]), num(cycle.u_by_phase_stderr[i]),
                str(int(n)) if np.isfinite(n) else ""]
        lines.append(",".join(row))
    write_text_atomic(path, "\n".join(lines) + "\n")


def dem_wall_feed(table, radius: float) -> dict:
    """The DEM's U wall fluctuation flux F . (v - V) (W/m^2) by region (REGIONS) from a
    calibration's [kinetic.wall_flux] table (io.calibration_file; its arc bins summed into the
    regions by arc length, the bins' errors in quadrature): "by_region_W_m2" and its
    "_stderr", and "by_phase_W_m2" (P, 3) with its "_stderr", the U's "u_wall_W_m2" (with
    "_stderr") and "u_wall_by_phase_W_m2"."""
    edges = np.asarray(table.arc_edges_m, float)
    dl = np.diff(edges)
    reg = region_of(0.5 * (edges[1:] + edges[:-1]), radius)
    arc = np.asarray(table.u_fluctuation_flux_by_arc_W_m2, float)
    arc_se = np.asarray(table.u_fluctuation_flux_by_arc_stderr_W_m2, float)
    pa = np.asarray(table.u_fluctuation_flux_by_phase_arc_W_m2, float)
    pa_se = np.asarray(table.u_fluctuation_flux_by_phase_arc_stderr_W_m2, float)
    out, out_se, ph, ph_se = [], [], [], []
    for r in range(len(REGIONS)):
        m = reg == r
        L = dl[m].sum() if m.any() else math.nan   # a region no bin covers: NaN
        out.append((arc[m] * dl[m]).sum() / L)
        out_se.append(math.sqrt(((arc_se[m] * dl[m]) ** 2).sum()) / L)
        ph.append((pa[:, m] * dl[m]).sum(1) / L)
        ph_se.append(np.sqrt(((pa_se[:, m] * dl[m]) ** 2).sum(1)) / L)
    return {"by_region_W_m2": np.array(out), "by_region_W_m2_stderr": np.array(out_se),
            "by_phase_W_m2": np.array(ph).T, "by_phase_W_m2_stderr": np.array(ph_se).T,
            "u_wall_W_m2": float(table.u_fluctuation_flux_W_m2),
            "u_wall_W_m2_stderr": float(table.u_fluctuation_flux_stderr_W_m2),
            "u_wall_by_phase_W_m2": np.asarray(table.u_fluctuation_flux_by_phase_W_m2, float)}


def dem_wall_feed_cycle(table, radius: float) -> WallFeedCycle:
    """The WallFeedCycle of a DEM run's calibration [kinetic.wall_flux] table (dem_wall_feed:
    the U's fluctuation flux F . (v - V) summed into the regions), at its phase bins
    (phase_rad / 2 pi; k / P where the table gives none); its samples not known (NaN)."""
    d = dem_wall_feed(table, radius)
    per = d["by_phase_W_m2"].shape[0]
    ph = getattr(table, "phase_rad", None)
    phase = (np.mod(np.asarray(ph, float) / (2 * math.pi), 1.0) if ph is not None
             and len(ph) == per else np.arange(per) / per)
    u_se = getattr(table, "u_fluctuation_flux_by_phase_stderr_W_m2", None)
    return WallFeedCycle(
        phase=phase, by_phase=d["by_phase_W_m2"], by_phase_stderr=d["by_phase_W_m2_stderr"],
        u_by_phase=d["u_wall_by_phase_W_m2"],
        u_by_phase_stderr=(np.asarray(u_se, float) if u_se is not None
                           else np.full(per, np.nan)),
        by_region=d["by_region_W_m2"], by_region_stderr=d["by_region_W_m2_stderr"],
        u_wall=d["u_wall_W_m2"], u_wall_stderr=d["u_wall_W_m2_stderr"],
        samples=np.full(per, np.nan))
