"""What every benchmark shares: the machine it ran on, its load, the case's scenario, the result file.

A script in this folder imports it as `import bench` (Python puts the script's folder first on
sys.path).  A speed is a ratio against a peer measured on the same machine in the same run
(benchmarks/README.md); the load average printed beside each case says whether the machine was
quiet enough for the ratio to mean something.
"""
from __future__ import annotations

import json
import os
import platform
import sys
from pathlib import Path

from vibroflow.errors import InputError
from vibroflow.io.atomic import json_safe, write_text_atomic
from vibroflow.scenario.io import load_scenario


def load_1min() -> float:
    """The 1-minute load average (runnable processes); above the core count, timings stretch."""
    return os.getloadavg()[0]


def cpu_name() -> str:
    """The processor's model name (/proc/cpuinfo), or platform's guess elsewhere."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor()


def machine() -> dict:
    """The machine a result was measured on, for the result file."""
    try:
        usable = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        usable = os.cpu_count()
    return {"cpus": os.cpu_count(), "cpus_usable": usable, "processor": cpu_name(),
            "platform": platform.platform(), "python": platform.python_version(),
            "load_1min": load_1min()}


def scenario(case: str, overrides=()):
    """A preset's or TOML file's validated scenario with `key=value` overrides (as --set)."""
    return load_scenario(case, list(overrides))


def with_sections(s, **sections):
    """The scenario with fields of its sections replaced: with_sections(s, run={"seed": 2})."""
    return s.model_copy(update={name: getattr(s, name).model_copy(update=fields)
                                for name, fields in sections.items()})


def write_json(path, data) -> Path:
    """Write a result atomically, NaN and numpy values made JSON-safe (NaN as null)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    return write_text_atomic(path, json.dumps(json_safe(data), indent=2, default=str) + "\n")


def run(main) -> None:
    """Exit with main()'s status; bad input (InputError) is its one line on stderr and exit 2,
    as the vibroflow commands give it."""
    try:
        sys.exit(main())
    except InputError as e:
        print(e.message, file=sys.stderr)
        sys.exit(2)
