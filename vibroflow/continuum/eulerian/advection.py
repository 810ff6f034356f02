"""The remap step: conservative transport of the material through the fixed mesh.

After the Lagrangian step (lagrangian_step.py) the material has moved by v dt relative to the
fixed cells; the remap brings it back onto them, as the Eulerian hydrocodes do (Benson 1992,
Comput. Methods Appl. Mech. Eng. 99, 235, "Computational methods in Lagrangian and Eulerian
hydrocodes", section 5: the operator split into a Lagrangian and a transport step).  The
transport is a finite-volume donor-cell scheme of second order (MUSCL, van Leer 1979) with the
monotonised-central limiter (van Leer 1977), unsplit in x and z (the advective Courant numbers
of a run are ~1e-3, far inside its stability limit, so neither dimensional splitting nor
corner-transport terms are needed):

* the conserved quantity is the cell mass m (kg per metre of thickness); the face flux is
  F = u_f dt h rho_f, with u_f the face-normal velocity (face_velocity.py: the nodal velocity
  field interpolated at the face's midpoint) and rho_f = m / h^2 reconstructed on the upwind
  side with the limited slope;
* every other field q (velocity, APIC affine matrix, stress: the material's intensive
  properties) is carried mass-weighted, (m q)_new = m q - sum F q_f, with q_f the limited
  upwind reconstruction of q itself (bounded by its neighbours, so the transport creates no new
  extrema of stress or velocity): this is the stress advection that the rate form of the
  elasto-plastic law needs in a fixed mesh;
* closed faces (mesh.py: the wall) carry no flux, and a slope is not taken across them or
  across an empty neighbour;
* an empty cell (at most EMPTY of the fullest cell's mass per volume) gives nothing: its fields
  are 0 (the renewal's mode 0) and its round-off mass stays, so the donor-cell scheme's
  numerical diffusion stops one row above the material instead of filling the mesh with masses
  of 1e-24 of a full cell (what lies above the material's top row is then the same at every
  step: remap_rows.py leaves it out).

Each face flux is added to one cell and taken from the other, so the total mass is conserved to
round-off; nothing is clipped (the Courant numbers keep every cell's mass >= 0; a negative one
is reported by the solver).  The volume fraction f = min(1, m / (rho h^2)) (solver.py) is
computed from the transported mass and density, so it is transported without losing mass too.

Speed (the remap is a large part of the Eulerian step).  The arithmetic is that of a
face-by-face loop (every cell's fluxes summed in the order x-faces by ascending i, then z-faces
by ascending k), but it runs field by field over flat arrays, each pass a long branch-free loop
(`_pick`) that the compiler vectorises; a loop over one row of cells was too short for it.
What does not depend on the carried fields (the mass fluxes, the upwind factors, the masks of
the slopes) is computed once a step (`_prepare`), not once per field.
"""
from __future__ import annotations

import math

import numba as nb
import numpy as np


#: a cell with less mass than this fraction of a full cell is empty
EMPTY = 1.0e-12


@nb.njit(cache=True, inline="always")
def _mc(a, b):
    """Monotonised-central limited slope of the two one-sided differences a, b: 0 when they
    differ in sign, else their mean clipped to twice the smaller (written without branches on
    the data, which the slopes' loop would mispredict)."""
    s = 0.5 * (a + b)
    lim = 2.0 * min(abs(a), abs(b))
    r = math.copysign(min(abs(s), lim), s)
    return r if a * b > 0.0 else 0.0


@nb.njit(cache=True, inline="always")
def _pick(flag, a, b):
    """a where flag else b: both already computed, so the loops stay free of branches and
    vectorise (the selects compile to masked moves)."""
    return a if flag else b


# The remap works on flat arrays over the cells, p = i * ncz + k, field after field, so that
# its loops run over whole fields and vectorise (one row of ncz cells is too short a loop).
# A face is stored at the index of the cell above or right of it: x-face (i, k) at i * ncz + k
# ((ncx + 1) ncz of them), z-face (i, k) below cell (i, k) at i * ncz + k (n + 1 of them, the
# last a dummy: the top face of every column is the wall, and index (i + 1) ncz, the top of
# row i, is the floor of row i + 1, also shut).


