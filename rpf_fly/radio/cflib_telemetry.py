"""What the cflib backend (rpf_fly/radio/cflib_backend.py) knows of each drone and hears from it: the bookkeeping of
one drone (`CflibDrone`), the status log block it asks for, and the callbacks cflib's threads call with the
drone's telemetry, link quality and radio traffic, read back as `DroneState`. Why apart: the receiving side runs
on cflib's threads and only records and reads back, under the backend's lock; the commands' side is the backend's
own module.

:class:`CflibTelemetry` is a part of :class:`~rpf_fly.radio.cflib_backend.CflibBackend`: it reads and sets the
backend's attributes named in its body.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass, field
from typing import Any

from cflib.crazyflie.log import LogConfig
from cflib.crazyflie.syncCrazyflie import SyncCrazyflie

from rpf_fly.radio.outbox import Outbox
from rpf_fly.radio.schedule import LinkCount
from rpf_fly.radio.telemetry_clock import TelemetryClock

from .backend import (
    BatteryState,
    DroneState,
    LinkLostCallback,
    LinkState,
    PmState,
    SupervisorState,
    Vec3,
)

logger = logging.getLogger("rpf_fly.radio.cflib_backend")  # the backend's records keep their logger's name

STATUS_VARIABLES: tuple[tuple[str, str], ...] = (
    ("pm.vbat", "float"),
    ("pm.state", "int8_t"),
    ("supervisor.info", "uint16_t"),
    ("stateEstimateZ.x", "int16_t"),
    ("stateEstimateZ.y", "int16_t"),
    ("stateEstimateZ.z", "int16_t"),
    ("stateEstimate.yaw", "float"),
    ("ctrltargetZ.x", "int16_t"),
    ("ctrltargetZ.y", "int16_t"),
    ("ctrltargetZ.z", "int16_t"),
)
"""The status log block (23 bytes; one log packet carries 26 bytes of values). The estimate and the controller's
target in the firmware's compressed groups (millimetres as int16, stabilizer.c): the target is where the drone's own
controller is taking it, which the supervisor needs while the high-level commander flies a take-off or a landing
(docs/flight.md, "Tracking"), and the float groups would not fit both in one packet."""
STATUS_VARIABLES_FLOAT: tuple[tuple[str, str], ...] = (
    ("pm.vbat", "float"),
    ("pm.state", "int8_t"),
    ("supervisor.info", "uint16_t"),
    ("stateEstimate.x", "float"),
    ("stateEstimate.y", "float"),
    ("stateEstimate.z", "float"),
    ("stateEstimate.yaw", "float"),
)
"""The status block of a firmware without the compressed groups (none since 2021 lacks them): no target."""
MM = 0.001
"""Metres per unit of the compressed log groups."""


def status_variables(log_toc: Any) -> tuple[tuple[str, str], ...]:
    """The status block a drone's log TOC (cflib's `Toc`) can give: `STATUS_VARIABLES` when it has every one of
    them, else `STATUS_VARIABLES_FLOAT`."""
    if all(log_toc.get_element_by_complete_name(name) is not None for name, _ in STATUS_VARIABLES):
        return STATUS_VARIABLES
    return STATUS_VARIABLES_FLOAT


@dataclass
class CflibDrone:
    """Bookkeeping of one drone (guarded by the backend lock)."""

    name: str
    uri: str
    link_uri: str = ""
    """What cflib opens: `uri` with the budget's ``?rate_limit=N`` for a ``radio://`` link (`budget.link_uri`)."""
    scf: SyncCrazyflie | None = None
    up: bool = False
    configured: bool = False
    """Connected and configured once (a later loss is reported to the link-lost callbacks)."""
    closing: bool = False
    lost_reported: bool = False
    error: str | None = None
    lost_at_s: float | None = None
    quality_pct: float | None = None
    latency_ms: float | None = None
    vbat_v: float | None = None
    pm_state: int | None = None
    sup_bits: int | None = None
    position: Vec3 | None = None
    target: Vec3 | None = None
    yaw_deg: float | None = None
    stamp_s: float | None = None
    measured_s: float | None = None
    """When the last status packet's values were true (its firmware timestamp mapped by `clock`)."""
    controller_params: dict[str, float] | None = None
    """`CONTROLLER_PARAMS` as the drone's parameters held them at connect."""
    clock: TelemetryClock = field(default_factory=TelemetryClock)
    watchdog: bool = False
    """`arm_watchdog` was called: the backend feeds the drone's emergency-stop watchdog until `close`."""
    rebooted: bool = False
    """`close` sent it the reboot commands."""
    streaming: bool = False
    last_setpoint: tuple[float, float, float, float] | None = None
    """x, y, z (m), yaw (deg) of the last streamed setpoint."""
    first_status: threading.Event = field(default_factory=threading.Event)
    command_lock: threading.Lock = field(default_factory=threading.Lock)
    """Serialises this drone's commands and guards `streaming` and `last_setpoint`."""
    outbox: Outbox | None = None
    """The drone's queued commands (sent by the backend's `SenderPool`), from the end of its configuration."""
    log_config: LogConfig | None = None
    radio_transactions: float = 0.0
    """Acknowledged transactions since the first window of cflib's link statistics (empty polls included)."""
    radio_packets: float = 0.0
    """... of them with an uplink packet."""
    radio_window_at: float | None = None
    """`time.monotonic()` when the last window of cflib's ``uplink_rate`` closed."""
    radio_pending: float | None = None
    """Transactions of the window just reported by ``uplink_rate``, waiting for its ``uplink_congestion``."""


