"""The bed's deformation within the cycle on a vibrating floor: Eulerian against Lagrangian
(where the Eulerian formulation differs, and why: docs/decisions/eulerian-cells.md).

    python benchmarks/floor_deformation.py [--calibration FILE] [--case tub47]
        [--width 0.3] [--periodic] [--floor-angle DEG] [--cycles 20]
        [--methods eulerian,lagrangian] [--transfer-cfl X]

A bed of the case's media (the calibration's moduli and rheology, the case's fill), 0.2 m deep,
in a rectangular box of the given width (walls on the floor and both sides; --periodic: a strip
four nodes wide, periodic along x, the floor only), shaken vertically with the case's vertical
stroke (its frequency and amplitude_z; no horizontal stroke, no rotation), in the box's own
frame, as the tub runs are.  Both formulations run with their tub defaults (grid spacing,
Courant numbers, transfers; the wall's stiffness (K + 4 G / 3) / (dx / 2), friction 0.2,
damping ratio 0.16).  The walls are axis-aligned, so the Eulerian mesh has no staircase: what
differs is the formulation.  --floor-angle DEG: a V floor instead, two planes through the box's
bottom centre inclined at DEG on either side (the bed filled above it to the same 0.2 m at the
centre plus 5 cm): the Eulerian mesh approximates it by a staircase of cells, as it does the
tub's U, where the Lagrangian's walls are exact planes.

Printed for each method, over `cycles` cycles after 10 cycles of start-up, sampled at 8 phases a
cycle, the phase-averaged velocity gradient binned on 15 mm cells (mass-weighted):

* the phase-field shear rate, sqrt(2 D':D') of the phase-averaged field (plane strain), the
  measure of vibroflow.measure.phase_shear, mean over the bed and the phases;
* its parts, the mean |dvz/dz| (the bed stretched and squeezed vertically) and |D_xz|;
* the bed's vertical velocity (mm/s) at phases 2/8 (flight) and 6/8 (landing) by 30 mm bands
  of height, floor to surface: a bed in flight moves nearly as a body;
* the Eulerian only: the volume fraction of its floor row and the volume its material fills
  after the shaking stops and the bed rests 0.3 s, over its mass / critical density.
"""
from __future__ import annotations

import argparse
import math
import sys

import numpy as np

import bench

G = 9.81
BED_DEPTH = 0.2
BIN = 0.015
#: node spacing (m): tub47's default grid, three ball diameters (continuum.options.default_dx)
DX = 0.01875


def _top(floor_angle):
    """The bed's initial surface (m): BED_DEPTH, 5 cm more over a V floor."""
    return BED_DEPTH if floor_angle is None else BED_DEPTH + 0.05


def _lithostatic(z, material, top):
    """Pressure (Pa) and density (kg/m^3) of the Eulerian cells of a bed at rest with its
    surface at `top` (m), at heights z (m) (the Lagrangian's points: column.lithostatic_state)."""
    rho_c = material.critical_density
    p = rho_c * G * np.clip(top - z, 0.0, None)
    return p, rho_c * np.exp(p / material.bulk_modulus)


def _v_floor(x, z, width, angle):
    """Signed distance (m, positive inside) to the box with a V floor of `angle` (rad) and
    its inward normal: (gap, nx, nz, arc) on arrays, the level set of EulerianMesh."""
    xm = 0.5 * width
    sn, cs = math.sin(angle), math.cos(angle)
    left = x < xm
    floor = np.where(left, (z - (xm - x) * math.tan(angle)) * cs,
                     (z - (x - xm) * math.tan(angle)) * cs)
    cand = [(floor, np.where(left, sn, -sn), np.full_like(x, cs)),
            (x, np.ones_like(x), np.zeros_like(x)),
            (width - x, -np.ones_like(x), np.zeros_like(x))]
    d = np.stack([c[0] for c in cand])
    j = np.argmin(d, axis=0)
    idx = np.arange(x.size)
    return (d[j, idx], np.stack([c[1] for c in cand])[j, idx],
            np.stack([c[2] for c in cand])[j, idx], np.zeros_like(x))


