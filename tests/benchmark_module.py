"""A script of benchmarks/ loaded as a module, for the tests that check its measures against
hand values (benchmarks/ is no package)."""
from __future__ import annotations

import importlib.util
from pathlib import Path


def load_benchmark(name: str):
    """benchmarks/<name>.py as a module."""
    path = Path(__file__).resolve().parents[1] / "benchmarks" / f"{name}.py"
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module
