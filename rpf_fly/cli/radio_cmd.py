"""``rpf-fly radio probe``: measure a Crazyradio through cflib's own radio driver, with one link and with several
(rpf_fly/radio/probe.py, docs/radio.md "Probing a dongle"): transactions a second, a setpoint's round trip, what an
address switch costs, loss; and the figure a mission takes, ``radio.budget_packets_s``."""

from __future__ import annotations

import json
from enum import Enum

import typer

from rpf_fly.cli import app
from rpf_fly.cli.errors import fail

radio_app = typer.Typer(help="The Crazyradio: probe what one dongle carries.", no_args_is_help=True)
app.add_typer(radio_app, name="radio")


class DongleType(str, Enum):
    """The Crazyradio models (`rpf_fly.emulator.crazyradio_timing.RADIO_TYPES`)."""

    crazyradio_pa = "crazyradio_pa"
    crazyradio_2 = "crazyradio_2"


@radio_app.command()
def probe(
    dongle: int | None = typer.Option(
        None, "--dongle", help="The dongle number (the URI's first number; a dry run's emulated dongle: default 0)."
    ),
    drones: str | None = typer.Option(
        None,
        "--drones",
        help="Powered-on drones on that dongle, radio:// URIs "
        "separated by commas (only link packets are sent: nothing flies).",
    ),
    dry_run: bool = typer.Option(False, "--dry-run", help="Probe an emulated dongle carrying simulated drones."),
    links: int | None = typer.Option(
        None,
        "--links",
        help="Links in the second run (a dry run: simulated drones, default 4; real: the first N of --drones).",
    ),
    radio: DongleType | None = typer.Option(
        None,
        "--radio",
        help="A dry run's dongle type (default "
        "crazyradio_pa); real: the type to report (default: from its "
        "firmware version).",
    ),
    seconds: float = typer.Option(2.0, "--seconds", help="How long each run measures."),
    as_json: bool = typer.Option(False, "--json", help="One JSON object per run, one a line."),
) -> None:
    """Measure one dongle: transactions a second with one link and with N, a setpoint's round trip (p50/p99), the
    cost of an address switch, loss; prints radio.budget_packets_s for the mission."""
    from rpf_fly.radio.probe import ProbeError, describe, probe_dongle

    uris = [u.strip() for u in drones.split(",") if u.strip()] if drones is not None else None
    progress = (lambda line: None) if as_json else (lambda line: typer.echo(line, err=True))
    try:
        runs = probe_dongle(
            drones=uris,
            dry_run=dry_run,
            dongle=dongle,
            links=links,
            radio=radio.value if radio is not None else None,
            seconds=seconds,
            on_progress=progress,
        )
    except ProbeError as err:
        raise fail(f"radio probe: {err}") from err
    for line in [json.dumps(run.as_dict()) for run in runs] if as_json else describe(runs):
        typer.echo(line)
