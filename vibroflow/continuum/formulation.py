"""The interface every continuum formulation implements, and the registry of formulations.

A formulation is a way of solving the same continuum (constitutive.py, stress_update.py, the
wall laws of boundary.py, the grid and transfers) on a tub scenario: the material point method
(vibroflow.continuum.mpm, "lagrangian") and the fixed mesh (vibroflow.continuum.eulerian,
"eulerian").  The tub driver (tub_run.py) and the column driver (column.py) run any of them
through this interface; what the formulations share (options.py, material.py, bed.py,
sampling.py, shear_outputs.py, timeline.py, checkpoint.py) is written once in this package.

A formulation supplies:

* its options with its own defaults (`options`, `default_grid`): one ContinuumOptions record;
* the system of a tub scenario in a frame (`make_system`) and the settled bed on it
  (`initial_state`, from bed.py), the steps (`advance`), the state back from a checkpoint
  (`restore`, with `checkpoint_meta` its own numbers in the checkpoint);
* what a sample records (`sampler`: a `Sampler`) and the summary's "continuum" block
  (`continuum_block`);
* the column collapse's system and state (`column_system`, `column_state`) and its deposit's
  cells or points (`column_deposit`).

A third formulation is one more package with its own module implementing `Formulation` and
one more line in FORMULATIONS; a new field carried by every formulation is a change of each
formulation's own files.
"""
from __future__ import annotations

import importlib
import math
from abc import ABC, abstractmethod
from pathlib import Path

from vibroflow.errors import InputError
from vibroflow.io.calibration_file import Calibration

#: the most grid cells over a tub's cross-section (tub47's default grid has about 1 400)
MAX_GRID_CELLS = 1.0e7

#: name -> module holding the formulation's FORMULATION; imported when the formulation is used
#: (`formulation`), so that `import vibroflow.study` and the CLI's import stay free of numba
FORMULATIONS: dict[str, str] = {
    "lagrangian": "vibroflow.continuum.mpm.formulation",
    "eulerian": "vibroflow.continuum.eulerian.formulation",
}


def formulation(name: str) -> "Formulation":
    """The registered formulation `name` (InputError, one line, for another name)."""
    if name not in FORMULATIONS:
        raise InputError(f"method = {name!r}: must be one of {', '.join(FORMULATIONS)}")
    return importlib.import_module(FORMULATIONS[name]).FORMULATION


class Sampler(ABC):
    """What one run records at each sample, set up once for its system and state: the
    sampled points or cells (n_points of them) as the DEM's balls, their wall contacts and
    shear rates, written into a sampling.Samples; its own arrays carried by the checkpoint."""

    #: how many "balls" each sample holds (the Samples' points)
    n_points: int
    #: the kinds of ParaView collection its vtk samples fill ("points", "grid")
    vtk_kinds: tuple[str, ...]
    #: whether the run keeps the start of each sample's last step (a measure over that step:
    #: continuum/wall_feed.py): the call that makes it is given `sample_step_start()` as the
    #: formulation's advance's keep; the same steps either way
    keeps_sample_step_start: bool = False

    def sample_step_start(self):
        """What the call whose last step ends at a sample fills with that step's start
        (keeps_sample_step_start; the formulation's advance's keep)."""

    @abstractmethod
    def record(self, j: int, samples) -> None:
        """Sample j into `samples` (at the state's current step)."""

    @abstractmethod
    def radius(self):
        """The radius (m) of each sampled ball, (n_points,): its solid volume over the slice."""

    @abstractmethod
    def early_frame(self, k: int, samples) -> None:
        """The ParaView files of the k-th frame before the averaging window, of the state now
        (VtkOptions.every; only called when the sampler writes ParaView files)."""

    def arrays(self) -> dict:
        """The sampler's own arrays to keep in a checkpoint (name -> array)."""
        return {}

    def restore(self, arrays: dict) -> None:
        """Take back the sampler's arrays from a checkpoint's samples."""


