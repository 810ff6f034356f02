"""The effective Coulomb friction of the tub wall and of the partitions, for the continuum, from
the DEM's ball-wall contacts (tub47.md "Wall contacts"; docs/decisions/wall-friction.md).

What is measured (contacts sampled at the snapshots of the averaging window, F_n > 0):
* the distribution of |F_t| / F_n, its mean, the ratio of sums sum|F_t| / sum F_n and the
  fraction of contacts at the Coulomb limit (sliding) against those below it (rolling or
  sticking), with batch-means standard errors (vibroflow.measure.contacts);
* the same along the U wall (arc position s from the bottom, + towards +x), and, where the
  contact forces are stored, the *mobilised* friction along the wall: the signed tangential
  force along the profile, sum F_s / sum F_n, whose sign says which way the bed drags the wall;
* the coherent friction of slipping patches: for each snapshot and each arc bin whose contacts
  mostly slide, |sum F_t| / sum F_n with the tangential forces summed as vectors, averaged with
  the normal force as weight.

The choice for the continuum, and why
-------------------------------------
The continuum's wall is a Coulomb contact (constant normal stiffness, friction mu_w): where the
bed slips along the wall its tangential traction is mu_w times its normal traction.  A traction
is a force per area, so the coefficient that gives the continuum the DEM's friction *force* for
the DEM's normal *load* is the force-weighted one, the ratio of sums sum|F_t| / sum F_n; the mean
of the ratios would weight a lightly touching ball (which carries almost no force) as much as a
loaded one, and it is biased upwards by contacts whose F_n is passing through zero.  The
continuum resolves the vibration cycle, so the coefficient must describe the instantaneous
contact, not the cycle average: that is why the magnitudes are summed (a cycle-averaged vector
sum would cancel the back-and-forth slip of the vibration).  This is the "ratio of tangential to
normal contact force" of the published study.  The coherent friction of slipping patches (lower:
the tangential forces of neighbouring balls are not all aligned) is reported beside it as the
bound to which a continuum wall should be expected to converge if the DEM bed slipped as a block.

The partitions (glass) are reduced the same way; the 2D continuum takes their friction as a
depth-averaged body force -2 mu_p p / L_y along the velocity (Jop, Forterre & Pouliquen 2005).
That body force acts along the mean flow, where each ball's tangential force opposes its own
slip, mean flow plus fluctuation and spin: the partitions' friction *along the mean flow*,
sum(-F_t . u / |u|) / sum F_n with u the mean velocity (relative to the tub, tub axes) of the
15 mm analysis cell holding the ball at that snapshot (`friction_along_flow`), is the part of
the ratio of sums the mean flow feels (tub47-quick: 0.10 against 0.14; docs/validation.md
section 22).  The continuum takes it with `--partition-friction along-flow`.
"""
from __future__ import annotations

import numpy as np

from vibroflow.measure.contacts import wall_contact_stats
from vibroflow.measure.stats import batch_means
from vibroflow.tub.geometry import geometry_of
from vibroflow.scenario.checks import find_contact
from vibroflow.dem.walls import WALL_PARTITION_HI, WALL_PARTITION_LO, WALL_U

from .dem_result import DEMResult

SLIPPING_PATCH = 0.5  # a (snapshot, arc bin) patch slips when at least half its contacts slide


def wall_normal_tangent(x, z, radius: float):
    """Inward unit normal (nx, nz) and unit tangent (tx, tz) of the U profile at wall points
    (x, z) of the tub frame (m); the tangent points along increasing arc (from the left rim
    through the bottom to the right rim), t = (n_z, -n_x)."""
    x = np.asarray(x, dtype=float)
    z = np.asarray(z, dtype=float)
    on_circle = z <= radius
    dx, dz = -x, radius - z
    rho = np.hypot(dx, dz)
    rho = np.where(rho > 0, rho, 1.0)
    nx = np.where(on_circle, dx / rho, -np.sign(np.where(x == 0, 1.0, x)))
    nz = np.where(on_circle, dz / rho, 0.0)
    return nx, nz, nz, -nx


def wall_friction(run, arc_bins: int | None = None, histogram_bins: int = 40) -> dict:
    """Wall and partition friction of a DEM run (a DEMResult, a run directory or a dem.h5).

    Returns a dict:
      tub_wall: {count, mean_ft_over_fn, ratio_of_sums, sliding_fraction, rolling_or_sticking
        _fraction, *_stderr, contact_friction (the pair's mu), coherent_slip_friction(_stderr),
        effective_friction, effective_friction_stderr, choice}
      partitions: the same keys (None when the tub is periodic)
      profile: {arc_edges_m, count, mean_ft_over_fn, sliding_fraction, ratio_of_sums,
        mobilised_friction} along the U (NaN in empty bins)
      histogram: {edges, counts_wall, counts_partitions} of |F_t| / F_n
    """
    own = not isinstance(run, DEMResult)
    res = DEMResult.open(run) if own else run
    try:
        return _wall_friction(res, arc_bins, histogram_bins)
    finally:
        if own:
            res.close()


