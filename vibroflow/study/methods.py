"""The registry of continuum formulations a study runs and compares with the DEM.

A formulation is one `ContinuumMethod` entry: its name (also its stage and folder name, and
the prefix of its `--set NAME.option=value` settings), the dataclass of its numerical options,
and a function that runs it into a folder and returns its summary (the DEM's summary keys:
probes, circulation, impacts, wall_time_s; bulk_velocity.csv next to it).
"""
from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from vibroflow.errors import InputError
from vibroflow.io.calibration_file import Calibration


@dataclass(frozen=True)
class ContinuumMethod:
    """name: stage and folder name; options: a dataclass of its options (validated in its
    __post_init__); run(scenario, out_dir, calibration, options, progress, resume) -> summary."""

    name: str
    description: str
    options: type
    run: Callable[..., dict]

    def make_options(self, settings: dict[str, Any]):
        """The options from `--set NAME.key=value` settings (key -> value); input errors name
        the setting and what is allowed."""
        allowed = [f.name for f in dataclasses.fields(self.options)]
        for key in settings:
            if key not in allowed:
                raise InputError(f"--set {self.name}.{key}: unknown option of the {self.name} "
                                 f"method; allowed: {', '.join(allowed)}")
        try:
            return self.options(**settings)
        except TypeError as exc:
            raise InputError(f"--set {self.name}: {exc}") from None


def _method(name: str, description: str, module: str, options: str, run: str):
    """The factory of a registered method whose options class and run function live in
    `module` (imported only when the method is used, so `import vibroflow.study` stays free of
    numba); its run first builds the material, so bad parameters are an input error first."""
    def factory() -> ContinuumMethod:
        import importlib

        mod = importlib.import_module(module)

        def run_method(scenario, out_dir: Path, calibration: Calibration | None, opts,
                       progress: bool, resume: bool) -> dict:
            from vibroflow.continuum.run import material_for

            material_for(scenario, calibration, opts)
            return getattr(mod, run)(scenario, out_dir, calibration=calibration, options=opts,
                                     progress=progress, resume=resume)

        return ContinuumMethod(name=name, description=description,
                               options=getattr(mod, options), run=run_method)
    return factory


#: name -> factory of the method (factories keep `import vibroflow.study` free of numba)
METHODS: dict[str, Callable[[], ContinuumMethod]] = {
    "lagrangian": _method("lagrangian", "material point method (vibroflow.continuum)",
                          "vibroflow.continuum.run", "LagrangianOptions", "run_lagrangian"),
    "eulerian": _method("eulerian", "fixed mesh of the tub, volume fraction transport "
                        "(vibroflow.continuum.eulerian)", "vibroflow.continuum.eulerian.run",
                        "EulerianOptions", "run_eulerian"),
}


def method(name: str) -> ContinuumMethod:
    """The registered method `name`."""
    if name not in METHODS:
        raise InputError(f"method = {name!r}: must be one of {', '.join(METHODS)}")
    return METHODS[name]()
