"""The Eulerian continuum formulation: a fixed mesh of the tub, material flowing through it
(solver.py explains the design; formulation.py is its tub formulation, column.py its column
collapse's set-up)."""
