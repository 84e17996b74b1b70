"""``rpf-fly worker``: the drones of one radio dongle in a distributed flight (docs/distributed.md), checked as
``fly`` checks a mission (:mod:`rpf_fly.app.checks`), then flown by :class:`~rpf_fly.runtime.worker.WorkerRun` with
the flight's Ctrl-C (:mod:`rpf_fly.app.signals`) and its libraries' records in a text file.

The flight's secret and the text log's name come from the environment, as the coordinator hands them to the
workers it starts (``RPF_FLY_SECRET``, ``RPF_FLY_WORKER_LOG``).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from rpf_fly.app import checks
from rpf_fly.app.errors import UserError

if TYPE_CHECKING:
    from rpf_fly.app.checks import PlannerFactory
    from rpf_fly.app.flight import FlightApp
    from rpf_fly.flight.events import FlightEvent
    from rpf_fly.flight.report import FlightReport

WORKER_LOG_ENV = "RPF_FLY_WORKER_LOG"
"""Where a worker writes the libraries' log records (default ``rpf-fly-worker-<flight>-dongle-<K>.log``)."""


@dataclass(frozen=True)
class WorkerRequest:
    """What ``rpf-fly worker`` is asked (its options); ``environ``: where the secret and the text log's name are."""

    dongle: int
    flight: str | None = None
    dry_run: bool = False
    connect: tuple[str, ...] = ()
    environ: Mapping[str, str] = field(default_factory=lambda: os.environ)


@dataclass(frozen=True)
class Worker:
    """A worker past its checks, ready to join its flight (:meth:`run`)."""

    app: FlightApp
    request: WorkerRequest
    factory: PlannerFactory
    secret: str
    connect: tuple[str, ...]

    @property
    def text_log(self) -> Path:
        request = self.request
        default = f"rpf-fly-worker-{request.flight or 'flight'}-dongle-{request.dongle}.log"
        return Path(request.environ.get(WORKER_LOG_ENV, default))

    def run(self, on_event: Callable[[FlightEvent], None], verbose: bool) -> FlightReport:
        """Fly this dongle's drones until the coordinator ends the flight: ``on_event`` gets every flight event. The
        first Ctrl-C (or SIGTERM) lands this worker's drones, a second stops their motors."""
        from rpf_fly.app.signals import LoopSignals
        from rpf_fly.log.text_log import route_logging
        from rpf_fly.runtime.session import ZenohUnavailable
        from rpf_fly.runtime.worker import WorkerError, WorkerRun

        request = self.request
        signals = LoopSignals("this worker's drones")
        signals.install()
        try:
            run = WorkerRun(
                self.app.mission,
                request.dongle,
                request.flight,
                self.secret,
                self.factory,
                dry_run=request.dry_run,
                connect=self.connect,
                event_sinks=(on_event,),
                on_loop=signals.attach,
            )
            with route_logging(self.text_log, verbose):
                try:
                    return run.run()
                except (ZenohUnavailable, WorkerError) as err:
                    raise UserError(str(err)) from None
        finally:
            signals.restore()


def prepare_worker(app: FlightApp, request: WorkerRequest) -> Worker:
    """Every check of ``rpf-fly worker`` before anything connects, in the command's order: the radio budget, the
    planner, a real flight's mocap server (unless the relay brings the mocap) and this dongle's Crazyradio, the
    flight's secret, the flight id, the endpoints."""
    from rpf_fly.runtime.auth import SECRET_ENV
    from rpf_fly.runtime.keys import check_flight_id

    app.check_radio_budget()
    factory = app.planner_factory()
    if not request.dry_run:
        problem = app.real_flight_problem()
        if problem:
            raise UserError(app.at(problem))
        from rpf_fly.runtime.relay import uses_relay

        if not uses_relay(app.mission):  # with the relay, the mocap is its host's to reach
            app.resolve_server()
        app.check_radios(only_dongle=request.dongle)
    secret = request.environ.get(SECRET_ENV, "")
    if len(secret) < 32:
        raise UserError(
            f"{SECRET_ENV}: the flight's secret is missing (the coordinator prints the worker's command line with it)"
        )
    try:
        if request.flight is not None:
            check_flight_id(request.flight)
    except ValueError as err:
        raise UserError(f"--flight: {err}") from None
    connect = checks.endpoints(request.connect, "--connect")
    return Worker(app, request, factory, secret, connect)
