"""Parts in the continuum against known answers: a layer on a part's flat top carries its weight
onto the part (both formulations); no material point ends inside a part, no Eulerian cell inside
one ever holds material; a bed on a part in a tub shaken up and down stays at rest relative to
the tub and the part feels m (g + Z''); the impact speed inferred by patch is the calibrated
relation applied to the surface nodes' shear rate (hand computed); parts.nc's force by phase is
the mean of the samples in each phase; a part the 2D continuum cannot take is a one-line error;
the torque of a layer on a part about a centre beside it is its weight times the lever arm.
"""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from continuum_helpers import G_ACC, lattice
from vibroflow.continuum.boundary import PartWall, UWall
from vibroflow.continuum.constitutive import ContinuumMaterial
from vibroflow.continuum.eulerian import solver as eulerian
from vibroflow.continuum.eulerian.mesh import EulerianMesh
from vibroflow.continuum.eulerian.solver import EulerianSystem
from vibroflow.continuum.eulerian.wall import (MeshWall, wall_force_on_material,
                                               wall_forces_by_cell)
from vibroflow.continuum.grid import Grid
from vibroflow.continuum.grid_update import LabFrame, TubFrame
from vibroflow.continuum.mpm.solver import MPMSystem, init_state, run_steps
from vibroflow.continuum.part_obstacle import (continuum_parts, packed_section,
                                               section_area_below, torque_on_part)
from vibroflow.continuum.part_outputs import part_dataset, patch_weights
from vibroflow.continuum.sampling import Samples
from vibroflow.continuum.timestep import stable_dt
from vibroflow.errors import InputError
from vibroflow.io.calibration_file import ImpactRelation
from vibroflow.io.parts_file import MAX_PATCHES, read_parts, write_parts
from vibroflow.measure.phase_shear import PhaseShear
from vibroflow.scenario.model import Scenario
from vibroflow.tub.geometry import TubGeometry
from vibroflow.tub.motion import TubMotion, pose
from vibroflow.tub.parts import Part, pack

#: a small U (m) and a box across it whose flat top is at z = R, where the U's sides turn
#: vertical: a layer on it between frictionless sides rests on the part alone
R, L_Y = 0.05, 0.02
GEO = TubGeometry(radius=R, rim_height=0.1, length=L_Y)
SHELF = Part(name="shelf", shape="box", center=(0.0, 0.5 * L_Y, R - 0.005), material="steel",
             half_size=(R + 0.01, 0.5 * L_Y, 0.005))
MAT = ContinuumMaterial(bulk_modulus=1e6, shear_modulus=5e5)
DX = 0.005
H_LAYER = 0.02
#: the torque's lever arm: the shelf's centre taken OFFSET_M along +x (the same top face, still
#: spanning the U): the layer, resting symmetrically about x = 0, presses its weight W at
#: r_x = -OFFSET_M from that centre, (r x F)_y = -r_x F_z = -OFFSET_M W
OFFSET_M = 0.01
OFFSET_SHELF = Part(name="shelf", shape="box",
                    center=(OFFSET_M, SHELF.center[1], SHELF.center[2]), material="steel",
                    half_size=SHELF.half_size)


def _mpm_layer_on_shelf(frame):
    """(system, state, part wall) of the material points: a layer H_LAYER deep on the shelf's
    top, frictionless U and shelf (the same wall law)."""
    sp = 0.5 * DX
    grid = Grid.covering(-R, R, 0.0, GEO.rim_height, DX)
    kn = (MAT.bulk_modulus + 4 * MAT.shear_modulus / 3) / sp
    packed = packed_section((SHELF,))
    u = UWall(radius=R, stiffness=kn, friction=0.0, damping_ratio=0.5)
    part = PartWall(name="shelf", packed=packed, index=0, y=0.5 * L_Y, stiffness=kn,
                    friction=0.0, damping_ratio=0.5)
    system = MPMSystem(grid, MAT, stable_dt(MAT, DX, sp, [u, part]), frame=frame,
                       boundaries=[u, part])
    x = lattice(-R + 0.25 * sp, R - 0.25 * sp, R, R + H_LAYER, sp)
    rho_c = MAT.critical_density
    p = rho_c * G_ACC * (R + H_LAYER - x[:, 1])
    stress = np.zeros((len(x), 4))
    stress[:, 1] = -p
    stress[:, 0] = stress[:, 3] = -(1 - math.sin(math.atan(MAT.mu_s))) * p
    state = init_state(system, x, sp * sp, rho_c, stress=stress)
    return system, state, part


