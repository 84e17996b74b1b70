"""``rpf-fly fly`` and ``rpf-fly check``: fly a mission (or dry-run it on simulated drones), validate and preflight.

Ctrl-C once: every drone lands and the log is closed. Ctrl-C twice: emergency stop (motors off). SIGTERM acts as
the first Ctrl-C. Exit codes: 0 every drone reached its goal and landed; 1 the flight ended otherwise (a drone
landed early, timed out, lost its link, the flight aborted before take-off); 2 invalid mission or policy;
130 interrupted.
"""

from __future__ import annotations

import signal
from datetime import datetime
from pathlib import Path
from typing import Optional

import typer

from rpf_fly.cli import app
from rpf_fly.cli.errors import fail

def _load(mission_path: Path):  # type: ignore[no-untyped-def]
    from rpf_fly.mission import MissionError, load_mission

    try:
        return load_mission(mission_path)
    except MissionError as err:
        raise fail(str(err))


def at(mission_path: Path, problem: str) -> str:
    """``FILE:LINE: FIELD: problem`` for a problem of the mission's ``FIELD`` found after loading (``problem`` starts
    with the field): the field's line in the file (docs/mission-format.md's convention), not 0, the command line's."""
    from rpf_fly.mission import field_line

    return f"{mission_path}:{field_line(mission_path, problem.split(':', 1)[0])}: {problem}"


def _resolve_server(mission, mission_path: Path) -> None:  # type: ignore[no-untyped-def]
    """An unresolvable ``mocap.server`` is an invalid mission: one line, exit 2, before anything connects."""
    from rpf_fly.flight.session import UnresolvableServer, resolve_mocap_server

    try:
        resolve_mocap_server(mission)
    except UnresolvableServer as err:
        raise fail(at(mission_path, f"{err.field}: {err}"))


def _require_library(mission, dry_run: bool, mocap: Optional[str] = None) -> None:  # type: ignore[no-untyped-def]
    """A flight that needs the optional motioncapture package and lacks it: one line naming the extra, exit 1."""
    from rpf_fly.flight.session import motioncapture_missing

    missing = motioncapture_missing(mission, dry_run, mocap)
    if missing:
        raise fail(f"mocap: {missing}", code=1)


def _check_radio_budget(mission, mission_path: Path) -> list:  # type: ignore[no-untyped-def]
    """Refuse a mission that asks a dongle for more than it carries (one line, exit 2, before anything connects),
    unless it says ``radio.allow_over_budget: true``; the per-dongle loads otherwise (docs/radio.md)."""
    from rpf_fly.radio.budget import over_budget_message, radio_loads

    loads = radio_loads(mission)
    over = [load for load in loads if load.over]
    if over and not mission.radio.allow_over_budget:
        raise fail(at(mission_path, f"radio: {over_budget_message(over[0])}"))
    return loads


def _remote(text: Optional[str]) -> tuple[int, ...]:
    from rpf_fly.cli.worker_cmd import _dongles

    return _dongles(text)


def _check_radios(mission, skip_dongles: tuple[int, ...] = (), only_dongle: Optional[int] = None) -> None:  # type: ignore[no-untyped-def]
    """Every ``radio://`` drone's Crazyradio on USB, before any link is tried: else one line, exit 2. A distributed
    flight checks the dongles of this host only: not ``skip_dongles`` (remote workers'), or ``only_dongle`` (a
    worker's)."""
    from rpf_fly.radio.budget import dongle_of
    from rpf_fly.radio.dongles import radio_problem

    drones = [d for d in mission.drones if dongle_of(d.uri) not in skip_dongles
              and (only_dongle is None or dongle_of(d.uri) == only_dongle)]
    problem = radio_problem(d.uri for d in drones)
    if problem:
        raise fail(problem)


def _planner_factory(mission, mission_path: Path):  # type: ignore[no-untyped-def]
    """Each drone gets its own planner instance (its own ONNX session for learned planners)."""
    from rpf_fly.planning.onnx_policy import PolicyError
    from rpf_fly.planning.factory import UnsupportedPlanner, mission_planner, obstacle_set

    obstacles = obstacle_set(mission.obstacles)
    try:
        mission_planner(mission, obstacles=obstacles)  # fail early, before anything connects
    except (UnsupportedPlanner, PolicyError) as err:
        raise fail(at(mission_path, f"planner.policy: {err}"))
    return lambda drone: mission_planner(mission, obstacles=obstacles)


