"""Many MPM steps in one numba call, parallel over a fixed number of point chunks.

The step is mpm/solver.py's (boundaries, p2g, grid update, g2p, volume and stress), made of the same
kernels (boundary.py, p2g.py, grid_step.py, g2p.py, plasticity.py, stress_update.py), but run
as one compiled loop over `nsteps` steps, without a Python step's dispatch per kernel, the
boundaries' Python methods and the frame's pose (~15 % of a tub47-quick step, whose time is
otherwise the scatter and the gather, ~40 % each).

Threads.  The N points are cut into `nchunk` fixed contiguous chunks (grid_step.chunk_bounds);
numba's threads take whole chunks (prange).  Every per-point kernel (walls, partitions, g2p,
volume, stress) writes only its own points, so it gives the same numbers however the chunks are
shared out.  The particle-to-grid scatter writes per-chunk grid buffers, which are then summed
node by node in the fixed order chunk 0, 1, ... (grid_step.grid_phase, the Eulerian loop's
too), so the grid sums, and with them the whole run, depend on the number of chunks and never
on the number of threads (as the DEM's run.force_chunks: vibroflow.dem.step).  With one chunk
the scatter is the serial p2g's, bit for bit.

Records (numba named tuples): `Points` the state's arrays (mpm.solver.MPMState), `MPMStep` the
step's constants, `Boundaries` the boundaries as BOUNDARY_DTYPE records in the system's order
with the walls' stacked histories (boundary.py, mpm.solver.pack_boundaries), and the grid's
GridSpec and GridWork (grid_step.py).

numba's cache watches only the file of the function it compiled, and a compiled loop holds its
own copy of every kernel it calls: edited boundary or constitutive kernels would go on running
in a cached loop compiled before.  The package drops its whole kernel cache when any of its
sources changes (vibroflow/_kernel_cache.py), which covers this loop with every other.
"""
from __future__ import annotations

from collections import namedtuple

import numba as nb
import numpy as np

from .boundary import boundary_forces
from .constitutive import P_ETA_BED
from .g2p import g2p
from .grid_step import grid_phase
from .p2g import p2g
from .plasticity import plasticity_step
from .stress_update import damped_stress
from .kinetic_stress import RATE_RATIO
from .temperature_field import add_stress
from .transfer_operator import operator_of_points

#: status of `advance_kernel`
OK, THROUGH_WALL, ESCAPED = 0, 1, 2

#: the material points' arrays (mpm.solver.MPMState's, units there) and stress_work (N, 4) the
#: stress scattered when the material has a bed viscosity or a kinetic pressure
#: (stress_update.damped_stress; (0, 4) without), p_kin (N, 5) the granular temperature's stress
#: (Pa) added to the scattered one and its return map's rate ratio (kinetic_stress.py; (0, 5)
#: without the temperature)
Points = namedtuple("Points", ["x", "v", "C", "L", "mass", "volume", "density", "stress",
                               "gamma_dot", "phase", "fext", "stress_work", "p_kin"])
#: the step's constants: dt (s), the material's params (constitutive.ContinuumMaterial.
#: as_array), the frame (grid_update.FRAME_FIELDS), box (4,) the region (m) a point may occupy
#: (xmin, xmax, zmin, zmax), bounds (nchunk + 1,) the point chunks (grid_step.chunk_bounds),
#: flip the FLIP fraction (mpm.solver.MPMSystem.flip)
MPMStep = namedtuple("MPMStep", ["dt", "params", "frame", "box", "bounds", "flip"])
#: records (nb,) of boundary.BOUNDARY_DTYPE in the system's order, and the walls' histories
#: (walls, N, ...) xi, f, fn, ft, state (boundary.py; row `hist` of a wall's record), and the
#: packed parts the part walls use (boundary.NO_PARTS' layout)
Boundaries = namedtuple("Boundaries", ["records", "xi", "f", "fn", "ft", "state", "parts"])


@nb.njit(cache=True)
def _escaped_range(a, b, x, v, xmin, xmax, zmin, zmax):
    """Points of a:b outside the box or with a non-finite velocity."""
    bad = 0
    for p in range(a, b):
        if not (xmin <= x[p, 0] <= xmax and zmin <= x[p, 1] <= zmax):
            bad += 1
        elif not (np.isfinite(v[p, 0]) and np.isfinite(v[p, 1])):
            bad += 1
    return bad


