"""Why the continuum's bed does not leave the U's floor: the floor force by phase of a
tub47-quick continuum run with each suspect switched off in turn (docs/validation.md
section 22, "Why the tub's bed stays on the floor").

    python benchmarks/tub_take_off.py [--methods lagrangian,eulerian]
        [--cases base,no-partitions,no-wall-friction,vertical,...] [--skip-cycles 10]
        [--cycles 20] [--batches 4] [--temperature] [--dem-dir RUN]

Cases (combine with '+', e.g. no-partitions+vertical):
  base              the run as `vibroflow continuum tub47-quick` makes it (the stored
                    calibration tests/data/tub47-quick-dem/calibration.toml)
  no-partitions     the partitions' friction body force off (mu_p = 0)
  no-wall-friction  the U wall's Coulomb friction off (mu_w = 0)
  vertical          the tub's motion its vertical stroke alone (A_x = 0, Theta = 0)
  along-flow        the partitions' friction along the mean flow (`vibroflow continuum
                    --partition-friction along-flow`: [partitions] friction_along_flow)
  uncalibrated      no calibration: the material's defaults (ContinuumMaterial: K 4.5 MPa,
                    G 1.3 MPa) and the scenario's contact friction (mu_w 0.4, mu_p 0.15)

The measure, sampled at the DEM's eight phases a cycle (t f, the tub's phase) over --cycles
cycles after --skip-cycles: the z component (tub axes) of the U wall's force within 30 degrees of
the bottom over the bed's weight (the Lagrangian's penalty force on the points, the Eulerian's on
its wall-layer cells); beside it the partitions' friction's z component and the rest of the U's
(arcs and side walls) and the partitions' normal force 2 p V / L_y summed over the compressed
material, over the weight; the take-off t f where the floor force first falls to a twentieth
of the weight after its maximum (vibroflow.measure.floor_force.sampled_take_off).  --dem-dir RUN
(--methods '' for it alone): the same forces of a DEM run from its sampled wall contacts, and
its partitions' friction over their normal force, the magnitudes' and along the mean flow of
each ball's 15 mm cell (calibration.wall_friction's cell_mean_velocity and along_flow, the
measure of [partitions] friction_along_flow).  The DEM (tub47-quick, fill seed 1): floor
force / weight 0.52, 0.037, 0, 0.0006, 0.11, 0.83, 1.82, 1.78; take-off 0.122.
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

from vibroflow.measure.floor_force import region_of, sampled_take_off

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_CALIBRATION = ROOT / "tests/data/tub47-quick-dem/calibration.toml"
DEM_FLOOR = (0.52, 0.037, 0.0, 0.0006, 0.11, 0.83, 1.82, 1.78)
CELL_M = 0.015   # the mean flow's cells (tub47.md's bulk velocity cells)
CASES = ("base", "no-partitions", "no-wall-friction", "vertical", "uncalibrated", "along-flow")


def partition_z(v, mass, volume, stress, mu_p, length, dt):
    """(z force, normal force) (N/m) of the partitions on the points or cells: the friction's
    z component as boundary.partition_forces makes it from the stress it is given, and the
    two partitions' normal force 2 p V / L_y summed over the compressed material."""
    p = -(stress[:, 0] + stress[:, 1] + stress[:, 3]) / 3.0
    sp = np.hypot(v[:, 0], v[:, 1])
    on = (p > 0) & (sp > 0)
    f = np.minimum(2.0 * mu_p * p[on] * volume[on] / length, mass[on] * sp[on] / dt)
    normal = 2.0 * np.where(p > 0, p, 0.0) * volume / length
    return float(-(f * v[on, 1] / sp[on]).sum()), float(normal.sum())


