"""The energy the tub wall and the partitions put into the balls, from the DEM's wall contacts
sampled at the snapshots (dem.h5 /wall_contacts: the wall's force on the ball, its contact point
and arc position; /snapshots: the balls' velocities and the tub's pose).

Per contact, with F the wall's force on the ball and v the ball's centre velocity relative to
the wall (the tub frame, tub axes; every wall moves with the tub):

* power F . v (W): the rate the contact changes the ball's translational kinetic energy in the
  wall's frame; over a collision its integral is the energy the contact takes (dissipation);
* fluctuation power F . (v - V), V the coarse-grained velocity at the ball's centre at the
  snapshot's phase: what the contact gives the fluctuation energy, i.e. the flux of Johnson &
  Jackson's (1987, J. Fluid Mech. 176, 67) wall condition, slip work minus collisional loss
  (F . v = F . V + F . (v - V), and -F . V is the slip work the mean flow loses to the wall);
* drive power F . v_wall (lab frame): the work of the vibrating wall on the balls, which over a
  steady cycle equals everything the bed dissipates.

A flux (W/m^2) is the sum of a power over the contacts of a set of snapshots, divided by the
number of snapshots and by the wall area: an arc bin of the U times the tub's length L, or, for
the partitions, the two faces' area of the bed, 2 A_bed.  Fluxes are given by arc bin and phase
bin, by arc (the cycle mean), by phase (over the whole U) and over the whole U, each with its
batch-means standard error (batches of whole cycles).
"""
from __future__ import annotations

import numpy as np

from vibroflow.dem.walls import WALL_PARTITION_HI, WALL_PARTITION_LO, WALL_U
from vibroflow.errors import InputError
from vibroflow.measure.stats import phase_bins, stderr_of_batches
from vibroflow.tub.geometry import geometry_of
from vibroflow.tub.motion import rigid_velocity, tub_to_lab

from .dem_result import DEMResult


def _flux(power, snap, sel_contact, bins, n_bins, snap_phase, snap_batch, n_phases, n_batches):
    """Sums of `power` by (batch, phase, bin) over the contacts `sel_contact`, and the
    snapshot counts by (batch, phase)."""
    b = snap_batch[snap[sel_contact]]
    ph = snap_phase[snap[sel_contact]]
    key = (b * n_phases + ph) * n_bins + bins[sel_contact]
    s = np.bincount(key, weights=power[sel_contact], minlength=n_batches * n_phases * n_bins)
    used = snap_batch >= 0
    cnt = np.bincount(snap_batch[used] * n_phases + snap_phase[used],
                      minlength=n_batches * n_phases).astype(float)
    return s.reshape(n_batches, n_phases, n_bins), cnt.reshape(n_batches, n_phases)


