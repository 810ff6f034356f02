"""vibroflow: media flow in vibratory tub finishers.

A 3D DEM of the steel-ball media (the ground truth), calibration of a continuum from it,
continuum models (Lagrangian MPM and Eulerian) and comparisons, all on scenarios read from TOML
(SI units).  The reference case is `tub47` (see `vibroflow scenario show tub47`).

Importing the package is light: `load_scenario` and `Scenario` are loaded on first use, and
nothing here imports numba.
"""
from __future__ import annotations

import importlib
import os as _os
import sys as _sys
from importlib import metadata as _metadata
from typing import TYPE_CHECKING, Any

try:
    __version__ = _metadata.version("vibroflow")
except _metadata.PackageNotFoundError:  # run from a source tree that is not installed
    __version__ = "0.1.0"

# numba's threading layer: OpenMP, else its own workqueue; TBB last.  numba picks TBB first
# whenever a libtbb is installed (Debian's liggghts package pulls one in), and with TBB every
# parallel region of the DEM's step builds and tears down a task arena: on a 2-core machine the
# engine then ran 10x slower (0.4 instead of 4-7 M particle-steps/s).  A user's own
# NUMBA_THREADING_LAYER(_PRIORITY) is respected.
if not {"NUMBA_THREADING_LAYER", "NUMBA_THREADING_LAYER_PRIORITY"} & set(_os.environ):
    _os.environ["NUMBA_THREADING_LAYER_PRIORITY"] = "omp workqueue tbb"
    if "numba" in _sys.modules:  # numba imported before us: set its config directly
        _sys.modules["numba"].config.THREADING_LAYER_PRIORITY = ["omp", "workqueue", "tbb"]
        # too late where its threads already run, on TBB: say so (vibroflow/threads.py)
        from vibroflow.threads import warn_if_tbb_launched

        warn_if_tbb_launched(_sys.modules["numba"])

# numba's threads: every core the process may use (vibroflow/threads.py), unless
# NUMBA_NUM_THREADS says otherwise
from vibroflow import threads as _threads  # noqa: E402

_threads.default_threads_env()

# OpenMP threads that finish their share spin before they sleep (GNU libgomp's default: ~300 000
# iterations).  While every thread has a core of its own a spin that spans a step's barrier
# waits makes the DEM's two-thread step 0.74 x as long as a spin of 1 000; when anything else
# runs on the cores, spinning starves the thread still working (a 2-thread DEM step 6 x slower
# at the default spin with one other job on the 2-core machine).  So the spin is chosen from
# what runs on the machine when vibroflow is imported (vibroflow/threads.py, spin_count).
_threads.default_spin_env()

# numba's cache keys a kernel on its own file only; kernels inline code from other files, so
# after an edit the cache is dropped whole (vibroflow/_kernel_cache.py says why)
from vibroflow import _kernel_cache  # noqa: E402

_kernel_cache.install()  # numba's cache files locked between processes (why: there)
_kernel_cache.ensure_fresh()

if TYPE_CHECKING:
    from vibroflow.scenario.io import load_scenario
    from vibroflow.scenario.model import Scenario

__all__ = ["__version__", "load", "load_scenario", "Scenario"]

_LAZY = {"load_scenario": "vibroflow.scenario.io", "Scenario": "vibroflow.scenario.model",
         "load": "vibroflow.study.results"}


def __getattr__(name: str) -> Any:
    if name in _LAZY:  # loaded on first use: `import vibroflow` stays light for the CLI
        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'vibroflow' has no attribute {name!r}")


def __dir__() -> list[str]:
    # the lazy names are listed (tab completion, help()) before their first use loads them
    return sorted(set(globals()) | set(_LAZY))
