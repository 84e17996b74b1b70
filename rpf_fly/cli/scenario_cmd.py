"""``rpf-fly scenario``: fly one drone through a dynamics scenario file and print or write its trace
(rpf_fly/flight/scenario_flight.py, docs/dynamics.md)."""

from __future__ import annotations

from datetime import datetime
from pathlib import Path
from typing import Optional

import typer

from rpf_fly.cli import app
from rpf_fly.cli.errors import fail


@app.command()
def scenario(
    file: Path = typer.Argument(..., help="Scenario YAML file (docs/dynamics.md: setpoints or commands)."),
    dry_run: bool = typer.Option(False, "--dry-run", help="On a private simulated drone."),
    lab: bool = typer.Option(False, "--lab", help="On the running `rpf-fly lab`'s drone."),
    mission: Optional[Path] = typer.Option(None, "--mission", help="The mission whose drone flies it (default: a "
                                           "one-drone mission made around the scenario's start; needs --dry-run)."),
    drone: Optional[str] = typer.Option(None, "--drone", help="Which drone of the mission (default: its first)."),
    log: Optional[Path] = typer.Option(None, "--log", help="MCAP log (default flights/scenario-<name>-<time>.mcap)."),
    json_out: bool = typer.Option(False, "--json", help="Print the trace (t, sp, pos, figures) as one JSON document."),
) -> None:
    """Fly one drone through a scenario file (streamed setpoints, a hold, or high-level commands) and trace it."""
    from rpf_fly.emulator.cf_scenario import Scenario
    from rpf_fly.flight.scenario_flight import ScenarioError, run_scenario, scenario_mission, write_json_trace

    if dry_run and lab:
        raise fail("--dry-run and --lab: choose one")
    try:
        loaded = Scenario.load(file)
    except FileNotFoundError:
        raise fail(f"{file}: no such file")
    except (OSError, ValueError, KeyError, TypeError) as err:
        raise fail(f"{file}: not a scenario file ({err}); expected name, start, duration_s and setpoints with "
                   "stream_hz, or commands (docs/dynamics.md)")
    if mission is not None:
        from rpf_fly.cli.fly_cmd import load_mission_or_fail

        the_mission = load_mission_or_fail(mission)
    elif dry_run or lab:
        the_mission = scenario_mission(loaded)
    else:
        raise fail("a real drone needs its mission (--mission MISSION), or fly the scenario with --dry-run")
    name = drone or the_mission.drones[0].name
    lab_info = None
    if lab:
        from rpf_fly.cli.fly_cmd import lab_info_or_fail

        lab_info = lab_info_or_fail(the_mission)
    log_path = log or Path("flights") / f"scenario-{loaded.name}-{datetime.now():%Y%m%d-%H%M%S}.mcap"
    log_path.parent.mkdir(parents=True, exist_ok=True)
    say = (lambda message: typer.echo(f"{name}: {message}", err=True))
    try:
        trace = run_scenario(loaded, the_mission, name, dry_run=dry_run, lab=lab_info, log_path=log_path,
                             on_event=say)
    except ScenarioError as err:
        raise fail(str(err), code=1)
    if json_out:
        typer.echo(write_json_trace(trace))
        return
    typer.echo(f"{loaded.name}: {len(trace['t'])} samples; log: {log_path}")
    for key, value in trace["figures"].items():
        shown = "not settled" if isinstance(value, float) and value == float("inf") else value
        typer.echo(f"  {key}: {shown if not isinstance(shown, float) else round(shown, 3)}")
