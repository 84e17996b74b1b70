"""A dry run's or lab's watch on its host: says, during the flight, when the simulated world falls behind its own
time (:mod:`rpf_fly.emulator.host_lag`), so no verdict of an overloaded dry run is taken for the stack's.

Once a second it reads the world's figures (one round trip to the world's process). The first time the world has
been behind since the flight began, and after each further second behind, it emits a ``host`` warning on the
flight's events (console and log). :attr:`HostWatch.behind_s` is what the flight's report and the command's last
line carry.
"""

from __future__ import annotations

import json
import logging
import os
from collections.abc import Callable
from typing import Any

from rpf_fly.emulator.host_lag import HOST_BEHIND_REPORT_S
from rpf_fly.flight.events import WARNING, EventBus
from rpf_fly.flight.periodic import PeriodicFeed

logger = logging.getLogger(__name__)

PERIOD_S = 1.0

WATCHED: list[float] = []
"""Every finished watch's seconds behind, in this process, oldest first: a test runner names a failed flight test
whose host could not keep up (tests/conftest.py); nothing of the product reads it."""

HOST_LOG_ENV = "RPF_FLY_HOST_LOG"
"""Where a finished watch whose flight's host fell behind (`HOST_BEHIND_REPORT_S` or more) appends one JSON line,
``{"pid": int, "behind_s": float}``, when the environment names a file: a program that runs dry runs in processes
of their own (a test runner, a campaign script) learns which of them were not evidence."""


class HostWatch(PeriodicFeed):
    """Reads ``fetch()`` (a `HostLag`) every `PERIOD_S`; the first reading is the baseline."""

    def __init__(self, fetch: Callable[[], Any], events: EventBus, period_s: float = PERIOD_S) -> None:
        super().__init__("host-watch", period_s)
        self._fetch = fetch
        self._events = events
        self._baseline: Any | None = None
        self._said_s = 0.0
        self.behind_s = 0.0
        self.failed = False
        self._quiet = False
        self._once()

    def stop(self) -> None:
        """Stop and take the last reading without saying it (the flight's log may be closed by now: the report
        and the command's last line carry it)."""
        self._quiet = True
        super().stop()
        WATCHED.append(self.behind_s)
        del WATCHED[:-100]
        path = os.environ.get(HOST_LOG_ENV)
        if path and self.behind_s >= HOST_BEHIND_REPORT_S:
            try:
                with open(path, "a", encoding="utf-8") as log:
                    log.write(json.dumps({"pid": os.getpid(), "behind_s": round(self.behind_s, 3)}) + "\n")
            except OSError as err:
                logger.warning("host watch: %s not written: %s", path, err)

    def _once(self) -> bool:
        if self.failed:
            return False
        try:
            lag = self._fetch()
        except Exception as err:  # noqa: BLE001 - the world is gone: nothing more to say about it
            logger.warning("host watch stopped: %s: %s", type(err).__name__, err)
            self.failed = True
            return False
        if self._baseline is None:
            self._baseline = lag
            return True
        self.behind_s = lag.behind_since(self._baseline)
        if (
            not self._quiet
            and self.behind_s >= HOST_BEHIND_REPORT_S
            and (self._said_s == 0.0 or self.behind_s >= self._said_s + 1.0)
        ):
            self._said_s = self.behind_s
            self._events.emit(WARNING, "host", lag.sentence(self._baseline))
        return True