def test_mpm_layer_on_a_part_carries_its_weight_and_no_point_enters_it():
    """The material points' layer on the shelf: after settling, the wall law's force on the
    part is the layer's weight per metre, downwards (within 1 %), its torque about a centre
    OFFSET_M along x is -OFFSET_M W (within 2 %), and no point's centre ever lies inside the
    part."""
    system, state, part = _mpm_layer_on_shelf(LabFrame((0.0, -G_ACC)))
    least = [np.inf]

    def watch(s):
        least[0] = min(least[0], float(part.gap(s.x).min()))

    run_steps(system, state, int(0.08 / system.dt), watch)
    force_on_part = -state.history[part.slot]["f"].sum(axis=0)
    weight = state.mass.sum() * G_ACC
    assert force_on_part[1] == pytest.approx(-weight, rel=0.01)  # pressed down
    assert abs(force_on_part[0]) < 1e-6 * weight
    assert least[0] > 0.0
    touching = np.nonzero(state.history[part.slot]["state"] > 0)[0]
    torque = torque_on_part(packed_section((OFFSET_SHELF,)), 0, 0.5 * L_Y, state.x[touching],
                            state.history[part.slot]["f"][touching])
    assert torque == pytest.approx(-OFFSET_M * weight, rel=0.02)


def _eulerian_layer_on_shelf(frame):
    """(system, state, the shelf's wall-layer cells, the cells inside the shelf) of the
    Eulerian mesh: the same layer on the shelf, frictionless U and shelf."""
    dx = 2 * R / 20
    mesh = EulerianMesh.tub(GEO, dx, (SHELF,), packed_section((SHELF,)))
    h = mesh.h
    wall = MeshWall((MAT.bulk_modulus + 4 * MAT.shear_modulus / 3) / h, friction=0.0,
                    damping_ratio=0.5)
    system = EulerianSystem(mesh, MAT, stable_dt(MAT, dx, h, [wall]), frame=frame, wall=wall)
    c = system.x
    in_part = (np.abs(c[:, 0]) < SHELF.half_size[0]) & (np.abs(c[:, 1] - SHELF.center[2])
                                                         < SHELF.half_size[2])
    filled = mesh.inside & (c[:, 1] > R) & (c[:, 1] < R + H_LAYER)
    rho_c = MAT.critical_density
    p = rho_c * G_ACC * np.clip(R + H_LAYER - c[:, 1], 0.0, None) * filled
    stress = np.zeros((mesh.n, 4))
    stress[:, 1] = -p
    stress[:, 0] = stress[:, 3] = -(1 - math.sin(math.atan(MAT.mu_s))) * p
    state = eulerian.init_state(system, np.where(filled, rho_c * h * h, 0.0), rho_c,
                                stress=stress)
    return system, state, np.nonzero(mesh.part_of == 0)[0], in_part


def test_eulerian_layer_on_a_part_carries_its_weight_and_no_cell_in_it_fills():
    """The Eulerian mesh's layer on the shelf: the cells inside the part are outside the domain
    and never hold material; the part's wall layer carries the layer's weight, pressed
    downwards (within 1 %), with the torque -OFFSET_M W about a centre OFFSET_M along x (2 %)."""
    system, state, cells, in_part = _eulerian_layer_on_shelf(LabFrame((0.0, -G_ACC)))
    assert in_part.any() and not system.mesh.inside[in_part].any()
    eulerian.run_steps(system, state, int(0.08 / system.dt))
    assert state.mass[in_part].sum() == 0.0
    force_on_part = -wall_force_on_material(cells, system.mesh.normal, state.wall)
    weight = state.total_mass() * G_ACC
    assert force_on_part[1] == pytest.approx(-weight, rel=0.01)  # pressed down
    torque = torque_on_part(packed_section((OFFSET_SHELF,)), 0, 0.5 * L_Y, system.x[cells],
                            wall_forces_by_cell(cells, system.mesh.normal, state.wall))
    assert torque == pytest.approx(-OFFSET_M * weight, rel=0.02)