def _pair_friction(scenario, a: str, b: str) -> float:
    """The contact friction of materials a and b (NaN when the scenario has no such pair)."""
    pair = find_contact(scenario, a, b)
    return float("nan") if pair is None else float(pair.friction)


def _wall_friction(res: DEMResult, arc_bins, histogram_bins) -> dict:
    sc = res.scenario
    f = res.file
    geometry = geometry_of(sc)
    nb = int(sc.run.batches)
    snap_batch = res.batches()
    if not res.has("wall_contacts/snapshot"):
        empty = np.zeros(0)
        cols = {"snapshot": empty.astype(np.int64), "wall": empty.astype(np.int64),
                "fn": empty, "ft": empty, "sliding": empty.astype(bool), "arc": empty,
                "position_tub": np.zeros((0, 3))}
    else:
        cols = {k: f[f"wall_contacts/{k}"][()] for k in
                ("snapshot", "wall", "fn", "ft", "sliding", "arc", "position_tub")}
    snap = cols["snapshot"].astype(np.int64)
    batch = np.where((snap >= 0) & (snap < snap_batch.size),
                     snap_batch[np.clip(snap, 0, max(snap_batch.size - 1, 0))], -1)
    wall = cols["wall"].astype(np.int64)
    fn = cols["fn"].astype(float)
    ft = cols["ft"].astype(float)
    sliding = cols["sliding"].astype(bool)
    L = geometry.wall_arc_length()
    n_arc = int(arc_bins) if arc_bins else max(1, int(np.ceil(L / sc.analysis.cell_size)))
    arc_edges = np.linspace(-0.5 * L, 0.5 * L, n_arc + 1)
    on_u = wall == WALL_U
    on_p = (wall == WALL_PARTITION_LO) | (wall == WALL_PARTITION_HI)
    use = (fn > 0) & (batch >= 0)
    ratio_top = 1.0
    if use.any():
        ratio_top = max(1e-3, float(np.nanmax(ft[use] / fn[use])))
    hist_edges = np.linspace(0.0, ratio_top * (1 + 1e-9), histogram_bins + 1)
    stats_u = wall_contact_stats(fn[on_u], ft[on_u], sliding[on_u], arc=cols["arc"][on_u],
                                 batch=batch[on_u], n_batches=nb, histogram_edges=hist_edges,
                                 arc_edges=arc_edges)
    mats = (sc.fill.material, sc.tub.wall_material, sc.tub.partition_material)
    out_u = _reduce(stats_u, _pair_friction(sc, mats[0], mats[1]))
    profile = {"arc_edges_m": arc_edges, "count": stats_u.arc_count,
               "mean_ft_over_fn": stats_u.arc_mean_ft_over_fn,
               "sliding_fraction": stats_u.arc_sliding_fraction}
    # ratio of sums by arc bin
    s = cols["arc"].astype(float)
    sel = on_u & use & np.isfinite(s)
    j = np.clip(np.searchsorted(arc_edges, s[sel], side="right") - 1, 0, n_arc - 1)
    sfn = np.bincount(j, weights=fn[sel], minlength=n_arc)
    sft = np.bincount(j, weights=ft[sel], minlength=n_arc)
    with np.errstate(invalid="ignore", divide="ignore"):
        profile["ratio_of_sums"] = np.where(sfn > 0, sft / sfn, np.nan)
    coherent = coherent_se = float("nan")
    if res.has_wall_forces and sel.any():
        # forces in tub axes: turn each lab force by its snapshot's -theta
        theta = f["snapshots/tub_pose"][()][:, 2]
        F = f["wall_contacts/force_lab"][()].astype(float)[sel]
        th = theta[snap[sel]]
        c, si = np.cos(th), np.sin(th)
        Fx = c * F[:, 0] + si * F[:, 2]
        Fz = -si * F[:, 0] + c * F[:, 2]
        Fy = F[:, 1]
        p = cols["position_tub"][sel].astype(float)
        nx, nz, tx, tz = wall_normal_tangent(p[:, 0], p[:, 2], geometry.radius)
        Fn = Fx * nx + Fz * nz
        Fs = Fx * tx + Fz * tz
        mob = np.bincount(j, weights=Fs, minlength=n_arc)
        with np.errstate(invalid="ignore", divide="ignore"):
            profile["mobilised_friction"] = np.where(sfn > 0, mob / sfn, np.nan)
        # coherent friction of slipping patches: group by (snapshot, arc bin)
        key = snap[sel] * n_arc + j
        uk, inv = np.unique(key, return_inverse=True)
        g_fn = np.bincount(inv, weights=Fn)
        g_fs = np.bincount(inv, weights=Fs)
        g_fy = np.bincount(inv, weights=Fy)
        g_sl = np.bincount(inv, weights=sliding[sel].astype(float)) / np.bincount(inv)
        g_b = snap_batch[uk // n_arc]
        ok = (g_sl >= SLIPPING_PATCH) & (g_fn > 0)
        if ok.any():
            mu_patch = np.hypot(g_fs[ok], g_fy[ok]) / g_fn[ok]
            coherent, coherent_se = batch_means(mu_patch, g_b[ok], nb, weights=g_fn[ok])
    else:
        profile["mobilised_friction"] = np.full(n_arc, np.nan)
    out_u["coherent_slip_friction"] = float(coherent)
    out_u["coherent_slip_friction_stderr"] = float(coherent_se)
    partitions = None
    hist_p = np.zeros(histogram_bins, dtype=np.int64)
    if not sc.tub.periodic:
        stats_p = wall_contact_stats(fn[on_p], ft[on_p], sliding[on_p], batch=batch[on_p],
                                     n_batches=nb, histogram_edges=hist_edges)
        partitions = _reduce(stats_p, _pair_friction(sc, mats[0], mats[2]))
        partitions["friction_along_flow"], partitions["friction_along_flow_stderr"] = \
            partition_friction_along_flow(res, snap, wall, fn, batch, nb)
        hist_p = stats_p.histogram_counts
    return {"tub_wall": out_u, "partitions": partitions, "profile": profile,
            "histogram": {"edges": hist_edges, "counts_wall": stats_u.histogram_counts,
                          "counts_partitions": hist_p}}


def along_flow(ft_x, ft_z, u_x, u_z):
    """The tangential force (ft_x, ft_z) (N) against the mean flow (u_x, u_z) (m/s):
    -F_t . u / |u| (N), zero where the flow is at rest."""
    ft_x, ft_z, u_x, u_z = (np.asarray(a, float) for a in (ft_x, ft_z, u_x, u_z))
    speed = np.hypot(u_x, u_z)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(speed > 0, -(ft_x * u_x + ft_z * u_z) / speed, 0.0)


def cell_mean_velocity(x, z, vx, vz, cell: float):
    """Each ball's cell's mean velocity (m/s): the balls at (x, z) (m) binned on square cells
    of side `cell` (m) centred on multiples of it (tub47.md's bulk velocity cells)."""
    ix = np.floor(np.asarray(x, float) / cell + 0.5).astype(np.int64)
    iz = np.floor(np.asarray(z, float) / cell + 0.5).astype(np.int64)
    _, inv = np.unique(np.stack([ix, iz], axis=1), axis=0, return_inverse=True)
    inv = inv.ravel()
    n = np.bincount(inv)
    return (np.bincount(inv, np.asarray(vx, float)) / n)[inv], \
        (np.bincount(inv, np.asarray(vz, float)) / n)[inv]


def partition_friction_along_flow(res: DEMResult, snap, wall, fn, batch, nb: int):
    """(mean, standard error) of the partitions' friction along the mean flow, sum(-F_t . u /
    |u|) / sum F_n over the partition contacts (module docstring); NaN without the contacts'
    force vectors or the snapshots' velocities."""
    f = res.file
    on_p = ((wall == WALL_PARTITION_LO) | (wall == WALL_PARTITION_HI)) & (fn > 0) & (batch >= 0)
    if not (res.has_wall_forces and res.has("snapshots/velocity") and on_p.any()):
        return float("nan"), float("nan")
    from vibroflow.tub.motion import lab_to_tub_np, relative_velocity_tub_axes_np

    cell = float(res.scenario.analysis.cell_size)
    pose = f["snapshots/tub_pose"][()]
    ball = f["wall_contacts/particle"][()].astype(np.int64)
    F = f["wall_contacts/force_lab"][()].astype(float)
    along = np.zeros(snap.size)
    rows_p = np.nonzero(on_p)[0]
    for i in np.unique(snap[rows_p]):
        X, Z, th, Xd, Zd, thd = pose[i]
        pos, vel = f["snapshots/position"][i], f["snapshots/velocity"][i]
        x = lab_to_tub_np(pos, X, Z, th)
        v = relative_velocity_tub_axes_np(pos, vel, X, Z, th, Xd, Zd, thd)
        ux, uz = cell_mean_velocity(x[:, 0], x[:, 2], v[:, 0], v[:, 2], cell)
        rows = rows_p[snap[rows_p] == i]
        b = ball[rows]
        c, si = np.cos(th), np.sin(th)
        along[rows] = along_flow(c * F[rows, 0] + si * F[rows, 2],
                                 -si * F[rows, 0] + c * F[rows, 2], ux[b], uz[b])
    mean, se = batch_means(along[rows_p] / fn[rows_p], batch[rows_p], nb, weights=fn[rows_p])
    return float(mean), float(se)


def _reduce(stats, contact_mu: float) -> dict:
    d = stats.as_dict()
    d["rolling_or_sticking_fraction"] = 1.0 - d["sliding_fraction"] if d["count"] else np.nan
    d["contact_friction"] = contact_mu
    d["effective_friction"] = d["ratio_of_sums"]
    d["effective_friction_stderr"] = d["ratio_of_sums_stderr"]
    d["choice"] = ("ratio of sums sum|F_t|/sum F_n over the contacts at the sampled instants "
                   "(force-weighted, instantaneous; see vibroflow.calibration.wall_friction)")
    return d
