"""The continuum's tub runs and `vibroflow continuum`, both formulations.

The command writes what the DEM's analysis reads (summary.json with the DEM's keys,
bulk_velocity.csv on the 15 mm cells, ParaView files); bad input is one line; a run is
reproducible, and a run stopped and resumed gives the uninterrupted numbers bit for bit; a
blow-up names its points; the shear-rate map holds both measures and infers the impact speeds;
the Eulerian cells' samples read a uniform bed as uniform.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

from continuum_helpers import METHODS, THREE_CYCLES, lattice
from cli_helpers import one_line_error
from vibroflow.continuum.boundary import Plane
from vibroflow.continuum.constitutive import ContinuumMaterial
from vibroflow.continuum.grid import Grid
from vibroflow.continuum.mpm.solver import MPMSystem, init_state, run_steps
from vibroflow.continuum.timestep import stable_dt
from vibroflow.errors import InputError

CALIBRATION = ("[source]\nrun = \"runs/seed3/dem\"\ncase = \"tub47-quick\"\n"
               "[rheology]\nmu_s = 0.35\nmu_2 = 0.60\nI_0 = 0.3\nphi_max = 0.61\n"
               "phi_min = 0.45\ncritical_solid_fraction = 0.61\n"
               "[elastic]\nbulk_modulus_Pa = 4.0e6\nshear_modulus_Pa = 1.5e6\n"
               "[wall]\nfriction = 0.3\n[partitions]\nfriction = 0.1\n"
               "[media]\ndiameter_m = 0.00635\nsolid_density_kg_m3 = 7800.0\n"
               "[impacts.ball_ball]\nc0_m_s = 0.05\nc1 = 0.8\n")


# ----------------------------------------------------------------------------------------------
# the command

def _check_lab_grid(vdir, scenario, dx):
    """The lab-frame grid files: taken back to the tub frame by the hand-written motion
    (tests/test_vtk_frame.hand_motion) the nodes lie on a lattice of spacing dx, and the lab
    velocity minus R(theta) (the velocity relative to the tub) is the tub's rigid velocity."""
    from tests.test_vtk_frame import hand_motion
    from tests.vtk_reader import read_pvd, read_vtk

    m = scenario.motion
    entries = read_pvd(vdir / "grid.pvd")
    assert len(entries) == 8 and all(f.endswith(".vts") for _, f in entries)
    assert [f for _, f in read_pvd(vdir / "tub.pvd")] == [f"tub_{f[5:10]}.vtu" for _, f in entries]
    t, name = entries[3]
    d = read_vtk(vdir / name)
    assert d["kind"] == "StructuredGrid" and d["FieldData"]["time_s"][0] == t
    X, Z, th, Xd, Zd, thd = hand_motion(m, t)
    c, s = np.cos(th), np.sin(th)
    p = d["Points"]["points"]
    rx, rz = p[:, 0] - X - m.pivot[0], p[:, 2] - Z - m.pivot[1]
    for q in (m.pivot[0] + c * rx + s * rz, m.pivot[1] - s * rx + c * rz):
        k = (q - q.min()) / dx
        assert np.abs(k - np.round(k)).max() < 1e-9 and np.ptp(k) > 10
    pd = d["PointData"]
    u, v = pd["velocity_relative_m_per_s"], pd["velocity_lab_m_per_s"]
    assert np.abs(v[:, 0] - u[:, 0] - (Xd - thd * rz)).max() < 1e-12
    assert np.abs(v[:, 2] - u[:, 2] - (Zd + thd * rx)).max() < 1e-12
    assert {"solid_fraction", "density_kg_per_m3", "pressure_Pa", "shear_rate_per_s"} <= set(pd)