@app.command()
def fly(
    mission: Path = typer.Argument(..., help="Mission YAML file."),
    dry_run: bool = typer.Option(False, "--dry-run", help="Simulated drones through the same stack (fake radio)."),
    lab: bool = typer.Option(False, "--lab", help="Fly the simulated drones of the running `rpf-fly lab` (they keep "
                             "their firmware state between commands) instead of private ones."),
    log: Optional[Path] = typer.Option(None, "--log", help="MCAP flight log (default flights/<mission>-<time>.mcap)."),
    mocap: Optional[str] = typer.Option(
        None, "--mocap", help="Dry run only: natnet (emulator over UDP), motioncapture (the emulator read by the "
        "motioncapture package in a child process) or sim. Default: motioncapture for mocap.kind motioncapture, "
        "else natnet."),
    console: bool = typer.Option(True, "--console/--no-console", help="Live status table while flying."),
    faults: Optional[Path] = typer.Option(None, "--faults", help="Dry run only: a fault schedule (docs/faults.md)."),
    radio_loss: bool = typer.Option(True, "--radio-loss/--no-radio-loss",
                                    help="Dry run only: bursty radio loss on every link (docs/radio.md)."),
    foxglove: bool = typer.Option(False, "--foxglove", help="Serve the flight live to Foxglove over WebSocket "
                                  "(ws://localhost:8765; the live extra; docs/foxglove.md)."),
    foxglove_port: Optional[int] = typer.Option(None, "--foxglove-port", help="Port of the live view (default 8765; "
                                                "0: any free port). Implies --foxglove."),
    foxglove_host: Optional[str] = typer.Option(None, "--foxglove-host", help="Address the live view listens on "
                                                "(default 127.0.0.1; 0.0.0.0: every network). Implies --foxglove."),
    verbose: bool = typer.Option(False, "--verbose", help="Also print the libraries' log records (cflib, foxglove-sdk) "
                                                          "on stderr; they always go to LOG.log beside the flight "
                                                          "log."),
    distributed: bool = typer.Option(False, "--distributed", help="One worker process per radio dongle, a "
                                     "coordinator and a logger, on Zenoh (docs/distributed.md)."),
    remote_dongles: Optional[str] = typer.Option(None, "--remote-dongles", help="With --distributed: dongles "
                                                 "(K[,K...]) whose workers run on other hosts (`rpf-fly worker`); "
                                                 "waits for them before any drone arms."),
    listen: Optional[list[str]] = typer.Option(None, "--listen", help="With --distributed: the Zenoh endpoint the "
                                               "coordinator listens on (default 127.0.0.1 only, e.g. "
                                               "tcp/0.0.0.0:7447 for remote workers)."),
) -> None:
    """Fly MISSION: its mocap (NatNet or motioncapture) and cflib radios, or simulated drones with --dry-run."""
    loaded = _load(mission)
    lab_info = None
    if lab:
        if dry_run:
            raise fail("--lab and --dry-run: choose one (--lab flies a running lab's drones, --dry-run private ones)")
        if distributed:
            raise fail("--lab flies in one process (without --distributed)")
        lab_info = _lab_info(loaded)
        dry_run = True
    if (remote_dongles or listen) and not distributed:
        raise fail("--remote-dongles and --listen go with --distributed")
    if faults is not None and not dry_run:
        raise fail(f"--faults: {faults}: faults are injected into simulated drones only; add --dry-run")
    schedule = _load_faults(faults, loaded) if faults is not None else None
    if lab_info is not None and schedule:
        powered = next((f for f in schedule if f.at_s is None and f.drone is not None), None)
        if powered is not None:
            raise fail(f"{faults}:{powered.line}: {powered.kind}: the lab's drones are already powered on: give "
                       "power-on faults to `rpf-fly lab --faults`")
    _check_radio_budget(loaded, mission)
    factory = _planner_factory(loaded, mission)
    from rpf_fly.flight.session import real_flight_problem

    if not dry_run and real_flight_problem(loaded):
        raise fail(at(mission, real_flight_problem(loaded)))
    if not dry_run:
        _resolve_server(loaded, mission)
        _check_radios(loaded, _remote(remote_dongles) if distributed else ())
    if mocap not in (None, "natnet", "sim", "motioncapture"):
        raise fail(f"--mocap: expected natnet, motioncapture or sim, got {mocap!r}")
    _require_library(loaded, dry_run, mocap)
    mocap = mocap or ("motioncapture" if loaded.mocap.kind == "motioncapture" else "natnet")
    log_path = log or Path("flights") / f"{loaded.name}-{datetime.now():%Y%m%d-%H%M%S}.mcap"
    _check_log_path(log_path)
    if distributed:
        from rpf_fly.cli.worker_cmd import fly_distributed

        if foxglove or foxglove_port is not None or foxglove_host is not None or mocap not in ("natnet",
                                                                                               "motioncapture"):
            raise fail("--distributed flies without --foxglove or --mocap sim (docs/distributed.md)")
        timed = next((f for f in schedule or () if f.at_s is not None or f.drone is None), None)
        if timed is not None:  # the power-on ones live in the simulated drones; the others need the worker's loop
            raise fail(f"{faults}:{timed.line}: {timed.kind}: --distributed takes the power-on faults only "
                       "(yaw_offset, start_offset, upside_down, motor_fault; docs/distributed.md)")
        from rpf_fly.flight.fault_injection import FaultInjection

        fly_distributed(loaded, mission, log_path, dry_run, remote_dongles, tuple(listen or ()), radio_loss,
                        verbose, console, FaultInjection(loaded, schedule).start_faults() if schedule else None)
    from rpf_fly.cli.live_opts import start_live
    from rpf_fly.cli.logs import route_logging

    live = start_live(foxglove, foxglove_port, foxglove_host)
    with route_logging(text_log_path(log_path), verbose) as logs:  # the live server's records too, to its close
        try:
            code = _run_flight(loaded, factory, dry_run, mocap, log_path, console, schedule, radio_loss,
                               live_view=live, lab=lab_info)
        finally:
            if live is not None:
                live.close()
                typer.echo(live.summary())
    if logs.warnings and logs.path is not None and not verbose:
        libraries = "cflib, foxglove-sdk" if live is not None else "cflib"
        typer.echo(f"({logs.warnings} warning(s) from {libraries} and rpf_fly: {logs.path})", err=True)
    raise typer.Exit(code)


