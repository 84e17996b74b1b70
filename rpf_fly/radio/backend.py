"""The `DroneBackend` protocol: what the flight loop needs from the radio edge.

A backend flies a set of drones addressed by *name* (the mission's drone names). The flight loop calls it from its
own thread at a fixed rate; the backend reports per-drone problems in return values and in `DroneState`, and never
raises one drone's failure across the swarm.

Units everywhere: positions in metres in the world frame (right-handed, Z up), durations in seconds, battery in
volts, yaw in DEGREES for setpoints (as cflib's `send_position_setpoint`), for `go_to` and in
`DroneState.yaw_deg` (as the firmware logs `stateEstimate.yaw`) but in RADIANS for `reset_estimator` (as the
firmware's `kalman.initialYaw`), link latency in milliseconds, link quality in percent (0-100, the share of radio
packets acknowledged without retries, as cflib computes it).

Implementations: `rpf_fly.radio.cflib_backend.CflibBackend` (cflib over `radio://` or the fake radio `fake://`).
"""

from __future__ import annotations

import enum
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

CONTROLLER_PARAMS = (
    "posCtlPid.xKp",
    "posCtlPid.xKi",
    "posCtlPid.xVelMax",
    "posCtlPid.pLimit",
    "velCtlPid.vxKp",
    "velCtlPid.vxKi",
)
"""The position controller's parameters a backend reads at connect (`DroneState.controller_params`): what the
ground station's model of the drone's response needs (rpf_fly/flight/response.py)."""

Vec3 = tuple[float, float, float]
"""x, y, z in metres."""

Quaternion = tuple[float, float, float, float]
"""qx, qy, qz, qw (unit quaternion, world from body)."""

LinkLostCallback = Callable[[str, str], None]
"""Called as ``callback(name, reason)`` once when a connected drone's link is lost."""


class PmState(enum.IntEnum):
    """Crazyflie power-management state, the firmware's `pm.state` log variable."""

    BATTERY = 0
    CHARGING = 1
    CHARGED = 2
    LOW_POWER = 3
    """Battery below `pm.lowVoltage` (3.2 V by default) for more than 5 s: land now."""
    SHUTDOWN = 4


class SupervisorBits(enum.IntFlag):
    """Bits of the firmware's `supervisor.info` bitfield (protocol 12)."""

    CAN_BE_ARMED = 0x0001
    ARMED = 0x0002
    AUTO_ARMED = 0x0004
    CAN_FLY = 0x0008
    FLYING = 0x0010
    TUMBLED = 0x0020
    LOCKED = 0x0040
    """Emergency stop or watchdog cut happened: the drone needs a reboot."""
    CRASHED = 0x0080
    HL_CONTROL_ACTIVE = 0x0100
    HL_TRAJ_FINISHED = 0x0200
    HL_CONTROL_DISABLED = 0x0400


@dataclass(frozen=True)
class SupervisorState:
    """Decoded `supervisor.info` bitfield."""

    bits: int

    def has(self, flag: SupervisorBits) -> bool:
        """True if `flag` is set."""
        return bool(self.bits & flag)

    @property
    def armed(self) -> bool:
        return self.has(SupervisorBits.ARMED)

    @property
    def can_be_armed(self) -> bool:
        return self.has(SupervisorBits.CAN_BE_ARMED)

    @property
    def can_fly(self) -> bool:
        return self.has(SupervisorBits.CAN_FLY)

    @property
    def flying(self) -> bool:
        return self.has(SupervisorBits.FLYING)

    @property
    def tumbled(self) -> bool:
        return self.has(SupervisorBits.TUMBLED)

    @property
    def locked(self) -> bool:
        return self.has(SupervisorBits.LOCKED)

    @property
    def crashed(self) -> bool:
        return self.has(SupervisorBits.CRASHED)


@dataclass(frozen=True)
class BatteryState:
    """Battery as the drone reports it."""

    voltage_v: float
    """`pm.vbat` in volts (under load while the motors run)."""
    pm_state: PmState

    @property
    def low(self) -> bool:
        """True when the firmware says the battery is low (or shutting down)."""
        return self.pm_state in (PmState.LOW_POWER, PmState.SHUTDOWN)


@dataclass(frozen=True)
class LinkState:
    """Radio link of one drone."""

    up: bool
    """True while the link is connected and configured."""
    quality_pct: float | None = None
    """Share of packets acknowledged without retries, 0-100 (cflib's link quality); None before the first report."""
    latency_ms: float | None = None
    """95th percentile of the echo round trip in milliseconds (cflib's latency); None before the first report."""

    @property
    def round_trip_s(self) -> float:
        """`latency_ms` in seconds; 0 before the first report."""
        return self.latency_ms / 1000.0 if self.latency_ms is not None else 0.0

    error: str | None = None
    """Why the link is down (connection failed or lost), None when up or closed on purpose."""
    lost_at_s: float | None = None
    """`time.monotonic()` when the link was lost, None if it was not."""