@nb.njit(cache=True, inline="always")
def _x_neighbours(i, ncx, periodic):
    """The rows left and right of row i: wrapped on a periodic mesh, else clamped (a closed
    edge's neighbour is read but masked off)."""
    if periodic:
        return (i + ncx - 1) % ncx, (i + 1) % ncx
    return max(i - 1, 0), min(i + 1, ncx - 1)


@nb.njit(cache=True)
def _slopes(qj, ncx, ncz, periodic, ml, mr, md, mu, sx, sz):
    """Limited slopes (times h) along x and z of the field qj (n,): sx, sz (n,); a one-sided
    difference is taken only where its mask (ml, mr, md, mu (n,): left, right, down, up) is
    set, else it is 0.  The loops run over views shifted by the neighbour's offset, indices
    from 0 (a shifted index would be checked for wrapping around, and not vectorise)."""
    n = ncx * ncz
    for i in (0, ncx - 1):
        il, ir = _x_neighbours(i, ncx, periodic)
        for k in range(ncz):
            p = i * ncz + k
            a = _pick(ml[p], qj[p] - qj[il * ncz + k], 0.0)
            b = _pick(mr[p], qj[ir * ncz + k] - qj[p], 0.0)
            sx[p] = _mc(a, b)
    w = n - 2 * ncz
    ql, qc, qr = qj[:w], qj[ncz:ncz + w], qj[2 * ncz:]
    l, r, out = ml[ncz:ncz + w], mr[ncz:ncz + w], sx[ncz:ncz + w]
    for p in range(w):
        out[p] = _mc(_pick(l[p], qc[p] - ql[p], 0.0), _pick(r[p], qr[p] - qc[p], 0.0))
    # z: the first and last cells' outer neighbours are the floor and the lid (masked off)
    sz[0] = _mc(0.0, _pick(mu[0], qj[1] - qj[0], 0.0))
    w = n - 2
    qd, qc, qu = qj[:w], qj[1:1 + w], qj[2:]
    d, u, out = md[1:1 + w], mu[1:1 + w], sz[1:1 + w]
    for p in range(w):
        out[p] = _mc(_pick(d[p], qc[p] - qd[p], 0.0), _pick(u[p], qu[p] - qc[p], 0.0))
    sz[n - 1] = _mc(_pick(md[n - 1], qj[n - 1] - qj[n - 2], 0.0), 0.0)


@nb.njit(cache=True)
def _combine(ncx, ncz, periodic, ax, gx, az, gz, d):
    """The net inflow d (n,) of every cell from its face fluxes gx (x-faces) and gz (z-faces)
    (from the lower to the higher index), counting only the faces flagged in ax, az: each
    cell's sum in the scheme's face order (x-faces by ascending i, then z-faces by ascending k,
    each flux added to one cell and taken from the other), every operation as in a
    face-by-face loop, so the numbers are that loop's, bit for bit.  (Views from 0, as in
    `_slopes`.)"""
    n = ncx * ncz
    w = n - ncz if periodic else n
    al, gl, ar, gr = ax[:w], gx[:w], ax[ncz:ncz + w], gx[ncz:ncz + w]
    ad, gd, au, gu = az[:w], gz[:w], az[1:1 + w], gz[1:1 + w]
    for p in range(w):
        v = 0.0
        v = _pick(al[p], v + gl[p], v)
        v = _pick(ar[p], v - gr[p], v)
        v = _pick(ad[p], v + gd[p], v)
        d[p] = _pick(au[p], v - gu[p], v)
    for p in range(w, n):
        # the last row of a periodic mesh: its right face is face 0, whose flux comes first
        k = p - w
        v = 0.0
        v = _pick(ax[k], v - gx[k], v)
        v = _pick(ax[p], v + gx[p], v)
        v = _pick(az[p], v + gz[p], v)
        d[p] = _pick(az[p + 1], v - gz[p + 1], v)


