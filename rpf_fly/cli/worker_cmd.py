"""``rpf-fly worker``: one dongle's drones of a distributed flight (docs/distributed.md); its checks and its run are
the application layer's (rpf_fly/app/worker.py), ``rpf-fly fly --distributed``'s coordinator is ``fly_cmd.py``'s."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import typer

from rpf_fly.cli import app
from rpf_fly.cli.errors import refused

if TYPE_CHECKING:
    from rpf_fly.flight.events import FlightEvent


@app.command()
def worker(
    mission: Path = typer.Argument(..., help="Mission YAML file (the coordinator's)."),
    dongle: int = typer.Option(
        ..., "--dongle", help="The radio dongle whose drones this worker flies (the URIs' first number)."
    ),
    flight: str | None = typer.Option(
        None,
        "--flight",
        help="The flight id the coordinator printed (its log's "
        "stem); default: the one flight whose coordinator --connect reaches.",
    ),
    dry_run: bool = typer.Option(False, "--dry-run", help="The coordinator's simulated drones (its dry run)."),
    connect: list[str] | None = typer.Option(
        None,
        "--connect",
        help="The coordinator's Zenoh endpoint, e.g. tcp/HOST:7447 (default: the mission's runtime.zenoh.connect).",
    ),
    verbose: bool = typer.Option(False, "--verbose", help="Also print the libraries' log records on stderr."),
) -> None:
    """Fly the drones of one dongle in a distributed flight (docs/distributed.md). The flight's secret comes in
    the environment, RPF_FLY_SECRET, as the coordinator printed it."""
    from rpf_fly.app.flight import FlightApp
    from rpf_fly.app.worker import WorkerRequest

    request = WorkerRequest(dongle=dongle, flight=flight, dry_run=dry_run, connect=tuple(connect or ()))
    with refused():
        prepared = FlightApp(mission).prepare_worker(request)
        report = prepared.run(_say, verbose)
    for name, outcome in report.outcomes.items():
        typer.echo(f"{name}: {outcome.value}")
    if report.interrupted:
        raise typer.Exit(130)
    raise typer.Exit(0 if report.success else 1)


def _say(event: FlightEvent) -> None:
    if event.level >= 3 or event.drone is None:
        who = f"{event.drone}: " if event.drone else ""
        typer.echo(f"[{event.kind}] {who}{event.message}", err=True)
