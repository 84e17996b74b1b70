"""One mission's flight assembled for the commands that fly it: ``fly`` (one process or distributed), ``check``,
``worker``, ``lab`` and ``scenario`` share :class:`FlightApp` to load the mission and run every check before
anything connects, then fly it, preflight it or hand it on.

Here, not in the CLI, so that the commands refuse a mission alike (one line, :class:`~rpf_fly.app.errors.UserError`)
and a flight is assembled one way: the planner factory, the dry-run rig or the running lab, fault injection, the
first and second Ctrl-C, the flight run and the final table's rows. What the user sees, the status console and the
lines printed, the CLI passes in (:class:`StatusView`) and prints from what comes back.
"""

from __future__ import annotations

from collections.abc import Callable
from contextlib import nullcontext
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any, Protocol

from rpf_fly.app import checks
from rpf_fly.app.checks import PlannerFactory
from rpf_fly.app.errors import UserError

if TYPE_CHECKING:
    from rpf_fly.app.lab import LabRun
    from rpf_fly.app.worker import Worker, WorkerRequest
    from rpf_fly.flight.events import FlightEvent
    from rpf_fly.flight.faults import Fault
    from rpf_fly.flight.lab import LabInfo
    from rpf_fly.flight.report import FlightReport
    from rpf_fly.log.live import LiveView
    from rpf_fly.log.text_log import LogRouting
    from rpf_fly.mission import Mission
    from rpf_fly.radio.budget import DongleLoad

MOCAP_KINDS = ("natnet", "sim", "motioncapture")
"""A dry run's mocap (``fly --mocap``): the NatNet emulator over UDP, the motioncapture package reading it, or the
simulated source."""

CHECK_LOG = Path("~/.cache/rpf_fly/check.log")
"""The libraries' log records of the last ``rpf-fly check`` (overwritten each time)."""


class StatusView(Protocol):
    """Where a flight's status goes while it flies (the CLI's status console, cli/flight_console.py): entered for
    the flight, :meth:`show` on every status change, :meth:`final` once with how it ended."""

    def __enter__(self) -> Any: ...

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> Any: ...

    def show(self, phase: str, rows_of: Callable[[], list[dict[str, Any]]]) -> None: ...

    def line(self, text: str) -> None: ...

    def final(self, phase: str, rows: list[dict[str, Any]]) -> None: ...


@dataclass(frozen=True)
class FlightRequest:
    """What ``rpf-fly fly`` is asked (its options; ``rpf-fly fly --help``). ``live``: a live view was asked for
    (``--foxglove``, its port or host)."""

    dry_run: bool = False
    lab: bool = False
    log: Path | None = None
    mocap: str | None = None
    faults: Path | None = None
    radio_loss: bool = True
    live: bool = False
    distributed: bool = False
    remote_dongles: str | None = None
    listen: tuple[str, ...] = ()


@dataclass(frozen=True)
class FlightResult:
    """How a flight of one process ended: its report, and whether the status view showed the final table."""

    report: FlightReport
    final_table: bool


@dataclass(frozen=True)
class DistributedResult:
    """How a distributed flight ended: the coordinator's exit code and its summary lines."""

    code: int
    summary: list[str]