@nb.njit(cache=True)
def _faces(u, r_lo, s_lo, r_hi, s_hi, h, dt, wf, r_empty, on, pos, fac, flux):
    """Faces j (m,) between cells lo and hi (mass per volume r (kg/m^3), limited slope s) with
    normal velocity u (m/s, from lo to hi): on, whether it carries a flux (u != 0 and its
    upwind cell is not empty, r > r_empty: nothing to carry from an empty cell, whose fields
    the renewal has set to 0 (`_modes`), so that its round-off mass stays where it is and the
    bed keeps a top above which no cell exchanges anything (remap_rows.py)); pos, whether its
    upwind cell is lo; fac = sgn (1 - c) / 2, its upwind reconstruction's factor
    (c = |u| dt / h); flux F = u dt h w (r + fac s)_upwind (kg/m, or kg per radian), w (m,) the
    face's weight (1 in plane strain; its radius in an axisymmetric section, whose face of side
    h sweeps h r per radian)."""
    for j in range(u.shape[0]):
        uj = u[j]
        p = uj > 0.0
        ru = _pick(p, r_lo[j], r_hi[j])
        su = _pick(p, s_lo[j], s_hi[j])
        c = abs(uj) * dt / h
        sgn = _pick(p, 1.0, -1.0)
        f = sgn * 0.5 * (1.0 - c)
        pos[j] = p
        on[j] = uj != 0.0 and ru > r_empty
        fac[j] = f
        flux[j] = uj * dt * h * wf[j] * (ru + f * su)


@nb.njit(cache=True)
def _prepare(m, ux, uz, h, dt, ncx, ncz, periodic, cells, masks, xf, xb, zf, zb, weights):
    """Everything of a transport step that does not depend on the carried fields, on the flat
    layout (above): cells = (rho, srx, srz, _, _, uzc) the mass per area (kg/m^3), its limited
    slopes and a work array; masks = (ol, orr, od, ou, okl, okr, okd, oku): the cells' open
    faces (the mesh's, `remap_work`) and the neighbours a field's slope may be taken against
    (an open face to a cell that is not empty); per face, xf, zf = (c, F): the upwind
    reconstruction's factor sgn (1 - c) / 2 and the mass flux F (kg/m, from the lower to the
    higher index), xb, zb = (on, pos): whether it carries a flux and whether its upwind cell is
    the lower-index one; weights = (wc, wx, wz) (`remap_work`): the cells' and the faces'
    weights, 1 in plane strain, the radius in an axisymmetric section.  Returns m_empty, the
    mass (kg/m) at or below which a cell is empty."""
    rho, srx, srz, uzc = cells[0], cells[1], cells[2], cells[5]
    ol, orr, od, ou, okl, okr, okd, oku = masks
    cx, fx = xf
    ax, px = xb
    cz, fz = zf
    az, pz = zb
    wc, wx, wz = weights
    n = ncx * ncz
    area = h * h
    full = 0.0
    for p in range(n):
        rho[p] = m[p] / (area * wc[p])
        if rho[p] > full:
            full = rho[p]
    rho_empty = EMPTY * full
    # the neighbours left and right (views from 0, as in `_slopes`)
    for i in (0, ncx - 1):
        il, ir = _x_neighbours(i, ncx, periodic)
        for k in range(ncz):
            p = i * ncz + k
            okl[p] = ol[p] and rho[il * ncz + k] > rho_empty
            okr[p] = orr[p] and rho[ir * ncz + k] > rho_empty
    w = n - 2 * ncz
    ol_, or_, rl, rr = ol[ncz:ncz + w], orr[ncz:ncz + w], rho[:w], rho[2 * ncz:]
    okl_, okr_ = okl[ncz:ncz + w], okr[ncz:ncz + w]
    for p in range(w):
        okl_[p] = ol_[p] and rl[p] > rho_empty
        okr_[p] = or_[p] and rr[p] > rho_empty
    # the neighbours below and above (views from 0, as in `_slopes`)
    w = n - 1
    od_, ou_, rd, ru = od[1:], ou[:w], rho[:w], rho[1:]
    okd_, oku_ = okd[1:], oku[:w]
    for p in range(w):
        okd_[p] = od_[p] and rd[p] > rho_empty
        oku_[p] = ou_[p] and ru[p] > rho_empty
    okd[0] = False
    oku[n - 1] = False
    _slopes(rho, ncx, ncz, periodic, ol, orr, od, ou, srx, srz)
    for p in range(n):
        # an empty cell is never upwind of a flux, so its slopes are never used
        srx[p] = _pick(rho[p] > 0.0, srx[p], 0.0)
        srz[p] = _pick(rho[p] > 0.0, srz[p], 0.0)
    # x-faces: face i * ncz + k between cells (i - 1, k) and (i, k); the outer ones of a closed
    # mesh are shut, and a periodic mesh's face ncx is its face 0
    for f in range(n, n + ncz):
        ax[f] = False
        fx[f] = 0.0
    if periodic:
        _faces(ux[:ncz], rho[n - ncz:], srx[n - ncz:], rho[:ncz], srx[:ncz], h, dt, wx[:ncz],
               rho_empty, ax[:ncz], px[:ncz], cx[:ncz], fx[:ncz])
    else:
        for f in range(ncz):
            ax[f] = False
            fx[f] = 0.0
    w = n - ncz
    _faces(ux[ncz:n], rho[:w], srx[:w], rho[ncz:], srx[ncz:], h, dt, wx[ncz:n], rho_empty,
           ax[ncz:n], px[ncz:n], cx[ncz:n], fx[ncz:n])
    # z-faces: below cell p, between cells p - 1 and p, their velocities copied to that
    # layout first (one flat pass, not one per column); the floor of a column is shut (u = 0)
    for i in range(ncx):
        for k in range(ncz):
            uzc[i * ncz + k] = uz[i, k]
    az[0] = False
    fz[0] = 0.0
    az[n] = False
    fz[n] = 0.0
    w = n - 1
    _faces(uzc[1:n], rho[:w], srz[:w], rho[1:], srz[1:], h, dt, wz[1:n], rho_empty, az[1:n],
           pz[1:n], cz[1:n], fz[1:n])
    return rho_empty * area


