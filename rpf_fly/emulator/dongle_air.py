"""The emulated Crazyradio's timing (:class:`RadioTiming`) and the air its links share (:class:`DongleAir`): what
a fake link (rpf_fly/emulator/fake_radio.py) and the emulated dongle (rpf_fly/emulator/crazyradio.py) take turns
on, as cflib's radio driver serialises the links of one dongle.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass


@dataclass(frozen=True)
class RadioTiming:
    """Timing of the emulated Crazyradio."""

    idle_poll_s: float = 0.01
    """Interval of empty polls when nothing is to be sent (cflib's radio thread relaxes to 10 ms)."""
    failed_attempt_s: float = 0.001
    """Time a lost ack costs before the next attempt."""
    max_lost_acks: int = 100
    """Lost acks in a row before the link error (cflib's radio driver: 100)."""
    arc_retries: int = 3
    """Automatic retransmissions within one transaction (cflib sets 3)."""
    transaction_s: float = 0.0
    """Air time each transaction holds its dongle (all links on one dongle number share it); 0 = unlimited. Only the
    air time: the drone's answer (in a dry run a UDP round trip to the world process and the firmware's Python) is
    computed outside it, as a real Crazyflie's ack payload is ready before the packet arrives (`DongleAir`)."""


class DongleAir:
    """The air of one emulated Crazyradio: every link on its dongle number takes turns, each transaction holding it
    for its air time (`RadioTiming.transaction_s`) and nothing else.

    Why: cflib's radio driver serialises the links of one dongle (one ``_SharedRadio`` thread per dongle, a FIFO
    command queue), and the dongle is busy for the packet's air time and its ack, about 1 ms a transaction with a
    Crazyradio PA (docs/radio.md, "Radio budget"). An emulated transaction also has to reach the simulated drone
    (in a dry run a UDP round trip to the world process, 0.1-0.5 ms, more on a loaded machine): held under the
    dongle's lock, that emulation cost was added to every transaction of every link on the dongle, so the fake
    dongle carried fewer transactions than a real one. Here a transaction reserves the next free slot of
    ``air_s`` (first come, first served, like cflib's queue) and waits for it; the drone's answer is computed
    after the slot has started and the ack is not handed back before the slot ends (:meth:`FakeLink._transact`).
    Thread-safe; times are ``time.monotonic()``."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._free_s = -math.inf
        self.transactions = 0
        """Slots reserved so far (each a transaction, acknowledged or not)."""
        self.busy_s = 0.0
        """Air time reserved so far."""

    def reserve(self, air_s: float, now_s: float) -> tuple[float, float]:
        """The next free slot of ``air_s`` at or after ``now_s``: (start, end)."""
        with self._lock:
            start = max(now_s, self._free_s)
            self._free_s = start + air_s
            self.transactions += 1
            self.busy_s += air_s
            return start, self._free_s