class FlightApp:
    """A mission loaded from ``mission_path`` (or given as ``mission``: its problems still name the path), and what
    every command flying it checks and builds. Constructing it loads the mission (:class:`UserError` when invalid)."""

    def __init__(self, mission_path: Path, mission: Mission | None = None) -> None:
        self.path = mission_path
        self.mission = mission if mission is not None else checks.load_mission(mission_path)

    def at(self, problem: str) -> str:
        """``FILE:LINE: FIELD: problem`` for a problem of the mission's ``FIELD``."""
        return checks.at(self.path, problem)

    def faults(self, path: Path) -> list[Fault]:
        return checks.load_faults(path, self.mission)

    def real_flight_problem(self) -> str | None:
        return checks.real_flight_problem(self.mission)

    def check_radio_budget(self) -> list[DongleLoad]:
        return checks.check_radio_budget(self.mission, self.path)

    def check_radios(self, skip_dongles: tuple[int, ...] = (), only_dongle: int | None = None) -> None:
        checks.check_radios(self.mission, skip_dongles, only_dongle)

    def resolve_server(self) -> None:
        checks.resolve_server(self.mission, self.path)

    def require_library(self, dry_run: bool, mocap: str | None = None) -> None:
        checks.require_library(self.mission, dry_run, mocap)

    def planner_factory(self) -> PlannerFactory:
        return checks.planner_factory(self.mission, self.path)

    def lab_info(self) -> LabInfo:
        return checks.lab_info(self.mission)

    def prepare_flight(self, request: FlightRequest) -> Flight:
        """Every check of ``rpf-fly fly`` before anything connects, in the order the command has always made them
        (the first refusal is the one the user reads); the flight, ready to fly."""
        mission = self.mission
        lab = None
        dry_run = request.dry_run
        if request.lab:
            if dry_run:
                raise UserError(
                    "--lab and --dry-run: choose one (--lab flies a running lab's drones, --dry-run private ones)"
                )
            if request.distributed:
                raise UserError("--lab flies in one process (without --distributed)")
            lab = self.lab_info()
            dry_run = True
        if (request.remote_dongles or request.listen) and not request.distributed:
            raise UserError("--remote-dongles and --listen go with --distributed")
        faults = request.faults
        if faults is not None and not dry_run:
            raise UserError(f"--faults: {faults}: faults are injected into simulated drones only; add --dry-run")
        schedule = self.faults(faults) if faults is not None else None
        if lab is not None and schedule:
            powered = next((f for f in schedule if f.at_s is None and f.drone is not None), None)
            if powered is not None:
                raise UserError(
                    f"{faults}:{powered.line}: {powered.kind}: the lab's drones are already powered on: "
                    "give power-on faults to `rpf-fly lab --faults`"
                )
        self.check_radio_budget()
        factory = self.planner_factory()
        problem = self.real_flight_problem()
        if not dry_run and problem:
            raise UserError(self.at(problem))
        if not dry_run:
            self.resolve_server()
            self.check_radios(checks.dongles(request.remote_dongles) if request.distributed else ())
        if request.mocap not in (None, *MOCAP_KINDS):
            raise UserError(f"--mocap: expected natnet, motioncapture or sim, got {request.mocap!r}")
        self.require_library(dry_run, request.mocap)
        mocap = request.mocap or ("motioncapture" if mission.mocap.kind == "motioncapture" else "natnet")
        log_path = request.log or Path("flights") / f"{mission.name}-{datetime.now():%Y%m%d-%H%M%S}.mcap"
        checks.check_log_path(log_path)
        remote: tuple[int, ...] = ()
        listen: tuple[str, ...] = ()
        if request.distributed:
            if request.live or mocap not in ("natnet", "motioncapture"):
                raise UserError("--distributed flies without --foxglove or --mocap sim (docs/distributed.md)")
            timed = next((f for f in schedule or () if f.at_s is not None or f.drone is None), None)
            if timed is not None:  # the power-on ones live in the simulated drones; the others need the worker's loop
                raise UserError(
                    f"{faults}:{timed.line}: {timed.kind}: --distributed takes the power-on faults only "
                    "(yaw_offset, start_offset, upside_down, motor_fault; docs/distributed.md)"
                )
            remote = checks.dongles(request.remote_dongles)
            listen = checks.endpoints(request.listen, "--listen")
        return Flight(self, request, factory, dry_run, mocap, log_path, schedule, lab, remote, listen)

    def preflight(self, factory: PlannerFactory, dry_run: bool, lab: LabInfo | None = None) -> dict[str, str]:
        """Connect to the drones (simulated with ``dry_run``; a running lab's with ``lab``) and the mocap and run the
        preflight checks, nothing takes off: each drone's problem ('' when ready). No mocap: exit 1."""
        from rpf_fly.flight import dry_run as dry_runs
        from rpf_fly.flight.loop import FlightLoop
        from rpf_fly.flight.session import DEFAULT_TOC_CACHE, mocap_source
        from rpf_fly.radio.cflib_backend import CflibBackend

        mission = self.mission
        rig = dry_runs.DryRun(mission, lab=lab) if dry_run else None
        with rig if rig is not None else nullcontext():
            try:
                source = rig.entered_mocap() if rig is not None else mocap_source(mission)
            except ConnectionError as err:
                raise UserError(f"mocap: {err}", code=1) from None
            backend = CflibBackend.for_mission(mission, rig.cache_dir if rig is not None else DEFAULT_TOC_CACHE)
            loop = FlightLoop(mission, backend, source, factory, uris=rig.uris if rig is not None else None)
            problems = loop.preflight_only()
            if rig is None:
                source.close()
        return problems

    def prepare_check(self, dry_run: bool, lab: bool, preflight: bool) -> Check:
        """``rpf-fly check``'s checks before its radio budget table: the planner, the running lab (``lab``), the
        mocap server of a real preflight, the motioncapture package; the check, ready to run."""
        factory = self.planner_factory()
        lab_info = None
        if lab:
            if dry_run:
                raise UserError(
                    "--lab and --dry-run: choose one (--lab checks a running lab's drones, --dry-run private ones)"
                )
            lab_info = self.lab_info() if preflight else None
            dry_run = True
        if preflight and not dry_run and not self.real_flight_problem():
            self.resolve_server()
        if preflight:
            self.require_library(dry_run)
        return Check(self, factory, dry_run, lab_info)

    def prepare_worker(self, request: WorkerRequest) -> Worker:
        """``rpf-fly worker``: one dongle's drones of a distributed flight (rpf_fly/app/worker.py)."""
        from rpf_fly.app.worker import prepare_worker

        return prepare_worker(self, request)

    def prepare_lab(self, faults: Path | None, log: Path | None) -> LabRun:
        """``rpf-fly lab``: the mission's simulated drones and Motive emulator until stopped (rpf_fly/app/lab.py)."""
        from rpf_fly.app.lab import prepare_lab

        return prepare_lab(self, faults, log)