@pytest.mark.parametrize("method", ["lagrangian", "eulerian"])
def test_a_part_in_a_shaken_tub_feels_the_frame_and_the_bed_stays_with_it(method):
    """Galilean check: the layer on a tub-fixed part in a tub shaken up and down at 10 Hz with
    0.3 g stays at rest relative to the tub (speeds below 2 mm/s, against the tub's 47 mm/s),
    and the part feels the layer's weight in the moving frame, m (g + Z''(t)): the force per
    unit mass less g against Z'' has slope 1 (within 5 %, the layer's own elastic lag) and no
    offset (within 1 % of g)."""
    f, a = 10.0, 0.3 * G_ACC
    motion = TubMotion(frequency=f, amplitude_x=0.0, amplitude_z=a / (2 * math.pi * f) ** 2,
                       phase_z=0.0, amplitude_theta=0.0)
    frame = TubFrame(motion, (0.0, -G_ACC))
    if method == "lagrangian":
        system, state, part = _mpm_layer_on_shelf(frame)
        steps = run_steps

        def held_up(s):  # the part's force on the material, per unit mass (m/s^2)
            return s.history[part.slot]["f"][:, 1].sum() / s.mass.sum()
    else:
        system, state, cells, _ = _eulerian_layer_on_shelf(frame)
        steps = eulerian.run_steps

        def held_up(s):
            return wall_force_on_material(cells, system.mesh.normal, s.wall)[1] / s.total_mass()
    steps(system, state, int(0.06 / system.dt))  # the start's settling transient
    acc, held, speeds = [], [], []

    def watch(s):
        acc.append(pose(motion.as_array(), float(s.t))[7])
        # the part holds the layer up: its force on the material is m (g + Z'')
        held.append(held_up(s) - G_ACC)
        full = s.mass > 0.5 * s.mass.max()
        speeds.append(float(np.hypot(s.v[full, 0], s.v[full, 1]).max()))

    steps(system, state, int(0.1 / system.dt), watch)
    assert np.max(speeds) < 2e-3
    slope, offset = np.polyfit(acc, held, 1)
    assert slope == pytest.approx(1.0, abs=0.05)
    assert abs(offset) < 0.01 * G_ACC


def test_a_part_section_below_a_height_is_its_area():
    """The section of a cylinder below its axis is half its disc, of a box its width times the
    height above its base (the bed around parts rises by it)."""
    bar = Part(name="bar", shape="cylinder", center=(0.0, 0.01, 0.05), material="steel",
               radius=0.01)
    packed = packed_section((bar, SHELF))
    assert section_area_below((bar,), packed_section((bar,)), 0.01, 0.05) == \
        pytest.approx(0.5 * math.pi * 0.01**2, rel=1e-3)
    assert section_area_below((SHELF,), packed_section((SHELF,)), 0.01, R - 0.004) == \
        pytest.approx(2 * SHELF.half_size[0] * 0.006, rel=1e-3)
    assert section_area_below((bar, SHELF), packed, 0.01, 1.0) == pytest.approx(
        math.pi * 0.01**2 + 4 * SHELF.half_size[0] * SHELF.half_size[2], rel=1e-3)