class Formulation(ABC):
    """One continuum formulation (module docstring).  Systems and states are the
    formulation's own records (mpm.MPMSystem / MPMState, eulerian.solver.EulerianSystem /
    EulerianState); the drivers only pass them back, read state.t, state.step and the
    fields every state has (x, v, L, mass, pressure())."""

    #: the registry's name: a run's "method", its checkpoint's and a study's stage name
    name: str
    #: one line for the study's registry
    description: str

    @abstractmethod
    def options(self, **settings):
        """The options.ContinuumOptions of a run: the settings over this formulation's
        defaults, with its own checks (InputError naming the setting)."""

    @abstractmethod
    def default_grid(self, scenario) -> float:
        """The default grid spacing (m) of a tub run of this scenario."""

    def grid(self, options, scenario) -> float:
        """The grid spacing (m) a run of this scenario uses: options.dx, or the default's;
        InputError where the tub's cross-section would hold more than MAX_GRID_CELLS of it."""
        dx = options.dx if options.dx is not None else self.default_grid(scenario)
        tub = scenario.tub
        cells = (2.0 * tub.radius / dx) * (tub.rim_height / dx)
        if cells > MAX_GRID_CELLS:
            least = math.sqrt(2.0 * tub.radius * tub.rim_height / MAX_GRID_CELLS)
            raise InputError(f"dx = {dx!r}: {cells:.3g} grid cells over the tub's cross-section; "
                             f"at most {MAX_GRID_CELLS:g} (dx at least {least:.3g} m)")
        return dx

    def transfers_on(self, options, scenario) -> int:
        """The APIC transfers a step of a run of this scenario makes (options.transfers on its
        grid, the damping length defaulting to the default grid's spacing)."""
        return options.transfers(self.grid(options, scenario), self.default_grid(scenario))

    @abstractmethod
    def make_system(self, scenario, material, calibration: Calibration | None, options, frame):
        """The system of a tub scenario in `frame` (grid_update.LabFrame or TubFrame): grid or
        mesh, the U wall and partitions with the calibration's (else the scenario's) friction,
        the time step (a whole number of steps between samples)."""

    @abstractmethod
    def initial_state(self, scenario, system) -> tuple[object, float]:
        """(state, bed height m) of the settled bed at rest on the system (bed.py)."""

    @abstractmethod
    def advance(self, system, state, steps: int, keep=None) -> None:
        """Advance the state by `steps` steps; keep (a Sampler's sample_step_start) receives
        the start of the last of them."""

    @abstractmethod
    def restore(self, system, saved, meta: dict):
        """The state of a checkpoint (checkpoint.load_checkpoint's saved arrays, history, t,
        step, and meta)."""

    def checkpoint_meta(self, state) -> dict:
        """The formulation's own numbers to keep in a checkpoint's meta (for `restore`)."""
        return {}

    @abstractmethod
    def sampler(self, scenario, system, state, out: Path, vtk) -> Sampler:
        """What a run's samples record (Sampler); with vtk (io.vtk_frame.VtkOptions, or None),
        its ParaView files go to out/vtk (continuum.paraview)."""

    @abstractmethod
    def continuum_block(self, system, state, bed_height: float) -> dict:
        """The formulation's part of the summary's "continuum" block: its method, grid,
        points or cells, wall and partitions (tub_run adds what every formulation shares)."""

    @abstractmethod
    def column_system(self, L0: float, H0: float, dx: float, material, floor_friction: float,
                      wall_friction: float, symmetric: bool, reach: float | None, cfl: float,
                      rough_floor: bool, flip: float, axisymmetric: bool, transfers: int):
        """The system of the column collapse (column.py's set-up) in the lab frame."""

    @abstractmethod
    def column_state(self, system, L0: float, H0: float, symmetric: bool):
        """The column at rest behind its gate(s) (column.py's initial state)."""

    @abstractmethod
    def column_deposit(self, system, state) -> tuple[object, object, float]:
        """(x (N,) m, mass (N,) kg per metre, or per radian, side m) of the points or cells
        holding material, for the deposit (column.ColumnRun.deposit_points)."""