@pytest.mark.parametrize("method", METHODS)
def test_continuum_command_writes_dem_comparable_results(method, run_cli, tmp_path):
    """`vibroflow continuum --method METHOD --vtk` on a short tub47-quick: summary.json with the
    DEM's keys (and the same keys for both formulations), bulk_velocity.csv on the 15 mm cells
    with the bed's solid fraction where it is dense (about phi_c = 0.6), the grid fields at the
    8 samples of the last cycle, no checkpoint left.  The Lagrangian run (0.15 s, 4 cycles
    averaged) takes a calibration of its own, which its summary reads back with the impact
    speeds it infers and the points' ParaView files; the Eulerian run (three cycles on a coarse
    mesh) has the Lagrangian run's keys and conserves its mass to round-off."""
    from vibroflow.continuum.formulation import formulation
    from vibroflow.continuum.tub_run import run_continuum
    from vibroflow.measure.bulk import read_csv
    from vibroflow.scenario.io import load_scenario

    out = tmp_path / "cont"
    if method == "lagrangian":
        cal = tmp_path / "calibration.toml"
        cal.write_text(CALIBRATION)
        args = ["--calibration", cal, "--set", "run.duration=0.15", "--set",
                "run.average_last=0.1"]
        snapshots = 4 * 8
    else:
        args = ["--dx", "0.015", "--vtk-frame", "lab",
                *(a for s in THREE_CYCLES for a in ("--set", s))]
        snapshots = 16
    r = run_cli("continuum", "tub47-quick", "--method", method, "--out", out, "--vtk", *args)
    assert r.returncode == 0, r.stderr
    assert "circulation" in r.stdout
    summary = json.loads((out / "summary.json").read_text())
    cont = summary["continuum"]
    assert summary["method"] == method
    for key in ("probes", "circulation", "wall_contacts", "impacts", "window", "cells",
                "n_particles", "wall_time_s", "compile_time_s"):
        assert key in summary
    assert set(summary["probes"]) == {"P1", "P2", "P3", "P4", "P5"}
    assert set(cont["probes"]) == {"P1", "P2", "P3", "P4", "P5"}
    assert cont["shear_rate"]["mean_1_s"] > 0
    # the DEM run its calibration was measured on, for `vibroflow compare`'s ensembles
    if method == "lagrangian":
        assert cont["calibration"] == {"source_run": "runs/seed3/dem",
                                       "source_case": "tub47-quick", "created": None}
    else:
        assert "calibration" not in cont
    # the options as run, the command line's among them, for the ensembles' grouping
    assert cont["options"]["dx"] == (0.015 if method == "eulerian" else None)
    assert cont["options"]["temperature"] is False and cont["options"]["cfl"] > 0
    assert summary["window"]["snapshots"] == snapshots
    table = read_csv(out / "bulk_velocity.csv", cell_size=0.015)
    assert len(table) == summary["cells"]
    # its batches beside it: a standard error for every cell, in bulk_velocity.csv's order
    se = (out / "bulk_velocity_stderr.csv").read_text().splitlines()
    assert se[0] == "x,z,vx_stderr_m_s,vz_stderr_m_s,solid_fraction_stderr,batches"
    cells = np.loadtxt(out / "bulk_velocity_stderr.csv", delimiter=",", skiprows=1, ndmin=2,
                       usecols=(0, 1))
    assert np.array_equal(cells, np.column_stack([table.x, table.z]))
    assert np.allclose(np.round(table.x / 0.015) * 0.015, table.x)
    # the bed's solid fraction where it is dense is the continuum's, about phi_c = 0.6
    dense = table.solid_fraction[table.z < 0.1]
    assert 0.5 < np.median(dense) < 0.7
    # ParaView: the grid fields at the 8 samples of the last cycle in a collection, and the
    # tub: in the tub frame rectilinear grids and one surface (Lagrangian run), in the lab
    # frame (Eulerian run) structured grids turned with the tub and a surface at each sample
    vdir = out / "vtk"
    assert (vdir / "grid.pvd").read_text().count("grid_0") == 8
    if method == "lagrangian":
        assert len(list(vdir.glob("grid_*.vtr"))) == 8
        assert (vdir / "tub.vtu").is_file()
    else:
        _check_lab_grid(vdir, load_scenario("tub47-quick", THREE_CYCLES), 0.015)
    assert not (out / "checkpoint.npz").exists()
    # the stress map: the shear-rate map's cells, at the phases sampled, nowhere in tension
    # (disconnected material carries none) and within the yield cone: tau_eq <= mu_2 p at
    # every point after its return map, so at their volume-weighted and sample means too,
    # tau_eq being a norm (the Eulerian remap mixes neighbouring cells' stresses after it,
    # which leaves a nearly unloaded cell a little outside until its next step: its cells
    # under a thousandth of the largest pressure are left out)
    st = np.genfromtxt(out / "stress.csv", delimiter=",", names=True)
    rates = np.genfromtxt(out / "shear_rate.csv", delimiter=",", names=True)
    assert set(zip(st["x"], st["z"])) <= set(zip(rates["x"], rates["z"]))
    assert set(st["phase"].astype(int)) == set(range(8))
    p_max = st["pressure"].max()
    assert p_max > 0.0 and st["pressure"].min() >= -1e-9 * p_max
    loaded = st["pressure"] > (1e-3 * p_max if method == "eulerian" else 0.0)
    assert loaded.sum() > 20
    assert st["friction_coefficient"][loaded].max() <= cont["material"]["mu_2"] * (1.0 + 1e-9)
    if method == "lagrangian":
        assert (cont["material"]["mu_s"], cont["material"]["bulk_modulus"]) == (0.35, 4.0e6)
        assert (cont["wall_friction"], cont["partition_friction"]) == (0.3, 0.1)
        # impact speed through the calibrated relation v = c0 + c1 d gamma_dot (the
        # phase-resolved field's shear rate, solid-fraction weighted over the cells)
        v = cont["impacts_from_shear_rate"]["ball_ball_mean_normal_speed_m_s"]
        assert v == pytest.approx(0.05 + 0.8 * 0.00635 * cont["shear_rate"]["mean_1_s"],
                                  rel=1e-9)
        assert summary["impacts"]["ball_ball_mean_normal_speed"] == pytest.approx(v, rel=1e-12)
        # the points at the 8 samples of the last cycle and their collection
        assert len(list((out / "vtk").glob("points_*.vtu"))) == 8
        assert (out / "vtk" / "points.pvd").is_file()
    else:
        lag = run_continuum(load_scenario("tub47-quick", THREE_CYCLES), tmp_path / "lag",
                            options=formulation("lagrangian").options(dx=0.015))
        assert set(summary) == set(lag)
        assert set(lag["continuum"]) <= set(summary["continuum"])
        assert set(summary["probes"]) == set(lag["probes"]) == {"P1", "P2", "P3", "P4", "P5"}
        assert summary["window"]["snapshots"] == lag["window"]["snapshots"] == 16
        assert abs(cont["mass_error"]) < 1e-12 and cont["mass_error_max_abs"] < 1e-12