def _phase_field(x, z, shear_rate, solid_fraction, n_batches=2):
    nz, nx = shear_rate.shape
    return PhaseShear(x=x, z=z, h=float(x[1] - x[0]), solid_fraction=solid_fraction,
                      shear_rate=shear_rate, phase_shear_rate=shear_rate[None],
                      phase_solid_fraction=solid_fraction[None],
                      batch_shear_rate=np.stack([shear_rate * 0.9, shear_rate * 1.1]),
                      batch_solid_fraction=np.stack([solid_fraction] * n_batches),
                      roll_shear_rate=shear_rate)


def test_inferred_speed_by_patch_is_the_relation_on_the_surface_nodes():
    """On a hand-made field around a bar (nodes 5 mm apart, the shear rate 10 1/s on the
    nodes right of the bar's axis and 30 1/s left of it), the speed inferred on the sector
    0-10 deg is c0 + c1 d 10 and on 180-190 deg c0 + c1 d 30 (their nodes within two spacings
    lie on one side), with the error |c1| d se of the batches' rates (0.9 and 1.1 times:
    se = 0.1 gamma); the node at (x0 + r + h/2, z0) weighs in sector 0, not in 180-190."""
    bar = Part(name="bar", shape="cylinder", center=(0.0, 0.01, 0.05), material="steel",
               radius=0.0125)
    h = 0.005
    x = np.arange(-8, 9) * h
    z = np.arange(0, 21) * h
    X, _ = np.meshgrid(x, z)
    rate = np.where(X > 0, 10.0, 30.0)
    phi = np.full(rate.shape, 0.5)
    phase = _phase_field(x, z, rate, phi)
    w = patch_weights(bar, pack((bar,)), 0, 0.01, phase, 36)
    k0, i_right = 10, int(np.argmin(np.abs(x - 0.015)))
    assert w[0, k0, i_right] > 0 and w[18, k0, i_right] == 0
    c0, c1, d = 0.1, 0.5, 0.00635
    calib = SimpleNamespace(impacts=SimpleNamespace(ball_wall=ImpactRelation(
        c0_cells_m_s=c0, c1_cells=c1)))
    scen = Scenario(tub={"radius": 0.05, "rim_height": 0.1, "length": 0.02},
                    fill={"count": 200},
                    parts=[{"name": "bar", "shape": "cylinder", "center": [0.0, 0.01, 0.05],
                            "radius": 0.0125}])
    samples = Samples(0, 1, 0)
    ds = part_dataset("lagrangian", scen, (bar,), pack((bar,)), calib, d, phase, samples,
                      np.zeros(0), np.zeros(0, np.int64), 1.0, None)
    v = ds["normal_speed_mean"].sel(part="bar").values
    se = ds["normal_speed_mean_stderr"].sel(part="bar").values
    assert v[0] == pytest.approx(c0 + c1 * d * 10.0)
    assert v[18] == pytest.approx(c0 + c1 * d * 30.0)
    assert se[0] == pytest.approx(c1 * d * 1.0)
    assert se[18] == pytest.approx(c1 * d * 3.0)
    assert np.isnan(v[36:]).all() and v.size == MAX_PATCHES
    assert "ball_wall" in ds.attrs["inferred_from"]