@nb.njit(cache=True, parallel=True)
def advance_kernel(nsteps, t, points, step, boundaries, grid, work):
    """Up to nsteps MPM steps of step.dt (s) from time t (s), in place (module docstring):
    points (Points), step (MPMStep), boundaries (Boundaries), grid (grid_step.GridSpec), work
    (grid_step.GridWork).

    Returns (steps done, t after them, status, boundary): status OK; THROUGH_WALL when points
    went through the boundary `boundary` (the step was not made: t is its start; the
    boundaries' forces and histories were computed); ESCAPED when after the last step made a
    point is off the box or non-finite."""
    x, v, C, L, mass, volume, density, stress, gamma_dot, phase, fext, stress_work, p_kin = \
        points
    dt, params, frame, box, bounds, flip = step
    records = boundaries.records
    hist = (boundaries.xi, boundaries.f, boundaries.fn, boundaries.ft, boundaries.state)
    parts = boundaries.parts
    x0, z0, dx, periodic, no_slip_rows, axis_cols = grid
    cm, cmv, cf, gm, gmv, gf, gv, transfers, cb, B, gtmp = work
    nchunk = bounds.shape[0] - 1
    nb_ = records.shape[0]
    deep = np.zeros((nchunk, max(nb_, 1)), np.int64)
    bad = np.zeros(nchunk, np.int64)
    damped = params[P_ETA_BED] > 0.0
    kinetic = p_kin.shape[0] > 0
    scattered = stress_work if damped or kinetic else stress
    for s in range(nsteps):
        # 1-2: the boundaries' forces in their order (fext zeroed first; deep: the points
        # through each wall, boundary.py `lost`) and the scatter, per chunk
        for c in nb.prange(nchunk):
            a = bounds[c]
            b = bounds[c + 1]
            fext[a:b] = 0.0
            for j in range(nb_):
                deep[c, j] = boundary_forces(records[j], x, v, mass, volume, stress, fext,
                                             hist, parts, a, b, t, dt)
            cm[c] = 0.0
            cmv[c] = 0.0
            cf[c] = 0.0
            if damped:
                # the bed's Kelvin-Voigt damping on the rate of the last step, scattered with
                # the stress but not stored in it
                damped_stress(stress[a:b], L[a:b], phase[a:b], params, stress_work[a:b])
            elif kinetic:
                stress_work[a:b] = stress[a:b]
            if kinetic:
                add_stress(stress_work, p_kin, a, b)
            p2g(x[a:b], v[a:b], C[a:b], mass[a:b], volume[a:b], scattered[a:b], fext[a:b], x0,
                z0, dx, periodic, cm[c], cmv[c], cf[c], axis_cols > 0)
            if transfers > 1:
                cb[c] = 0.0
                operator_of_points(x[a:b], mass[a:b], x0, z0, dx, periodic, cb[c])
        for j in range(nb_):
            n_deep = 0
            for c in range(nchunk):
                n_deep += deep[c, j]
            if n_deep > 0:
                return s, t, THROUGH_WALL, j
        # 3: the grid's part (grid_step.py): the chunks' sums, the update with the frame's
        # acceleration at mid-step, the grid's conditions and the further transfers
        gv = grid_phase(grid, work, frame, t, dt)
        # 4-5: gather, move, volume and stress, per chunk
        for c in nb.prange(nchunk):
            a = bounds[c]
            b = bounds[c + 1]
            g2p(x[a:b], v[a:b], C[a:b], L[a:b], gv, x0, z0, dx, dt, periodic, gm, gmv,
                flip)
            plasticity_step(L[a:b], mass[a:b], volume[a:b], density[a:b], stress[a:b], dt,
                            params, gamma_dot[a:b], phase[a:b], p_kin[a:b, RATE_RATIO])
            bad[c] = _escaped_range(a, b, x, v, box[0], box[1], box[2], box[3])
        t += dt
        n_bad = 0
        for c in range(nchunk):
            n_bad += bad[c]
        if n_bad > 0:
            return s + 1, t, ESCAPED, -1
    return nsteps, t, OK, -1
