"""The Eulerian continuum formulation: a fixed mesh of the tub, material flowing through it
(solver.py explains the design; run.py runs a tub scenario)."""
