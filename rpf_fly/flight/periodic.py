"""A feed thread of the flight's process that samples something every ``period_s`` into the log: the dry run's
truth (:mod:`rpf_fly.flight.truth`) and the radio's measured load (:mod:`rpf_fly.flight.radio_load`). One place
for the start, the idempotent stop that joins the thread and takes a last sample, and the thread's CPU time."""

from __future__ import annotations

import threading
import time
from typing import TypeVar

_Feed = TypeVar("_Feed", bound="PeriodicFeed")


class PeriodicFeed:
    """Calls :meth:`_once` on a daemon thread every ``period_s`` until :meth:`stop` (or until it returns False),
    then once more in :meth:`stop`, so the log ends with the last sample before it closes."""

    def __init__(self, name: str, period_s: float) -> None:
        self.period_s = float(period_s)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self.cpu_s = 0.0
        """CPU time of the feed's thread, set when it ends."""

    def start(self: _Feed) -> _Feed:
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop the thread, then take the last sample (idempotent)."""
        if self._stop.is_set():
            return
        self._stop.set()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout=5.0)
        self._once()

    def _run(self) -> None:
        try:
            while not self._stop.wait(self.period_s):
                if not self._once():
                    return
        finally:
            self.cpu_s = time.thread_time()

    def _once(self) -> bool:
        """One sample into the log; False once the feed has failed (it then stays silent)."""
        raise NotImplementedError
