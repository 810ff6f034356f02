"""One step of the granular temperature balance on a regular grid of square cells, compiled.

The balance (kinetic_theory.py) (3/2) rho_s phi dT/dt = S - div q - Gamma, with S (W/m^3) the
production sigma : D and the walls' heating, q = -kappa grad T, is advanced over dt by a Strang
split (Strang 1968, SIAM J. Numer. Anal. 5, 506) around its stiff dissipation:

1. dissipation over dt/2, integrated exactly for the step's frozen phi: dT/dt = -a T^(3/2)
   gives T / (1 + a sqrt(T) dt / 4)^2 (a from kinetic_theory.cooling_coefficient).  It is
   unconditionally stable, keeps T >= 0, and is exact for homogeneous cooling (Haff's law) at
   any dt, however far below dt the dense core's cooling time falls;
2. the sources over dt, explicit: T += dt S / ((3/2) rho_s phi), floored at 0 (an expansion's
   -p div u cannot take more energy than the cell holds);
3. conduction over dt, implicit: backward Euler, locally one-dimensional (an x sweep, then a z
   sweep; Yanenko 1971), each line a tridiagonal Thomas solve of the conservative finite-volume
   form, face conductance the harmonic mean of the cells' kappa (Patankar 1980, section 4.2-4).
   Each sweep is an M-matrix, so the step is unconditionally stable and keeps T >= 0 where the
   dilute surface gas makes kappa / (rho_s phi) large; the sum of the fluxes telescopes, so
   the energy is conserved to round-off with zero-flux edges; and the cost is O(cells), like
   the mechanical step's.  kappa is taken at the step's temperature (linearised);
4. dissipation over dt/2 as in 1.

For the local terms with production frozen over the step the split is second order in dt, so
a balance of production and dissipation reaches its algebraic steady value to O(dt^2);
conduction's backward Euler is first order.

Cells are (nx, nz) arrays (x first).  A cell whose solid fraction is below the grid's
void_solid_fraction is empty: it holds no fluctuation energy, exchanges none, and its T is left
as it is.  The grid's edges are zero-flux; a given flux through them, or through a wall inside
the grid (the walls' Johnson & Jackson flux), enters as the heating field S_wall (W/m^3): the
flux (W/m^2) times the wall's length in the cell over the cell's area (`edge_heating_W_m3` for
the grid's edges), and the walls' stiff collision loss as a cooling coefficient added to the
dissipation's (`step_temperature_walls`, wall_energy_flux.py).  Energies are per metre of
thickness (plane strain).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

from .kinetic_theory import conductivity_kg_m_s, cooling_coefficient, sliding_rate


class TemperatureGrid(NamedTuple):
    """A regular grid of square cells of side spacing_m (m); cells with a solid fraction below
    void_solid_fraction (-) are empty."""

    spacing_m: float
    void_solid_fraction: float = 1e-3


@nb.njit(cache=True)
def exact_cooling(T, a, dt):
    """T (m^2/s^2) after dt (s) of dT/dt = -a T^(3/2) (a >= 0): T / (1 + a sqrt(T) dt / 2)^2."""
    if T <= 0.0:
        return 0.0
    s = 1.0 + 0.5 * a * math.sqrt(T) * dt
    return T / (s * s)


@nb.njit(cache=True)
def exact_cooling_sliding(T, a, b, dt):
    """T (m^2/s^2) after dt (s) of dT/dt = -a T^(3/2) - b T^(1/2) (a, b >= 0; b the dense
    sliding loss's rate, kinetic_theory.sliding_rate): with s = sqrt(T), ds/dt = -(a s^2 + b)/2,
    so s = r tan(atan(s0 / r) - sqrt(a b) dt / 2), r = sqrt(b / a), until s reaches 0 (a = 0:
    s0 - b dt / 2); exact_cooling when b = 0."""
    if b <= 0.0:
        return exact_cooling(T, a, dt)
    if T <= 0.0:
        return 0.0
    s0 = math.sqrt(T)
    if a <= 0.0:
        s = s0 - 0.5 * b * dt
    else:
        r = math.sqrt(b / a)
        theta = math.atan(s0 / r) - 0.5 * math.sqrt(a * b) * dt
        s = r * math.tan(theta) if theta > 0.0 else 0.0
    return s * s if s > 0.0 else 0.0


@nb.njit(cache=True)
def _face(k1, k2):
    """Face conductance (kg/(m s)): the harmonic mean, zero next to a non-conducting cell."""
    if k1 <= 0.0 or k2 <= 0.0:
        return 0.0
    return 2.0 * k1 * k2 / (k1 + k2)


@nb.njit(cache=True)
def _thomas(lower, diag, upper, rhs, out, n, cp, dp):
    """Solves the tridiagonal system (lower[i] x[i-1] + diag[i] x[i] + upper[i] x[i+1] = rhs[i])
    into out[:n] (Thomas algorithm; stable for the diagonally dominant rows built here); cp,
    dp scratch of length >= n."""
    cp[0] = upper[0] / diag[0]
    dp[0] = rhs[0] / diag[0]
    for i in range(1, n):
        m = diag[i] - lower[i] * cp[i - 1]
        cp[i] = upper[i] / m
        dp[i] = (rhs[i] - lower[i] * dp[i - 1]) / m
    out[n - 1] = dp[n - 1]
    for i in range(n - 2, -1, -1):
        out[i] = dp[i] - cp[i] * out[i + 1]


@nb.njit(cache=True)
def _sweep_line(T, capacity, kappa, r, lo, di, up, rhs, line, cp, dp):
    """One line of cells (1-D views T, capacity, kappa along x or z) after a backward-Euler step
    of conduction along it, written into T; r = dt / h^2 (s/m^2); lo .. dp are scratch.  A
    line of empty cells only (the space above the bed, outside the tub) is left as it is: its
    system is the identity."""
    n = T.shape[0]
    empty = True
    for i in range(n):
        if capacity[i] > 0.0:
            empty = False
            break
    if empty:
        return
    for i in range(n):
        if capacity[i] <= 0.0:
            lo[i] = 0.0
            di[i] = 1.0
            up[i] = 0.0
            rhs[i] = T[i]
            continue
        kb = _face(kappa[i - 1], kappa[i]) if i > 0 else 0.0
        kf = _face(kappa[i], kappa[i + 1]) if i < n - 1 else 0.0
        lo[i] = -r * kb
        up[i] = -r * kf
        di[i] = capacity[i] + r * (kb + kf)
        rhs[i] = capacity[i] * T[i]
    _thomas(lo, di, up, rhs, line, n, cp, dp)
    for i in range(n):
        T[i] = line[i]


@nb.njit(cache=True)
def conduct(T, capacity, kappa, dt, h):
    """T (m^2/s^2, (nx, nz)) after dt (s) of capacity dT/dt = div (kappa grad T) on cells of side
    h (m), zero-flux edges: backward Euler, an x sweep then a z sweep (module docstring).
    capacity = (3/2) rho_s phi (kg/m^3), <= 0 in empty cells; kappa (kg/(m s)), 0 in empty
    cells.  Returns a new array."""
    nx, nz = T.shape
    r = dt / (h * h)
    out = T.copy()
    n = max(nx, nz)
    lo = np.empty(n)
    di = np.empty(n)
    up = np.empty(n)
    rhs = np.empty(n)
    line = np.empty(n)
    cp = np.empty(n)
    dp = np.empty(n)
    for k in range(nz):
        _sweep_line(out[:, k], capacity[:, k], kappa[:, k], r, lo, di, up, rhs, line, cp, dp)
    for i in range(nx):
        _sweep_line(out[i, :], capacity[i, :], kappa[i, :], r, lo, di, up, rhs, line, cp, dp)
    return out


@nb.njit(cache=True)
def step_temperature(T, phi, production_W_m3, wall_heating_W_m3, shear_rate, dt, grid, prm):
    """The temperature (m^2/s^2, (nx, nz)) after one step dt (s) of the balance (module
    docstring), for the cells' solid fraction phi (-), production sigma : D (W/m^3), the walls'
    heating (W/m^3) and shear rate (1/s, for Jenkins' correlation length only), all (nx, nz)
    and frozen over the step; grid a TemperatureGrid, prm a KineticParameters.  Returns a new
    array."""
    return step_temperature_walls(T, phi, production_W_m3, wall_heating_W_m3,
                                  np.zeros(T.shape), shear_rate, dt, grid, prm)


@nb.njit(cache=True)
def step_temperature_walls(T, phi, production_W_m3, wall_heating_W_m3, wall_cooling, shear_rate,
                           dt, grid, prm):
    """`step_temperature` with the walls' collision loss dT/dt = -a_w T^(3/2) (wall_cooling =
    a_w, (nx, nz), wall_energy_flux.wall_cooling_coefficient) added to the dissipation's
    coefficient, so that it is integrated exactly with it (step 1 and 4)."""
    return step_temperature_pressed(T, phi, production_W_m3, wall_heating_W_m3, wall_cooling,
                                    shear_rate, np.zeros(T.shape), dt, grid, prm)


@nb.njit(cache=True)
def step_temperature_pressed(T, phi, production_W_m3, wall_heating_W_m3, wall_cooling,
                             shear_rate, pressure_Pa, dt, grid, prm):
    """`step_temperature_walls` with the dense sliding loss of the cells' compressive mean
    stress pressure_Pa (nx, nz) (kinetic_theory.sliding_dissipation_W_m3, on when
    prm.sliding_coefficient > 0), integrated exactly with the collisional loss in steps 1 and 4
    (exact_cooling_sliding)."""
    nx, nz = T.shape
    h = grid.spacing_m
    out = T.copy()
    a = np.zeros((nx, nz))
    b = np.zeros((nx, nz))
    capacity = np.zeros((nx, nz))
    for i in range(nx):
        for k in range(nz):
            if phi[i, k] >= grid.void_solid_fraction:
                capacity[i, k] = 1.5 * prm.density_kg_m3 * phi[i, k]
                a[i, k] = (cooling_coefficient(phi[i, k], out[i, k], shear_rate[i, k], prm)
                           + wall_cooling[i, k])
                b[i, k] = sliding_rate(phi[i, k], pressure_Pa[i, k], prm)
    kappa = np.zeros((nx, nz))
    for i in range(nx):
        for k in range(nz):
            if capacity[i, k] > 0.0:
                t = exact_cooling_sliding(out[i, k], a[i, k], b[i, k], 0.5 * dt)
                t += dt * (production_W_m3[i, k] + wall_heating_W_m3[i, k]) / capacity[i, k]
                out[i, k] = max(t, 0.0)
                kappa[i, k] = conductivity_kg_m_s(phi[i, k], out[i, k], prm)
    out = conduct(out, capacity, kappa, dt, h)
    for i in range(nx):
        for k in range(nz):
            if capacity[i, k] > 0.0:
                out[i, k] = exact_cooling_sliding(out[i, k], a[i, k], b[i, k], 0.5 * dt)
    return out


def edge_heating_W_m3(shape, spacing_m, left_W_m2=0.0, right_W_m2=0.0, bottom_W_m2=0.0,
                      top_W_m2=0.0):
    """The heating field (W/m^3, shape (nx, nz)) of given fluxes into the grid through its four
    edges (W/m^2, positive inwards; a number or an array along the edge): each edge cell gets
    flux x spacing / spacing^2, so that the grid gains flux x edge length per metre of
    thickness and per second."""
    nx, nz = shape
    s = np.zeros((nx, nz))
    h = float(spacing_m)
    s[0, :] += np.broadcast_to(np.asarray(left_W_m2, float), (nz,)) / h
    s[-1, :] += np.broadcast_to(np.asarray(right_W_m2, float), (nz,)) / h
    s[:, 0] += np.broadcast_to(np.asarray(bottom_W_m2, float), (nx,)) / h
    s[:, -1] += np.broadcast_to(np.asarray(top_W_m2, float), (nx,)) / h
    return s


def fluctuation_energy_J_m(T, phi, grid, prm) -> float:
    """The fluctuation energy (J per metre of thickness) of the non-empty cells:
    sum (3/2) rho_s phi T h^2."""
    phi = np.asarray(phi, float)
    full = phi >= grid.void_solid_fraction
    return float(np.sum(1.5 * prm.density_kg_m3 * phi[full] * np.asarray(T, float)[full])
                 * grid.spacing_m ** 2)
