"""The continuum's constitutive law against known answers.

The mu(I) law (Dunatunga & Kamrin 2015) in steady simple shear; Drucker-Prager with viscosity;
no stress below the critical density or in tension; the material's defaults, bad values and
calibration record; elastic P waves at sqrt((K + 4G/3)/rho); the bed viscosity as a
Kelvin-Voigt solid, in both formulations.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from continuum_helpers import METHODS, lattice
from vibroflow.continuum.constitutive import ContinuumMaterial
from vibroflow.continuum.grid import Grid
from vibroflow.continuum.grid_update import LabFrame
from vibroflow.continuum.mpm.solver import MPMSystem, init_state, run_steps
from vibroflow.continuum.rheology import mu_of_I
from vibroflow.continuum.stress_update import update_stress_points
from vibroflow.continuum.timestep import stable_dt
from vibroflow.errors import InputError


# ----------------------------------------------------------------------------------------------
# the plastic flow

def shear_at_constant_pressure(mat, p, rate, steps, dt):
    """Drive one point in simple shear (L_xz = rate, 1/s) at density above rho_c from the
    isotropic stress -p; returns (tau_eq, pressure, plastic shear rate)."""
    stress = np.array([[-p, -p, 0.0, -p]])
    L = np.array([[0.0, rate, 0.0, 0.0]])
    rho = np.array([mat.critical_density * 1.01])
    gd = np.zeros(1)
    st = np.zeros(1, np.int8)
    params = mat.as_array()
    for _ in range(steps):
        update_stress_points(stress, L, rho, dt, params, gd, st)
    s = stress[0]
    pr = -(s[0] + s[1] + s[3]) / 3
    dev = np.array([s[0] + pr, s[1] + pr, s[3] + pr])
    tau = math.sqrt(0.5 * (dev @ dev) + s[2] ** 2)
    return tau, pr, gd[0], st[0]


@pytest.mark.parametrize("rate", [1.0, 30.0, 300.0])
def test_mu_i_steady_shear_stress(rate):
    """Steady simple shear: tau / p = mu(I), I = gamma_dot d / sqrt(p / rho_s) (GDR MiDi 2004),
    reached by the elastic predictor + return map (Dunatunga & Kamrin 2015 eq. 3.7)."""
    mat = ContinuumMaterial()
    p = 2.0e3
    tau, pr, gd, state = shear_at_constant_pressure(mat, p, rate, 4000, 1e-5)
    assert state == 2
    assert pr == pytest.approx(p, rel=1e-9)  # isochoric flow: the pressure is unchanged
    # Jaumann-rotated steady state: the plastic rate equals the imposed shear rate
    assert gd == pytest.approx(rate, rel=1e-3)
    I = rate * mat.diameter / math.sqrt(p / mat.solid_density)
    assert tau / pr == pytest.approx(float(mu_of_I(I, mat.mu_s, mat.mu_2, mat.I_0)), rel=1e-3)


def test_drucker_prager_viscous_shear_stress():
    """Drucker-Prager with viscosity: tau = mu_dp p + eta gamma_dot, with the plane-strain
    matched slope tan(beta)/sqrt(3) (models.md)."""
    mat = ContinuumMaterial(model="drucker_prager", viscosity=2.0)
    p, rate = 3.0e3, 50.0
    tau, pr, gd, _ = shear_at_constant_pressure(mat, p, rate, 4000, 1e-5)
    phi_f = math.atan(mat.mu_s)
    tan_beta = 3 * math.sqrt(3) * math.tan(phi_f) / math.sqrt(9 + 12 * math.tan(phi_f) ** 2)
    assert tau == pytest.approx(tan_beta / math.sqrt(3) * p + 2.0 * rate, rel=1e-3)


def test_disconnected_below_critical_density_and_in_tension():
    """Below rho_c, or under a tensile trial pressure, the media carries no stress
    (Dunatunga & Kamrin 2015 eq. 2.9)."""
    mat = ContinuumMaterial()
    params = mat.as_array()
    stress = np.array([[-1e3, -1e3, 100.0, -1e3], [1e2, 1e2, 0.0, 1e2]])
    L = np.zeros((2, 4))
    rho = np.array([0.999 * mat.critical_density, 1.01 * mat.critical_density])
    gd, st = np.zeros(2), np.zeros(2, np.int8)
    update_stress_points(stress, L, rho, 1e-5, params, gd, st)
    assert np.all(stress == 0.0) and np.all(st == 0)


def test_material_defaults_and_bad_input():
    mat = ContinuumMaterial()
    assert mat.mu_s == pytest.approx(math.tan(math.radians(20.9)))
    assert mat.mu_2 == pytest.approx(math.tan(math.radians(32.8)))
    assert mat.I_0 == 0.279
    with pytest.raises(InputError, match="bulk_modulus"):
        ContinuumMaterial(bulk_modulus=-1.0)
    with pytest.raises(InputError, match="model"):
        ContinuumMaterial(model="bingham")


def test_material_from_calibration_record():
    from vibroflow.io.calibration_file import Calibration

    cal = Calibration.from_dict({
        "rheology": {"mu_s": 0.30, "mu_2": 0.55, "I_0": 0.3, "phi_max": 0.61, "phi_min": 0.5,
                     "critical_solid_fraction": 0.605},
        "elastic": {"bulk_modulus_Pa": 2e6, "shear_modulus_Pa": 1e6},
        "wall": {"friction": 0.2},
        "media": {"diameter_m": 0.006, "solid_density_kg_m3": 7700.0},
        "drucker_prager": {"viscosity_Pa_s": 3.5}})
    mat = ContinuumMaterial.from_calibration(cal)
    assert (mat.mu_s, mat.mu_2, mat.I_0, mat.bulk_modulus) == (0.30, 0.55, 0.3, 2e6)
    assert mat.critical_density == pytest.approx(0.605 * 7700.0)
    assert ContinuumMaterial.from_calibration(cal, model="drucker_prager").eta == 3.5



# ----------------------------------------------------------------------------------------------
# the elastic waves

def test_elastic_p_wave_speed():
    """A plane compressional pulse travels at c = sqrt((K + 4G/3) / rho) (uniaxial strain in the
    middle of a tall block, far from its free surfaces)."""
    mat = ContinuumMaterial(mu_s=2.0, mu_2=2.5)  # stays elastic
    dx, size = 0.005, 0.4
    sp = dx / 2
    grid = Grid.covering(0.0, size, 0.0, size, dx)
    x = lattice(0.0, size, 0.0, size, sp)
    K, G = mat.bulk_modulus, mat.shear_modulus
    M, lam = K + 4 * G / 3, K - 2 * G / 3
    rho0 = mat.critical_density * 1.000001
    c = math.sqrt(M / rho0)
    # a right-going wave: v = A f(x - c t), strain -v/c, stress -M v/c (lateral lambda v/c)
    v = np.zeros_like(x)
    v[:, 0] = 1e-3 * np.exp(-((x[:, 0] - 0.12) / 0.03) ** 2)
    eps = v[:, 0] / c
    stress = np.zeros((len(x), 4))
    stress[:, 0] = -M * eps
    stress[:, 1] = stress[:, 3] = -lam * eps
    system = MPMSystem(grid, mat, stable_dt(mat, dx, sp), frame=LabFrame((0.0, 0.0)))
    state = init_state(system, x, sp * sp / (1 + eps), rho0 * (1 + eps), v=v, stress=stress)
    band = np.abs(x[:, 1] - size / 2) < 0.05
    t, centre = [], []

    def record(s):
        w = s.v[band, 0]
        t.append(s.t)
        centre.append((w * s.x[band, 0]).sum() / w.sum())

    run_steps(system, state, int(0.12 / c / system.dt), record)
    speed = np.polyfit(t, centre, 1)[0]
    assert speed == pytest.approx(c, rel=0.02)


# ----------------------------------------------------------------------------------------------
# the bed viscosity (stress_update.damped_stress): a Kelvin-Voigt standing shear wave

def _standing_shear_wave(method: str, eta: float, H=0.1, dx=0.005, V=0.01, periods=10):
    """The first shear mode of a free layer of height H (m), periodic along x, no gravity:
    v_x = V cos(pi z / H) at rest in displacement (its shear stress G du_x/dz vanishes at both
    free surfaces, and it has no volume change, so the free surfaces stay free), elastic
    (mu_s = 2, in-plane pre-stress sigma_xx = sigma_yy = -20 kPa, sigma_zz = 0, density 1.01
    rho_c: connected).  Returns (decay rate of the mode's amplitude (1/s), Kelvin-Voigt's
    eta k^2 / (2 rho) (1/s))."""
    mat = ContinuumMaterial(mu_s=2.0, mu_2=2.5, bed_viscosity=eta)
    h = dx / 2
    W = 4 * dx
    rho = mat.critical_density * 1.01
    k = math.pi / H
    omega = math.sqrt(mat.shear_modulus / rho) * k
    if method == "lagrangian":
        grid = Grid.periodic_strip(W, -3 * dx, H + 3 * dx, dx)
        x = lattice(0.0, W, 0.0, H, h)
        z = x[:, 1]
        v = np.zeros_like(x)
        v[:, 0] = V * np.cos(k * z)
        stress = np.zeros((len(x), 4))
        stress[:, 0] = stress[:, 3] = -2.0e4
        system = MPMSystem(grid, mat, stable_dt(mat, dx, h), frame=LabFrame((0.0, 0.0)))
        state = init_state(system, x, h * h, rho, v=v, stress=stress)
        shape = np.cos(k * z)
        step = run_steps
    else:
        from vibroflow.continuum.eulerian.mesh import EulerianMesh
        from vibroflow.continuum.eulerian.solver import EulerianSystem
        from vibroflow.continuum.eulerian.solver import init_state as eulerian_state
        from vibroflow.continuum.eulerian.solver import run_steps as eulerian_steps

        z0 = 4 * dx       # the layer between empty cells, away from the floor and the lid
        mesh = EulerianMesh.box(0.0, W, 0.0, H + 8 * dx, dx, periodic=True)
        system = EulerianSystem(mesh, mat, stable_dt(mat, dx, h), frame=LabFrame((0.0, 0.0)))
        z = system.x[:, 1] - z0
        layer = (z > 0) & (z < H)
        v = np.zeros((mesh.n, 2))
        v[:, 0] = np.where(layer, V * np.cos(k * z), 0.0)
        stress = np.zeros((mesh.n, 4))
        stress[layer, 0] = stress[layer, 3] = -2.0e4
        state = eulerian_state(system, np.where(layer, rho * h * h, 0.0), rho, v=v,
                               stress=stress)
        shape = np.where(layer, np.cos(k * z), 0.0)
        step = eulerian_steps
    norm = (state.mass * shape**2).sum()
    t, amp = [], []

    def record(s):
        t.append(s.t)
        amp.append((s.mass * s.v[:, 0] * shape).sum() / norm)

    step(system, state, int(periods * 2 * math.pi / omega / system.dt), record)
    a = np.abs(amp)
    peaks = [i for i in range(1, len(a) - 1) if a[i] >= a[i - 1] and a[i] > a[i + 1]]
    assert len(peaks) >= 2 * periods - 1
    rate = -np.polyfit(np.array(t)[peaks], np.log(a[peaks]), 1)[0]
    return rate, eta * k * k / (2.0 * rho)


@pytest.mark.parametrize("method", METHODS)
def test_bed_viscosity_damps_a_shear_wave_as_kelvin_voigt(method):
    """A Kelvin-Voigt solid rho u_tt = G u_zz + eta u_zzt damps the standing shear wave of
    wavenumber k at the rate eta k^2 / (2 rho) (underdamped: here damping ratio 0.02).  The
    mode's amplitude, sampled every step over 10 periods, decays at that rate within 2 %
    once the formulation's own damping (the run without viscosity: the APIC transfers,
    0.19 1/s) is taken off (measured 0.994 of it in both formulations: the same kernel,
    stress_update.damped_stress, scattered with the stress)."""
    base, _ = _standing_shear_wave(method, 0.0)
    rate, want = _standing_shear_wave(method, 100.0)
    print(f"\n{method}: decay {rate:.3f} 1/s, without viscosity {base:.3f}, Kelvin-Voigt "
          f"{want:.3f}")
    assert base < 0.05 * want
    assert rate - base == pytest.approx(want, rel=0.02)


def test_bed_viscosity_leaves_a_rigid_motion_alone_and_bad_values_are_errors():
    """The viscous stress is 2 eta D (plus eta tr D I - 2/3 eta tr D I): zero for a rigid
    rotation, none on disconnected material; a negative or non-finite viscosity is a one-line
    error naming the field."""
    from vibroflow.continuum.formulation import formulation
    from vibroflow.continuum.stress_update import damped_stress

    mat = ContinuumMaterial(bed_viscosity=1000.0)
    L = np.array([[0.0, 2.0, -2.0, 0.0], [1.0, 0.5, 0.5, -3.0], [1.0, 0.5, 0.5, -3.0]])
    stress = np.full((3, 4), -100.0)
    out = np.zeros((3, 4))
    damped_stress(stress, L, np.array([1, 2, 0], np.int8), mat.as_array(), out)
    np.testing.assert_array_equal(out[0], stress[0])     # rigid rotation
    np.testing.assert_array_equal(out[2], stress[2])     # disconnected
    tr = 1.0 - 3.0
    np.testing.assert_allclose(out[1], -100.0 + np.array(
        [1000 * tr / 3 + 2000 * 1.0, 1000 * tr / 3 + 2000 * -3.0, 2000 * 0.5, 1000 * tr / 3]))
    for bad in (-1.0, math.inf, math.nan):
        with pytest.raises(InputError, match="bed_viscosity") as err:
            ContinuumMaterial(bed_viscosity=bad)
        assert "\n" not in str(err.value)
        with pytest.raises(InputError, match="bed_viscosity"):
            formulation("lagrangian").options(bed_viscosity=bad)
