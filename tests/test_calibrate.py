"""Checks of the calibration from a DEM run: the impact statistics
against kinetic theory, the wall-friction reduction against Coulomb's law and geometry, and the
`vibroflow calibrate` command end to end on a small tub run (its files, their units and
conservation of what the coarse-graining deposits).  The command's checks share one calibration
of the session's tiny study, which compiles the calibration's kernels on a fresh clone (about
two and a half minutes, against 40 s once numba's cache holds them): they are `slow`, so the
default suite stays under ten minutes there.
"""
from __future__ import annotations

import math
import os
import shutil
import subprocess
import sys

import h5py
import numpy as np
import pytest

from tests.cli_helpers import one_line_error
from tests.dem_helpers import D_STEEL, RHO_STEEL, Sim, ball, contact, one_thread, plane, scenario
from vibroflow.calibration.impacts import weighted_linear_fit
from vibroflow.calibration.wall_friction import wall_normal_tangent
from vibroflow.dem import simulate as S
from vibroflow.io.calibration_file import read_calibration

# a small but dense bed: 400 balls in a U of radius 4 cm, 8 whole cycles averaged, probes
# inside it (the tub47-quick tub would hold them as a fluidised film with no dense cell)
SMALL = ["fill.count=400", "tub.radius=0.04", "tub.rim_height=0.12", "fill.settle_time=0.1",
         "fill.max_settle_time=0.1", "run.duration=0.2", "run.average_last=0.17",
         "analysis.probes.P1.x=-0.03", "analysis.probes.P1.z=0.04",
         "analysis.probes.P2.z=0.04", "analysis.probes.P3.x=0.03", "analysis.probes.P3.z=0.04",
         "analysis.probes.P4.z=0.015", "analysis.probes.P5.z=0.06"]


# ----------------------------------------------------------------------------------------------
# Impact speeds of a Maxwellian gas (models.md "Impact velocity from the continuum")

@pytest.mark.slow
def test_impact_speeds_of_an_elastic_gas_follow_kinetic_theory():
    """In a gas of elastic spheres with a Maxwellian velocity distribution of temperature T
    (per-component variance), the normal approach speed u of the collisions is distributed as
    the collision flux weights it: f(u) ~ u exp(-u^2 / 4T) between two balls (relative velocity
    variance 2T per component) and f(u) ~ u exp(-u^2 / 2T) against a wall, so the mean impact
    speeds are sqrt(pi T) and sqrt(pi T / 2) (Chapman & Cowling; models.md).  The relations the
    calibration fits and the continuum uses rest on these; the DEM's impact recorder must
    reproduce them.  A box of 6 plane walls, no gravity, e = 1, random Maxwellian start."""
    rng = np.random.default_rng(7)
    L = 0.08          # box side (m): 216 balls at solid fraction 0.06 (a gas)
    n_side = 6
    sigma = 0.3       # m/s per component
    g = (np.arange(n_side) + 0.5) * L / n_side
    pos = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    vel = rng.normal(0.0, sigma, pos.shape)
    vel -= vel.mean(axis=0)
    balls = [ball(p, v) for p, v in zip(pos, vel)]
    walls = [plane((0, 0, 0), (1, 0, 0)), plane((L, 0, 0), (-1, 0, 0)),
             plane((0, 0, 0), (0, 1, 0)), plane((0, L, 0), (0, -1, 0)),
             plane((0, 0, 0), (0, 0, 1)), plane((0, 0, L), (0, 0, -1))]
    sc = scenario(balls, [contact(e=1.0, mu=0.0)], walls=walls, dt=2e-5, duration=10.0)
    sim = Sim(sc)
    # let the lattice start relax into a gas (a few collision times), then record
    sim.run(5000)
    rows = []
    temps = []
    for _ in range(100):
        with one_thread():  # a small system: threads would only wait on each other
            S.run_steps(sim.system, sim.state, 1000, record_impacts=True,
                        on_impacts=lambda imp: rows.append(imp.copy()))
        v = sim.state.vel
        temps.append(float(((v - v.mean(axis=0)) ** 2).sum(axis=1).mean() / 3.0))
    imp = np.concatenate(rows)
    T = float(np.mean(temps))
    kind = imp[:, 1].astype(int)
    bb = imp[kind == 0, 5]
    bw = imp[kind == 3, 5]
    assert bb.size > 5000 and bw.size > 3000, (bb.size, bw.size)
    # the sample means have relative standard errors of about 0.5/sqrt(n): below 1 %
    assert bb.mean() == pytest.approx(math.sqrt(math.pi * T), rel=0.03)
    assert bw.mean() == pytest.approx(math.sqrt(math.pi * T / 2.0), rel=0.03)


