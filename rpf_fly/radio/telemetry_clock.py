"""When a drone's telemetry was true: the firmware's log timestamp mapped onto this computer's clock.

A Crazyflie stamps every log packet with its own clock (milliseconds since boot, 24 bits: cflib hands it to the log
callback), and the packet then waits in the drone's queue for the radio (the downlink rides on the acks of the
host's packets) and in cflib's threads: from a few milliseconds on a quiet radio to hundreds on a full one. A check
that compares the on-board estimate with mocap must compare it with where the drone was when the estimate was
made, not when it arrived; without the stamp a late estimate of a moving drone and a wrong one look alike.

The mapping is the smallest (arrival - firmware time) seen: the offset of the two clocks plus the least delay a
packet had, which on a radio that sometimes answers at once is a few milliseconds. It is allowed to grow by
`DRIFT_ALLOWANCE` (s/s: crystal drift between the two clocks, 100 ppm) so it follows a firmware clock that runs slow,
and restarts when the firmware's clock goes backwards (a reboot, or the 24-bit wrap after 4.66 hours) or a packet
claims to be older than `RESTART_S` (a reboot not seen as one). Pure arithmetic: the caller passes the arrival time.
"""

from __future__ import annotations

WRAP_S = (1 << 24) / 1000.0
"""The firmware's log timestamp wraps after 2^24 ms (4.66 hours)."""
DRIFT_ALLOWANCE = 1e-4
"""How fast the offset may grow (s per s): twice a cheap crystal's 50 ppm."""
RESTART_S = 5.0
"""A packet this much later than the mapping says starts a new mapping (no radio holds a packet that long and
keeps its link: cflib drops it after 100 missed acks)."""


class TelemetryClock:
    """Maps one drone's firmware timestamps onto the host's monotonic clock (module doc)."""

    def __init__(self) -> None:
        self._offset_s: float | None = None
        self._last_firmware_s = -1.0
        self._last_arrival_s = 0.0

    def measured_at(self, firmware_ms: int, arrival_s: float) -> float:
        """The host time (same clock as ``arrival_s``) at which a packet stamped ``firmware_ms`` was made."""
        firmware_s = firmware_ms / 1000.0
        offset = arrival_s - firmware_s
        if self._offset_s is None or firmware_s < self._last_firmware_s or offset - self._offset_s > RESTART_S:
            self._offset_s = offset
        else:
            grown = self._offset_s + DRIFT_ALLOWANCE * max(0.0, arrival_s - self._last_arrival_s)
            self._offset_s = min(grown, offset)
        self._last_firmware_s, self._last_arrival_s = firmware_s, arrival_s
        return firmware_s + self._offset_s