@dataclass(frozen=True)
class Check:
    """``rpf-fly check`` past its checks: the preflight to run (:meth:`run`)."""

    app: FlightApp
    factory: PlannerFactory
    dry_run: bool
    lab: LabInfo | None

    def log_records(self, verbose: bool) -> LogRouting:
        """The libraries' log records of the check: :data:`CHECK_LOG` (and stderr with ``verbose``)."""
        from rpf_fly.log.text_log import route_logging

        return route_logging(CHECK_LOG.expanduser(), verbose)

    def run(self) -> dict[str, str]:
        return self.app.preflight(self.factory, self.dry_run, self.lab)


@dataclass(frozen=True)
class Flight:
    """A flight past every check (:meth:`FlightApp.prepare_flight`), nothing connected yet: fly it in this process
    (:meth:`fly`) or distributed (:meth:`fly_distributed`)."""

    app: FlightApp
    request: FlightRequest
    factory: PlannerFactory
    dry_run: bool
    mocap: str
    log_path: Path
    schedule: list[Fault] | None
    lab: LabInfo | None
    remote: tuple[int, ...] = ()
    listen: tuple[str, ...] = ()

    @property
    def mission(self) -> Mission:
        return self.app.mission

    @property
    def distributed(self) -> bool:
        return self.request.distributed

    def log_records(self, verbose: bool) -> LogRouting:
        """The libraries' log records of the flight: a text file beside its log (and stderr with ``verbose``)."""
        from rpf_fly.log.text_log import route_logging, text_log_path

        return route_logging(text_log_path(self.log_path), verbose)

    def fly(
        self, view: StatusView | None, on_event: Callable[[FlightEvent], None], live: LiveView | None = None
    ) -> FlightResult:
        """Fly in this process: the mission's drones, or a dry run's (its rig, faults injected) or the running lab's.
        ``view``: the status console (entered for the flight; its final table from the loop and the report),
        ``on_event``: every flight event, ``live``: the started live view. The first Ctrl-C (or SIGTERM) lands every
        drone, a second stops the motors. No mocap: :class:`UserError` with exit code 1."""
        from rpf_fly.app.signals import LoopSignals
        from rpf_fly.flight.dry_run import RADIO_LOSS, DryRun, world_exit_report_for
        from rpf_fly.flight.fault_injection import FaultInjection
        from rpf_fly.flight.session import run_flight

        mission = self.mission
        signals = LoopSignals()
        injection = FaultInjection(mission, self.schedule) if self.schedule else None
        rig_holder: dict[str, Any] = {}

        def on_loop(loop: Any) -> None:
            rig_holder["loop"] = loop
            signals.attach(loop)
            signals.install()
            if injection is not None:
                injection.start(loop, rig_holder["rig"])

        factory = injection.planner_factory(self.factory) if injection is not None else self.factory
        kwargs: dict[str, Any] = dict(
            status_hook=(lambda loop: view.show(loop.phase.value, loop.snapshot)) if view is not None else None,
            event_sinks=(on_event,),
            on_loop=on_loop,
            live=live,
        )
        try:
            with view if view is not None else nullcontext():
                if self.dry_run:
                    start_faults = injection.start_faults() if injection is not None else None
                    with DryRun(
                        mission,
                        mocap=self.mocap,
                        start_faults=start_faults,
                        radio_loss=RADIO_LOSS if self.request.radio_loss else None,
                        world_exit_report=world_exit_report_for(self.log_path),
                        lab=self.lab,
                    ) as rig:
                        rig_holder["rig"] = rig
                        if injection is not None:
                            FaultInjection.wrap(rig)
                        try:
                            report = run_flight(mission, factory, self.log_path, rig=rig, **kwargs)
                        finally:
                            if injection is not None:
                                injection.close()
                else:
                    report = run_flight(mission, factory, self.log_path, **kwargs)
                if view is not None and "loop" in rig_holder:
                    view.final(report.phase.value, final_rows(rig_holder["loop"], report))
        except ConnectionError as err:
            raise UserError(f"mocap: {err}", code=1) from None
        finally:
            signals.restore()
        return FlightResult(report, final_table=view is not None and "loop" in rig_holder)

    def fly_distributed(self, view: StatusView | None, say: Callable[[str], None], verbose: bool) -> DistributedResult:
        """The coordinator of ``rpf-fly fly --distributed`` (docs/distributed.md): its workers, logger and relay,
        the swarm's phases; ``view``: the status console from the coordinator's snapshot, each drone with its worker;
        ``say``: the coordinator's lines. A signal interrupts the coordinator (it lands the swarm)."""
        from rpf_fly.app.signals import on_signals, restore
        from rpf_fly.flight.fault_injection import FaultInjection
        from rpf_fly.log.text_log import route_logging, text_log_path
        from rpf_fly.runtime.coordinator import Coordinator
        from rpf_fly.runtime.session import StartError, ZenohUnavailable

        mission = self.mission
        start_faults = FaultInjection(mission, self.schedule).start_faults() if self.schedule else None
        try:
            coordinator = Coordinator(
                mission,
                self.app.path,
                self.log_path,
                dry_run=self.dry_run,
                remote_dongles=self.remote,
                listen=self.listen,
                radio_loss=self.request.radio_loss,
                say=say,
                status_hook=(lambda c: view.show(c.phase, c.snapshot)) if view is not None else None,
                start_faults=start_faults,
            )
        except ValueError as err:
            raise UserError(str(err)) from None
        previous = on_signals(lambda signum, frame: coordinator.interrupt())
        try:
            with route_logging(text_log_path(self.log_path), verbose), view if view is not None else nullcontext():
                try:
                    code = coordinator.run()
                except (ZenohUnavailable, StartError) as err:
                    raise UserError(str(err)) from None
                if view is not None:
                    view.final(coordinator.phase, coordinator.snapshot())
        finally:
            restore(previous)
        return DistributedResult(code, list(coordinator.summary()))


def final_rows(loop: Any, report: FlightReport) -> list[dict[str, Any]]:
    """The final table's rows: the loop's last snapshot, each drone with its outcome and why it ended so."""
    rows = loop.snapshot()
    for row in rows:
        outcome = report.outcomes.get(row["name"])
        row["outcome"] = outcome.value if outcome is not None else None
        row["reason"] = report.reasons.get(row["name"]) or ""
    return rows