def test_weighted_linear_fit_recovers_known_coefficients_within_its_errors():
    rng = np.random.default_rng(3)
    x = np.linspace(0.0, 0.2, 40)
    w = rng.integers(50, 500, x.size).astype(float)
    noise = rng.normal(0.0, 0.01, x.size) / np.sqrt(w / 100.0)
    y = 0.05 + 0.8 * x + noise
    fit = weighted_linear_fit(x, y, w)
    assert abs(fit["c0"] - 0.05) < 4 * fit["c0_stderr"]
    assert abs(fit["c1"] - 0.8) < 4 * fit["c1_stderr"]
    assert fit["r2"] > 0.95
    through0 = weighted_linear_fit(x, 0.8 * x, w, intercept=False)
    assert through0["c1"] == pytest.approx(0.8, rel=1e-12)


def test_wall_normal_and_tangent_of_the_u_profile():
    R = 0.15
    # bottom: normal up, tangent +x; right side: normal -x, tangent up; left side: tangent down;
    # on the circle at 45 degrees right of the bottom: normal towards the centre (0, R)
    nx, nz, tx, tz = wall_normal_tangent([0.0, R, -R, R * math.sin(math.pi / 4)],
                                         [0.0, 0.3, 0.3, R - R * math.cos(math.pi / 4)], R)
    s = math.sqrt(0.5)
    assert np.allclose(nx, [0.0, -1.0, 1.0, -s])
    assert np.allclose(nz, [1.0, 0.0, 0.0, s])
    assert np.allclose(tx, [1.0, 0.0, 0.0, s])
    assert np.allclose(tz, [0.0, 1.0, -1.0, s])


# ----------------------------------------------------------------------------------------------
# `vibroflow calibrate` on a small tub run

def _cli(*args, env):
    return subprocess.run([sys.executable, "-m", "vibroflow.cli", *map(str, args)],
                          capture_output=True, text=True, env=env, stdin=subprocess.DEVNULL)


@pytest.fixture(scope="module")
def calibrated_run(study_run, tmp_path_factory):
    """`vibroflow calibrate` on a copy of the session's tiny study's DEM (tub47-quick with
    SMALL), as a DEM run folder of its own."""
    tmp = tmp_path_factory.mktemp("calibrate")
    env = dict(os.environ, VIBROFLOW_CACHE=str(tmp / "cache"), NO_COLOR="1")
    out = tmp / "run"
    shutil.copytree(study_run[1] / "dem", out, ignore=shutil.ignore_patterns("stage.json"))
    r = _cli("calibrate", out, env=env)
    assert r.returncode == 0, r.stderr
    return out, r