def _table(sums, counts, area):
    """Fluxes (W/m^2) and batch-means errors from power sums (batch, phase, bin), snapshot
    counts (batch, phase) and bin areas (bin,) (m^2)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        def f(s, c, a):
            return s / c / a
        nb_ = sums.shape[0]
        out = {
            "phase_arc": f(sums.sum(0), counts.sum(0)[:, None], area),
            "phase_arc_stderr": stderr_of_batches(f(sums, counts[:, :, None], area)),
            "arc": f(sums.sum((0, 1)), counts.sum(), area),
            "arc_stderr": stderr_of_batches(f(sums.sum(1), counts.sum(1)[:, None], area)),
            "phase": f(sums.sum((0, 2)), counts.sum(0), area.sum()),
            "phase_stderr": stderr_of_batches(f(sums.sum(2), counts, area.sum())),
            "mean": float(f(sums.sum(), counts.sum(), area.sum())),
            "mean_stderr": (float(stderr_of_batches(f(sums.sum((1, 2)), counts.sum(1),
                                                       area.sum()))) if nb_ >= 2
                            else float("nan")),
        }
    return out


def wall_flux_of_contacts(force, velocity, snapshot, arc, wall, snapshot_phase, snapshot_batch,
                          n_phases: int, n_batches: int, arc_edges, length: float,
                          partition_area: float, mean_velocity=None, wall_velocity=None
                          ) -> dict:
    """Wall fluxes of a set of sampled contacts (see the module notes).

    force : (C, 3) the wall's force on the ball (N); velocity : (C, 3) the ball's centre
    velocity relative to the wall (m/s), both in one set of axes; snapshot : (C,) snapshot of
    each contact; arc : (C,) arc position on the U (m; ignored off the U); wall : (C,) wall slot
    (vibroflow.dem.walls); snapshot_phase, snapshot_batch : (S,) phase bin and batch (-1: not
    used) of each snapshot; arc_edges (m); length : the tub's length L (m); partition_area :
    the area of the partitions the bed wets (m^2); mean_velocity : (C, 3) the coarse-grained
    velocity at the ball (for the fluctuation power), wall_velocity : (C, 3) the wall's lab
    velocity with the force in lab axes (for the drive power).

    Returns {"u": {name: table}, "partitions": {name: table}} for name in `power`,
    `fluctuation_power`, `drive_power` (those computable), each table with phase_arc (phase,
    arc bin), arc, phase and mean fluxes (W/m^2) and their *_stderr.
    """
    F = np.asarray(force, float).reshape(-1, 3)
    v = np.asarray(velocity, float).reshape(-1, 3)
    snap = np.asarray(snapshot, np.int64).ravel()
    wall = np.asarray(wall, np.int64).ravel()
    arc = np.asarray(arc, float).ravel()
    sph = np.asarray(snapshot_phase, np.int64).ravel()
    sb = np.asarray(snapshot_batch, np.int64).ravel()
    edges = np.asarray(arc_edges, float).ravel()
    c = F.shape[0]
    if not (v.shape[0] == snap.size == wall.size == arc.size == c):
        raise InputError(f"force, velocity, snapshot, wall, arc have {c}, {v.shape[0]}, "
                         f"{snap.size}, {wall.size}, {arc.size} rows: must have one per contact")
    if sph.size != sb.size or (c and (snap.min() < 0 or snap.max() >= sb.size)):
        raise InputError(f"snapshot: must index the {sb.size} snapshots of snapshot_phase and "
                         "snapshot_batch")
    if edges.size < 2 or np.any(np.diff(edges) <= 0):
        raise InputError(f"arc_edges = {edges!r}: must be at least two increasing arc "
                         "positions (m)")
    if not (length > 0 and partition_area > 0):
        raise InputError(f"length = {length!r}, partition_area = {partition_area!r}: must be "
                         "> 0 (m, m^2)")
    if int(n_phases) < 1 or int(n_batches) < 1 or (sb >= n_batches).any() or \
            (sph >= n_phases).any() or (sph < 0).any():
        raise InputError(f"n_phases = {n_phases!r}, n_batches = {n_batches!r}: must be >= 1 "
                         "and hold every snapshot's phase bin and batch")
    powers = {"power": np.einsum("ij,ij->i", F, v)}
    if mean_velocity is not None:
        V = np.asarray(mean_velocity, float).reshape(-1, 3)
        powers["fluctuation_power"] = np.einsum("ij,ij->i", F, v - V)
    if wall_velocity is not None:
        powers["drive_power"] = np.einsum("ij,ij->i", F, np.asarray(wall_velocity,
                                                                    float).reshape(-1, 3))
    n_arc = edges.size - 1
    j = np.searchsorted(edges, arc, side="right") - 1
    in_batch = (sb[snap] >= 0) if c else np.zeros(0, bool)
    on_u = (wall == WALL_U) & np.isfinite(arc) & (j >= 0) & (j < n_arc) & in_batch
    on_p = ((wall == WALL_PARTITION_LO) | (wall == WALL_PARTITION_HI)) & in_batch
    j = np.clip(j, 0, n_arc - 1)
    zero = np.zeros(c, np.int64)
    area_u = np.diff(edges) * float(length)
    out = {"u": {}, "partitions": {}}
    for name, pw in powers.items():
        pw = np.where(np.isfinite(pw), pw, 0.0)
        s, n = _flux(pw, snap, on_u, j, n_arc, sph, sb, int(n_phases), int(n_batches))
        out["u"][name] = _table(s, n, area_u)
        s, n = _flux(pw, snap, on_p, zero, 1, sph, sb, int(n_phases), int(n_batches))
        out["partitions"][name] = _table(s, n, np.array([float(partition_area)]))
    return out


def wall_flux(run, phase_fields, arc_bins: int | None = None) -> dict | None:
    """Wall fluxes of a DEM run (a DEMResult, a run directory or a dem.h5): the wall contacts
    of the averaging window's snapshots with the balls' velocities relative to the tub;
    phase_fields (run_fields' phase-resolved Dataset) gives the mean velocity for the
    fluctuation power and the bed's area for the partitions'.  None when the run has no stored
    wall forces or no wall contact in the window (then F . v cannot be formed)."""
    own = not isinstance(run, DEMResult)
    res = DEMResult.open(run) if own else run
    try:
        if not res.has_wall_forces:
            return None
        return _run_flux(res, phase_fields, arc_bins)
    finally:
        if own:
            res.close()


def _run_flux(res: DEMResult, pf, arc_bins):
    sc = res.scenario
    geometry = geometry_of(sc)
    L = float(sc.tub.length)
    n_ph = int(pf.sizes["phase"])
    sb = res.batches()
    sph = phase_bins(res.times, float(sc.motion.frequency), n_ph)
    used = np.nonzero(sb >= 0)[0]
    arc_len = geometry.wall_arc_length()
    n_arc = int(arc_bins) if arc_bins else max(1, int(np.ceil(arc_len / sc.analysis.cell_size)))
    edges = np.linspace(-0.5 * arc_len, 0.5 * arc_len, n_arc + 1)
    x = np.asarray(pf["x"].values, float)
    z = np.asarray(pf["z"].values, float)
    Vf = np.nan_to_num(np.asarray(pf["velocity"].values, float))   # (phase, x, z, 3)
    rho = np.asarray(pf["density"].values, float)
    hx = float(x[1] - x[0])
    rows = {k: [] for k in ("F", "F_lab", "v", "V", "vw", "snap", "wall")}
    f = res.file
    for s, snap in res.iter_snapshots(used):
        if "wall_particle" not in snap:
            continue
        i = snap["wall_particle"]
        X, Z, th, Xd, Zd, thd = (float(q) for q in snap["pose"])
        pv = res.pivot
        F_tub = snap["wall_force"]
        v = snap["velocities_rel_tub"][i]
        p = snap["wall_point"]
        # the wall's lab velocity at the contact point, and the force back in lab axes
        lx, lz = tub_to_lab(p[:, 0], p[:, 2], X, Z, th, pv[0], pv[1])
        vwx, vwz = rigid_velocity(lx, lz, X, Z, Xd, Zd, thd, pv[0], pv[1])
        co, si = np.cos(th), np.sin(th)
        F_lab = np.stack([co * F_tub[:, 0] - si * F_tub[:, 2], F_tub[:, 1],
                          si * F_tub[:, 0] + co * F_tub[:, 2]], axis=1)
        rows["F"].append(F_tub)
        rows["v"].append(v)
        rows["vw"].append(np.stack([vwx, np.zeros_like(vwx), vwz], axis=1))
        rows["F_lab"].append(F_lab)
        rows["snap"].append(np.full(i.size, s))
        rows["wall"].append(snap["wall_kind"])
        c = snap["positions_tub"][i]
        ia = np.clip(np.floor((c[:, 0] - x[0]) / hx + 0.5).astype(np.int64), 0, x.size - 1)
        ib = np.clip(np.floor((c[:, 2] - z[0]) / hx + 0.5).astype(np.int64), 0, z.size - 1)
        rows["V"].append(Vf[sph[s], ia, ib])
    # the file's rows are in snapshot order, as iter_snapshots hands them out
    arc = f["wall_contacts/arc"][()].astype(float)[np.isin(f["wall_contacts/snapshot"][()],
                                                          used)]
    cat = {k: np.concatenate(v) for k, v in rows.items() if v}
    if "F" not in cat:
        return None
    # the bed's cross-section: the balls' mass over (L rho_bed), rho_bed the mass-weighted
    # mean density of the phase-resolved cells
    w = np.nansum(rho, axis=(1, 2))
    rho_bed = np.nanmean(np.nansum(rho * rho, axis=(1, 2)) / np.where(w > 0, w, np.nan))
    A_bed = float(res.mass.sum() / (L * rho_bed))
    out = wall_flux_of_contacts(
        cat["F"], cat["v"], cat["snap"], arc, cat["wall"], sph, sb, n_ph, int(sc.run.batches),
        edges, L, 2.0 * A_bed, mean_velocity=cat["V"])
    drive = wall_flux_of_contacts(
        cat["F_lab"], cat["vw"], cat["snap"], arc, cat["wall"], sph, sb, n_ph,
        int(sc.run.batches), edges, L, 2.0 * A_bed)
    for part in ("u", "partitions"):
        out[part]["drive_power"] = drive[part]["power"]
    out.update(arc_edges_m=edges, phase_rad=2.0 * np.pi * np.arange(n_ph) / n_ph,
               length_m=L, partition_area_m2=2.0 * A_bed)
    return out
