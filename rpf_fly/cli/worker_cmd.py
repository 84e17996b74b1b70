"""``rpf-fly worker`` (one dongle's drones of a distributed flight) and ``rpf-fly fly --distributed`` (the
coordinator): docs/distributed.md."""

from __future__ import annotations

import os
import signal
from pathlib import Path
from typing import Optional

import typer

from rpf_fly.cli import app
from rpf_fly.cli.errors import fail


def _dongles(text: Optional[str]) -> tuple[int, ...]:
    if not text:
        return ()
    try:
        return tuple(int(part) for part in text.split(",") if part.strip())
    except ValueError:
        raise fail(f"--remote-dongles: expected dongle numbers such as 1,2, got {text!r}")


def _endpoints(values: tuple[str, ...], option: str) -> tuple[str, ...]:
    for value in values:
        proto, sep, rest = value.partition("/")
        if not sep or proto not in ("tcp", "udp", "tls", "quic") or ":" not in rest:
            raise fail(f"{option}: expected a Zenoh endpoint such as tcp/127.0.0.1:7447, got {value!r}")
    return values


def fly_distributed(mission, mission_path: Path, log_path: Path, dry_run: bool, remote: Optional[str],  # type: ignore[no-untyped-def]
                    listen: tuple[str, ...], radio_loss: bool, verbose: bool, console: bool = True,
                    start_faults=None) -> None:
    """The coordinator of ``rpf-fly fly --distributed`` (raises typer.Exit with the flight's code). ``console``: the
    status table of ``rpf-fly fly`` (cli/flight_console.py) from the coordinator's snapshot, with each drone's worker:
    live on a terminal, the final table at the end. ``start_faults``: a dry run's power-on faults."""
    from rpf_fly.cli.fly_cmd import _nothing, text_log_path
    from rpf_fly.cli.logs import route_logging
    from rpf_fly.runtime.coordinator import Coordinator
    from rpf_fly.runtime.session import StartError, ZenohUnavailable

    live = None
    if console:
        from rpf_fly.cli.flight_console import FlightConsole

        live = FlightConsole(mission.name)
    try:
        coordinator = Coordinator(mission, mission_path, log_path, dry_run=dry_run, remote_dongles=_dongles(remote),
                                  listen=_endpoints(listen, "--listen"), radio_loss=radio_loss,
                                  say=live.line if live is not None else lambda line: typer.echo(line, err=True),
                                  status_hook=(lambda c: live.show(c.phase, c.snapshot)) if live is not None
                                  else None, start_faults=start_faults)
    except ValueError as err:
        raise fail(str(err))

    def on_interrupt(signum, frame) -> None:  # type: ignore[no-untyped-def]
        coordinator.interrupt()

    previous = {sig: signal.signal(sig, on_interrupt) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        with route_logging(text_log_path(log_path), verbose), (live if live is not None else _nothing()):
            try:
                code = coordinator.run()
            except (ZenohUnavailable, StartError) as err:
                raise fail(str(err))
            if live is not None:
                live.final(coordinator.phase, coordinator.snapshot())
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    for line in coordinator.summary():
        typer.echo(line)
    raise typer.Exit(code)


@app.command()
def worker(
    mission: Path = typer.Argument(..., help="Mission YAML file (the coordinator's)."),
    dongle: int = typer.Option(..., "--dongle", help="The radio dongle whose drones this worker flies (the URIs' "
                               "first number)."),
    flight: Optional[str] = typer.Option(None, "--flight", help="The flight id the coordinator printed (its log's "
                                         "stem); default: the one flight whose coordinator --connect reaches."),
    dry_run: bool = typer.Option(False, "--dry-run", help="The coordinator's simulated drones (its dry run)."),
    connect: Optional[list[str]] = typer.Option(None, "--connect", help="The coordinator's Zenoh endpoint, e.g. "
                                                "tcp/HOST:7447 (default: the mission's runtime.zenoh.connect)."),
    verbose: bool = typer.Option(False, "--verbose", help="Also print the libraries' log records on stderr."),
) -> None:
    """Fly the drones of one dongle in a distributed flight (docs/distributed.md). The flight's secret comes in
    the environment, RPF_FLY_SECRET, as the coordinator printed it."""
    from rpf_fly.cli.fly_cmd import _check_radio_budget, _check_radios, _load, _planner_factory, _resolve_server, at
    from rpf_fly.flight.session import real_flight_problem
    from rpf_fly.runtime.auth import SECRET_ENV
    from rpf_fly.runtime.keys import check_flight_id

    loaded = _load(mission)
    _check_radio_budget(loaded, mission)
    factory = _planner_factory(loaded, mission)
    if not dry_run:
        if real_flight_problem(loaded):
            raise fail(at(mission, real_flight_problem(loaded)))
        from rpf_fly.runtime.relay import uses_relay

        if not uses_relay(loaded):  # with the relay, the mocap is its host's to reach
            _resolve_server(loaded, mission)
        _check_radios(loaded, only_dongle=dongle)
    secret = os.environ.get(SECRET_ENV, "")
    if len(secret) < 32:
        raise fail(f"{SECRET_ENV}: the flight's secret is missing (the coordinator prints the worker's command "
                   "line with it)")
    try:
        if flight is not None:
            check_flight_id(flight)
    except ValueError as err:
        raise fail(f"--flight: {err}")
    endpoints = _endpoints(tuple(connect or ()), "--connect")
    from rpf_fly.cli.logs import route_logging
    from rpf_fly.flight.loop import signal_stop
    from rpf_fly.runtime.session import ZenohUnavailable
    from rpf_fly.runtime.worker import WorkerError, WorkerRun

    def say(event) -> None:  # type: ignore[no-untyped-def]
        if event.level >= 3 or event.drone is None:
            who = f"{event.drone}: " if event.drone else ""
            typer.echo(f"[{event.kind}] {who}{event.message}", err=True)

    presses = {"n": 0}
    holder: dict = {}

    def on_interrupt(signum, frame) -> None:  # type: ignore[no-untyped-def]
        presses["n"] += 1
        loop = holder.get("loop")
        if loop is None:
            return
        if presses["n"] == 1 or signum == signal.SIGTERM:
            loop.request_stop(*signal_stop(signum, "this worker's drones"))
        else:
            loop.emergency_stop("second Ctrl-C: emergency stop, motors off")

    previous = {sig: signal.signal(sig, on_interrupt) for sig in (signal.SIGINT, signal.SIGTERM)}
    run = WorkerRun(loaded, dongle, flight, secret, factory, dry_run=dry_run, connect=endpoints,
                    event_sinks=(say,), on_loop=lambda loop: holder.update(loop=loop))
    text_log = Path(os.environ.get("RPF_FLY_WORKER_LOG", f"rpf-fly-worker-{flight or 'flight'}-dongle-{dongle}.log"))
    try:
        with route_logging(text_log, verbose):
            try:
                report = run.run()
            except (ZenohUnavailable, WorkerError) as err:
                raise fail(str(err))
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    for name, outcome in report.outcomes.items():
        typer.echo(f"{name}: {outcome.value}")
    if report.interrupted:
        raise typer.Exit(130)
    raise typer.Exit(0 if report.success else 1)
