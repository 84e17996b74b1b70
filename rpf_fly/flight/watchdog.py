"""The safety thread: the loop watchdog, and the hands that act when the loop cannot.

While drones stream setpoints, the Crazyflie firmware levels out 0.5 s after the last setpoint and cuts its motors
after 2 s (the drone falls). If the loop has not completed a planning tick for ``timeout_s``, this thread calls
``on_stall()`` (the flight lands every airborne drone through its commander, with the high-level commander, which
needs no further setpoints, and the landing stands when the loop recovers). It re-arms once the loop ticks again,
so a second stall is caught too.

The timeout follows the mission's planning period (:func:`stall_timeout_s`): three missed ticks, at least 0.35 s, at
most 0.4 s; a mission whose timeout would not act before the firmware's 0.5 s setpoint watchdog is rejected when it is
loaded (``flight.rate_hz``, docs/mission-format.md).

The same thread sends an emergency stop requested from a signal handler (:meth:`LoopWatchdog.emergency`): a
handler may only set flags, since radio I/O inside it could deadlock on cflib's send lock held by the very thread
it interrupted.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

from rpf_fly.mission.model import MIN_STALL_TIMEOUT_S, STALL_TICKS

__all__ = ["LoopWatchdog", "stall_timeout_s"]


def stall_timeout_s(period_s: float) -> float:
    """The loop watchdog's timeout for a planning period: ``STALL_TICKS`` missed ticks, at least 0.35 s."""
    return max(MIN_STALL_TIMEOUT_S, STALL_TICKS * period_s)


class LoopWatchdog:
    """Calls ``on_stall()`` when :meth:`beat` is not called for ``timeout_s`` while armed (once a stall; again after
    the loop ticked again), and ``on_emergency()`` when :meth:`emergency` is called."""

    def __init__(
        self,
        on_stall: Callable[[], None],
        timeout_s: float = 0.35,
        *,
        on_emergency: Callable[[], None] | None = None,
        clock: Callable[[], float] = time.monotonic,
    ):
        self._on_stall = on_stall
        self._on_emergency = on_emergency
        self._timeout_s = timeout_s
        self._clock = clock
        self._last = clock()
        self._armed = False
        self._fired = False
        self.stalls = 0
        """How many stalls it caught."""
        self._emergency = False
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    @property
    def timeout_s(self) -> float:
        return self._timeout_s

    @property
    def fired(self) -> bool:
        return self.stalls > 0

    def start(self) -> None:
        self._thread = threading.Thread(target=self._run, name="rpf-fly-safety", daemon=True)
        self._thread.start()

    def arm(self, armed: bool) -> None:
        """Watch only while drones depend on streamed setpoints."""
        self._last = self._clock()
        self._armed = armed

    def beat(self) -> None:
        self._last = self._clock()
        self._fired = False

    def emergency(self) -> None:
        """Ask the thread to run ``on_emergency`` now. Signal-safe: sets flags only."""
        self._emergency = True
        self._wake.set()

    def close(self) -> None:
        self._stop.set()
        self._wake.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)

    def _run(self) -> None:
        while not self._stop.is_set():
            self._wake.wait(self._timeout_s / 5)
            self._wake.clear()
            if self._emergency and self._on_emergency is not None:
                self._emergency = False
                self._on_emergency()
            if self._armed and not self._fired and self._clock() - self._last > self._timeout_s:
                self._fired = True
                self.stalls += 1
                self._on_stall()
