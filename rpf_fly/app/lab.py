"""``rpf-fly lab``: a mission's simulated Crazyflies and Motive emulator (:class:`rpf_fly.flight.lab.Lab`), running
until SIGINT or SIGTERM, for ``check|fly|scenario --lab`` and cflib programs to fly one command after another
(docs/flight.md, "Lab"). The mission and its power-on faults are checked as ``fly`` checks them
(:mod:`rpf_fly.app.checks`); what the lab says once it runs, the CLI prints (``on_started``).
"""

from __future__ import annotations

import signal
from collections.abc import Callable
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rpf_fly.app.errors import UserError

if TYPE_CHECKING:
    from rpf_fly.app.flight import FlightApp
    from rpf_fly.emulator.host_lag import HostLag
    from rpf_fly.flight.lab import LabInfo


@dataclass(frozen=True)
class LabResult:
    """How the lab ended: the signal that stopped it ('' when it closed otherwise) and how far the host let its
    world fall behind (None when it never started)."""

    stopped_by: str
    lag: HostLag | None


@dataclass(frozen=True)
class LabRun:
    """A lab past its checks, ready to run (:meth:`run`)."""

    app: FlightApp
    log_path: Path
    start_faults: Any = None

    def run(self, on_started: Callable[[LabInfo, Path], None]) -> LabResult:
        """Start the lab (its drones on the floor at their mission starts), call ``on_started`` with its info and its
        lab file, and serve it until SIGINT or SIGTERM; the drones power off when it stops."""
        from rpf_fly.app.signals import on_signals, restore
        from rpf_fly.emulator.host_lag import ahead_of_the_ground_station
        from rpf_fly.flight.lab import Lab

        ahead_of_the_ground_station()  # the lab's process is the drones' and Motive's, not a ground station's
        the_lab = Lab(self.app.mission, self.app.path, self.log_path, start_faults=self.start_faults)
        stop = {"signal": ""}

        def on_signal(signum: int, frame: object) -> None:
            stop["signal"] = signal.Signals(signum).name
            the_lab.close()

        previous = on_signals(on_signal)
        try:
            try:
                info = the_lab.start()
            except (RuntimeError, OSError) as err:
                raise UserError(f"lab: {err}") from None
            on_started(info, the_lab.path)
            while not the_lab.wait(1.0):
                pass
        finally:
            the_lab.close()
            restore(previous)
        return LabResult(stop["signal"], the_lab.host_lag() if the_lab.server is not None else None)


def prepare_lab(app: FlightApp, faults: Path | None, log: Path | None) -> LabRun:
    """The lab's checks: its faults power-on ones only (timed faults are a flight's, ``fly --lab --faults``), its
    log's folder made (default ``flights/lab-<mission>-<time>.mcap``)."""
    from rpf_fly.flight.fault_injection import FaultInjection

    start_faults = None
    if faults is not None:
        schedule = app.faults(faults)
        timed = next((f for f in schedule if f.at_s is not None or f.drone is None), None)
        if timed is not None:
            raise UserError(
                f"{faults}:{timed.line}: {timed.kind}: a lab takes the power-on faults only; give timed "
                "faults to `rpf-fly fly MISSION --lab --faults FILE`"
            )
        start_faults = FaultInjection(app.mission, schedule).start_faults()
    log_path = log or Path("flights") / f"lab-{app.mission.name}-{datetime.now():%Y%m%d-%H%M%S}.mcap"
    try:
        log_path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise UserError(f"--log {log_path}: cannot make its folder: {err.strerror or err}") from None
    return LabRun(app, log_path, start_faults)
