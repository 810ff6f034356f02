"""Calibration of continuum models on DEM results, one concept per module:

* coarse_grain  -- coarse-grained continuum fields (density, velocity, stresses, strain rate,
                   inertial number, stress ratio) on a grid of the tub's x-z plane; its kernel
                   and deposits in coarse_grain_kernel, the derived fields in
                   coarse_grain_fields
* dem_result    -- a DEM result on disk (dem.h5) read back in the tub frame
* run_fields    -- the coarse-grained fields of a whole run (time-averaged, phase-resolved),
                   fields.nc
* wall_friction -- the effective Coulomb friction of the wall and partitions
* impacts       -- impact speeds against the local shear rate and temperature
* tub_rheology  -- mu(I) read from the tub's own cells, and fitted to their dense points
* bed_contacts  -- the bed's coordination number and contact stiffness at its pressure
* shear_cell, elastic -- Lees-Edwards simple-shear cells (vibroflow.dem.lees_edwards) and elastic
                   tests of the media
* media_tests   -- those tests (and the cyclic shear and dilatancy cells) run at the bed's
                   pressure for the calibration
* rheology_fit  -- mu(I), phi(I) fits and the equivalent Drucker-Prager model
* calibration_tables -- the tables of calibration.toml from the stages' results
* calibrate     -- `vibroflow calibrate`: all of the above into calibration.toml
* plots         -- the pictures
"""
from vibroflow.calibration.calibrate import calibrate
from vibroflow.io.calibration_file import read_calibration
from vibroflow.calibration.coarse_grain import CoarseGrainer, snapshot_from_state
from vibroflow.calibration.coarse_grain_fields import rheology, velocity_gradient_on_grid
from vibroflow.calibration.coarse_grain_kernel import kernel_value
from vibroflow.calibration.elastic import elastic_moduli
from vibroflow.calibration.rheology_fit import drucker_prager_equivalent, fit_mu_i, fit_phi_i
from vibroflow.calibration.run_fields import coarse_grain_run, read_fields, write_fields
from vibroflow.calibration.shear_cell import run_shear_cell, tub_mid_depth_pressure

__all__ = ["CoarseGrainer", "calibrate", "coarse_grain_run", "drucker_prager_equivalent",
           "elastic_moduli", "fit_mu_i", "fit_phi_i", "kernel_value", "read_calibration",
           "read_fields", "rheology", "run_shear_cell",
           "snapshot_from_state", "tub_mid_depth_pressure", "velocity_gradient_on_grid",
           "write_fields"]
