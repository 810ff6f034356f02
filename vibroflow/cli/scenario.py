"""`vibroflow scenario show` and `vibroflow scenario check`.  The scenario's modules are imported
inside the commands, so that `--help` stays quick."""
from __future__ import annotations

import typer

from .apps import scenario_app
from .failures import input_errors
from .options import ScenarioArg, SetOption, load


@scenario_app.command("show")
@input_errors
def scenario_show(scenario: ScenarioArg, set_: SetOption = None) -> None:
    """Print a scenario (preset or file, with overrides) as complete TOML."""
    from vibroflow.scenario.io import dump_scenario

    typer.echo(dump_scenario(load(scenario, set_)), nl=False)


def summary_line(s) -> str:
    """One line describing a valid scenario."""
    from vibroflow.scenario.checks import contact_times

    if s.explicit:
        what = (f"explicit mode, particles: {len(s.particles)}, plane walls: "
                f"{len(s.walls or [])}, simulate {s.run.duration:g} s")
    else:
        what = (f"{s.fill.count} {s.fill.material} balls d = {s.fill.diameter * 1e3:g} mm in a "
                f"tub of length {s.tub.length:g} m, settle {s.fill.settle_time:g} s, vibrate "
                f"{s.run.duration:g} s at {s.motion.frequency:g} Hz x{s.motion.amplitude_factor:g}"
                f", average the last {s.run.average_last:g} s")
    steps = round(s.run.duration / s.run.dt)
    line = f"{s.case}: ok: {what}; dt = {s.run.dt:g} s ({steps} steps)"
    times = contact_times(s)
    if times:
        tp, t_c = times[0]
        line += f", 1/{t_c / s.run.dt:.1f} of the {tp.label} contact time {t_c:.3g} s"
    return line


@scenario_app.command("check")
@input_errors
def scenario_check(scenario: ScenarioArg, set_: SetOption = None) -> None:
    """Validate a scenario and print a one-line summary (exit code 2 if it is invalid)."""
    typer.echo(summary_line(load(scenario, set_)))