def lab_info_or_fail(mission):  # type: ignore[no-untyped-def]
    """The running lab's info for ``mission`` (one line, exit 2, when there is none)."""
    return _lab_info(mission)


def _lab_info(mission):  # type: ignore[no-untyped-def]
    """The running lab's info, checked against ``mission``'s drones (one line, exit 2, when none runs or it has
    not every drone)."""
    from rpf_fly.flight.dry_run import uri_address
    from rpf_fly.flight.lab import LabNotRunning, read_lab

    try:
        info = read_lab()
    except LabNotRunning as err:
        raise fail(f"--lab: {err}")
    missing = [d.name for d in mission.drones if uri_address(d.uri) not in info.addresses.values()]
    if missing:
        raise fail(f"--lab: the running lab ({info.mission}) has no drone at the address of "
                   f"{', '.join(missing)}: start the lab with this mission")
    return info


def _check_log_path(log_path: Path) -> None:
    """The flight log's folder made and writable before anything connects (one line, exit 2, nothing armed)."""
    try:
        log_path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise fail(f"--log {log_path}: cannot make its folder: {err.strerror or err}")
    existed = log_path.exists()
    try:  # a real try: permissions alone do not say it (root may write anywhere but /proc, a read-only mount)
        with open(log_path, "ab"):
            pass
        if not existed:
            log_path.unlink()
    except OSError as err:
        raise fail(f"--log {log_path}: cannot write it: {err.strerror or err}")


def text_log_path(log_path: Path) -> Path:
    """The libraries' log records of a flight: beside its MCAP log, ``.log`` for ``.mcap``."""
    return log_path.with_suffix(".log") if log_path.suffix != ".log" else log_path.with_name(log_path.name + ".txt")


CHECK_LOG = Path("~/.cache/rpf_fly/check.log")
"""The libraries' log records of the last ``rpf-fly check`` (overwritten each time)."""


