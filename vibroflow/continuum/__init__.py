"""Continuum models of the media: the shared elasto-visco-plastic mu(I) law (constitutive.py)
and the Lagrangian formulation, a 2D plane-strain material point method (grid, p2g,
grid_update, g2p, plasticity, boundary, timestep, mpm; orchestration in run.py)."""