@dataclass(frozen=True)
class DroneState:
    """Everything the preflight check and the flight supervisor need about one drone."""

    name: str
    uri: str
    link: LinkState
    battery: BatteryState | None
    """None until the first status log packet."""
    supervisor: SupervisorState | None
    """None until the first status log packet."""
    position_m: Vec3 | None
    """Estimated position (`stateEstimate.x/y/z`) in metres; None until the first status log packet."""
    telemetry_stamp_s: float | None
    """`time.monotonic()` when the last status log packet arrived (10 Hz by default); None if none yet."""
    yaw_deg: float | None = None
    """Estimated yaw (`stateEstimate.yaw`) in DEGREES, as the firmware logs it; None until the first status log
    packet. Compare it with the mocap's yaw before take-off: position-only extpos never corrects it."""
    estimate_stamp_s: float | None = None
    """When the drone made the telemetry of `telemetry_stamp_s` (its log timestamp on the host's `time.monotonic()`
    clock: rpf_fly/radio/telemetry_clock.py); None where the backend cannot tell. Compare the estimate with the
    mocap pose of this time: a packet may wait in the radio for hundreds of milliseconds."""
    target_m: Vec3 | None = None
    """Where the drone's own controller is taking it (`ctrltargetZ.x/y/z`, metres) at `estimate_stamp_s`: the
    streamed setpoint, or the high-level commander's plan (a take-off or landing keeps the x, y where it began);
    None where the firmware does not log it. Garbage while the motors are off (the firmware's setpoint then holds
    nothing)."""
    controller_params: Mapping[str, float] | None = None
    """The position controller's gains and limits the drone flies with (firmware parameter names, e.g.
    ``posCtlPid.xKp``: `CONTROLLER_PARAMS`), read from its parameters at connect; None where the backend cannot
    read them (the flight then assumes the firmware's defaults: rpf_fly/flight/response.py)."""
    setpoints_superseded: int = 0
    """Setpoints of this drone replaced by a newer one before its radio link took them, since it connected: a link
    that lags its setpoint stream (rpf_fly/flight/radio_lag_check.py)."""
    setpoint_waiting_s: float = 0.0
    """How long a streamed setpoint of this drone has been waiting for its radio link, replaced by newer ones
    meanwhile (0: none waits): the drone has had none of them that long (rpf_fly/flight/radio_lag_check.py)."""
    extpos_sent_s: float | None = None
    """`time.monotonic()` when the ground station last handed a mocap position of this drone to its radio (its
    link's queue, or a packed broadcast that went out); None where the backend cannot tell or none went yet. A
    position queued but dropped as stale, or still waiting behind a full radio, has not fed the drone's estimator
    (rpf_fly/flight/estimate_check.py)."""