def test_a_uniform_bed_gives_every_covered_patch_the_same_speed_and_none_above_it():
    """A uniform shear rate (20 1/s, solid fraction 0.5) around a bar of radius 12.5 mm on
    nodes 5 mm apart: buried, all 36 sectors get c0 + c1 d 20; with the bed's surface at the
    bar's axis (no material above z0), the sectors near the bar's top (80-100 deg, 12.5 mm
    above the nearest material node, beyond the two-spacing reach) are NaN and those at the
    axis's height (0-10 deg, 170-180 deg) keep the uniform value."""
    bar = Part(name="bar", shape="cylinder", center=(0.0, 0.01, 0.05), material="steel",
               radius=0.0125)
    h = 0.005
    x = np.arange(-8, 9) * h
    z = np.arange(0, 21) * h
    X, Z = np.meshgrid(x, z)
    c0, c1, d = 0.1, 0.5, 0.00635
    calib = SimpleNamespace(impacts=SimpleNamespace(ball_wall=ImpactRelation(
        c0_cells_m_s=c0, c1_cells=c1)))
    scen = Scenario(tub={"radius": 0.05, "rim_height": 0.1, "length": 0.02},
                    fill={"count": 200},
                    parts=[{"name": "bar", "shape": "cylinder", "center": [0.0, 0.01, 0.05],
                            "radius": 0.0125}])
    expected = c0 + c1 * d * 20.0
    for phi in (np.full(X.shape, 0.5), np.where(Z <= 0.05 + 1e-9, 0.5, 0.0)):
        phase = _phase_field(x, z, np.where(phi > 0, 20.0, np.nan), phi)
        ds = part_dataset("lagrangian", scen, (bar,), pack((bar,)), calib, d, phase,
                          Samples(0, 1, 0), np.zeros(0), np.zeros(0, np.int64), 1.0, None)
        v = ds["normal_speed_mean"].sel(part="bar").values[:36]
        if phi.min() > 0:
            assert v == pytest.approx(np.full(36, expected))
        else:
            assert np.isnan(v[8:10]).all()
            assert v[[0, 17, 18, 35]] == pytest.approx(np.full(4, expected))


def test_parts_nc_force_by_phase_is_the_mean_of_its_samples(tmp_path):
    """Four cycles of two phases, two batches: the force by phase is the mean of that phase's
    samples, its error the batch means' (hand computed), and parts.nc reads back."""
    bar = Part(name="bar-1", shape="cylinder", center=(0.0, 0.01, 0.05), material="steel",
               radius=0.0125)
    scen = Scenario(tub={"radius": 0.05, "rim_height": 0.1, "length": 0.02},
                    fill={"count": 200},
                    run={"phases_per_cycle": 2, "batches": 2, "duration": 1.0,
                         "average_last": 0.5},
                    parts=[{"name": "bar-1", "shape": "cylinder",
                            "center": [0.0, 0.01, 0.05], "radius": 0.0125}])
    f = scen.motion.frequency
    times = np.arange(8) / (2 * f)
    batch = np.array([0, 0, 0, 0, 1, 1, 1, 1])
    samples = Samples(8, 1, 0, n_parts=1)
    fz = np.array([1.0, 5.0, 3.0, 7.0, 2.0, 6.0, 4.0, 8.0])  # phase 0: 1 3 2 4, phase 1: 5 7 6 8
    for j in range(8):
        samples.add_part_forces(j, np.array([[0.0, -fz[j]]]), np.array([0.1 * fz[j]]), 1.0)
    samples.j = 8
    ds = part_dataset("eulerian", scen, (bar,), pack((bar,)), None, 0.00635, None, samples,
                      times, batch, 4 / f, None)
    write_parts(tmp_path / "parts.nc", ds)
    back = read_parts(tmp_path / "parts.nc")
    force = back["force"].sel(part="bar-1", component="z").values
    assert force == pytest.approx([2.5, 6.5])
    # batch means 2 and 3 (phase 0): se = std([2, 3], ddof=1) / sqrt(2) = 0.5
    assert back["force_stderr"].sel(part="bar-1", component="z").values == \
        pytest.approx([0.5, 0.5])
    assert back.attrs["method"] == "eulerian" and back.attrs["batches"] == 2
    assert np.isnan(back["impact_rate_per_area"]).all()
    assert back["force"].attrs["units"] == "N"
    assert back["torque"].sel(part="bar-1", component="y").values == pytest.approx([0.25, 0.65])
    assert (back["torque"].sel(part="bar-1", component=["x", "z"]).values == 0.0).all()
    assert back["torque"].attrs["units"] == "N m"


