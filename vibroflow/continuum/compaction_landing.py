"""The landing counted where the falling material is stopped: the inelastic compaction of
neighbouring cells, compiled.

A loose layer landing on a floor is not stopped by the floor alone.  It is stopped row by row
by the material already at rest below it: a compaction front runs up from the floor, and each
layer it sweeps closes its voids against the stopped material, a completely inelastic
collision (the compaction shock of a porous medium, whose work of closing the pores is
dissipated: Zel'dovich & Raizer 1967, Physics of Shock Waves, ch. XI; for a landing granular
layer, Mehta & Luck 1990's completely inelastic block).  The kinetic energy of the relative
normal motion the collision destroys does not go into elastic storage (the voids close
stress-free: eulerian/lagrangian_step.void_first) but into the grains' fluctuations: it is
fluctuation energy, as the landing at the wall is (wall_energy_flux.landing_terms).

Two neighbouring cells a, b across an open face of unit normal n (from a to b), masses m_a,
m_b at the step's start, approach when w = (v_b - v_a) . n < 0.  In their centre-of-mass frame
their kinetic energy of normal motion is E = mu w^2 / 2, mu = m_a m_b / (m_a + m_b), the most
a completely inelastic collision can destroy.  Over a step of dt the pair's momentum exchange
(the grid's and the remap's momentum transfer between them, the continuum's contact impulse)
takes from it

    E_lost = mu (w_0^2 - min(w_1, 0)^2) / 2 - p_f h max(-(w_0 + w_1) / 2, 0) dt,
             clipped to [0, mu w_0^2 / 2],

w_0, w_1 the relative normal velocities at the step's start and end: what the stopping has
destroyed, never more than the pair had, nothing for a pair separating (w_1 > 0 is a stop and
a rebound: only the stop counts) or still approaching faster.  The second term is the part the
stress took: the face's compressive normal stress p_f (Pa, the mean of the two cells' scattered
normal stress at the step's start, elastic-plastic plus the temperature's kinetic pressure)
on the face of length h (m) working on the approach.  That work is stored (elastic) or is
already the temperature's production (the kinetic pressure's -p_k tr D): counted again, it
would make energy (the shaken layer's pairs then feed 948 W/m^2 at every phase, 25 times what
they feed without it: docs/validation.md section 22).  What remains is the
momentum exchange that no stress carries, the void's closing.  The reduced mass is the
start's: mass moving between cells changes no velocity.  Each cell gets its own share of it, its
kinetic energy in the pair's centre-of-mass frame, m_b / (m_a + m_b) of E_lost for a and
m_a / (m_a + m_b) for b.  The wall's landing is the limit of an infinitely heavy b at rest.

Only where voids close: the pair counts when one of its cells, at the step's start, holds a
void (volume fraction f < 1) or loose, disconnected material (density below the critical
density rho_c).  Two connected, full cells approaching compress elastically, and that energy
comes back (the ringing of a settled bed, the elastic wave of a landing block): it is not lost.
A block resting or sliding feeds nothing (w = 0 across every face; the sliding's relative
motion is tangential), and a falling block feeds nothing until it meets slower material
(Galilean: only velocity differences enter).

Per cell the kernel adds the power E_lost / dt (W/m, per metre of thickness) to the landing
column out[:, 3] of the cells' wall contact sums (wall_energy_flux.contact_terms), which
cell_wall_terms turns into the landing heating of every cell holding material.
"""
from __future__ import annotations

import numba as nb

#: a cell holds a void when its volume fraction is below 1 by more than round-off
FULL = 1.0 - 1.0e-9


@nb.njit(cache=True)
def _pair(a, b, j, m0, v0, full0, rho0, sigma0, v1, h, rho_c, dt, out):
    """Adds the pair (a, b)'s compaction loss along axis j (0: x, 1: z; the face's normal from a
    to b) to out[a, 3] and out[b, 3] (module docstring); full0 (m^2) the area times FULL that a
    full cell's mass over its density reaches."""
    ma = m0[a]
    mb = m0[b]
    if not (ma > 0.0 and mb > 0.0):
        return
    w0 = v0[b, j] - v0[a, j]
    if not w0 < 0.0:
        return
    if ma >= full0 * rho0[a] and mb >= full0 * rho0[b] and rho0[a] >= rho_c and rho0[b] >= rho_c:
        return
    w1 = v1[b, j] - v1[a, j]
    m = ma + mb
    mu = ma * mb / m
    e0 = 0.5 * mu * w0 * w0
    # the reversible part: the face's compressive normal stress working on the approach
    p_face = -0.5 * (sigma0[a, j] + sigma0[b, j])
    stored = max(p_face, 0.0) * h * max(-0.5 * (w0 + w1), 0.0) * dt
    w1 = min(w1, 0.0)
    lost = min(max(e0 - 0.5 * mu * w1 * w1 - stored, 0.0), e0) / dt
    out[a, 3] += lost * mb / m
    out[b, 3] += lost * ma / m


@nb.njit(cache=True)
def z_face_terms(m0, v0, rho0, sigma0, v1, h, open_z, rho_c, dt, out):
    """`compaction_terms` over the open z faces alone."""
    ncx = open_z.shape[0]
    ncz = open_z.shape[1] - 1
    full0 = FULL * h * h
    for i in range(ncx):
        for k in range(1, ncz):
            if open_z[i, k]:
                _pair(i * ncz + k - 1, i * ncz + k, 1, m0, v0, full0, rho0, sigma0, v1, h,
                      rho_c, dt, out)


@nb.njit(cache=True)
def x_face_terms(m0, v0, rho0, sigma0, v1, h, open_x, rho_c, dt, out):
    """`compaction_terms` over the open x faces alone (a periodic mesh's face 0 is its face
    ncx, between cells ncx - 1 and 0)."""
    ncx = open_x.shape[0] - 1
    ncz = open_x.shape[1]
    full0 = FULL * h * h
    for k in range(ncz):
        for i in range(1, ncx):
            if open_x[i, k]:
                _pair((i - 1) * ncz + k, i * ncz + k, 0, m0, v0, full0, rho0, sigma0, v1, h,
                      rho_c, dt, out)
        if ncx > 1 and open_x[0, k]:
            _pair((ncx - 1) * ncz + k, k, 0, m0, v0, full0, rho0, sigma0, v1, h, rho_c, dt, out)


@nb.njit(cache=True)
def compaction_terms(m0, v0, rho0, sigma0, v1, h, open_x, open_z, rho_c, dt, out):
    """Adds the cells' compaction landing power (W/m) of a step of dt (s) to out[:, 3] (module
    docstring), over every open face of an Eulerian mesh (eulerian/mesh.py: open_x
    (ncx + 1, ncz), open_z (ncx, ncz + 1), cell p = i ncz + k; a periodic mesh's face 0 is its
    face ncx, between cells ncx - 1 and 0; plane strain).  m0 (N,) kg/m, v0 (N, 2) m/s, rho0
    (N,) the material's density (kg/m^3) and sigma0 (N, >= 2) the stress the step scatters
    (Pa, [xx, zz, ...], tension positive: the elastic-plastic stress plus the temperature's)
    at the step's start, v1 (N, 2) m/s at its end, h (m) the cells' side, rho_c (kg/m^3) the
    critical density."""
    z_face_terms(m0, v0, rho0, sigma0, v1, h, open_z, rho_c, dt, out)
    x_face_terms(m0, v0, rho0, sigma0, v1, h, open_x, rho_c, dt, out)