def build(method, material, motion, width, periodic, transfer_cfl, floor_angle=None):
    """(system, state, advance) of one formulation: the bed at rest, lithostatic, in the
    shaken box's frame; floor_angle (rad) a V floor (module docstring)."""
    from vibroflow.continuum.formulation import formulation
    from vibroflow.continuum.grid_update import TubFrame
    from vibroflow.continuum.timestep import stable_dt

    frame = TubFrame(motion, (0.0, -G))
    period = 1.0 / motion.frequency
    opts = formulation(method).options(
        **({} if transfer_cfl is None else {"transfer_cfl": transfer_cfl}))
    dx = DX
    h = dx / 2
    if periodic:
        width = 4 * dx
    M = material.bulk_modulus + 4.0 * material.shear_modulus / 3.0
    kn = M / h
    if method == "eulerian":
        from vibroflow.continuum.eulerian.mesh import EulerianMesh
        from vibroflow.continuum.eulerian.solver import EulerianSystem, advance, init_state
        from vibroflow.continuum.eulerian.wall import MeshWall

        if floor_angle is None:
            mesh = EulerianMesh.box(0.0, width, 0.0, 2 * BED_DEPTH, dx, periodic=periodic)
        else:
            mesh = EulerianMesh.from_level_set(
                0.0, width, 0.0, 2 * BED_DEPTH, dx,
                lambda x, z: _v_floor(x, z, width, floor_angle))
        wall = MeshWall(kn, friction=0.2, damping_ratio=0.16)
        dt = stable_dt(material, dx, h, [wall], v_max=2.0, cfl=opts.cfl)
        dt = period / (8 * math.ceil(period / 8 / dt))
        system = EulerianSystem(mesh, material, dt, frame=frame, wall=wall,
                                transfers=opts.transfers())
        c = system.x
        filled = (c[:, 1] < _top(floor_angle)) & mesh.inside
        p, rho = _lithostatic(c[:, 1], material, _top(floor_angle))
        stress = np.zeros((mesh.n, 4))
        stress[:, [0, 1, 3]] = -(p * filled)[:, None]
        state = init_state(system, np.where(filled, rho * h * h, 0.0), rho, stress=stress)
        return system, state, advance
    from vibroflow.continuum.boundary import Plane
    from vibroflow.continuum.grid import Grid
    from vibroflow.continuum.mpm.column import column_points, lithostatic_state
    from vibroflow.continuum.mpm.solver import MPMSystem, advance

    if floor_angle is None:
        walls = [Plane((0.0, 0.0), (0.0, 1.0), kn, friction=0.2, damping_ratio=0.16)]
    else:
        sn, cs = math.sin(floor_angle), math.cos(floor_angle)
        walls = [Plane((0.5 * width, 0.0), (sn, cs), kn, friction=0.2, damping_ratio=0.16),
                 Plane((0.5 * width, 0.0), (-sn, cs), kn, friction=0.2, damping_ratio=0.16)]
    if periodic:
        grid = Grid.periodic_strip(width, -dx, 2 * BED_DEPTH, dx)
    else:
        grid = Grid.covering(0.0, width, 0.0, 2 * BED_DEPTH, dx)
        walls += [Plane((0.0, 0.0), (1.0, 0.0), kn, friction=0.2, damping_ratio=0.16),
                  Plane((width, 0.0), (-1.0, 0.0), kn, friction=0.2, damping_ratio=0.16)]
    dt = stable_dt(material, dx, h, walls, v_max=2.0, cfl=opts.cfl)
    dt = period / (8 * math.ceil(period / 8 / dt))
    system = MPMSystem(grid, material, dt, frame=frame, boundaries=walls,
                       transfers=opts.transfers())
    x = column_points(0.0, width, _top(floor_angle), h)
    if floor_angle is not None:
        x = x[x[:, 1] > np.abs(x[:, 0] - 0.5 * width) * math.tan(floor_angle) + 0.5 * h]
    return system, lithostatic_state(system, x, np.full(len(x), _top(floor_angle))), advance


def measure(method, material, motion, width, periodic, cycles, transfer_cfl, floor_angle=None):
    from vibroflow.continuum.grid_update import LabFrame

    system, state, advance = build(method, material, motion, width, periodic, transfer_cfl,
                                   floor_angle)
    period = 1.0 / motion.frequency
    dt = system.dt
    advance(system, state, int(round(10 * period / dt)))
    w = 4 * DX if periodic else width
    nxb, nzb = int(math.ceil(w / BIN)), int(math.ceil(2 * BED_DEPTH / BIN))
    SL = np.zeros((8, nxb, nzb, 4))
    SM = np.zeros((8, nxb, nzb))
    SV = np.zeros((8, nzb))
    SMz = np.zeros((8, nzb))
    for cyc in range(cycles):
        for ph in range(8):
            advance(system, state, int(round((10 + cyc + ph / 8) * period / dt)) - state.step)
            m = state.mass
            ib = np.clip((state.x[:, 0] / BIN).astype(int), 0, nxb - 1)
            kb = np.clip((state.x[:, 1] / BIN).astype(int), 0, nzb - 1)
            np.add.at(SM[ph], (ib, kb), m)
            for c in range(4):
                np.add.at(SL[ph, :, :, c], (ib, kb), m * state.L[:, c])
            np.add.at(SMz[ph], kb, m)
            np.add.at(SV[ph], kb, m * state.v[:, 1])
    Lm = SL / np.maximum(SM, 1e-30)[..., None]
    Dxx, Dzz, Dxz = Lm[..., 0], Lm[..., 3], 0.5 * (Lm[..., 1] + Lm[..., 2])
    tr = (Dxx + Dzz) / 3.0
    rate = np.sqrt(2.0 * ((Dxx - tr) ** 2 + (Dzz - tr) ** 2 + tr**2 + 2.0 * Dxz**2))
    wt = SM / SM.sum(axis=(1, 2), keepdims=True)
    out = {"rate": float((wt * rate).sum(axis=(1, 2)).mean()),
           "dvz_dz": float((wt * np.abs(Dzz)).sum(axis=(1, 2)).mean()),
           "dxz": float((wt * np.abs(Dxz)).sum(axis=(1, 2)).mean()),
           "profiles": {}}
    for ph in (2, 6):
        bands = []
        for j in range(int(round(_top(floor_angle) / 0.03)) + 1):
            mm = SMz[ph, 2 * j:2 * j + 2].sum()
            if mm > 0:
                bands.append(1e3 * SV[ph, 2 * j:2 * j + 2].sum() / mm)
        out["profiles"][ph] = bands
    if method == "eulerian":
        mesh = system.mesh
        frac = state.frac.reshape(mesh.ncx, mesh.ncz)
        inside = mesh.inside.reshape(mesh.ncx, mesh.ncz)
        # the lowest cell of each column clear of the side walls
        lowest = [frac[i, int(np.argmax(inside[i]))] for i in range(1, mesh.ncx - 1)]
        out["floor_fraction"] = float(np.mean(lowest))
        system.frame = LabFrame((0.0, -G))
        advance(system, state, int(round(0.3 / dt)))
        held = (state.mass > 0) & (state.density > 0)
        out["volume"] = float((state.mass[held] / state.density[held]).sum()
                              / (state.mass[held].sum() / material.critical_density))
    return out