@nb.njit(cache=True)
def _field_fluxes(qj, ncx, ncz, periodic, masks, xf, xb, zf, zb, sx, sz, gx, gz, d):
    """The net inflow d (n,) (kg/m times the field's unit) of the field qj (n,) into every
    cell: the limited slopes sx, sz, the face fluxes gx, gz (work arrays), then `_combine`."""
    okl, okr, okd, oku = masks[4], masks[5], masks[6], masks[7]
    cx, fx = xf
    px = xb[1]
    cz, fz = zf
    pz = zb[1]
    n = ncx * ncz
    _slopes(qj, ncx, ncz, periodic, okl, okr, okd, oku, sx, sz)
    # the upwind reconstruction q + sgn (1 - c) / 2 slope on either side of the face; the
    # face's own pos picks its upwind one
    for f in range(ncz):
        left = f - ncz + n
        gx[f] = fx[f] * _pick(px[f], qj[left] + cx[f] * sx[left], qj[f] + cx[f] * sx[f])
    w = n - ncz
    ql, sl, qr, sr = qj[:w], sx[:w], qj[ncz:], sx[ncz:]
    c, fl, pos, g = cx[ncz:ncz + w], fx[ncz:ncz + w], px[ncz:ncz + w], gx[ncz:ncz + w]
    for f in range(w):
        g[f] = fl[f] * _pick(pos[f], ql[f] + c[f] * sl[f], qr[f] + c[f] * sr[f])
    gz[0] = 0.0
    w = n - 1
    qd, sd, qu, su = qj[:w], sz[:w], qj[1:], sz[1:]
    c, fl, pos, g = cz[1:1 + w], fz[1:1 + w], pz[1:1 + w], gz[1:1 + w]
    for p in range(w):
        g[p] = fl[p] * _pick(pos[p], qd[p] + c[p] * sd[p], qu[p] + c[p] * su[p])
    _combine(ncx, ncz, periodic, xb[0], gx, zb[0], gz, d)


@nb.njit(cache=True)
def _modes(m, dm, m_empty, mode, inv):
    """How each cell's fields are renewed (`renew_cells`): mode 1, a cell that held material and
    still does, q = (m q + dq) / m_new; 2, an empty cell filling, q = dq / dm (what it holds is
    what came in: its round-off mass carried no properties); 0, a cell left empty, q = 0; inv
    the reciprocal used (1/kg)."""
    for p in range(m.shape[0]):
        mo = m[p]
        mn = mo + dm[p]
        if mn > m_empty and mo > m_empty:
            mode[p] = 1
            inv[p] = 1.0 / mn
        elif mn > m_empty:
            mode[p] = 2
            inv[p] = 1.0 / dm[p]
        else:
            mode[p] = 0
            inv[p] = 0.0


