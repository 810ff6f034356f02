"""The Lagrangian continuum formulation: the material point method in 2D plane strain or
axisymmetric (solver.py: the state record and the step; formulation.py: the tub run's
formulation; column.py: the column collapse's set-up)."""