def case_media(case: str, calibration: str):
    """(scenario, material, full motion, vertical stroke alone) of a case and a calibration
    file: the continuum material of `material_for` with the default options, the case's tub
    motion, and the same motion with no horizontal stroke and no rotation."""
    from vibroflow.io.calibration_file import read_calibration
    from vibroflow.continuum.formulation import formulation
    from vibroflow.continuum.material import material_for
    from vibroflow.tub.motion import TubMotion

    scenario = bench.scenario(case)
    material = material_for(scenario, read_calibration(calibration),
                            formulation("lagrangian").options())
    full = TubMotion.of_scenario(scenario)
    motion = TubMotion(frequency=full.frequency, amplitude_x=0.0, amplitude_z=full.amplitude_z,
                       phase_z=full.phase_z, amplitude_theta=0.0)
    return scenario, material, full, motion


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--calibration", default="tests/data/tub47-dem/calibration.toml")
    ap.add_argument("--case", default="tub47")
    ap.add_argument("--width", type=float, default=0.3)
    ap.add_argument("--periodic", action="store_true")
    ap.add_argument("--floor-angle", type=float, default=None,
                    help="a V floor inclined at this angle (degrees) on either side")
    ap.add_argument("--cycles", type=int, default=20)
    ap.add_argument("--methods", default="eulerian,lagrangian")
    ap.add_argument("--transfer-cfl", type=float, default=None)
    a = ap.parse_args(argv)
    _, material, full, motion = case_media(a.case, a.calibration)
    gamma = full.amplitude_z * (2 * math.pi * full.frequency) ** 2 / G
    if a.periodic and a.floor_angle is not None:
        print("--periodic and --floor-angle: choose one", file=sys.stderr)
        return 2
    angle = None if a.floor_angle is None else math.radians(a.floor_angle)
    where = "periodic strip" if a.periodic else f"box {a.width:g} m wide"
    if angle is not None:
        where += f", V floor at {a.floor_angle:g} deg"
    print(f"{a.case}'s media (K {material.bulk_modulus:.3g} Pa, G {material.shear_modulus:.3g} "
          f"Pa), bed {BED_DEPTH} m deep, {where}, vertical stroke {full.frequency:g} Hz, "
          f"{1e3 * full.amplitude_z:.3g} mm (Gamma {gamma:.2f}); {a.cycles} cycles sampled")
    print("| method | phase-field shear rate (1/s) | mean abs dvz/dz | mean abs D_xz | "
          "vz at 2/8 (flight), floor to surface, mm/s | at 6/8 (landing) | floor row's fill | "
          "volume at rest / at rho_c |")
    print("|---|---|---|---|---|---|---|---|")
    for method in a.methods.split(","):
        r = measure(method, material, motion, a.width, a.periodic, a.cycles, a.transfer_cfl,
                    angle)
        prof = {ph: " ".join(f"{v:.0f}" for v in r["profiles"][ph]) for ph in (2, 6)}
        fill = f"{r['floor_fraction']:.2f}" if "floor_fraction" in r else "-"
        vol = f"{r['volume']:.4f}" if "volume" in r else "-"
        print(f"| {method} | {r['rate']:.2f} | {r['dvz_dz']:.2f} | {r['dxz']:.2f} | {prof[2]} | "
              f"{prof[6]} | {fill} | {vol} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
