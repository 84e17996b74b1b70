"""The loop watchdog: the last line of defence if the flight loop itself stops (a call that never returns).

While drones stream setpoints, the Crazyflie firmware levels out 0.5 s after the last setpoint and cuts its
motors after 2 s (the drone falls). If the loop has not completed a tick for ``timeout_s`` (default 0.35 s, before
the firmware levels out), this thread lands every airborne drone through the high-level commander, which needs no
further setpoints. It acts at most once.
"""

from __future__ import annotations

import threading
import time
from typing import Callable, Optional


class LoopWatchdog:
    """Calls ``on_stall()`` once if :meth:`beat` is not called for ``timeout_s`` while armed."""

    def __init__(self, on_stall: Callable[[], None], timeout_s: float = 0.35, clock: Callable[[], float] = time.monotonic):
        self._on_stall = on_stall
        self._timeout_s = timeout_s
        self._clock = clock
        self._last = clock()
        self._armed = False
        self._fired = False
        self._stop = threading.Event()
        self._thread: Optional[threading.Thread] = None

    @property
    def fired(self) -> bool:
        return self._fired

    def start(self) -> None:
        self._thread = threading.Thread(target=self._run, name="rpf-fly-watchdog", daemon=True)
        self._thread.start()

    def arm(self, armed: bool) -> None:
        """Watch only while drones depend on streamed setpoints."""
        self._last = self._clock()
        self._armed = armed

    def beat(self) -> None:
        self._last = self._clock()

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=1.0)

    def _run(self) -> None:
        while not self._stop.wait(self._timeout_s / 5):
            if self._armed and not self._fired and self._clock() - self._last > self._timeout_s:
                self._fired = True
                self._on_stall()
