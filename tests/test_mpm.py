"""The Lagrangian continuum (material point method) against known answers.

Constitutive law (Dunatunga & Kamrin 2015) in steady simple shear; elastic P waves at
sqrt((K + 4G/3)/rho); linear and angular momentum of the APIC transfers (Jiang et al. 2015); a
block on an accelerating plate that sticks or slips as Coulomb's law says; the steady inclined
layer (Bagnold profile of mu(I)) and its convergence with the grid.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from vibroflow.continuum.boundary import Plane
from vibroflow.continuum.constitutive import ContinuumMaterial
from vibroflow.continuum.rheology import mu_of_I
from vibroflow.continuum.stress_update import update_stress_points
from vibroflow.continuum.grid import Grid
from vibroflow.continuum.grid_update import LabFrame
from vibroflow.continuum.mpm.solver import MPMSystem, init_state, run_steps
from vibroflow.continuum.timestep import stable_dt
from vibroflow.errors import InputError

from continuum_helpers import G_ACC, lattice, spinning_compressed_disc


# ----------------------------------------------------------------------------------------------
# constitutive law


# ----------------------------------------------------------------------------------------------
# MPM


def bagnold_error(nz: int) -> float:
    """Steady flow down a rough incline (theta = 25 deg, layer H = 1 cm of d = 2 mm grains,
    periodic along the slope) from rest: max |u - u_analytic| / u_analytic(H) after 1 s, with
    the mu(I) solution u(z) = (2/3) (I/d) sqrt(phi g cos theta) (H^1.5 - (H - z)^1.5),
    tan theta = mu(I) (GDR MiDi 2004; Silbert et al. 2001), z from the base."""
    d, H, theta = 2e-3, 0.01, math.radians(25.0)
    mat = ContinuumMaterial(bulk_modulus=1e5, shear_modulus=5e4, diameter=d)
    dx = H / nz
    sp = dx / 2
    grid = Grid.periodic_strip(4 * dx, 0.0, 1.1 * H, dx)
    x = lattice(0.0, 4 * dx, 0.0, H, sp)
    rho_c = mat.critical_density
    p = rho_c * G_ACC * math.cos(theta) * (H - x[:, 1])
    rho = rho_c * np.exp(p / mat.bulk_modulus)
    stress = np.zeros((len(x), 4))
    stress[:, [0, 1, 3]] = -p[:, None]
    base = Plane((0.0, 0.0), (0.0, 1.0), (mat.bulk_modulus + 4 * mat.shear_modulus / 3) / sp,
                 friction=10.0)
    gravity = (G_ACC * math.sin(theta), -G_ACC * math.cos(theta))
    system = MPMSystem(grid, mat, stable_dt(mat, dx, sp, [base]), frame=LabFrame(gravity),
                       boundaries=[base])
    state = init_state(system, x, sp * sp * rho_c / rho, rho, stress=stress)
    run_steps(system, state, int(1.0 / system.dt))
    rows = np.floor(x[:, 1] / sp).astype(int)
    z = np.bincount(rows, state.x[:, 1]) / np.bincount(rows)
    u = np.bincount(rows, state.v[:, 0]) / np.bincount(rows)
    I = mat.I_0 * (math.tan(theta) - mat.mu_s) / (mat.mu_2 - math.tan(theta))
    phi = mat.critical_solid_fraction
    ua = (2 / 3) * (I / d) * math.sqrt(phi * G_ACC * math.cos(theta)) * (
        H**1.5 - np.clip(H - z, 0, None) ** 1.5)
    return float(np.max(np.abs(u - ua)) / ua.max())


def test_bagnold_inclined_layer_profile_and_convergence():
    """The steady mu(I) profile within 3% at 16 grid cells across the layer, and the error
    falls as the grid is refined (8 -> 16 cells)."""
    coarse, fine = bagnold_error(8), bagnold_error(16)
    assert fine < 0.03
    assert fine < 0.6 * coarse


@pytest.mark.slow
def test_bagnold_inclined_layer_fine_grid():
    """32 cells across the layer: within 1.5%."""
    assert bagnold_error(32) < 0.015


# ----------------------------------------------------------------------------------------------
# the tub run and its command


def test_continuum_command_writes_dem_comparable_results(run_cli, tmp_path):
    """`vibroflow continuum` on a short tub47-quick: bulk_velocity.csv on the 15 mm cells and
    summary.json with the DEM's keys, readable by the analysis code."""
    import json

    from vibroflow.measure.bulk import read_csv

    out = tmp_path / "cont"
    cal = tmp_path / "calibration.toml"
    cal.write_text("[rheology]\nmu_s = 0.35\nmu_2 = 0.60\nI_0 = 0.3\nphi_max = 0.61\n"
                   "phi_min = 0.45\ncritical_solid_fraction = 0.61\n"
                   "[elastic]\nbulk_modulus_Pa = 4.0e6\nshear_modulus_Pa = 1.5e6\n"
                   "[wall]\nfriction = 0.3\n[partitions]\nfriction = 0.1\n"
                   "[media]\ndiameter_m = 0.00635\nsolid_density_kg_m3 = 7800.0\n"
                   "[impacts.ball_ball]\nc0_m_s = 0.05\nc1 = 0.8\n")
    r = run_cli("continuum", "tub47-quick", "--method", "lagrangian", "--out", out,
                "--calibration", cal, "--set", "run.duration=0.15",
                "--set", "run.average_last=0.1", "--vtk")
    assert r.returncode == 0, r.stderr
    summary = json.loads((out / "summary.json").read_text())
    cont = summary["continuum"]
    assert (cont["material"]["mu_s"], cont["material"]["bulk_modulus"]) == (0.35, 4.0e6)
    assert (cont["wall_friction"], cont["partition_friction"]) == (0.3, 0.1)
    # impact speed through the calibrated relation v = c0 + c1 d gamma_dot (the phase-resolved
    # field's shear rate, solid-fraction weighted over the cells)
    v = cont["impacts_from_shear_rate"]["ball_ball_mean_normal_speed_m_s"]
    assert v == pytest.approx(0.05 + 0.8 * 0.00635 * cont["shear_rate"]["mean_1_s"], rel=1e-9)
    assert summary["impacts"]["ball_ball_mean_normal_speed"] == pytest.approx(v, rel=1e-12)
    assert cont["shear_rate"]["mean_1_s"] > 0
    assert set(cont["probes"]) == {"P1", "P2", "P3", "P4", "P5"}
    # ParaView: the points at the 8 samples of the last cycle, their collection, the tub
    assert len(list((out / "vtk").glob("points_*.vtu"))) == 8
    assert (out / "vtk" / "points.pvd").is_file() and (out / "vtk" / "tub.vtu").is_file()
    # and the grid fields at the same instants, as rectilinear grids in a collection
    assert len(list((out / "vtk").glob("grid_*.vtr"))) == 8
    assert (out / "vtk" / "grid.pvd").read_text().count("grid_0") == 8
    assert not (out / "checkpoint.npz").exists()
    for key in ("probes", "circulation", "wall_contacts", "impacts", "window", "cells",
                "n_particles", "wall_time_s", "compile_time_s"):
        assert key in summary
    assert set(summary["probes"]) == {"P1", "P2", "P3", "P4", "P5"}
    assert summary["window"]["snapshots"] == 4 * 8
    table = read_csv(out / "bulk_velocity.csv", cell_size=0.015)
    assert len(table) == summary["cells"]
    assert np.allclose(np.round(table.x / 0.015) * 0.015, table.x)
    # the bed's solid fraction where it is dense is the continuum's, about phi_c = 0.6
    dense = table.solid_fraction[table.z < 0.1]
    assert 0.5 < np.median(dense) < 0.7


