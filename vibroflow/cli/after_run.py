"""Warnings a command prints after a run: what its results cannot show, and why."""
from __future__ import annotations

import typer


def warn_empty_probes(label: str, summary: dict) -> None:
    """One line on stderr for each probe of a run's summary whose cell held no ball (its
    velocity is n/a), with the reason its summary gives (measure.bulk.probe_values)."""
    for name, p in (summary.get("probes") or {}).items():
        if p.get("note"):
            typer.echo(f"warning: {label} probe {name} at (x, z) = ({p['x']:g}, {p['z']:g}) m: "
                       f"{p['note']}", err=True)
