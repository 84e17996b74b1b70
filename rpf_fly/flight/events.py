"""Flight events: every state change, safety finding and error, fanned out to the log and the console.

Levels follow foxglove.Log: 1 debug, 2 info, 3 warning, 4 error, 5 fatal.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from dataclasses import dataclass

DEBUG, INFO, WARNING, ERROR, FATAL = 1, 2, 3, 4, 5
_LOGGING_LEVEL = {
    DEBUG: logging.DEBUG,
    INFO: logging.INFO,
    WARNING: logging.WARNING,
    ERROR: logging.ERROR,
    FATAL: logging.CRITICAL,
}

logger = logging.getLogger("rpf_fly.flight")


@dataclass(frozen=True)
class FlightEvent:
    """One event: ``time_s`` on the flight's monotonic clock, ``kind`` a short machine name (phase, separation,
    obstacle, geofence, pose_stale, pose_lost, mocap_lost, link_lost, battery, planner_fault, interrupt,
    emergency, error, preflight, takeoff, arrived, landed), ``drone`` None for swarm-wide events."""

    time_s: float
    level: int
    kind: str
    message: str
    drone: str | None = None


EventSink = Callable[[FlightEvent], None]


class EventBus:
    """Collects events and passes each to every sink (the MCAP log, the console). Thread-safe; a failing sink is
    logged and skipped, never raised into the flight loop."""

    def __init__(self, clock: Callable[[], float]):
        self._clock = clock
        self._sinks: list[EventSink] = []
        self._lock = threading.Lock()
        self.history: list[FlightEvent] = []

    def subscribe(self, sink: EventSink) -> None:
        with self._lock:
            self._sinks.append(sink)

    def emit(self, level: int, kind: str, message: str, drone: str | None = None) -> FlightEvent:
        event = FlightEvent(self._clock(), level, kind, message, drone)
        with self._lock:
            self.history.append(event)
            sinks = list(self._sinks)
        logger.log(_LOGGING_LEVEL.get(level, logging.INFO), "%s%s", f"{drone}: " if drone else "", message)
        for sink in sinks:
            try:
                sink(event)
            except Exception:  # noqa: BLE001 - a sink must never break the flight
                logger.exception("event sink failed")
        return event

    def of_kind(self, kind: str, drone: str | None = None) -> list[FlightEvent]:
        with self._lock:
            return [e for e in self.history if e.kind == kind and (drone is None or e.drone == drone)]
