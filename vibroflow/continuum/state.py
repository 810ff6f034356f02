"""The fields every continuum formulation's state carries, and what is measured on them alone.

A formulation's state record (mpm.solver.MPMState, eulerian.solver.EulerianState) extends
`ContinuumState` with its own fields; checkpoint.py stores any of them by their fields' names.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(kw_only=True)
class ContinuumState:
    """The material's fields (arrays over its N points or cells) and the clock.

    x, v (N, 2) m, m/s; C, L (N, 4) [xx, xz, zx, zz] 1/s (L (N, 5) in an axisymmetric
    section: the hoop rate last); mass (N,) kg/m; volume (N,) m^2; density (N,) kg/m^3;
    stress (N, 4) Pa [xx, zz, xz, yy]; gamma_dot (N,) plastic shear rate 1/s; phase (N,)
    0 disconnected / 1 elastic / 2 flowing; fext (N, 2) N/m (work array); history: per-boundary
    dicts of per-point arrays; t (s), step; temperature (N,) the granular temperature
    m^2/s^2 where the run carries it (options.ContinuumOptions.temperature), else None."""

    x: np.ndarray
    v: np.ndarray
    C: np.ndarray
    L: np.ndarray
    mass: np.ndarray
    volume: np.ndarray
    density: np.ndarray
    stress: np.ndarray
    gamma_dot: np.ndarray
    phase: np.ndarray
    fext: np.ndarray
    history: list
    t: float = 0.0
    step: int = 0
    temperature: np.ndarray | None = None

    @property
    def n(self) -> int:
        return int(self.mass.shape[0])

    def pressure(self) -> np.ndarray:
        """p = -tr(sigma)/3 (Pa) per point."""
        return -(self.stress[:, 0] + self.stress[:, 1] + self.stress[:, 3]) / 3.0

    def momentum(self) -> np.ndarray:
        """Total linear momentum (kg/s per m of thickness), [x, z]."""
        return (self.mass[:, None] * self.v).sum(axis=0)

    def kinetic_energy(self) -> float:
        """0.5 sum m v^2 (J per m of thickness)."""
        return float(0.5 * (self.mass * (self.v**2).sum(axis=1)).sum())
