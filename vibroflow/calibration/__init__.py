"""Calibration of continuum models on DEM results (issue 3).

* coarse_grain -- coarse-grained continuum fields (density, velocity, stresses, strain rate,
                  inertial number, friction coefficient) on a grid of the tub's x-z plane
"""
from vibroflow.calibration.coarse_grain import (CoarseGrainer, kernel_value, phase_bins,
                                                rheology, snapshot_from_state,
                                                velocity_gradient_on_grid)

__all__ = ["CoarseGrainer", "kernel_value", "phase_bins", "rheology", "snapshot_from_state",
           "velocity_gradient_on_grid"]
