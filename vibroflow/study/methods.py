"""The continuum formulations a study runs and compares with the DEM: one `ContinuumMethod`
for each formulation of vibroflow.continuum.formulation.FORMULATIONS.

A method's name is also its stage and folder name, and the prefix of its `--set
NAME.option=value` settings; its options are the formulation's (continuum.options.
ContinuumOptions with the formulation's defaults); its run writes the formulation's tub run
(continuum.tub_run.run_continuum) into a folder and returns its summary (the DEM's summary
keys: probes, circulation, impacts, wall_time_s; bulk_velocity.csv next to it).
"""
from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from vibroflow.continuum.formulation import FORMULATIONS, formulation
from vibroflow.continuum.material import material_for
from vibroflow.continuum.options import ContinuumOptions
from vibroflow.continuum.part_obstacle import continuum_parts
from vibroflow.continuum.tub_run import run_continuum
from vibroflow.errors import InputError
from vibroflow.io.calibration_file import Calibration


@dataclass(frozen=True)
class ContinuumMethod:
    """name: stage and folder name; options: the dataclass of its options; make: the options
    from settings (the formulation's defaults and checks); run(scenario, out_dir,
    calibration, options, progress, resume) -> summary; check(scenario): the input errors the
    method's run would raise on the scenario itself (the parts it cannot take), raised before
    the study starts."""

    name: str
    description: str
    options: type
    make: Callable[..., Any]
    run: Callable[..., dict]
    check: Callable[[Any], Any]

    def make_options(self, settings: dict[str, Any]):
        """The options from `--set NAME.key=value` settings (key -> value); input errors name
        the setting and what is allowed."""
        allowed = [f.name for f in dataclasses.fields(self.options)]
        for key in settings:
            if key not in allowed:
                raise InputError(f"--set {self.name}.{key}: unknown option of the {self.name} "
                                 f"method; allowed: {', '.join(allowed)}")
        try:
            return self.make(**settings)
        except InputError as exc:  # "FIELD = VALUE: ...", the field one of the settings'
            raise InputError(f"{self.name}.{exc.message}") from None
        except TypeError as exc:
            raise InputError(f"--set {self.name}: {exc}") from None


def _method(name: str):
    """The factory of the method of formulation `name` (imported only when the method is used,
    so `import vibroflow.study` stays free of numba); its run first builds the material, so bad
    parameters are an input error first."""
    def factory() -> ContinuumMethod:
        # imported here: the continuum's modules load numba (the factory's reason to exist)

        form = formulation(name)

        def run_method(scenario, out_dir: Path, calibration: Calibration | None, opts,
                       progress: bool, resume: bool, vtk=None) -> dict:
            material_for(scenario, calibration, opts)
            return run_continuum(scenario, out_dir, name, calibration=calibration,
                                 options=opts, progress=progress, resume=resume, vtk=vtk)

        return ContinuumMethod(name=name, description=form.description,
                               options=ContinuumOptions, make=form.options, run=run_method,
                               check=continuum_parts)
    return factory


#: name -> factory of the method (factories keep `import vibroflow.study` free of numba)
METHODS: dict[str, Callable[[], ContinuumMethod]] = {name: _method(name) for name in FORMULATIONS}


def method(name: str) -> ContinuumMethod:
    """The registered method `name`."""
    if name not in METHODS:
        raise InputError(f"method = {name!r}: must be one of {', '.join(METHODS)}")
    return METHODS[name]()