def remap_work(open_x, open_z, nq: int, radius=None):
    """The work arrays of `remap` on a mesh with open faces open_x (ncx + 1, ncz), open_z
    (ncx, ncz + 1) carrying nq fields, with each cell's open faces (left, right, down, up: the
    mesh's constants) and the weights of the cells and faces: 1 in plane strain; with
    `radius` = (r_cells (ncx,), r_faces (ncx + 1,)) (m), an axisymmetric section's, where a
    cell of side h holds h^2 r per radian and its faces sweep h r (x-faces at their own
    radius, z-faces at their cell's)."""
    ncx, ncz = open_z.shape[0], open_x.shape[1]
    n = ncx * ncz
    nf = (ncx + 1) * ncz
    if radius is None:
        weights = (np.ones(n), np.ones(nf), np.ones(n + 1))
    else:
        r_cells, r_faces = (np.asarray(r, dtype=float) for r in radius)
        wz = np.ones(n + 1)
        wz[:n] = np.repeat(r_cells, ncz)
        weights = (np.repeat(r_cells, ncz), np.repeat(r_faces, ncz), wz)
    faces = (open_x[:-1].ravel(), open_x[1:].ravel(), open_z[:, :-1].ravel(),
             open_z[:, 1:].ravel())
    masks = tuple(np.array(f, bool) for f in faces) + tuple(np.zeros(n, bool) for _ in range(4))
    return (tuple(np.zeros(n) for _ in range(6)), masks,
            (np.zeros(nf), np.zeros(nf)), (np.zeros(nf, bool), np.zeros(nf, bool)),
            (np.zeros(n + 1), np.zeros(n + 1)), (np.zeros(n + 1, bool), np.zeros(n + 1, bool)),
            np.zeros(n, np.int8), (np.zeros((nq, n)), np.zeros((nq, n))),
            (np.zeros((nq, nf)), np.zeros((nq, n + 1))), np.zeros((nq, n)), weights)


@nb.njit(cache=True, inline="always")
def renewed(mk, mo, ip, qv, dqv):
    """A carried field's value after the transport step in a cell of mode mk (`_modes`), old
    mass mo (kg/m) and reciprocal ip: (mo q + dq) ip, dq ip or 0, q its value before and dq
    its inflow."""
    qa = (mo * qv + dqv) * ip
    qb = dqv * ip
    return _pick(mk == 1, qa, _pick(mk == 2, qb, 0.0))


@nb.njit(cache=True)
def renew_cells(a, b, qf, dq, mf, dm, mode, inv):
    """The end of a transport step on the cells a:b: every carried field qf (nq, n) renewed
    from its inflow dq by the cell's mode (`renewed`), then the masses mf (n,) given their
    inflow dm.  Returns the smallest new mass among them (kg/m; inf for none).  `remap` calls
    it on every cell, after `remap_fluxes` (fused.py renews its fields straight into the
    cells' arrays with `renewed`, and the masses with `renew_masses`)."""
    nq = qf.shape[0]
    for p in range(a, b):
        mk = mode[p]
        mo = mf[p]
        ip = inv[p]
        for j in range(nq):
            qf[j, p] = renewed(mk, mo, ip, qf[j, p], dq[j, p])
    return renew_masses(a, b, mf, dm)


@nb.njit(cache=True)
def renew_masses(a, b, mf, dm):
    """The masses mf (n,) of the cells a:b given their inflow dm (after their fields are
    renewed, which read the old masses).  Returns the smallest new mass (kg/m; inf for none)."""
    lowest = np.inf
    for p in range(a, b):
        mn = mf[p] + dm[p]
        if mn < lowest:
            lowest = mn
        mf[p] = mn
    return lowest


