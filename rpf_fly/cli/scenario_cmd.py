"""``rpf-fly scenario``: fly one drone through a dynamics scenario file and print or write its trace
(rpf_fly/flight/scenario_flight.py, docs/dynamics.md); the application layer checks and flies it
(rpf_fly/app/scenario.py)."""

from __future__ import annotations

from pathlib import Path

import typer

from rpf_fly.cli import app
from rpf_fly.cli.errors import refused


@app.command()
def scenario(
    file: Path = typer.Argument(..., help="Scenario YAML file (docs/dynamics.md: setpoints or commands)."),
    dry_run: bool = typer.Option(False, "--dry-run", help="On a private simulated drone."),
    lab: bool = typer.Option(False, "--lab", help="On the running `rpf-fly lab`'s drone."),
    mission: Path | None = typer.Option(
        None,
        "--mission",
        help="The mission whose drone flies it (default: a "
        "one-drone mission made around the scenario's start; needs --dry-run).",
    ),
    drone: str | None = typer.Option(None, "--drone", help="Which drone of the mission (default: its first)."),
    log: Path | None = typer.Option(None, "--log", help="MCAP log (default flights/scenario-<name>-<time>.mcap)."),
    json_out: bool = typer.Option(False, "--json", help="Print the trace (t, sp, pos, figures) as one JSON document."),
) -> None:
    """Fly one drone through a scenario file (streamed setpoints, a hold, or high-level commands) and trace it."""
    from rpf_fly.app.scenario import ScenarioRequest, prepare_scenario
    from rpf_fly.flight.scenario_flight import write_json_trace

    request = ScenarioRequest(file=file, dry_run=dry_run, lab=lab, mission=mission, drone=drone, log=log)
    with refused():
        flight = prepare_scenario(request)
        trace = flight.run(lambda message: typer.echo(f"{flight.drone}: {message}", err=True))
    if json_out:
        typer.echo(write_json_trace(trace))
        return
    typer.echo(f"{flight.scenario.name}: {len(trace['t'])} samples; log: {flight.log_path}")
    for key, value in trace["figures"].items():
        shown = "not settled" if isinstance(value, float) and value == float("inf") else value
        typer.echo(f"  {key}: {shown if not isinstance(shown, float) else round(shown, 3)}")