def load_mission_or_fail(mission_path: Path):  # type: ignore[no-untyped-def]
    """The mission at ``mission_path``; an invalid one is one line ``FILE:LINE: FIELD: problem``, exit 2."""
    return _load(mission_path)


def load_faults_or_fail(path: Path, mission):  # type: ignore[no-untyped-def]
    """The fault schedule at ``path`` for ``mission``; an invalid one is one line, exit 2."""
    return _load_faults(path, mission)


def _load_faults(path: Path, mission):  # type: ignore[no-untyped-def]
    from rpf_fly.flight.faults import load_faults
    from rpf_fly.mission import MissionError

    try:
        return load_faults(path, mission)
    except MissionError as err:
        raise fail(str(err))


def _run_flight(mission, factory, dry_run: bool, mocap_kind: str, log_path: Path, console: bool,  # type: ignore[no-untyped-def]
                schedule=None, radio_loss: bool = True, live_view=None, lab=None) -> int:
    from rpf_fly.flight.dry_run import RADIO_LOSS, DryRun, world_exit_report_for
    from rpf_fly.flight.fault_injection import FaultInjection
    from rpf_fly.flight.session import run_flight

    live = _Console(mission) if console else None
    restore: dict = {}
    injection = FaultInjection(mission, schedule) if schedule else None
    rig_holder: dict = {}

    def on_loop(loop) -> None:  # type: ignore[no-untyped-def]
        rig_holder["loop"] = loop
        restore.update(_install_signals(loop))
        if injection is not None:
            injection.start(loop, rig_holder["rig"])

    if injection is not None:
        factory = injection.planner_factory(factory)
    kwargs = dict(status_hook=live.update if live else None, event_sinks=(live.event if live else _print_event,),
                  on_loop=on_loop, live=live_view)
    try:
        with (live if live is not None else _nothing()):
            if dry_run:
                start_faults = injection.start_faults() if injection is not None else None
                with DryRun(mission, mocap=mocap_kind, start_faults=start_faults,
                            radio_loss=RADIO_LOSS if radio_loss else None,
                            world_exit_report=world_exit_report_for(log_path), lab=lab) as rig:
                    rig_holder["rig"] = rig
                    if injection is not None:
                        FaultInjection.wrap(rig)
                    try:
                        report = run_flight(mission, factory, log_path, rig=rig, **kwargs)
                    finally:
                        if injection is not None:
                            injection.close()
            else:
                report = run_flight(mission, factory, log_path, **kwargs)
            if live is not None and "loop" in rig_holder:
                live.final(rig_holder["loop"], report)
    except ConnectionError as err:
        raise fail(f"mocap: {err}", code=1)
    finally:
        for sig, handler in restore.items():
            signal.signal(sig, handler)
    _summary(report, log_path, final_table=live is not None and "loop" in rig_holder)
    if report.host_sentence:
        typer.echo(report.host_sentence)
    if report.interrupted:
        return 130
    return 0 if report.success else 1


class _nothing:
    def __enter__(self) -> None:
        return None

    def __exit__(self, *exc: object) -> None:
        return None


def _install_signals(loop) -> dict:  # type: ignore[no-untyped-def]
    from rpf_fly.flight.loop import signal_stop

    presses = {"n": 0}

    def on_interrupt(signum, frame) -> None:  # type: ignore[no-untyped-def]
        presses["n"] += 1
        if presses["n"] == 1 or signum == signal.SIGTERM:
            loop.request_stop(*signal_stop(signum))
        else:
            loop.emergency_stop("second Ctrl-C: emergency stop, motors off")

    previous = {}
    for sig in (signal.SIGINT, signal.SIGTERM):
        previous[sig] = signal.signal(sig, on_interrupt)
    return previous


def _print_event(event) -> None:  # type: ignore[no-untyped-def]
    if event.level >= 2 and event.kind != "phase" or event.drone is None:
        who = f"{event.drone}: " if event.drone else ""
        typer.echo(f"[{event.kind}] {who}{event.message}", err=True)