@pytest.mark.slow
def test_calibrate_writes_its_files_and_reads_back(calibrated_run):
    from vibroflow.calibration.run_fields import read_fields
    from vibroflow.io.calibration_file import read_calibration, write_calibration

    out, r = calibrated_run
    assert "wall friction (effective)" in r.stdout
    cal = read_calibration(out)
    for table in ("source", "media", "rheology", "elastic", "drucker_prager", "wall",
                  "partitions", "impacts"):
        assert getattr(cal, table) is not None, table
    assert cal.source.case == "tub47-quick"
    assert cal.media.diameter_m == pytest.approx(D_STEEL)
    # the partitions' friction along the mean flow is a projection of the tangential forces,
    # |F_t . u / |u|| <= |F_t|: never above their ratio of sums
    p = cal.partitions
    assert 0.0 < p.friction_along_flow <= p.friction
    assert p.friction_along_flow_stderr >= 0.0
    # each impact relation's intercept-slope covariance is one (|rho| <= 1): the jackknife's
    # sums are a sample covariance's
    rel = cal.impacts.ball_ball
    assert math.isfinite(rel.c0_c1_cells_covariance_m_s)
    for r in (cal.impacts.ball_ball, cal.impacts.ball_wall):
        for e0, e1, cov in ((r.c0_cells_stderr_m_s, r.c1_cells_stderr,
                             r.c0_c1_cells_covariance_m_s),
                            (r.c0_stderr_m_s, r.c1_stderr, r.c0_c1_covariance_m_s)):
            if math.isfinite(cov):
                assert abs(cov) <= e0 * e1 * (1.0 + 1e-9)
    # and each coefficient's covariance with the measured mean, which the same cycles move
    assert math.isfinite(rel.c0_cells_measured_covariance_m2_s2)
    assert math.isfinite(rel.c1_cells_measured_covariance_m_s)
    # the record written and read back is the same file
    write_calibration(out / "again.toml", cal)
    assert (out / "again.toml").read_bytes() == (out / "calibration.toml").read_bytes()
    (out / "again.toml").unlink()
    for name in ("fields.png", "mu_I.png", "wall_friction.png", "impacts.png"):
        p = out / "calibration" / name
        assert p.is_file() and p.stat().st_size > 10_000, name
    ds = read_fields(out / "fields.nc")
    assert ds["pressure"].attrs["units"] == "Pa"
    assert ds["velocity"].attrs["units"] == "m s-1"
    ph = read_fields(out / "fields.nc", phase_resolved=True)
    assert ph.sizes["phase"] == 8
    # the thermal temperature beside the phase-resolved one, with its units and errors
    assert ph["thermal_temperature"].attrs["units"] == "m2 s-2"
    assert "thermal_temperature_stderr" in ph
    assert ds["thermal_temperature_cycle_mean"].attrs["units"] == "m2 s-2"
    # the cycle-mean shear rate's jackknife error, wherever the bed is dense and sampled in
    # every batch, is a finite positive fraction of the value (tests/test_cycle_mean_errors.py)
    se = ds["shear_rate_cycle_mean_stderr"].values
    dense = (ds["solid_fraction"].values > 0.4) & np.isfinite(se)
    assert dense.sum() > 20
    assert np.all(se[dense] > 0.0)
    assert np.median(se[dense] / ds["shear_rate_cycle_mean"].values[dense]) < 0.5
    assert not list(out.glob("*.tmp*"))


@pytest.mark.slow
def test_continuum_gets_the_cyclic_secant_modulus_at_the_tubs_strain(calibrated_run):
    """The continuum's shear modulus is the cyclic shear cell's secant modulus at the strain
    amplitude the bed's measured cycle-mean shear rate implies (gamma_0 = pi gamma_dot / (2
    omega)), below the small-strain modulus (modulus reduction), and between the measured
    amplitudes' moduli."""
    import math

    from vibroflow.io.calibration_file import read_calibration

    out, r = calibrated_run
    cal = read_calibration(out)
    cs, el = cal.cyclic_shear, cal.elastic
    f = cs.frequency_Hz
    assert cs.tub_strain_amplitude == pytest.approx(
        math.pi * cs.tub_shear_rate_cycle_mean_1_s / (4 * math.pi * f))
    assert el.shear_modulus_Pa == pytest.approx(cs.secant_shear_modulus_at_tub_amplitude_Pa)
    assert el.shear_modulus_Pa < el.shear_modulus_small_strain_Pa
    amps, G = cs.strain_amplitude, cs.secant_shear_modulus
    assert amps == sorted(amps)
    # the reduction curve, over amplitudes far enough apart to beat the cycle-to-cycle scatter
    assert all(G[j] < G[i] for i in range(len(amps)) for j in range(len(amps))
               if amps[j] >= 2.5 * amps[i])
    assert "cyclic secant" in r.stdout


@pytest.mark.slow
def test_the_unloading_modulus_reads_the_same_strain_from_the_packing_and_the_divergence(
        calibrated_run):
    """Mass conservation, d ln phi / dt = -div v following the solid: the unloading modulus with
    the strain from the solid fraction's material change and with the strain from the
    coarse-grained velocity's divergence are one quantity measured twice (within 15%; 7% on
    tub47-quick's 1.5 s run); the pressure falls along the branch."""
    from vibroflow.io.calibration_file import read_calibration

    out, r = calibrated_run
    e = read_calibration(out).elastic
    K = e.unloading_bulk_modulus_Pa
    assert K > 0 and e.unloading_bulk_modulus_stderr_Pa > 0
    assert e.unloading_bulk_modulus_divergence_Pa == pytest.approx(K, rel=0.15)
    assert (e.unloading_release_pressure_Pa < e.unloading_start_pressure_Pa
            <= e.unloading_peak_pressure_Pa)
    assert "unloading bulk modulus" in r.stdout + r.stderr


