"""Ctrl-C and SIGTERM during a flight: the first asks the flight loop to land every drone it flies, a second Ctrl-C
stops the motors (docs/flight.md). Shared by ``fly`` (one process) and ``worker`` (one dongle's drones of a
distributed flight) so both answer a signal alike; the handlers found are put back when the flight ends."""

from __future__ import annotations

import signal
from collections.abc import Callable
from typing import Any

Handler = Callable[[int, Any], None]


class LoopSignals:
    """SIGINT and SIGTERM handlers for one flight loop. :meth:`install` sets them (a signal before :meth:`attach`
    gave the loop is ignored), :meth:`restore` puts back the handlers that were there. ``drones``: who lands, as
    the stop notice says it (``all drones``; a worker's ``this worker's drones``)."""

    def __init__(self, drones: str | None = None) -> None:
        self.drones = drones
        self.loop: Any = None
        self.presses = 0
        self.previous: dict[int, Any] = {}

    def attach(self, loop: Any) -> None:
        """The flight loop the signals stop, once it exists."""
        self.loop = loop

    def install(self) -> None:
        for sig in (signal.SIGINT, signal.SIGTERM):
            self.previous[sig] = signal.signal(sig, self._on_signal)

    def restore(self) -> None:
        for sig, handler in self.previous.items():
            signal.signal(sig, handler)
        self.previous = {}

    def _on_signal(self, signum: int, frame: Any) -> None:
        from rpf_fly.flight.loop import signal_stop

        self.presses += 1
        loop = self.loop
        if loop is None:
            return
        if self.presses == 1 or signum == signal.SIGTERM:
            loop.request_stop(*(signal_stop(signum) if self.drones is None else signal_stop(signum, self.drones)))
        else:
            loop.emergency_stop("second Ctrl-C: emergency stop, motors off")


def on_signals(act: Handler) -> dict[int, Any]:
    """``act`` for SIGINT and SIGTERM; the handlers that were there (give them to :func:`restore`)."""
    return {sig: signal.signal(sig, act) for sig in (signal.SIGINT, signal.SIGTERM)}


def restore(previous: dict[int, Any]) -> None:
    """Put back the handlers :func:`on_signals` replaced."""
    for sig, handler in previous.items():
        signal.signal(sig, handler)