def test_continuum_command_bad_input(run_cli, tmp_path):
    r = run_cli("continuum", "tub47-quick", "--method", "euler", "--out", tmp_path / "o")
    assert r.returncode == 2
    assert r.stderr.strip().splitlines() == [
        "error: --method = 'euler': must be lagrangian or eulerian"]
    r = run_cli("continuum", "tub47-quick", "--out", tmp_path / "o", "--calibration",
                tmp_path / "missing.toml")
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()
    r = run_cli("continuum", "tub47-quick", "--out", tmp_path / "o", "--damping-length", "-1")
    assert r.returncode == 2
    assert r.stderr.strip().splitlines() == [
        "error: damping_length = -1.0: must be a length > 0 m (or unset: the default grid's "
        "spacing)"]
    assert not (tmp_path / "o").exists()


# ----------------------------------------------------------------------------------------------
# the tub frame


def test_continuum_run_is_reproducible(tmp_path):
    """The same scenario gives the same numbers (DEVELOPERS.md): two runs write identical cell
    tables and summaries (wall times aside)."""
    from vibroflow.continuum.tub_run import run_continuum
    from vibroflow.scenario.io import load_scenario

    s = load_scenario("tub47-quick", ["run.duration=0.1", "run.average_last=0.1"])
    runs = []
    for k in range(2):
        summary = run_continuum(s, tmp_path / f"r{k}")
        for key in ("wall_time_s", "compile_time_s", "particle_steps_per_s",
                    "bulk_velocity_csv"):
            summary.pop(key)
        summary["continuum"].pop("wall_time_s")
        runs.append((summary, (tmp_path / f"r{k}" / "bulk_velocity.csv").read_bytes()))
    assert runs[0][1] == runs[1][1]
    assert runs[0][0] == runs[1][0]