@pytest.mark.slow
def test_the_vibrating_walls_drive_the_bed_and_its_restitution_is_the_contact_laws(
        calibrated_run):
    """[kinetic]: over steady cycles the walls' lab-frame work on the balls is what the bed
    dissipates, so it is positive; e is the scenario's ball-ball restitution."""
    from vibroflow.io.calibration_file import read_calibration

    out, _ = calibrated_run
    kin = read_calibration(out).kinetic
    assert kin is not None and kin.restitution == pytest.approx(0.85)
    assert 0.1 < kin.phi_rcp <= 0.7405 and kin.phi_rcp_stderr > 0
    w = kin.wall_flux
    arc_area = (w.arc_edges_m[-1] - w.arc_edges_m[0]) * w.length_m
    drive = w.u_drive_flux_W_m2 * arc_area + w.partitions_drive_flux_W_m2 * w.partition_area_m2
    drive_se = math.hypot(w.u_drive_flux_stderr_W_m2 * arc_area,
                          w.partitions_drive_flux_stderr_W_m2 * w.partition_area_m2)
    assert drive > 2 * drive_se
    # the fluxes by arc average to the whole U's (equal arc bins)
    assert np.mean(w.u_fluctuation_flux_by_arc_W_m2) == pytest.approx(
        w.u_fluctuation_flux_W_m2, rel=1e-9)
    # wall_feed.csv: the U's by phase, and the regions' fluxes (measure.floor_force) weighted
    # by their bins' arc length make the whole U's again
    from vibroflow.measure.floor_force import dem_wall_feed, region_of
    from vibroflow.scenario.io import load_scenario
    from vibroflow.tub.geometry import geometry_of

    R = geometry_of(load_scenario("tub47-quick")).radius
    rows = np.genfromtxt(out / "wall_feed.csv", delimiter=",", names=True)
    np.testing.assert_allclose(rows["u_wall_W_m2"], w.u_fluctuation_flux_by_phase_W_m2)
    edges = np.asarray(w.arc_edges_m)
    reg = region_of(0.5 * (edges[1:] + edges[:-1]), R)
    lengths = np.array([np.diff(edges)[reg == r].sum() for r in range(3)])
    by_region = dem_wall_feed(w, R)["by_region_W_m2"]
    held = lengths > 0
    assert np.sum(by_region[held] * lengths[held]) / lengths.sum() == pytest.approx(
        w.u_fluctuation_flux_W_m2, rel=1e-9)


@pytest.mark.slow
def test_calibrated_wall_friction_obeys_coulomb(calibrated_run):
    """Every contact has |F_t| <= mu F_n, so the ratio of sums and the coherent friction of
    slipping patches cannot exceed the contact's mu; sliding contacts sit exactly at mu (to the
    float32 of dem.h5)."""
    from vibroflow.io.calibration_file import read_calibration

    out, _ = calibrated_run
    cal = read_calibration(out)
    w = cal.wall
    mu = w.contact_friction
    assert mu == pytest.approx(0.40)
    assert 0.0 < w.ratio_of_sums <= mu * (1 + 1e-5)
    assert w.friction == w.ratio_of_sums
    if math.isfinite(w.coherent_slip_friction):
        assert w.coherent_slip_friction <= mu * (1 + 1e-5)
    with h5py.File(out / "dem.h5") as f:
        fn = f["wall_contacts/fn"][()]
        ft = f["wall_contacts/ft"][()]
        sl = f["wall_contacts/sliding"][()]
        wall = f["wall_contacts/wall"][()]
    use = (fn > 0) & (wall == 0)
    assert np.all(ft[use] <= mu * fn[use] * (1 + 1e-5))
    slide = use & sl
    assert slide.any()
    assert np.allclose(ft[slide] / fn[slide], mu, rtol=1e-4)


