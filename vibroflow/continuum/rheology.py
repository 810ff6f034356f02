"""The dense-flow rheology's laws in numpy form: mu(I) and phi(I).

* mu(I) = mu_s + (mu_2 - mu_s) / (1 + I_0 / I)        (GDR MiDi 2004; Jop, Forterre &
  Pouliquen 2006, Nature 441:727)
* phi(I) = phi_max - (phi_max - phi_min) I             (GDR MiDi 2004; Forterre & Pouliquen
  2008, Annu. Rev. Fluid Mech. 40:1)

The continuum's constitutive update (stress_update.py) solves the mu(I) return map in its
quadratic form; the calibration fits these laws to the DEM (vibroflow.calibration.rheology_fit)
and plots them (vibroflow.calibration.plots).
"""
from __future__ import annotations

import numpy as np


def mu_of_I(I, mu_s, mu_2, I_0):
    """mu(I) = mu_s + (mu_2 - mu_s) / (1 + I_0 / I) (-), I > 0."""
    I = np.asarray(I, float)
    return mu_s + (mu_2 - mu_s) / (1.0 + I_0 / I)


def phi_of_I(I, phi_max, phi_min):
    """phi(I) = phi_max - (phi_max - phi_min) I (-)."""
    return phi_max - (phi_max - phi_min) * np.asarray(I, float)
