"""The bed's force balance by phase of the cycle: what the tub wall and the partitions exert on
the bed, DEM against the continuum formulations (docs/validation.md).

    python benchmarks/force_balance.py --dem-dir runs/study-quick/dem [--calibration FILE]
        [--methods lagrangian,eulerian] [--skip-cycles 20] [--cycles 40] [--set NAME=VALUE ...]

Averaged over a cycle, the vertical forces on the bed balance its weight (the tub's mean
acceleration is zero): the U wall's upward push plus the partitions' friction equals m g.  How
the two share it, and when in the cycle each acts, is what drives the bed (a vibratory
conveyor's ratchet is friction that acts harder in one half-cycle than in the other).  This
script prints, for each of the phases_per_cycle sampled phases, in the tub's axes (N over the
slice between the partitions, the DEM's unit):

* the U wall's normal force in five regions (the vertical side walls above z = 0.15 m, right
  and left; the arc of the half circle beyond 30 degrees from the bottom, right and left; the
  floor within 30 degrees of it) and its total vertical component;
* the partitions' total vertical force (their friction: their normal force is horizontal), and
  their total normal force (both partitions; the continuum's is the 2 p V_p over its points
  that its friction is taken from, boundary.partition_forces).

DEM: every ball-wall contact sampled in DIR/dem.h5 (wall_contacts: force in the lab frame,
rotated into the tub's axes with the tub's angle at its snapshot).  Continuum: a run of the same
scenario and calibration, from the bed that vibroflow.continuum.tub_run.run_continuum starts
vibrating with each formulation (tub_run.vibration_start), advanced one sampling
interval at a time from the start of the vibration; after --skip-cycles cycles, at every
sample, the U wall's force on each point (the penalty law's last force, boundary.UWall's
history) or wall-layer cell (eulerian.wall: fn along the cell's inward normal n, ft along
(n_z, -n_x)) and the partitions' friction
(boundary.partition_forces on the state) over the next --cycles cycles.

And the bed's state by phase, the same measures for both codes: its mass-weighted mean
velocity relative to the tub (vx, vz, mm/s, tub axes), its centre of mass's height (mm, from
its cycle mean), and its internal virial P V = sum_contacts f . b / 3 (J; the DEM's ball-ball
contacts at the snapshot, f the force on i by j and b the branch vector r_i - r_j; the
continuum's sum of p V over its points or cells): the bed's mean pressure times its volume,
which tells when in the cycle the bed is loaded and how fast it unloads.

--set NAME=VALUE changes the calibration (`section.key`, e.g. partitions.friction=0.05) or an
options field (`opt.NAME`, e.g. opt.cfl=0.3) for the continuum.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

#: region bounds: the side walls start at the U's centre height; the floor is the arc within
#: FLOOR_DEG of the bottom
FLOOR_DEG = 30.0
REGIONS = ("R-wall", "R-arc", "floor", "L-arc", "L-wall")
#: the bed's state by phase (module docstring)
BED = ("bed vx mm/s", "bed vz mm/s", "bed z_cm mm", "bed P V (J)")


def regions_of(x, z, radius):
    """Region index (REGIONS) of wall-contact points at tub-frame (x, z) (m) of a U of
    `radius` (m) whose half circle is centred at (0, radius)."""
    angle = np.degrees(np.arctan2(x, radius - z))  # 0 at the bottom, +90 at the right wall
    out = np.where(angle > FLOOR_DEG, 1, np.where(angle < -FLOOR_DEG, 3, 2))
    side = z > radius
    out = np.where(side & (x > 0), 0, out)
    return np.where(side & (x <= 0), 4, out)


def by_phase(values, phase_index, per, n_samples_by_phase):
    """Sum of `values` per phase index, over the number of samples at that phase: the mean
    total per sample (per,)."""
    tot = np.bincount(phase_index, weights=values, minlength=per)
    return tot / np.maximum(n_samples_by_phase, 1)


def dem_balance(dem_dir: Path, per: int, radius: float) -> dict:
    """{name: (per,) mean total per sample} of the DEM run's sampled wall contacts."""
    import h5py

    from vibroflow.dem.walls import WALL_U

    with h5py.File(dem_dir / "dem.h5", "r") as h:
        phase = h["snapshots/phase"][:]
        theta = h["snapshots/tub_pose"][:, 2]
        w = h["wall_contacts"]
        snap = w["snapshot"][:]
        wall = w["wall"][:]
        pos = w["position_tub"][:].astype(float)
        fn = w["fn"][:].astype(float)
        f_lab = w["force_lab"][:].astype(float)
    k_snap = np.rint(phase * per).astype(np.int64) % per
    n_by_phase = np.bincount(k_snap, minlength=per)
    k = k_snap[snap]
    th = theta[snap]
    fz_tub = -np.sin(th) * f_lab[:, 0] + np.cos(th) * f_lab[:, 2]
    u = wall == WALL_U  # the other slots of a tub run are the partitions
    reg = regions_of(pos[u, 0], pos[u, 2], radius)
    out = {name: by_phase(fn[u][reg == r], k[u][reg == r], per, n_by_phase)
           for r, name in enumerate(REGIONS)}
    out["U wall Fz"] = by_phase(fz_tub[u], k[u], per, n_by_phase)
    out["partitions Fz"] = by_phase(fz_tub[~u], k[~u], per, n_by_phase)
    out["partitions Fn"] = by_phase(fn[~u], k[~u], per, n_by_phase)
    out.update(dem_bed(dem_dir, per))
    return out