class _Console:
    """The single process's status console (cli/flight_console.py): the rows of ``FlightLoop.snapshot``, live on a
    terminal (the flight loop calls :meth:`update`), and the final table from the loop and its report."""

    def __init__(self, mission):  # type: ignore[no-untyped-def]
        from rpf_fly.cli.flight_console import FlightConsole

        self.mission = mission
        self.out = FlightConsole(mission.name)
        self.event = self.out.event

    def __enter__(self) -> "_Console":
        self.out.__enter__()
        return self

    def __exit__(self, *exc: object) -> None:
        self.out.__exit__(*exc)

    def update(self, loop) -> None:  # type: ignore[no-untyped-def]
        self.out.show(loop.phase.value, loop.snapshot)

    def final(self, loop, report) -> None:  # type: ignore[no-untyped-def]
        """The table of how the flight ended: the swarm's final phase, each drone's final state and outcome."""
        rows = loop.snapshot()
        for row in rows:
            outcome = report.outcomes.get(row["name"])
            row["outcome"] = outcome.value if outcome is not None else None
            row["reason"] = report.reasons.get(row["name"]) or ""
        self.out.final(report.phase.value, rows)


def _summary(report, log_path: Path, final_table: bool = False) -> None:  # type: ignore[no-untyped-def]
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
    verbose: bool = typer.Option(False, "--verbose", help="Also print the libraries' log records (cflib) on stderr; "
                                                          "they always go to ~/.cache/rpf_fly/check.log."),
) -> None:
    """Validate MISSION; then connect to the drones and the mocap and run the preflight checks (nothing takes off)."""
    loaded = _load(mission)
    factory = _planner_factory(loaded, mission)
    from rpf_fly.flight.session import real_flight_problem

    lab_info = None
    if lab:
        if dry_run:
            raise fail("--lab and --dry-run: choose one (--lab checks a running lab's drones, --dry-run private ones)")
        lab_info = _lab_info(loaded) if preflight else None
        dry_run = True
    hardware = preflight and not dry_run and not real_flight_problem(loaded)
    if hardware:
        _resolve_server(loaded, mission)
    if preflight:
        _require_library(loaded, dry_run)
    from rpf_fly.radio.budget import budget_table, radio_loads

    typer.echo("radio budget (transactions a second per dongle, cflib 0.1.34 on the dongle's figures; docs/radio.md):")
    for line in budget_table(radio_loads(loaded)):
        typer.echo(f"  {line}")
    _check_radio_budget(loaded, mission)
    policy = f" ({loaded.planner.policy})" if loaded.planner.policy is not None else ""
    typer.echo(f"{mission}: valid mission '{loaded.name}' with {len(loaded.drones)} drones, planner "
               f"{loaded.planner.kind}{policy}")
    if not preflight:
        return
    if not dry_run and real_flight_problem(loaded):
        typer.echo(f"preflight skipped: {real_flight_problem(loaded)}")
        return
    if not dry_run:
        _check_radios(loaded)
    from rpf_fly.cli.logs import route_logging

    with route_logging(CHECK_LOG.expanduser(), verbose) as logs:
        problems = _preflight(loaded, factory, dry_run, lab_info)
    for name, problem in problems.items():
        typer.echo(f"{name}: {'ok' if not problem else problem}")
    if logs.warnings and logs.path is not None and not verbose:
        typer.echo(f"({logs.warnings} warning(s) from cflib and rpf_fly: {logs.path})", err=True)
    raise typer.Exit(0 if not any(problems.values()) else 1)


def _preflight(loaded, factory, dry_run: bool, lab=None) -> dict[str, str]:  # type: ignore[no-untyped-def]
    from rpf_fly.flight.dry_run import DryRun
    from rpf_fly.flight.loop import FlightLoop
    from rpf_fly.radio.cflib_backend import CflibBackend
    from rpf_fly.flight.session import DEFAULT_TOC_CACHE, mocap_source

    rig = DryRun(loaded, lab=lab) if dry_run else None
    with (rig if rig is not None else _nothing()):
        try:
            source = rig.mocap if rig is not None else mocap_source(loaded)
        except ConnectionError as err:
            raise fail(f"mocap: {err}", code=1)
        backend = CflibBackend.for_mission(loaded, rig.cache_dir if rig is not None else DEFAULT_TOC_CACHE)
        loop = FlightLoop(loaded, backend, source, factory, uris=rig.uris if rig is not None else None)
        problems = loop.preflight_only()
        if rig is None:
            source.close()
    return problems
