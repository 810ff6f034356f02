"""The shear rates a sample reads from the cells holding material, in one compiled pass.

A sample (formulation.CellSampler.record) reads, of the mesh's cells inside the tub that hold
at least half a cell of material: their shear rates gamma_dot = sqrt(2 D':D') (1/s;
stress_update.equivalent_shear_rate), all of them, those of the U's wall layer and those in
each probe's analysis cell, and for the analysis cells' maps their analysis cells, volumes and
stresses, and the means of the rates.  One loop packs each selection in the cells' order and
takes its mean in numpy's summation order (numpy_sum.py), so the means are those numpy takes
of its masks' selections, bit for bit.
"""
from __future__ import annotations

from collections import namedtuple

import numba as nb
import numpy as np

from ..numpy_sum import pairwise_mean
from ..stress_update import equivalent_shear_rate

#: a sample's selections (`held_rates`): held (M,) whether each of the M cells holds material
#: and rates (M,) 1/s the rates of those that do (in the cells' places);
#: rate (M,) 1/s, index (M,), volume (M,) m^2 and stress (M, 4) Pa of those that do, packed
#: first; wall (M,) the rates of those in the wall layer, packed; probe (P,) the rates of those
#: in each probe, probe after probe (P the probes' cell count), probe_n (Q,) how many each;
#: means (2 + Q,) 1/s the mean rate of all of them, of the wall layer's and of each probe's
#: (NaN where none)
HeldRates = namedtuple("HeldRates", ["held", "rates", "rate", "index", "volume", "stress", "wall",
                                     "probe", "probe_n", "means"])


def held_rates_work(n_cells: int, probe_members: list) -> HeldRates:
    """`held_rates`' arrays for n_cells cells and the probes' members (indices into them)."""
    total = sum(len(m) for m in probe_members)
    return HeldRates(np.zeros(n_cells, np.bool_), np.zeros(n_cells), np.zeros(n_cells),
                     np.zeros(n_cells, np.int64),
                     np.zeros(n_cells), np.zeros((n_cells, 4)), np.zeros(n_cells),
                     np.zeros(total), np.zeros(len(probe_members), np.int64),
                     np.zeros(2 + len(probe_members)))


@nb.njit(cache=True)
def held_rates(L, mass, half, cells, index, volume, stress, near_wall, members, member_ptr,
               out):
    """The cells `cells` (M,) of velocity gradients L (N, 4+) [xx, xz, zx, zz] (1/s), masses
    (N,) (kg/m) and volumes (N,) (m^2), stresses (N, 4) (Pa) that hold at least `half` of
    material, their analysis cells index (M,), whether each is in the wall layer near_wall (M,),
    the probes' cells members (indices into cells, probe q's at member_ptr[q]:member_ptr[q + 1]).
    Fills out (HeldRates); returns (held count, wall count)."""
    m = 0
    w = 0
    for j in range(cells.shape[0]):
        p = cells[j]
        h = mass[p] >= half
        out.held[j] = h
        if h:
            r = equivalent_shear_rate(L[p, 0], L[p, 1], L[p, 2], L[p, 3])
            out.rates[j] = r
            out.rate[m] = r
            out.index[m] = index[j]
            out.volume[m] = volume[p]
            for c in range(4):
                out.stress[m, c] = stress[p, c]
            m += 1
            if near_wall[j]:
                out.wall[w] = r
                w += 1
    out.means[0] = pairwise_mean(out.rate, 0, m)
    out.means[1] = pairwise_mean(out.wall, 0, w)
    k = 0
    for q in range(member_ptr.shape[0] - 1):
        c = 0
        for t in range(member_ptr[q], member_ptr[q + 1]):
            j = members[t]
            if out.held[j]:
                out.probe[k] = out.rates[j]
                k += 1
                c += 1
        out.probe_n[q] = c
        out.means[2 + q] = pairwise_mean(out.probe, k - c, c)
    return m, w
