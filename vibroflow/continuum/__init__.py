"""Continuum models of the media: one elasto-visco-plastic mu(I) law (constitutive.py,
rheology.py, stress_update.py) solved by formulations that plug into one tub driver
(tub_run.py) and one column driver (column.py) through formulation.py: the material point
method (mpm/) and the fixed Eulerian mesh (eulerian/).  What they share is written once here:
the options (options.py), the material (material.py), the settled bed (bed.py), the grid,
stencil and wall laws, the sampling (sampling.py), the shear-rate outputs (shear_outputs.py),
the timeline (timeline.py) and the checkpoints (checkpoint.py)."""