# ----------------------------------------------------------------------------------------------
# checkpoints, resume, blow-ups, grid fields

def test_continuum_resume_gives_the_uninterrupted_numbers_bit_for_bit(tmp_path):
    """A run stopped twice (checkpoint, then resume) inside its averaging window, with
    checkpoints at every step in between, writes the same bulk_velocity.csv, summary (wall
    times aside) and ParaView files as the run never interrupted; a stopped run leaves no
    summary.json; a checkpoint of other options is refused."""
    import json

    from vibroflow.continuum.files import CHECKPOINT_NAME
    from vibroflow.continuum.formulation import formulation
    from vibroflow.continuum.tub_run import run_continuum
    from vibroflow.scenario.io import load_scenario

    over = ["run.duration=0.05", "run.average_last=0.043", "run.batches=2"]
    s = load_scenario("tub47-quick", over)
    full = run_continuum(s, tmp_path / "full", vtk=True)
    n_steps = full["steps"]
    split = tmp_path / "split"
    busy = load_scenario("tub47-quick", over + ["run.checkpoint_every=1e-9"])
    assert run_continuum(s, split, vtk=True, stop_after_steps=n_steps // 2 + 7) is None
    assert (split / CHECKPOINT_NAME).is_file() and not (split / "summary.json").exists()
    with pytest.raises(InputError, match="another scenario, calibration, method or options"):
        run_continuum(s, split, options=formulation("lagrangian").options(cfl=0.25), resume=True)
    assert run_continuum(busy, split, vtk=True, resume=True, stop_after_steps=60) is None
    resumed = run_continuum(s, split, vtk=True, resume=True)
    assert not (split / CHECKPOINT_NAME).exists()
    for summary in (full, resumed):
        for key in ("wall_time_s", "compile_time_s", "particle_steps_per_s",
                    "bulk_velocity_csv"):
            summary.pop(key)
        summary["continuum"].pop("wall_time_s")
    assert json.dumps(resumed, sort_keys=True) == json.dumps(full, sort_keys=True)
    for name in ("bulk_velocity.csv", "vtk/grid.pvd", "vtk/points.pvd", "vtk/grid_00010.vtr",
                 "vtk/points_00012.vtu"):
        assert (split / name).read_bytes() == (tmp_path / "full" / name).read_bytes(), name


def test_continuum_blowup_names_the_points_and_the_time_step():
    """A block dropped on a stiff plate with 30 times the stable time step blows up; the error
    names the points and says the time step is too large for the stiffness."""
    from vibroflow.continuum.mpm.solver import ContinuumBlowUp

    mat = ContinuumMaterial()
    dx = 0.01
    grid = Grid.covering(-0.1, 0.1, 0.0, 0.2, dx)
    x = lattice(-0.03, 0.03, 0.01, 0.05, dx / 2)
    kn = (mat.bulk_modulus + 4 * mat.shear_modulus / 3) / (dx / 2)
    plate = Plane((0.0, 0.0), (0.0, 1.0), kn, friction=0.3)
    dt = 30 * stable_dt(mat, dx, dx / 2, [plate])
    system = MPMSystem(grid, mat, dt, boundaries=[plate])
    state = init_state(system, x, (dx / 2) ** 2, mat.critical_density, v=np.tile([0.0, -1.0],
                                                                                (len(x), 1)))
    with pytest.raises(ContinuumBlowUp) as err:
        run_steps(system, state, 2000)
    message = str(err.value)
    assert "material point(s) " in message and f"of {len(x)})" in message
    assert "time step is too large for the stiffness" in message


def test_shear_rate_map_holds_both_measures_and_infers_impacts(tmp_path):
    """The continuum's shear-rate map (continuum.shear_outputs.write_shear_rate_csv): each analysis
    cell holds the phase-resolved field's cycle-mean shear rate at its centre (analysis.phase_shear:
    here a steady simple shear v_x = G z sampled on a lattice, so G at the interior cells) and the
    mean over samples of its points' instantaneous rates (Samples.add_cell_rates: a linear field a +
    b x over points symmetric in each cell gives a + b x_cell exactly); the impact columns are the
    calibrated c0 + c1 d gamma_dot of the phase-field rate, with the relation fitted on the
    continuum's measure (c0_cells_m_s, c1_cells) preferred to the fine one."""
    from vibroflow.measure.phase_shear import PhaseShearAccumulator
    from vibroflow.continuum.sampling import Samples
    from vibroflow.continuum.shear_outputs import impact_relation, write_shear_rate_csv
    from vibroflow.io.calibration_file import Calibration, ImpactRelation

    h, a, b, G, length = 0.015, 2.0, 40.0, 1.5, 0.0635
    s = Samples(2, 1, 1, cell_grid=(h, 6, 8))
    offsets = np.array([-0.25, 0.25]) * h
    cx, cz = np.meshgrid(np.arange(-2, 3) * h, np.arange(0, 3) * h, indexing="ij")
    px = (cx.ravel()[:, None] + offsets[None, :]).ravel()
    pz = np.repeat(cz.ravel(), 2)
    x = np.stack([px, pz], axis=1)
    for _ in range(2):
        s.add_cell_rates(x, a + b * x[:, 0])
    acc = PhaseShearAccumulator(h, 6, 8, length, 1, 1)
    xs = np.arange(-0.09, 0.0901, h / 3)
    zs = np.arange(0.0, 0.1201, h / 3)
    X, Z = np.meshgrid(xs, zs)
    pos = np.stack([X.ravel(), np.full(X.size, length / 2), Z.ravel()], axis=1)
    vel = np.zeros_like(pos)
    vel[:, 0] = G * pos[:, 2]
    acc.add(pos, vel, np.zeros(6), np.full(X.size, 0.6 * (h / 3) ** 2 * length), 0, 0)
    phase = acc.result()
    cal = Calibration.from_dict({
        "rheology": {"mu_s": 0.30, "mu_2": 0.55, "I_0": 0.3, "phi_max": 0.61, "phi_min": 0.5},
        "elastic": {"bulk_modulus_Pa": 2e6, "shear_modulus_Pa": 1e6},
        "wall": {"friction": 0.2},
        "media": {"diameter_m": 0.00635, "solid_density_kg_m3": 7800.0},
        "impacts": {"ball_ball": {"c0_m_s": 0.01, "c1": 3.0, "c0_cells_m_s": 0.005,
                                  "c1_cells": 4.0},
                    "ball_wall": {"c0_m_s": 0.02, "c1": 5.0}}})
    assert impact_relation(cal.impacts.ball_ball) == (0.005, 4.0, "c0_cells, c1_cells")
    assert impact_relation(cal.impacts.ball_wall) == (0.02, 5.0, "c0, c1")
    assert impact_relation(ImpactRelation(c0_m_s=float("nan"), c1=1.0)) == (None, None, "")
    assert impact_relation(None) == (None, None, "")
    d = 0.00635
    write_shear_rate_csv(tmp_path / "shear_rate.csv", s, phase, cal, d)
    rows = np.genfromtxt(tmp_path / "shear_rate.csv", delimiter=",", names=True)
    inst = rows["samples"] > 0
    assert inst.sum() == 15 and np.all(rows["samples"][inst] == 2)
    assert np.allclose(rows["instantaneous_shear_rate"][inst], a + b * rows["x"][inst], rtol=0,
                       atol=1e-12)
    # two spacings in from the lattice's edges (the tent average of a linear field is exact)
    inner = (np.abs(rows["x"]) <= 0.06 + 1e-9) & (rows["z"] >= 2 * h - 1e-9) & (
        rows["z"] <= 0.09 + 1e-9)
    assert inner.sum() >= 20
    assert np.allclose(rows["shear_rate"][inner], G, rtol=1e-9)
    got = np.isfinite(rows["shear_rate"])
    assert np.allclose(rows["impact_ball_ball"][got], 0.005 + 4.0 * d * rows["shear_rate"][got])
    assert np.allclose(rows["impact_ball_wall"][got], 0.02 + 5.0 * d * rows["shear_rate"][got])


# ----------------------------------------------------------------------------------------------
# the FLIP fraction of the points' velocity update (MPMSystem.flip, ContinuumOptions.flip)


# ----------------------------------------------------------------------------------------------
# the bed viscosity (stress_update.damped_stress): a Kelvin-Voigt standing shear wave