@pytest.mark.parametrize("part, says", [
    ({"shape": "sphere", "radius": 0.01, "center": [0.0, 0.01, 0.05]}, "shape = \"sphere\""),
    ({"shape": "box", "size": [0.02, 0.01, 0.02], "center": [0.0, 0.01, 0.05]},
     "spans y = 0.005 .. 0.015 m"),
    ({"shape": "cylinder", "radius": 0.01, "center": [0.0, 0.01, 0.05], "frame": "lab"},
     "frame = \"lab\""),
])
def test_a_part_the_continuum_cannot_take_is_one_line(part, says):
    scen = Scenario(tub={"radius": 0.05, "rim_height": 0.1, "length": 0.02},
                    fill={"count": 200},
                    parts=[{"name": "p1", **part}])
    with pytest.raises(InputError) as e:
        continuum_parts(scen)
    text = str(e.value)
    assert "\n" not in text and "parts.0 (\"p1\")" in text and says in text


def test_section_outlines_are_the_parts_sections(tmp_path):
    """The ParaView outline of a cylinder's section lies on its circle; a box turned by 30
    degrees has its four corners where the rotation puts them; an STL prism of that box (12
    triangles across the slice) cut at the slice's middle has the box's perimeter; the file
    holds one line cell per segment with its part's index."""
    from vtk_reader import read_vtk
    from vibroflow.continuum.part_obstacle import section_segments
    from vibroflow.io.vtk import write_section_lines

    bar = Part(name="bar", shape="cylinder", center=(0.05, 0.01, 0.1), material="steel",
               radius=0.0125)
    seg = section_segments(bar, 0.01)
    assert np.hypot(seg[..., 0] - 0.05, seg[..., 1] - 0.1) == pytest.approx(0.0125)
    box = Part(name="box", shape="box", center=(0.0, 0.01, 0.05), material="steel",
               half_size=(0.02, 0.01, 0.01), angle_y=math.radians(30))
    corners = section_segments(box, 0.01)[:, 0]
    c, s = math.cos(math.radians(30)), math.sin(math.radians(30))
    assert corners[1] == pytest.approx([0.02 * c + 0.01 * s, 0.05 + 0.02 * s - 0.01 * c])
    hx, hz = 0.02, 0.01
    v = np.array([[x, y, z] for x in (-hx, hx) for y in (0.0, 0.02) for z in (-hz, hz)])
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    tri = np.array([[v[a], v[b], v[c_]] for q in quads
                    for a, b, c_ in ((q[0], q[1], q[2]), (q[0], q[2], q[3]))])
    prism = Part(name="prism", shape="stl", center=(0.0, 0.01, 0.0), material="steel",
                 triangles=tri)
    cut = section_segments(prism, 0.01)
    assert np.linalg.norm(cut[:, 1] - cut[:, 0], axis=1).sum() == pytest.approx(
        4 * (hx + hz))
    write_section_lines(tmp_path / "parts.vtu", [seg, cut], 0.01)
    got = read_vtk(tmp_path / "parts.vtu")
    assert got["CellData"]["part"].tolist() == [0] * len(seg) + [1] * len(cut)
    (points,) = got["Points"].values()
    assert points[:, 1] == pytest.approx(0.01)


def test_a_study_refuses_a_part_the_continuum_cannot_take_before_it_starts(tmp_path):
    """`vibroflow run` with a sphere in the bed: the one-line error before any stage, no
    folder made (the DEM would otherwise run first)."""
    from vibroflow.study.pipeline import run_study

    scen = Scenario(tub={"radius": 0.05, "rim_height": 0.1, "length": 0.02},
                    fill={"count": 200},
                    parts=[{"name": "ball", "shape": "sphere", "radius": 0.008,
                            "center": [0.0, 0.01, 0.05]}])
    with pytest.raises(InputError, match=r"parts\.0 \(\"ball\"\)\.shape = \"sphere\""):
        run_study(scen, tmp_path / "study", echo=None)
    assert not (tmp_path / "study").exists()


