"""``rpf-fly lab``: a mission's simulated Crazyflies and Motive emulator, running until stopped (Ctrl-C, SIGTERM),
for ``rpf-fly check|fly MISSION --lab`` and cflib programs to fly one command after another, as real drones outlive
their ground station (rpf_fly/flight/lab.py, docs/flight.md "Lab"); the lab is run by the application layer
(rpf_fly/app/lab.py), here are its options and what it says."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import typer

from rpf_fly.cli import app
from rpf_fly.cli.errors import refused

if TYPE_CHECKING:
    from rpf_fly.flight.lab import LabInfo


@app.command()
def lab(
    mission: Path = typer.Argument(..., help="Mission YAML file: its drones, starts, obstacles and mocap."),
    faults: Path | None = typer.Option(
        None,
        "--faults",
        help="Power-on faults of the drones (yaw_offset, start_offset, upside_down, motor_fault; docs/faults.md).",
    ),
    log: Path | None = typer.Option(
        None, "--log", help="The lab's MCAP log (default flights/lab-<mission>-<time>.mcap)."
    ),
) -> None:
    """Run MISSION's simulated drones and mocap until stopped; `check --lab` and `fly --lab` fly them."""
    from rpf_fly.app.flight import FlightApp
    from rpf_fly.flight.lab import crazyradio_plug_call

    with refused():
        flight_app = FlightApp(mission)
        prepared = flight_app.prepare_lab(faults, log)
    loaded = flight_app.mission
    log_path = prepared.log_path

    def started(info: LabInfo, lab_file: Path) -> None:
        typer.echo(
            f"lab: {len(info.addresses)} simulated Crazyflies of '{loaded.name}' on the floor at their "
            f"mission starts, Motive emulated on 127.0.0.1:{info.natnet_command_port}"
        )
        typer.echo(f"  fly them:   rpf-fly check {mission} --lab   then   rpf-fly fly {mission} --lab")
        typer.echo(
            "  from cflib: from rpf_fly.emulator import fake_radio; from rpf_fly.flight.lab import lab_world; "
            "fake_radio.register(lab_world()); then fake:// URIs (the mission's radio paths)"
        )
        typer.echo(
            "  or through cflib's radio driver: from rpf_fly.emulator import crazyradio; from rpf_fly.flight.lab "
            f"import lab_world; {crazyradio_plug_call(loaded)}; then the mission's radio:// URIs"
        )
        typer.echo(f"  lab file:   {lab_file}   log: {log_path}")
        typer.echo("  Ctrl-C stops the lab (its drones power off)")

    with refused():
        result = prepared.run(started)
    typer.echo(f"lab stopped ({result.stopped_by or 'closed'}); log: {log_path}  (rpf-fly review {log_path})")
    if result.lag is not None and result.lag.sentence():
        typer.echo(result.lag.sentence())