def dem_bed(dem_dir: Path, per: int) -> dict:
    """{BED name: (per,) mean per sample} of the DEM run's snapshots (module docstring)."""
    from vibroflow.calibration.dem_result import DEMResult

    sums = {name: np.zeros(per) for name in BED}
    count = np.zeros(per)
    with DEMResult.open(dem_dir) as res:
        phase = res.file["snapshots/phase"][()]
        for s, snap in res.iter_snapshots(wall_contacts=False):  # the ball contacts alone
            k = int(np.rint(phase[s] * per)) % per
            m = snap["mass"]
            x, v = snap["positions_tub"], snap["velocities_rel_tub"]
            rows = _bed_rows(m, v[:, 0], v[:, 2], x[:, 2],
                             (snap["contact_force"] * snap["contact_branch"]).sum() / 3.0)
            for name, value in zip(BED, rows):
                sums[name][k] += value
            count[k] += 1
    return _centred({name: v / np.maximum(count, 1) for name, v in sums.items()})


def _bed_rows(mass, vx, vz, z, virial):
    """The BED values of one sample: mass-weighted mean vx, vz (mm/s), centre of mass z (mm),
    the virial (J) as given."""
    mt = mass.sum()
    return ((mass * vx).sum() / mt * 1e3, (mass * vz).sum() / mt * 1e3,
            (mass * z).sum() / mt * 1e3, virial)


def _centred(rows: dict) -> dict:
    """The centre of mass's height from its cycle mean."""
    rows["bed z_cm mm"] = rows["bed z_cm mm"] - rows["bed z_cm mm"].mean()
    return rows


def phase_means(scenario, system, state, advance, wall_of, mu_p, per: int, skip: int,
                cycles: int) -> dict:
    """{name: (per,) mean per sample} of a continuum run from the start of the vibration
    (module docstring): `advance(system, state, n)` steps it; `wall_of(state)` gives the tub
    frame positions (N, 2) m of its points or cells, their wall normal force and the wall
    force's z component (N,) in N/m of thickness; mu_p the partitions' friction (None: no
    partitions)."""
    from vibroflow.tub.geometry import geometry_of
    from vibroflow.continuum.boundary import partition_forces

    geo = geometry_of(scenario)
    length = geo.length
    f = scenario.motion.frequency
    steps = int(round(1.0 / (f * per) / system.dt))  # make_system's dt divides the interval
    names = (*REGIONS, "U wall Fz", "partitions Fz", "partitions Fn", *BED)
    sums = {name: np.zeros(per) for name in names}
    count = np.zeros(per)
    fext = np.zeros((state.n, 2))
    for s in range((skip + cycles) * per):
        advance(system, state, steps)
        if s < skip * per:
            continue
        k = int(round(state.t * f * per)) % per
        x, fn, fz = wall_of(state)
        reg = regions_of(x[:, 0], x[:, 1], geo.radius)
        for r, name in enumerate(REGIONS):
            sums[name][k] += fn[reg == r].sum() * length  # N/m of thickness -> N over the slice
        sums["U wall Fz"][k] += fz.sum() * length
        if mu_p is not None:
            fext[:] = 0.0
            partition_forces(state.v, state.mass, state.volume, state.stress, fext, mu_p,
                             length, system.dt)
            sums["partitions Fz"][k] += fext[:, 1].sum() * length
            # the normal stress the friction is taken from (partition_forces: p where p > 0)
            # on both partitions, 2 p V_p / L_y per metre, so 2 p V_p over the slice
            sums["partitions Fn"][k] += 2.0 * np.clip(state.pressure(), 0.0, None) @ state.volume
        # the continuum's virial sum p V (V in m^2 per metre of thickness, so times length)
        rows = _bed_rows(state.mass, state.v[:, 0], state.v[:, 1], x[:, 1],
                         (state.pressure() * state.volume).sum() * length)
        for name, value in zip(BED, rows):
            sums[name][k] += value
        count[k] += 1
    return _centred({name: v / np.maximum(count, 1) for name, v in sums.items()})