def dem_forces(dem_dir: Path, per: int, batches: int, radius: float):
    """The DEM's forces over the bed's weight by (batch, eighth), from its sampled wall
    contacts: the U floor's z force (tub axes), the rest of the U's, the partitions' z force
    and the partitions' normal force."""
    import h5py

    from vibroflow.calibration.wall_friction import along_flow, cell_mean_velocity
    from vibroflow.dem.walls import WALL_PARTITION_HI, WALL_PARTITION_LO, WALL_U
    from vibroflow.tub.geometry import point_to_arc
    from vibroflow.tub.motion import lab_to_tub_np, relative_velocity_tub_axes_np

    with h5py.File(dem_dir / "dem.h5", "r") as hf:
        phase = hf["snapshots/phase"][:]
        theta = hf["snapshots/tub_pose"][:, 2]
        w = hf["wall_contacts"]
        snap = w["snapshot"][:]
        wall = w["wall"][:]
        pos = w["position_tub"][:].astype(float)
        f_lab = w["force_lab"][:].astype(float)
        fn = w["fn"][:].astype(float)
        ball = w["particle"][:]
        pose = hf["snapshots/tub_pose"][:]
        pos_all = hf["snapshots/position"]
        vel_all = hf["snapshots/velocity"]
        along = np.zeros(snap.size)
        part_rows = np.nonzero((wall == WALL_PARTITION_LO) | (wall == WALL_PARTITION_HI))[0]
        for i in np.unique(snap[part_rows]):
            X, Z, th_i, Xd, Zd, thd = pose[i]
            x = lab_to_tub_np(pos_all[i], X, Z, th_i)
            v = relative_velocity_tub_axes_np(pos_all[i], vel_all[i], X, Z, th_i, Xd, Zd, thd)
            ux, uz = cell_mean_velocity(x[:, 0], x[:, 2], v[:, 0], v[:, 2], CELL_M)
            rows = part_rows[snap[part_rows] == i]
            b = ball[rows]
            c_, s_ = np.cos(th_i), np.sin(th_i)
            along[rows] = along_flow(c_ * f_lab[rows, 0] + s_ * f_lab[rows, 2],
                                     -s_ * f_lab[rows, 0] + c_ * f_lab[rows, 2], ux[b], uz[b])
        mass = float(hf["particles/mass"][:].sum()) if "particles/mass" in hf else None
        if mass is None:
            r = hf["particles/radius"][:]
            mass = float((4.0 / 3.0 * np.pi * r ** 3).sum() * 7800.0)
    weight = 9.81 * mass
    n_snap = phase.size
    k_snap = np.rint(phase * per).astype(np.int64) % per
    b_snap = np.minimum(np.arange(n_snap) * batches // n_snap, batches - 1)
    th = theta[snap]
    fz = -np.sin(th) * f_lab[:, 0] + np.cos(th) * f_lab[:, 2]
    u = wall == WALL_U
    floor = u & (region_of(point_to_arc(pos[:, 0], pos[:, 2], radius), radius) == 0)
    part = (wall == WALL_PARTITION_LO) | (wall == WALL_PARTITION_HI)
    key = b_snap[snap] * per + k_snap[snap]
    cnt = np.bincount(b_snap * per + k_snap, minlength=batches * per).reshape(batches, per)

    def by(mask, val):
        tot = np.bincount(key[mask], val[mask], batches * per).reshape(batches, per)
        return tot / np.maximum(cnt, 1) / weight

    return {"floor": by(floor, fz), "rest": by(u & ~floor, fz), "partitions": by(part, fz),
            "partition_normal": by(part, fn), "partition_along_flow": by(part, along),
            "partition_magnitude": by(part, np.hypot(f_lab[:, 0], f_lab[:, 2]))}


def run_case(method: str, case: str, skip: int, cycles: int, batches: int,
             temperature: bool) -> dict:
    """Floor force, partitions' z force and the rest of the U's, over the weight, by (batch,
    eighth)."""
    from vibroflow.continuum import material as material_mod
    from vibroflow.continuum.boundary import PartitionFriction, UWall
    from vibroflow.continuum.eulerian import formulation as eul_form
    from vibroflow.continuum.eulerian.solver import advance as eul_advance
    from vibroflow.continuum.formulation import formulation
    from vibroflow.continuum.mpm import formulation as mpm_form
    from vibroflow.continuum.mpm.solver import advance as mpm_advance
    from vibroflow.continuum.tub_run import vibration_start
    from vibroflow.io.calibration_file import read_calibration
    from vibroflow.scenario.io import load_scenario
    from vibroflow.tub.geometry import geometry_of, point_to_arc

    parts = set(case.split("+"))
    unknown = parts - set(CASES)
    if unknown:
        raise SystemExit(f"--cases: {sorted(unknown)} not in {CASES}")
    overrides = ["motion.amplitude_x=0.0", "motion.amplitude_theta=0.0"] \
        if "vertical" in parts else []
    scenario = load_scenario("tub47-quick", overrides)
    cal = None if "uncalibrated" in parts else read_calibration(DEFAULT_CALIBRATION)
    original = material_mod.boundary_friction

    def friction(sc, c, partitions="contacts"):
        pair, mu_w, mu_p = original(sc, c, partitions)
        if "no-wall-friction" in parts:
            mu_w = 0.0
        if "no-partitions" in parts and mu_p is not None:
            mu_p = 0.0
        return pair, mu_w, mu_p

    settings = {"temperature": True, "initial_temperature": 0.01} if temperature else {}
    if "along-flow" in parts:
        settings["partition_friction"] = "along_flow"
    options = formulation(method).options(**settings)
    mpm_form.boundary_friction = eul_form.boundary_friction = friction
    try:
        system, state = vibration_start(scenario, cal, options, method)
    finally:
        mpm_form.boundary_friction = eul_form.boundary_friction = original
    geo = geometry_of(scenario)
    f = scenario.motion.frequency
    per = 8
    steps = int(round(1.0 / (f * per) / system.dt))
    weight = float(np.hypot(scenario.gravity[0], scenario.gravity[2])) * state.mass.sum()
    if method == "eulerian":
        advance = eul_advance
        cells = system.wall_cells
        n = system.mesh.normal
        part = system.partitions
        x_wall = system.x[cells]
        reg_wall = region_of(point_to_arc(x_wall[:, 0], x_wall[:, 1], geo.radius),
                                  geo.radius)

        def forces():
            fn, ft = state.wall["fn"], state.wall["ft"]
            fz = fn * n[cells, 1] - ft * n[cells, 0] if fn.size == cells.size else \
                (fn * n[:, 1] - ft * n[:, 0])[cells]
            pz = (0.0, 0.0) if part is None else partition_z(
                state.v, state.mass, state.volume, state.stress, part.friction, part.length,
                system.dt)
            return (fz[reg_wall == 0].sum(), fz[reg_wall != 0].sum()) + pz
    else:
        advance = mpm_advance
        wall = next(b for b in system.boundaries if isinstance(b, UWall))
        part = next((b for b in system.boundaries if isinstance(b, PartitionFriction)), None)

        def forces():
            hist = state.history[wall.slot]
            touch = hist["fn"] > 0
            x = state.x[touch]
            reg = region_of(point_to_arc(x[:, 0], x[:, 1], geo.radius), geo.radius)
            fz = hist["f"][touch, 1]
            pz = (0.0, 0.0) if part is None else partition_z(
                state.v, state.mass, state.volume, state.stress, part.friction, part.length,
                system.dt)
            return (fz[reg == 0].sum(), fz[reg != 0].sum()) + pz

    out = np.zeros((4, batches, per))
    count = np.zeros((batches, per))
    t0 = time.perf_counter()
    for s in range((skip + cycles) * per):
        advance(system, state, steps)
        if s < skip * per:
            continue
        b = min((s - skip * per) * batches // (cycles * per), batches - 1)
        k = int(round(state.t * f * per)) % per
        out[:, b, k] += forces()
        count[b, k] += 1
    out = out / np.maximum(count, 1) / weight
    return {"floor": out[0], "rest": out[1], "partitions": out[2], "partition_normal": out[3],
            "wall_s": time.perf_counter() - t0, "take_off": sampled_take_off(out[0].mean(0), per)}


def _row(name, per_batch):
    from vibroflow.measure.stats import stderr_of_batches

    m, se = per_batch.mean(0), stderr_of_batches(per_batch)
    return f"  {name:<22}" + ", ".join(f"{a:.3f}+-{b:.2g}" for a, b in zip(m, se))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--methods", default="lagrangian,eulerian")
    ap.add_argument("--cases", default="base,no-partitions,no-wall-friction,vertical")
    ap.add_argument("--skip-cycles", type=int, default=10)
    ap.add_argument("--cycles", type=int, default=20)
    ap.add_argument("--batches", type=int, default=4)
    ap.add_argument("--temperature", action="store_true",
                    help="the granular temperature on (initial 0.01 m^2/s^2)")
    ap.add_argument("--dem-dir", type=Path, help="a tub47-quick DEM run (vibroflow dem): "
                    "its forces by phase from its sampled wall contacts")
    a = ap.parse_args(argv)
    if a.dem_dir is not None:
        from vibroflow.scenario.io import load_scenario
        from vibroflow.tub.geometry import geometry_of

        d = dem_forces(a.dem_dir, 8, a.batches, geometry_of(load_scenario("tub47-quick")).radius)
        print(f"DEM {a.dem_dir}: by eighth 0/8 - 7/8, over the weight:")
        print(_row("U floor (30 deg)", d["floor"]))
        print(_row("U arcs + side walls", d["rest"]))
        print(_row("partitions", d["partitions"]))
        print(_row("partitions' normal", d["partition_normal"]))
        print(_row("partitions' |F_t|", d["partition_magnitude"]))
        print(_row("partitions along flow", d["partition_along_flow"]))
        n, t, al = (d[k].sum() for k in ("partition_normal", "partition_magnitude",
                                         "partition_along_flow"))
        print(f"  the partitions' friction over their normal force, the cycle's sums: "
              f"|F_t| {t / n:.4f}, along the cell's mean flow {al / n:.4f}")
        if not a.methods:
            return 0
    print("DEM floor force / weight by eighth: " + ", ".join(f"{x:.3g}" for x in DEM_FLOOR)
          + "; take-off t f 0.122")
    for method in filter(None, a.methods.split(",")):
        for case in a.cases.split(","):
            r = run_case(method, case, a.skip_cycles, a.cycles, a.batches, a.temperature)
            to = r["take_off"]
            print(f"{method} {case}{' (T)' if a.temperature else ''}: take-off t f "
                  f"{'none' if not math.isfinite(to) else f'{to:.3f}'}; "
                  f"{r['wall_s']:.0f} s; by eighth 0/8 - 7/8, over the weight:")
            print(_row("U floor (30 deg)", r["floor"]))
            print(_row("U arcs + side walls", r["rest"]))
            print(_row("partitions", r["partitions"]))
            print(_row("partitions' normal", r["partition_normal"]))
            sys.stdout.flush()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
