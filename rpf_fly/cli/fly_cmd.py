"""``rpf-fly fly`` and ``rpf-fly check``: fly a mission (or dry-run it on simulated drones), validate and preflight.

Ctrl-C once: every drone lands and the log is closed. Ctrl-C twice: emergency stop (motors off). SIGTERM acts as
the first Ctrl-C. Exit codes: 0 every drone reached its goal and landed; 1 the flight ended otherwise (a drone
landed early, timed out, lost its link, the flight aborted before take-off); 2 invalid mission or policy;
130 interrupted.

The flight itself is assembled by the application layer (rpf_fly/app/flight.py: the checks before anything
connects, the dry-run rig or lab, fault injection, the signals, the run); here are the options, the status console
and what is printed.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import typer

from rpf_fly.cli import app
from rpf_fly.cli.errors import refused

if TYPE_CHECKING:
    from rpf_fly.app.flight import Flight
    from rpf_fly.cli.flight_console import FlightConsole
    from rpf_fly.flight.events import FlightEvent
    from rpf_fly.log.live import LiveView
    from rpf_fly.mission import Mission


@app.command()
def fly(
    mission: Path = typer.Argument(..., help="Mission YAML file."),
    dry_run: bool = typer.Option(False, "--dry-run", help="Simulated drones through the same stack (fake radio)."),
    lab: bool = typer.Option(
        False,
        "--lab",
        help="Fly the simulated drones of the running `rpf-fly lab` (they keep "
        "their firmware state between commands) instead of private ones.",
    ),
    log: Path | None = typer.Option(None, "--log", help="MCAP flight log (default flights/<mission>-<time>.mcap)."),
    mocap: str | None = typer.Option(
        None,
        "--mocap",
        help="Dry run only: natnet (emulator over UDP), motioncapture (the emulator read by the "
        "motioncapture package in a child process) or sim. Default: motioncapture for mocap.kind motioncapture, "
        "else natnet.",
    ),
    console: bool = typer.Option(True, "--console/--no-console", help="Live status table while flying."),
    faults: Path | None = typer.Option(None, "--faults", help="Dry run only: a fault schedule (docs/faults.md)."),
    radio_loss: bool = typer.Option(
        True, "--radio-loss/--no-radio-loss", help="Dry run only: bursty radio loss on every link (docs/radio.md)."
    ),
    foxglove: bool = typer.Option(
        False,
        "--foxglove",
        help="Serve the flight live to Foxglove over WebSocket "
        "(ws://localhost:8765; the live extra; docs/foxglove.md).",
    ),
    foxglove_port: int | None = typer.Option(
        None, "--foxglove-port", help="Port of the live view (default 8765; 0: any free port). Implies --foxglove."
    ),
    foxglove_host: str | None = typer.Option(
        None,
        "--foxglove-host",
        help="Address the live view listens on (default 127.0.0.1; 0.0.0.0: every network). Implies --foxglove.",
    ),
    verbose: bool = typer.Option(
        False,
        "--verbose",
        help="Also print the libraries' log records (cflib, foxglove-sdk) "
        "on stderr; they always go to LOG.log beside the flight "
        "log.",
    ),
    distributed: bool = typer.Option(
        False,
        "--distributed",
        help="One worker process per radio dongle, a coordinator and a logger, on Zenoh (docs/distributed.md).",
    ),
    remote_dongles: str | None = typer.Option(
        None,
        "--remote-dongles",
        help="With --distributed: dongles "
        "(K[,K...]) whose workers run on other hosts (`rpf-fly worker`); "
        "waits for them before any drone arms.",
    ),
    listen: list[str] | None = typer.Option(
        None,
        "--listen",
        help="With --distributed: the Zenoh endpoint the "
        "coordinator listens on (default 127.0.0.1 only, e.g. "
        "tcp/0.0.0.0:7447 for remote workers).",
    ),
) -> None:
    """Fly MISSION: its mocap (NatNet or motioncapture) and cflib radios, or simulated drones with --dry-run."""
    from rpf_fly.app.flight import FlightApp, FlightRequest

    request = FlightRequest(
        dry_run=dry_run,
        lab=lab,
        log=log,
        mocap=mocap,
        faults=faults,
        radio_loss=radio_loss,
        live=foxglove or foxglove_port is not None or foxglove_host is not None,
        distributed=distributed,
        remote_dongles=remote_dongles,
        listen=tuple(listen or ()),
    )
    with refused():
        flight = FlightApp(mission).prepare_flight(request)
    if flight.distributed:
        _fly_distributed(flight, console, verbose)
    from rpf_fly.cli.live_opts import start_live

    live = start_live(foxglove, foxglove_port, foxglove_host)
    with flight.log_records(verbose) as logs:  # the live server's records too, to its close
        try:
            code = _fly_here(flight, console, live)
        finally:
            if live is not None:
                live.close()
                typer.echo(live.summary())
    if logs.warnings and logs.path is not None and not verbose:
        libraries = "cflib, foxglove-sdk" if live is not None else "cflib"
        typer.echo(f"({logs.warnings} warning(s) from {libraries} and rpf_fly: {logs.path})", err=True)
    raise typer.Exit(code)


def _fly_here(flight: Flight, console: bool, live: LiveView | None) -> int:
    """The flight in this process, with its status console; what it prints last; its exit code."""
    view = _status_console(flight.mission) if console else None
    with refused():
        result = flight.fly(view, view.event if view is not None else _print_event, live)
    report = result.report
    _summary(report, flight.log_path, final_table=result.final_table)
    if report.host_sentence:
        typer.echo(report.host_sentence)
    if report.interrupted:
        return 130
    return 0 if report.success else 1


def _fly_distributed(flight: Flight, console: bool, verbose: bool) -> None:
    """The coordinator of ``rpf-fly fly --distributed`` (raises typer.Exit with the flight's code). ``console``: the
    status table of ``rpf-fly fly`` (cli/flight_console.py) from the coordinator's snapshot, with each drone's worker:
    live on a terminal, the final table at the end."""
    view = _status_console(flight.mission) if console else None
    with refused():
        result = flight.fly_distributed(view, view.line if view is not None else _say, verbose)
    for line in result.summary:
        typer.echo(line)
    raise typer.Exit(result.code)


def _status_console(mission: Mission) -> FlightConsole:
    from rpf_fly.cli.flight_console import FlightConsole

    return FlightConsole(mission.name)


def _say(line: str) -> None:
    typer.echo(line, err=True)


def _print_event(event: FlightEvent) -> None:
    if event.level >= 2 and event.kind != "phase" or event.drone is None:
        who = f"{event.drone}: " if event.drone else ""
        typer.echo(f"[{event.kind}] {who}{event.message}", err=True)


def _summary(report, log_path: Path, final_table: bool = False) -> None:
    """What a flight prints last on stdout: each drone's outcome, the loop's summary line, the log. The outcome
    lines only where no final table (``final_table``: the status console's, on stderr) already showed them on the
    same screen: with ``--no-console``, or when stdout or stderr is not a terminal (a script reading stdout gets
    them as ever)."""
    from rpf_fly.cli.output import console

    stats = report.stats.summary()
    on_screen = final_table and console().is_terminal and console(stderr=True).is_terminal
    for name, outcome in report.outcomes.items() if not on_screen else ():
        reason = report.reasons.get(name) or ""
        typer.echo(f"{name}: {outcome.value}{' (' + reason + ')' if reason and outcome.value != 'reached' else ''}")
    if stats["latency_p50_s"] is not None:
        typer.echo(
            f"ticks {stats['ticks']}, overruns {stats['overruns']}, mocap-to-setpoint latency p50 "
            f"{stats['latency_p50_s'] * 1e3:.2f} ms p99 {stats['latency_p99_s'] * 1e3:.2f} ms"
        )
    if report.error:
        typer.echo(f"error: {report.error}", err=True)
    typer.echo(f"log: {log_path}  (rpf-fly review {log_path})")


@app.command()
def check(
    mission: Path = typer.Argument(..., help="Mission YAML file."),
    dry_run: bool = typer.Option(False, "--dry-run", help="Preflight the simulated drones instead of hardware."),
    lab: bool = typer.Option(False, "--lab", help="Preflight the simulated drones of the running `rpf-fly lab`."),
    preflight: bool = typer.Option(True, "--preflight/--no-preflight", help="Connect and run the preflight checks."),
    verbose: bool = typer.Option(
        False,
        "--verbose",
        help="Also print the libraries' log records (cflib) on stderr; they always go to ~/.cache/rpf_fly/check.log.",
    ),
) -> None:
    """Validate MISSION; then connect to the drones and the mocap and run the preflight checks (nothing takes off)."""
    from rpf_fly.app.flight import FlightApp

    with refused():
        flight_app = FlightApp(mission)
        prepared = flight_app.prepare_check(dry_run, lab, preflight)
    loaded = flight_app.mission
    from rpf_fly.radio.budget import budget_table, radio_loads

    typer.echo("radio budget (transactions a second per dongle, cflib 0.1.34 on the dongle's figures; docs/radio.md):")
    for line in budget_table(radio_loads(loaded)):
        typer.echo(f"  {line}")
    with refused():
        flight_app.check_radio_budget()
    policy = f" ({loaded.planner.policy})" if loaded.planner.policy is not None else ""
    typer.echo(
        f"{mission}: valid mission '{loaded.name}' with {len(loaded.drones)} drones, planner "
        f"{loaded.planner.kind}{policy}"
    )
    if not preflight:
        return
    if not prepared.dry_run and flight_app.real_flight_problem():
        typer.echo(f"preflight skipped: {flight_app.real_flight_problem()}")
        return
    with refused():
        if not prepared.dry_run:
            flight_app.check_radios()
        with prepared.log_records(verbose) as logs:
            problems = prepared.run()
    for name, problem in problems.items():
        typer.echo(f"{name}: {'ok' if not problem else problem}")
    if logs.warnings and logs.path is not None and not verbose:
        typer.echo(f"({logs.warnings} warning(s) from cflib and rpf_fly: {logs.path})", err=True)
    raise typer.Exit(0 if not any(problems.values()) else 1)