@pytest.mark.parametrize("args, line", [
    pytest.param(["--method", "euler"],
                 "error: --method = 'euler': must be lagrangian or eulerian",
                 id="unknown-method"),
    pytest.param(["--calibration", "{tmp}/missing.toml"], None, id="missing-calibration"),
    pytest.param(["--damping-length", "-1"],
                 "error: damping_length = -1.0: must be a length > 0 m (or unset: the default "
                 "grid's spacing)",
                 id="negative-damping-length"),
    pytest.param(["--method", "eulerian", "--dx", "0.007"],
                 "error: dx = 0.007 m: must divide the tub's width 0.3 m into whole cells of "
                 "dx/2",
                 id="eulerian-mesh-that-does-not-fit-the-tub"),
])
def test_continuum_command_bad_input(args, line, run_cli, tmp_path):
    """An unknown method, a missing calibration file, a bad option, a mesh that does not fit
    the tub: one line naming the value and what is allowed, exit code 2, nothing written."""
    r = run_cli("continuum", "tub47-quick", "--out", tmp_path / "o",
                *(a.format(tmp=tmp_path) for a in args))
    got = one_line_error(r)
    if line is not None:
        assert got == line
    assert not (tmp_path / "o").exists()


# ----------------------------------------------------------------------------------------------
# reproducible, resumable

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


#: per formulation: the scenario's overrides (4 cycles averaged in 2 batches, ~50 ms of
#: vibration; three cycles, the last two averaged in 2 batches), the options, the ParaView files
#: compared besides bulk_velocity.csv (tub frame, lab frame)
RESUMES = {
    "lagrangian": (["run.duration=0.05", "run.average_last=0.043", "run.batches=2"], {},
                   ("vtk/grid.pvd", "vtk/points.pvd", "vtk/grid_00010.vtr",
                    "vtk/points_00012.vtu"), "tub"),
    "eulerian": (THREE_CYCLES, {"dx": 0.015}, ("vtk/grid.pvd", "vtk/tub.pvd",
                                               "vtk/grid_00010.vts", "vtk/tub_00012.vtu"), "lab"),
}