class CflibTelemetry:
    """cflib's callbacks (cflib's threads) and the drones' state read from them."""

    _lock: threading.RLock
    _drones: dict[str, CflibDrone]
    _callbacks: list[LinkLostCallback]

    def _on_status(self, name: str, timestamp: int, data: dict[str, float], _config: LogConfig) -> None:
        drone = self._drones[name]
        arrived = time.monotonic()
        with self._lock:
            drone.vbat_v = float(data["pm.vbat"])
            drone.pm_state = int(data["pm.state"])
            drone.sup_bits = int(data["supervisor.info"])
            if "stateEstimateZ.x" in data:
                drone.position = (
                    data["stateEstimateZ.x"] * MM,
                    data["stateEstimateZ.y"] * MM,
                    data["stateEstimateZ.z"] * MM,
                )
                drone.target = (data["ctrltargetZ.x"] * MM, data["ctrltargetZ.y"] * MM, data["ctrltargetZ.z"] * MM)
            else:
                drone.position = (
                    float(data["stateEstimate.x"]),
                    float(data["stateEstimate.y"]),
                    float(data["stateEstimate.z"]),
                )
            drone.yaw_deg = float(data["stateEstimate.yaw"])
            drone.stamp_s = arrived
            drone.measured_s = drone.clock.measured_at(int(timestamp), arrived)
        drone.first_status.set()

    def _on_quality(self, name: str, quality: float) -> None:
        with self._lock:
            self._drones[name].quality_pct = float(quality)

    def _on_latency(self, name: str, latency_ms: float) -> None:
        with self._lock:
            self._drones[name].latency_ms = float(latency_ms)

    def _on_connection_lost(self, name: str, uri: str, message: str) -> None:
        drone = self._drones[name]
        full, message = message, " ".join((message.strip().splitlines() or ["no reason given"])[0].split())
        with self._lock:
            report = drone.configured and not drone.closing and not drone.lost_reported
            drone.lost_reported = drone.lost_reported or report
            drone.up = False
            drone.error = f"connection lost: {message}"  # one line: cflib appends a traceback to its reason
            drone.lost_at_s = time.monotonic()
            callbacks = list(self._callbacks) if report else []
        logger.warning("drone %s (%s): link lost: %s", name, uri, full)  # the whole of it, for the text log
        for callback in callbacks:
            try:
                callback(name, message)
            except Exception:  # a user callback must not break cflib's thread
                logger.exception("link-lost callback failed for %s", name)

    def _on_disconnected(self, name: str, uri: str) -> None:
        with self._lock:
            self._drones[name].up = False

    def add_link_lost_callback(self, callback: LinkLostCallback) -> None:
        with self._lock:
            self._callbacks.append(callback)

    def _on_uplink_rate(self, name: str, rate: float) -> None:
        """cflib's link statistics close a window (at least 0.1 s) with its transactions a second; the window's
        share of them carrying a packet follows at once (``uplink_congestion``, same call). The first window seen
        started before the callback was registered and is not counted."""
        now = time.monotonic()
        with self._lock:
            drone = self._drones.get(name)
            if drone is None:
                return
            drone.radio_pending = rate * (now - drone.radio_window_at) if drone.radio_window_at is not None else None
            drone.radio_window_at = now

    def _on_uplink_congestion(self, name: str, congestion: float) -> None:
        with self._lock:
            drone = self._drones.get(name)
            if drone is None or drone.radio_pending is None:
                return
            drone.radio_transactions += drone.radio_pending
            drone.radio_packets += drone.radio_pending * congestion
            drone.radio_pending = None

    def radio_counts(self) -> dict[str, LinkCount]:
        """Each connected drone's radio traffic so far, as cflib's link statistics measured it (acknowledged
        transactions, and those with an uplink packet), and the setpoints its outbox superseded before the radio
        took them, by name; kept after `close` (the last window, under 0.1 s, is never reported by cflib)."""
        with self._lock:
            return {
                d.name: LinkCount(
                    d.uri,
                    d.radio_transactions,
                    d.radio_packets,
                    float(d.outbox.setpoints_replaced) if d.outbox is not None else 0.0,
                )
                for d in self._drones.values()
                if d.radio_window_at is not None
            }

    # State ----------------------------------------------------------------------------------------------------

    def names(self) -> tuple[str, ...]:
        return tuple(self._drones)

    def state(self, name: str) -> DroneState:
        with self._lock:
            d = self._drones[name]
            battery = None
            if d.vbat_v is not None and d.pm_state is not None:
                try:
                    pm = PmState(d.pm_state)
                except ValueError:
                    pm = PmState.BATTERY
                battery = BatteryState(d.vbat_v, pm)
            return DroneState(
                name=d.name,
                uri=d.uri,
                link=LinkState(d.up, d.quality_pct, d.latency_ms, d.error, d.lost_at_s),
                battery=battery,
                supervisor=SupervisorState(d.sup_bits) if d.sup_bits is not None else None,
                position_m=d.position,
                telemetry_stamp_s=d.stamp_s,
                yaw_deg=d.yaw_deg,
                estimate_stamp_s=d.measured_s,
                target_m=d.target,
                controller_params=d.controller_params,
                setpoints_superseded=d.outbox.setpoints_replaced if d.outbox is not None else 0,
                extpos_sent_s=self._extpos_sent_s(d),
                setpoint_waiting_s=d.outbox.setpoint_waiting_s() if d.outbox is not None else 0.0,
            )

    def _extpos_sent_s(self, d: CflibDrone) -> float | None:
        """When this drone's last mocap position went to its radio (`DroneState.extpos_sent_s`): its outbox's."""
        return d.outbox.extpos_taken_s if d.outbox is not None else None

    def states(self) -> dict[str, DroneState]:
        return {name: self.state(name) for name in self._drones}

    def battery(self, name: str) -> BatteryState | None:
        return self.state(name).battery

    def link(self, name: str) -> LinkState:
        return self.state(name).link