@pytest.mark.slow
def test_coarse_grained_fields_of_the_run_conserve_mass_and_momentum(calibrated_run):
    """The fields integrate back to what was deposited: the integral of rho over the x-z plane
    times L_y is the balls' mass, and the integral of the momentum density the balls' momentum
    relative to the tub (the time average over the window's snapshots), computed here from
    dem.h5 independently of the calibration code."""
    from vibroflow.measure.stats import batches_of_whole_cycles
    from vibroflow.calibration.run_fields import read_fields
    from vibroflow.tub.motion import relative_velocity_tub_axes_np

    out, _ = calibrated_run
    ds = read_fields(out / "fields.nc")
    h = float(ds.attrs["cell_size_m"])
    depth = float(ds.attrs["depth_m"])
    with h5py.File(out / "dem.h5") as f:
        r = f["particles/radius"][()]
        m = 4.0 / 3.0 * math.pi * r**3 * RHO_STEEL
        t = f["snapshots/time"][()]
        use = batches_of_whole_cycles(t, 0.03, 0.2, 47.0, 4) >= 0
        mom, absmom = [], []
        for s in np.nonzero(use)[0]:
            X, Z, th, Xd, Zd, thd = f["snapshots/tub_pose"][s]
            v = relative_velocity_tub_axes_np(f["snapshots/position"][s].astype(float),
                                              f["snapshots/velocity"][s].astype(float),
                                              X, Z, th, Xd, Zd, thd, (0.0, -0.10))
            mom.append((m[:, None] * v).sum(axis=0))
            absmom.append(float((m * np.linalg.norm(v, axis=1)).sum()))
    mass = float(ds["density"].sum()) * h * h * depth
    assert mass == pytest.approx(m.sum(), rel=3e-3)  # a sum over grid points
    P = (ds["density"].values[..., None] * ds["velocity"].fillna(0.0).values).sum(axis=(0, 1))
    P *= h * h * depth
    ref = np.mean(mom, axis=0)
    scale = float(np.mean(absmom))
    assert np.all(np.abs(P - ref) <= 3e-3 * scale + 1e-12)


@pytest.mark.slow
def test_the_calibration_records_the_runs_scenario_and_continuum_like_takes_both(
        calibrated_run, tmp_path):
    """[scenario] holds the run's media and tub (set on the command line of `vibroflow dem`);
    `vibroflow continuum --like RUN_DIR` runs that scenario with that calibration, and a --set on
    top that changes the tub is refused by the calibration's check."""
    out, _ = calibrated_run
    cal = read_calibration(out)
    assert list(cal.to_toml_dict())[-1] == "scenario"
    assert cal.scenario.case == "tub47-quick"
    assert (cal.scenario.tub.radius_m, cal.scenario.tub.rim_height_m) == (0.04, 0.12)
    assert cal.scenario.media.diameter_m == pytest.approx(D_STEEL)
    assert cal.scenario.media.density_kg_m3 == pytest.approx(RHO_STEEL)
    env = dict(os.environ, VIBROFLOW_CACHE=str(tmp_path / "cache"), NO_COLOR="1")
    line = one_line_error(_cli("continuum", "--like", out, "--set", "tub.radius=0.05",
                               "-o", tmp_path / "other", env=env))
    assert "scenario.tub.radius_m = 0.04" in line and "0.05" in line
    assert str(out / "calibration.toml") in line
    r = _cli("continuum", "--like", out, "--stop-after-steps", "0", "-o", tmp_path / "like",
             env=env)
    assert r.returncode == 0, r.stderr
    assert "warning" not in r.stderr
    x = np.load(tmp_path / "like" / "checkpoint.npz")["state/x"]
    assert 0.03 < np.abs(x[:, 0]).max() <= 0.04  # the run's tub (radius 0.04 m), not tub47's


def test_calibrate_bad_input_is_one_line_exit_2(tmp_path):
    env = dict(os.environ, NO_COLOR="1")
    r = _cli("calibrate", tmp_path / "nowhere", env=env)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "RUN_DIR" in r.stderr
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "dem.h5").write_text("not hdf5")
    r = _cli("calibrate", bad, env=env)
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert "Traceback" not in r.stderr
    assert not (bad / "calibration.toml").exists()