@pytest.mark.parametrize("method", METHODS)
def test_continuum_resume_gives_the_uninterrupted_numbers_bit_for_bit(method, tmp_path):
    """A run stopped twice (checkpoint, then resume) inside its averaging window, with
    checkpoints at every step in between, writes the same bulk_velocity.csv with its batches
    (bulk_velocity_stderr.csv, bulk_velocity_batches.csv), stress map, summary (wall times aside) and
    ParaView files as the run never interrupted; a stopped run leaves no
    summary.json; a checkpoint of other options is refused."""
    from vibroflow.continuum.files import CHECKPOINT_NAME
    from vibroflow.continuum.formulation import formulation
    from vibroflow.continuum.tub_run import run_continuum
    from vibroflow.io.vtk_frame import VtkOptions
    from vibroflow.scenario.io import load_scenario

    over, kw, vtk_files, frame = RESUMES[method]
    vtk = VtkOptions(frame=frame)
    opt = formulation(method).options(**kw) if kw else None
    s = load_scenario("tub47-quick", over)
    full = run_continuum(s, tmp_path / "full", method, options=opt, vtk=vtk)
    n_steps = full["steps"]
    split = tmp_path / "split"
    busy = load_scenario("tub47-quick", over + ["run.checkpoint_every=1e-9"])
    assert run_continuum(s, split, method, options=opt, vtk=vtk,
                         stop_after_steps=n_steps // 2 + 7) is None
    assert (split / CHECKPOINT_NAME).is_file() and not (split / "summary.json").exists()
    with pytest.raises(InputError, match=r"the checkpoint of another run \(options\.cfl = "
                                         r"0\.3 there, 0\.25 now\)"):
        run_continuum(s, split, method, options=formulation(method).options(**kw, cfl=0.25),
                      resume=True)
    assert run_continuum(busy, split, method, options=opt, vtk=vtk, resume=True,
                         stop_after_steps=60) is None
    resumed = run_continuum(s, split, method, options=opt, vtk=vtk, resume=True)
    assert not (split / CHECKPOINT_NAME).exists()
    for summary in (full, resumed):
        for key in ("wall_time_s", "compile_time_s", "particle_steps_per_s",
                    "bulk_velocity_csv"):
            summary.pop(key)
        summary["continuum"].pop("wall_time_s")
    assert json.dumps(resumed, sort_keys=True) == json.dumps(full, sort_keys=True)
    for name in ("bulk_velocity.csv", "bulk_velocity_stderr.csv",
                 "bulk_velocity_batches.csv", "stress.csv", "stress_batches.csv") + vtk_files:
        assert (split / name).read_bytes() == (tmp_path / "full" / name).read_bytes(), name


# ----------------------------------------------------------------------------------------------
# what a run reports: blow-ups, the shear-rate map, the Eulerian cells' samples

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



def test_sampled_solid_fraction_is_even_on_cells_that_do_not_divide_the_analysis_cell(
        tmp_path, monkeypatch):
    """The pseudo-balls of the mesh's cells are spread over each cell by the samples' R2 offsets
    (eulerian.formulation.cell_offset), so a uniform bed reads as uniform on the 15 mm analysis
    cells even when the mesh's cells (9.375 mm at the default dx of tub47-quick, 18.75 mm) do not
    divide them: some analysis cells cover two rows of cell centres, some one. With the balls at the
    fixed centres the bed's interior is striped (on tub47: 0.62 +- 0.27, the DEM's +- 0.006);
    spread, over this short run's 16 samples, it is even to the samples' resolution."""
    import vibroflow.continuum.eulerian.formulation as ER
    from vibroflow.continuum.tub_run import run_continuum
    from vibroflow.measure.bulk import read_csv
    from vibroflow.scenario.io import load_scenario

    offsets = np.array([ER.cell_offset(j) for j in range(512)])
    assert np.all(np.abs(offsets) <= 0.5)
    # low discrepancy: every quarter of the cell holds a quarter of the offsets, to 2 %
    quarters = np.histogram2d(offsets[:, 0], offsets[:, 1], bins=2, range=[[-0.5, 0.5]] * 2)[0]
    assert np.allclose(quarters / 512, 0.25, atol=0.005)

    def interior(out):
        table = read_csv(out / "bulk_velocity.csv", cell_size=0.015)
        inner = (table.z > 0.03) & (table.z < 0.12) & (np.abs(table.x) < 0.08)
        return table.solid_fraction[inner]

    scenario = load_scenario("tub47-quick", THREE_CYCLES)
    run_continuum(scenario, tmp_path / "spread", "eulerian")
    spread = interior(tmp_path / "spread")
    monkeypatch.setattr(ER, "cell_offset", lambda j: (0.0, 0.0))
    run_continuum(scenario, tmp_path / "centres", "eulerian")
    centres = interior(tmp_path / "centres")
    print(f"\ninterior solid fraction: spread {spread.mean():.3f} +- {spread.std():.3f}, "
          f"at the centres {centres.mean():.3f} +- {centres.std():.3f}")
    assert spread.size >= 40
    assert 0.55 < spread.mean() < 0.65
    assert spread.std() < 0.08 and spread.std() < centres.std() / 3




@pytest.mark.slow
def test_resume_of_a_finished_run_says_so_and_reruns_nothing(run_cli, tmp_path):
    """--resume on a folder whose run finished (summary.json, no checkpoint) keeps the results
    as they are and says the run is finished; on another formulation's finished run it is a
    one-line error (exit 2) that leaves the folder alone."""
    out = tmp_path / "cont"
    args = ["--dx", "0.015", *(a for s in THREE_CYCLES for a in ("--set", s))]
    r = run_cli("continuum", "tub47-quick", "--method", "eulerian", "--out", out, *args)
    assert r.returncode == 0, r.stderr
    before = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()}
    r = run_cli("continuum", "tub47-quick", "--method", "eulerian", "--out", out, "--resume",
                *args)
    assert r.returncode == 0, r.stderr
    assert "finished already" in r.stdout + r.stderr
    assert {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()} == before
    r = run_cli("continuum", "tub47-quick", "--method", "lagrangian", "--out", out, "--resume",
                *args)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "holds the finished eulerian run" in lines[0], r.stderr
    assert {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()} == before