@runtime_checkable
class DroneBackend(Protocol):
    """Per-drone radio operations used by the flight loop.

    Commands return True when the command was accepted for a live link and False when the drone is unknown to the
    link (never connected, lost or closed); they do not wait for the drone, nor for the radio: a backend may queue
    them (`CflibBackend` sends each drone's commands from a thread of that drone's own, in order, newest setpoint
    only, so that one dying link holds back no other drone). The emergency stop is never queued. Swarm-wide operations
    return a mapping name -> error message holding only the drones that failed (empty when all succeeded).
    """

    def connect(self, drones: Mapping[str, str]) -> dict[str, str]:
        """Connect to `drones` (name -> URI) in parallel and configure them; blocks until every drone is connected or
        has failed. Returns name -> error for the drones that failed; the others are usable."""
        ...

    def close(self) -> None:
        """Close every link. Only on the ground: closing a cflib link sends a zero-thrust setpoint. First reboots
        every drone whose watchdog was armed (`arm_watchdog`) and that is neither flying nor locked."""
        ...

    def names(self) -> tuple[str, ...]:
        """Names given to `connect`, in order."""
        ...

    def state(self, name: str) -> DroneState:
        """Latest known state of one drone (raises KeyError for an unknown name)."""
        ...

    def states(self) -> dict[str, DroneState]:
        """`state` for every drone."""
        ...

    def add_link_lost_callback(self, callback: LinkLostCallback) -> None:
        """Register ``callback(name, reason)``, called once per drone whose link is lost after connecting.

        It runs on a radio thread: keep it short and thread-safe. `state(name).link` gives the same fact polled."""
        ...

    def arm(self, name: str, armed: bool = True) -> bool:
        """Send an arming (or disarming) request to the supervisor."""
        ...

    def arm_watchdog(self, name: str) -> bool:
        """Arm the drone's emergency-stop watchdog; call it when arming the drone for take-off. From then until
        `close` the backend sends the drone a keep-alive every 0.2 s from a thread of its own (not the caller's, so
        a flight loop busy for half a second does not trip it), and the firmware stops the drone (motors off,
        locked until reboot) 1 s after the last keep-alive arrived.

        Why: during a high-level take-off, hold or landing the firmware's high-level commander renews its own
        setpoint every 10 ms, so the commander's setpoint watchdog never trips; a drone whose ground station died
        (a killed process, an unplugged dongle, a dropped link) would fly its last plan on dead reckoning for
        minutes. With the watchdog armed it is stopped within about 1 s. The firmware never disarms it, so `close`
        reboots the drones it fed that are on the floor with motors off (neither flying nor locked), over their own
        links, and the next connection finds them ready. False when the link is down (nothing armed)."""
        ...

    def takeoff(self, name: str, height_m: float, duration_s: float) -> bool:
        """High-level take-off to the absolute height `height_m` in `duration_s`, keeping the current yaw."""
        ...

    def go_to(self, name: str, position: Vec3, yaw_deg: float, duration_s: float) -> bool:
        """High-level go-to an absolute position and yaw (degrees) in `duration_s`."""
        ...

    def send_position_setpoint(
        self, name: str, x: float, y: float, z: float, yaw_deg: float, origin_s: float | None = None
    ) -> bool:
        """Stream one low-level position setpoint (metres, yaw in degrees). Streaming takes priority over the
        high-level commander; the firmware levels out 0.5 s after the last one and cuts the motors after 2 s.
        ``origin_s``: the `time.monotonic()` of the data it was planned from (a mocap frame's receipt), for a
        backend that measures the latency to the radio (``take_setpoint_latencies``, optional)."""
        ...

    def hand_over(self, name: str, hold_duration_s: float = 1.0) -> bool:
        """Hand a streaming drone back to the high-level commander: notify-setpoint-stop, then a high-level go-to
        to the last streamed setpoint in `hold_duration_s`, so the drone holds position without a stream."""
        ...

    def land(self, name: str, height_m: float = 0.0, duration_s: float = 2.0) -> bool:
        """High-level landing to `height_m` in `duration_s` (hands a streaming drone over first); the motors stop at
        the end."""
        ...

    def stop(self, name: str) -> bool:
        """Stop the motors now (high-level stop, plus a stop setpoint when streaming). Use on the ground."""
        ...

    def emergency_stop(self, name: str | Iterable[str] | None = None, *, wait_s: float = 2.5) -> dict[str, str]:
        """Supervisor emergency stop of one drone, several, or (None) all of them: motors off, latched until
        reboot; nothing sent to them afterwards. Waits ``wait_s`` at most. Returns name -> error for the drones it
        could not reach, or whose stop was still being sent when the wait ended."""
        ...

    def send_extpos(self, name: str, position: Vec3, received_s: float | None = None) -> bool:
        """Forward a motion-capture position (metres) to the drone's estimator; ``received_s``: when its pose was
        received (`time.monotonic()`), so that one that waited too long in the ground station is not sent
        (rpf_fly/radio/outbox.py, `EXTPOS_MAX_WAIT_S`)."""
        ...

    def send_extpose(self, name: str, position: Vec3, quaternion: Quaternion, received_s: float | None = None) -> bool:
        """Forward a motion-capture pose (metres, unit quaternion qx, qy, qz, qw) to the drone's estimator
        (``received_s`` as for `send_extpos`)."""
        ...

    def reset_estimator(self, name: str, position: Vec3, yaw_rad: float) -> bool:
        """Restart the drone's estimate at `position` (metres) and yaw `yaw_rad` (RADIANS, as the firmware's
        `kalman.initialYaw`), typically its mocap pose before take-off: with position-only extpos the yaw estimate
        is otherwise wherever the estimator started. Blocks only for the parameter confirmations, not for the
        estimate to settle. False when the drone is unreachable or a write is not confirmed."""
        ...

    def battery(self, name: str) -> BatteryState | None:
        """Latest battery report, None before the first one."""
        ...

    def link(self, name: str) -> LinkState:
        """Link state of one drone."""
        ...