def _make_remap_fluxes(parallel: bool):
    """remap_fluxes, parallel over the carried fields or serial."""

    @nb.njit(cache=True, parallel=parallel)
    def remap_fluxes(m, q, ux, uz, h, dt, periodic, work):
        """A transport step's fluxes (`remap`, the same arguments): every cell's inflow of mass
        (work's cells[3]) and of each field (work's dq), and how each cell's fields are renewed
        (work's mode and cells[4]), nothing changed yet: `renew_cells` ends the step.
        Parallel over the fields, each field's fluxes one thread's."""
        _ = parallel
        cells, masks, xf, xb, zf, zb, mode, (sx, sz), (gx, gz), dq, weights = work
        ncx, ncz = m.shape
        nq = q.shape[0]
        n = ncx * ncz
        mf = m.reshape(n)
        qf = q.reshape((nq, n))
        dm, inv = cells[3], cells[4]
        m_empty = _prepare(mf, ux.reshape((ncx + 1) * ncz), uz, h, dt, ncx, ncz, periodic,
                           cells, masks, xf, xb, zf, zb, weights)
        for j in nb.prange(nq + 1):
            if j == nq:
                _combine(ncx, ncz, periodic, xb[0], xf[1], zb[0], zf[1], dm)
            else:
                _field_fluxes(qf[j], ncx, ncz, periodic, masks, xf, xb, zf, zb, sx[j], sz[j],
                              gx[j], gz[j], dq[j])
        _modes(mf, dm, m_empty, mode, inv)

    return remap_fluxes


remap_fluxes = _make_remap_fluxes(True)
remap_fluxes_serial = _make_remap_fluxes(False)


#: `remap`'s chunks of cells for the renewal (the smallest mass is the same in any number)
RENEW_CHUNKS = 4


def _make_remap(parallel: bool):
    """remap, parallel (its fluxes over the carried fields, its renewal over chunks of cells)
    or serial."""

    @nb.njit(cache=True, parallel=parallel)
    def remap(m, q, ux, uz, h, dt, periodic, work):
        """One transport step (module docstring), in place.  m (ncx, ncz) cell masses (kg/m);
        q (nq, ncx, ncz) intensive fields carried with the mass, field after field (the flat
        layout above); ux, uz face velocities (m/s) of face_velocity.face_velocities; h cell
        side (m); dt (s); work: remap_work's arrays (the mesh's open faces with them).  Returns the
        smallest cell mass after the step (kg/m; negative means the Courant number was too
        large).

        Parallel over the fields for their fluxes (`remap_fluxes`), each field's one
        thread's, then over chunks of cells for their renewal (`renew_cells`), each cell's one
        thread's: the numbers are the serial loop's, bit for bit, whatever the threads."""
        if parallel:
            remap_fluxes(m, q, ux, uz, h, dt, periodic, work)
        else:
            remap_fluxes_serial(m, q, ux, uz, h, dt, periodic, work)
        ncx, ncz = m.shape
        nq = q.shape[0]
        n = ncx * ncz
        qf, mf = q.reshape((nq, n)), m.reshape(n)
        dm, inv, mode, dq = work[0][3], work[0][4], work[6], work[9]
        lows = np.empty(RENEW_CHUNKS)
        for c in nb.prange(RENEW_CHUNKS):
            lows[c] = renew_cells((c * n) // RENEW_CHUNKS, ((c + 1) * n) // RENEW_CHUNKS, qf,
                                  dq, mf, dm, mode, inv)
        return lows.min()

    return remap


remap = _make_remap(True)
remap_serial = _make_remap(False)


def advect(m, q, ux, uz, h, dt, open_x, open_z, periodic, work_rho, srx, srz, sqx, sqz, dm,
           dq):
    """`remap` of fields q (ncx, ncz, nq) stored cell after cell; work_rho, srx, srz, dm
    (ncx, ncz) and sqx, sqz, dq (ncx, ncz, nq) serve as remap_work's arrays of their sizes."""
    ncx, ncz, nq = q.shape
    n = ncx * ncz
    w = remap_work(open_x, open_z, nq)
    cells = (work_rho.reshape(n), srx.reshape(n), srz.reshape(n), dm.reshape(n), w[0][4],
             w[0][5])
    work = (cells,) + w[1:7] + ((sqx.reshape(nq, n), sqz.reshape(nq, n)), w[8],
                                dq.reshape(nq, n), w[10])
    qf = np.ascontiguousarray(np.moveaxis(q, 2, 0))
    lowest = remap_serial(m, qf, ux, uz, h, dt, periodic, work)
    q[...] = np.moveaxis(qf, 0, 2)
    return lowest