def test_inferred_speed_by_patch_from_the_temperature_where_the_calibration_prefers_it():
    """With a calibration preferring T at the wall and a run carrying T: the speed on a patch
    is max(b0 + b1 sqrt(T), 0) of the T map at its nodes (T = 0.01 m^2/s^2 right of the bar,
    0.04 left of it: 0.05 + 2 x 0.1 = 0.25 m/s and 0.05 + 2 x 0.2 = 0.45 m/s), its error the
    bed-mean T's carried through, b1 se(T) / (2 sqrt(T_bed))."""
    bar = Part(name="bar", shape="cylinder", center=(0.0, 0.01, 0.05), material="steel",
               radius=0.0125)
    h = 0.005
    nxh, nz = 8, 21
    x = np.arange(-nxh, nxh + 1) * h
    z = np.arange(nz) * h
    X, _ = np.meshgrid(x, z)
    phase = _phase_field(x, z, np.full(X.shape, 10.0), np.full(X.shape, 0.5))
    samples = Samples(0, 1, 0, cell_grid=(h, nxh, nz), temperature=True)
    samples.temperature_cell_sum[:] = np.where(X > 0, 0.01, 0.04)
    samples.temperature_cell_n[:] = 1.0
    calib = SimpleNamespace(impacts=SimpleNamespace(ball_wall=ImpactRelation(
        c0_cells_m_s=9.0, c1_cells=9.0, preferred_relation="temperature",
        b0_temperature_cells_m_s=0.05, b1_temperature_cells=2.0)))
    scen = Scenario(tub={"radius": 0.05, "rim_height": 0.1, "length": 0.02},
                    fill={"count": 200},
                    parts=[{"name": "bar", "shape": "cylinder", "center": [0.0, 0.01, 0.05],
                            "radius": 0.0125}])
    ds = part_dataset("eulerian", scen, (bar,), pack((bar,)), calib, 0.00635, phase, samples,
                      np.zeros(0), np.zeros(0, np.int64), 1.0, (0.0225, 0.003))
    v = ds["normal_speed_mean"].sel(part="bar").values
    assert v[0] == pytest.approx(0.25) and v[18] == pytest.approx(0.45)
    assert ds["normal_speed_mean_stderr"].sel(part="bar").values[0] == pytest.approx(
        2.0 * 0.003 / (2 * math.sqrt(0.0225)))
    assert "sqrt(T)" in ds.attrs["inferred_from"]


@pytest.mark.slow
@pytest.mark.parametrize("method", ["lagrangian", "eulerian"])
def test_a_tub_run_with_a_bar_writes_parts_nc_and_resumes_to_it_bit_for_bit(method, tmp_path):
    """tub47-quick with the 25 mm bar at (0.05, 0.10) m, three cycles: parts.nc has the
    schema's variables, the bar's force in every phase finite, speeds inferred on the patches
    next to nodes with material; a run stopped and resumed writes the same parts.nc."""
    from continuum_helpers import THREE_CYCLES
    from vibroflow.continuum.tub_run import run_continuum
    from vibroflow.io.calibration_file import read_calibration
    from vibroflow.io.parts_file import VARIABLES
    from vibroflow.scenario.io import load_scenario

    d = load_scenario("tub47-quick", THREE_CYCLES).model_dump()
    d["parts"] = [{"name": "bar", "shape": "cylinder", "center": [0.05, 0.0, 0.10],
                   "radius": 0.0125}]
    s = Scenario.model_validate(d)
    calib = read_calibration("tests/data/tub47-quick-dem/calibration.toml")
    full = run_continuum(s, tmp_path / "full", method, calibration=calib)
    assert full["continuum"]["parts"]["names"] == ["bar"]
    ds = read_parts(tmp_path / "full" / "parts.nc")
    assert set(VARIABLES) <= set(ds.data_vars) and ds.attrs["method"] == method
    assert np.isfinite(ds["force"].values).all()
    assert np.isfinite(ds["normal_speed_mean"].values[0]).sum() >= 4
    split = tmp_path / "split"
    assert run_continuum(s, split, method, calibration=calib,
                         stop_after_steps=full["steps"] // 2) is None
    run_continuum(s, split, method, calibration=calib, resume=True)
    again = read_parts(split / "parts.nc")
    for var in ("force", "force_stderr", "normal_speed_mean", "normal_speed_mean_stderr"):
        assert np.array_equal(again[var].values, ds[var].values, equal_nan=True), var

