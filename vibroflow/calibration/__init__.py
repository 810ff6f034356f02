"""Calibration of continuum models on DEM results (issue 3).

* coarse_grain -- coarse-grained continuum fields (density, velocity, stresses, strain rate,
                  inertial number, friction coefficient) on a grid of the tub's x-z plane
"""
from vibroflow.calibration.coarse_grain import (CoarseGrainer, kernel_value, phase_bins,
                                                rheology, snapshot_from_state,
                                                velocity_gradient_on_grid)

__all__ = ["CoarseGrainer", "kernel_value", "phase_bins", "rheology", "snapshot_from_state",
           "velocity_gradient_on_grid"]

# the media's rheology from DEM (issue 3 section 2): Lees-Edwards shear cell, elastic moduli,
# mu(I) / phi(I) fits and the equivalent Drucker-Prager model
from vibroflow.calibration.elastic import elastic_moduli  # noqa: E402
from vibroflow.calibration.rheology_fit import (drucker_prager_equivalent, fit_mu_i,  # noqa: E402
                                                fit_phi_i, mu_of_i, phi_of_i)
from vibroflow.calibration.shear_cell import run_shear_cell, tub_mid_depth_pressure  # noqa: E402

__all__ += ["drucker_prager_equivalent", "elastic_moduli", "fit_mu_i", "fit_phi_i", "mu_of_i",
            "phi_of_i", "run_shear_cell", "tub_mid_depth_pressure"]