def eulerian_balance(scenario, calibration, options, per: int, skip: int, cycles: int) -> dict:
    """phase_means of an Eulerian run, from the bed run_continuum starts vibrating."""
    from vibroflow.continuum.eulerian.solver import advance
    from vibroflow.continuum.tub_run import vibration_start

    system, state = vibration_start(scenario, calibration, options, "eulerian")
    n = system.mesh.normal

    def wall_of(st):
        # eulerian/wall.py: fn along the inward normal n, ft along (n_z, -n_x)
        fn, ft = st.wall["fn"], st.wall["ft"]
        return system.x, fn, fn * n[:, 1] - ft * n[:, 0]

    mu_p = system.partitions.friction if system.partitions is not None else None
    return phase_means(scenario, system, state, advance, wall_of, mu_p, per, skip, cycles)


def continuum_balance(scenario, calibration, options, per: int, skip: int, cycles: int) -> dict:
    """phase_means of a Lagrangian run, from the bed run_continuum starts vibrating."""
    from vibroflow.continuum.mpm.solver import advance
    from vibroflow.continuum.tub_run import vibration_start

    system, state = vibration_start(scenario, calibration, options, "lagrangian")

    def wall_of(st):
        hist = st.history[0]  # boundary.UWall's: the penalty law's last force on each point
        return st.x, hist["fn"], hist["f"][:, 1]

    mu_p = next((b.friction for b in system.boundaries if hasattr(b, "length")), None)
    return phase_means(scenario, system, state, advance, wall_of, mu_p, per, skip, cycles)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--dem-dir", required=True, type=Path)
    ap.add_argument("--calibration", type=Path)
    ap.add_argument("--methods", default="lagrangian",
                    help="comma-separated: lagrangian, eulerian")
    ap.add_argument("--skip-cycles", type=int, default=20)
    ap.add_argument("--cycles", type=int, default=40)
    ap.add_argument("--set", action="append", default=[], metavar="NAME=VALUE")
    a = ap.parse_args(argv)

    from vibroflow.io.calibration_file import Calibration, read_calibration
    from vibroflow.continuum.formulation import formulation
    from vibroflow.calibration.dem_result import DEMResult

    with DEMResult.open(a.dem_dir) as res:
        scenario = res.scenario
    cal_path = a.calibration or a.dem_dir / "calibration.toml"
    tables = read_calibration(cal_path).to_toml_dict()
    opts = {}
    for item in a.set:
        name, _, value = item.partition("=")
        if name.startswith("opt."):
            opts[name[4:]] = float(value)
        else:
            section, _, key = name.partition(".")
            tables[section][key] = float(value)
    calibration = Calibration.from_dict(tables, where=str(cal_path))
    per = scenario.run.phases_per_cycle
    radius = scenario.tub.radius
    results = {"DEM": dem_balance(a.dem_dir, per, radius)}
    for method in a.methods.split(","):
        if method == "lagrangian":
            results["Lagrangian"] = continuum_balance(
                scenario, calibration, formulation(method).options(**opts), per,
                a.skip_cycles, a.cycles)
        elif method == "eulerian":
            results["Eulerian"] = eulerian_balance(
                scenario, calibration, formulation(method).options(**opts), per,
                a.skip_cycles, a.cycles)
        else:
            ap.error(f"--methods: {method!r} is not lagrangian or eulerian")
    fill = scenario.fill
    weight = fill.count * np.pi * fill.diameter**3 / 6.0 * fill_density(scenario) * 9.81
    print(f"{scenario.case}: forces on the bed by phase of the cycle (N over the slice, tub "
          f"axes; the DEM's balls weigh {weight:.1f} N){' ' + ' '.join(a.set) if a.set else ''}")
    print(f"{'':>24} " + " ".join(f"{k}/{per}".rjust(7) for k in range(per)) + "     mean")
    for name in (*REGIONS, "U wall Fz", "partitions Fz", "partitions Fn", *BED):
        fmt = "{:7.2f}" if name == "bed P V (J)" else "{:7.1f}"
        for label, r in results.items():
            row = r[name]
            print(f"{label:>10} {name:>13} " + " ".join(fmt.format(x) for x in row)
                  + "  " + fmt.format(row.mean()))
    return 0


def fill_density(scenario) -> float:
    """The fill material's density (kg/m^3)."""
    return float(scenario.materials[scenario.fill.material].density)


if __name__ == "__main__":
    sys.exit(main())
