"""`CflibBackend`: the `DroneBackend` on cflib's own API, for ``radio://`` drones and ``fake://`` ones alike.

What it does per drone (cflib 0.1.34, firmware protocol 12):
- connect: `Swarm` with `CachedCfFactory` builds the `SyncCrazyflie` objects (TOC cache in `cache_dir`); each link
  (a ``radio://`` one with the radio budget's ``?rate_limit=N``, rpf_fly/radio/budget.py) is opened on its own
  thread with a deadline (``cf.open_link`` and cflib's connected / fully-connected /
  connection-failed / connection-lost callbacks; not `SyncCrazyflie.open_link`, which waits forever when a link
  drops during the TOC download), so one drone's failure neither blocks nor fails the others;
- configure: first notify-setpoint-stop (below, "Latched priority"), then `stabilizer.estimator` = 2 (Kalman),
  `commander.enHighLevel` = 1 (when the firmware still has it), `locSrv.extQuatStdDev` when streaming poses,
  `locSrv.extPosStdDev` if given; each write is confirmed by the firmware's echo;
- telemetry: one `LogConfig` at 10 Hz with `pm.vbat`, `pm.state`, `supervisor.info`, `stateEstimateZ.x/y/z` (mm),
  `stateEstimate.yaw` (degrees) and the controller's target `ctrltargetZ.x/y/z` (mm); link quality and latency from
  `cf.link_statistics`;
- estimator: `reset_estimator` sets `kalman.initialX/Y/Z/Yaw` (from mocap) and triggers `kalman.resetEstimation`
  without waiting for the variance; `reset_estimators` resets and waits until the variance settles;
- commands: supervisor arming, high-level take-off / go-to / land / stop, streamed position setpoints (yaw in
  degrees) with `send_notify_setpoint_stop` at every hand-over back to the high-level commander, extpos / extpose
  (or packed extpos broadcasts, rpf_fly/radio/broadcast.py),
  supervisor emergency stop (cflib falls back to the localization emergency stop for firmware older than protocol
  12);
- watchdog: `arm_watchdog` feeds the supervisor's emergency-stop watchdog until `close`, which then reboots the
  drones it fed that are down (below, "Emergency-stop watchdog");
- link loss: cflib's connection-lost callback marks the drone down, records why and when, and calls the
  registered link-lost callbacks.

Thread model: after `connect` returns, every public method may be called from any thread. One lock guards the
backend's bookkeeping (telemetry, link state). Every command but the emergency stop and the estimator's parameter
writes is queued in the drone's `Outbox` (rpf_fly/radio/outbox.py) and handed to cflib by the backend's
`SenderPool` (one thread sends every drone's in turn; one stuck in a dying link keeps that drone, and another takes
over the others): the command methods return at once, and a dying link (cflib's radio driver blocks its caller up
to 2 s when its queue is full) holds back only its own drone's commands, never the caller nor the other drones. The
outbox keeps high-level commands in order, sends the newest setpoint and extpos only, and drops a waiting setpoint
when a command that ends the stream (take-off, go-to, hand-over, land, stop) is queued after it, so no setpoint
queued before a landing reaches the drone after it. `wait_sent` waits until the queued commands went out. Packets go
through `Crazyflie.send_packet`, which holds cflib's own send lock. `emergency_stop` drops the drones' pending
commands, refuses any after it, and sends at once from a thread per drone (not through the pool), waiting a bounded
time, so a blocked link delays no other drone's stop nor its caller. The keep-alives of `arm_watchdog` are queued by a
thread of the backend's own (started by the first call, ended by `close`), never by the caller's. Telemetry and
link callbacks run on cflib's threads (the link's receive thread, the radio thread on link loss). `connect`,
`reset_estimators` and `close` block and must not run concurrently with each other. Link-lost callbacks must be
short and must not call `close`.

Hand-over rule (crazyflie-firmware `commander.c`, `crtp_commander_high_level.c`): a streamed setpoint stops the
high-level plan; notify-setpoint-stop relaxes the commander's priority, and at its next tick (100 Hz) the
high-level commander takes over and, with no plan, asks for motors off. A high-level command sent while the stream
still holds the priority is planned at once (from the state the planner tracks every tick) but its setpoints are
ignored until the priority is relaxed; until then the last streamed setpoint holds the drone. So every high-level
command sent while streaming goes first and notify-setpoint-stop right after it (`hand_over`, `go_to`, `land`,
`takeoff` do both): two radio transactions about 1 ms apart, and a firmware tick between them finds the drone
holding its last setpoint, never motors off. The reverse order (notify first) cuts the motors for the tick that
falls between the two packets, and for as long as the command packet is retried or lost.

Latched priority (crazyflie-firmware `commander.c`): a low-level setpoint takes the commander at CRTP priority, and
only notify-setpoint-stop lowers it again; the high-level commander runs below it, so until then every high-level
command is planned but never flown. cflib's `close_link` sends a zero-thrust setpoint, so any earlier connection in
the same power cycle (`rpf-fly check`, an earlier flight, cfclient) leaves the drone latched: a take-off is silently
refused until power-cycle. Each drone therefore gets notify-setpoint-stop right after it connects, before any other
command (on a drone with nothing latched it does nothing: the idle high-level commander keeps the motors off).

Emergency-stop watchdog (crazyflie-firmware `supervisor.c`, `crtp_supervisor.c`): while the high-level commander
flies a take-off, a hold or a landing it re-stamps its setpoint every 10 ms, so the commander's setpoint watchdog
never trips, and a drone whose ground station died (a killed process, an unplugged dongle, a dropped link) would fly
its plan on dead reckoning for minutes. The supervisor's emergency-stop watchdog is the firmware's answer: once the
first keep-alive arrived, 1 s without one is an emergency stop (motors off, free fall, locked until reboot).
`arm_watchdog` (the flight calls it when it arms a drone for take-off) starts feeding it: a backend-owned thread
queues a keep-alive every `KEEPALIVE_PERIOD_S` into the drone's outbox (first in its turn, never stacked behind a
stuck link), so a flight loop busy for half a second does not trip it, while a dead process, dongle or link stops
the drone within about 1 s. The firmware never disarms that watchdog: a drone fed once ends locked 1 s after the
feeding stops, even on the floor. So `close` reboots every fed drone that its telemetry says is neither flying nor
locked (`_reboot_if_down`), over its own link, before closing it: a flight leaves its drones rebooted and ready.

Safety: `close` must only be called on the ground: cflib's `close_link` sends a zero-thrust setpoint, which cuts the
motors of a flying drone.

Parts: connecting, configuring and the estimator resets are `CflibConnection` (rpf_fly/radio/cflib_connect.py); each
drone's bookkeeping (`CflibDrone`), the status log block, cflib's callbacks and the state read from them are
`CflibTelemetry` (rpf_fly/radio/cflib_telemetry.py); this module keeps the commands, the watchdog's feeder and
`close`.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable, Iterable, Mapping
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from cflib.crazyflie.swarm import Swarm
from cflib.crtp.crtpstack import CRTPPacket

from rpf_fly.radio.broadcast import PackedExtposSender
from rpf_fly.radio.cflib_connect import CflibConnection
from rpf_fly.radio.cflib_telemetry import CflibDrone, CflibTelemetry
from rpf_fly.radio.outbox import Action, SenderPool
from rpf_fly.radio.packed_extpos import PACKED_EXT_POS_STD_DEV_M

from .backend import (
    LinkLostCallback,
    Quaternion,
    SupervisorState,
    Vec3,
)

if TYPE_CHECKING:
    from rpf_fly.mission.model import Mission


class _Command(Protocol):
    """One drone's command as the backend queues it: run on a sender thread with the drone's cflib Crazyflie."""

    def __call__(self, cf: Any, drone: CflibDrone) -> None: ...


logger = logging.getLogger(__name__)

KEEPALIVE_PERIOD_S = 0.2
"""How often each armed drone's emergency-stop watchdog is fed (the firmware stops the drone after 1 s without:
supervisor.c DEFAULT_EMERGENCY_STOP_WATCHDOG_TIMEOUT), so four in a row may be lost or late before it trips."""
REBOOT_STATUS_WAIT_S = 0.5
"""`close` decides whether to reboot a drone on a status packet that arrived after its last command went out;
this long at most (five status periods at 10 Hz), else it is not rebooted."""
BOOTLOADER_HEADER = 0xFF
"""CRTP port 15 (link), channel 3: the nRF51's bootloader commands (cflib/utils/power_switch.py)."""
NRF_TARGET = 0xFE
"""First payload byte of a command the nRF51 takes for itself (not forwarded to the STM32)."""
BOOTLOADER_CMD_RESET_INIT = 0xFF
BOOTLOADER_CMD_RESET = 0xF0
RESET_TO_FIRMWARE = 1


class CflibBackend(CflibConnection, CflibTelemetry):
    """`DroneBackend` implementation on cflib. See the module docstring for behaviour and thread model."""

    CONNECT_TIMEOUT_S = 10.0
    """One drone's connection and configuration, on a dongle of its own (`budget.connect_timeouts` for shared)."""

    def __init__(
        self,
        *,
        cache_dir: str | Path | None = None,
        use_extpose: bool = False,
        ext_quat_std_dev: float = 8.0e-3,
        ext_pos_std_dev: float | None = None,
        reset_estimators: bool = False,
        status_period_ms: int = 100,
        connect_timeout_s: float = CONNECT_TIMEOUT_S,
        param_timeout_s: float = 2.0,
        init_drivers: bool = True,
        packed_extpos: bool = False,
        rate_limits: Mapping[str, int] | None = None,
        connect_timeouts: Mapping[str, float] | None = None,
    ) -> None:
        """
        Args:
            cache_dir: directory of cflib's TOC cache (created if missing); None disables the cache.
            use_extpose: the mocap sends poses (`send_extpose`): sets `locSrv.extQuatStdDev` at connect.
            ext_quat_std_dev: orientation standard deviation (rad-ish, quaternion units) for extpose.
            ext_pos_std_dev: position standard deviation (m) to set, None keeps the firmware's (0.01 m).
            reset_estimators: reset the Kalman estimators at the end of `connect` and wait until they settle.
            status_period_ms: period of the status log block (10 Hz by default).
            connect_timeout_s: deadline for one drone's connection (link, TOCs, parameter values, first status).
            param_timeout_s: deadline for one parameter write to be echoed.
            init_drivers: call `cflib.crtp.init_drivers()` when the radio drivers are not registered yet.
            packed_extpos: `send_extpos` broadcasts the positions packed, up to four drones a packet
                (rpf_fly/radio/broadcast.py) instead of one unicast packet a drone.
            rate_limits: drone name -> the ``rate_limit`` its ``radio://`` link is opened with (cflib's
                ``?rate_limit=N``: at most N transactions a second, polls included; rpf_fly/radio/budget.py).
            connect_timeouts: drone name -> its own ``connect_timeout_s`` (a drone sharing a busy dongle waits for
                the others' connections too: `budget.connect_timeouts`).
        """
        self._cache_dir = str(cache_dir) if cache_dir is not None else None
        self._use_extpose = use_extpose
        self._ext_quat_std_dev = ext_quat_std_dev
        self._ext_pos_std_dev = ext_pos_std_dev
        self._reset_on_connect = reset_estimators
        self._status_period_ms = status_period_ms
        self._connect_timeout_s = connect_timeout_s
        self._param_timeout_s = param_timeout_s
        self._init_drivers = init_drivers
        self._packed_extpos = packed_extpos
        self._rate_limits = dict(rate_limits or {})
        self._connect_timeouts = dict(connect_timeouts or {})
        self._packed: PackedExtposSender | None = None
        self._lock = threading.RLock()
        self._drones: dict[str, CflibDrone] = {}
        self._callbacks: list[LinkLostCallback] = []
        self._swarm: Swarm | None = None
        self._pool = SenderPool()
        """The threads that send every drone's queued commands (rpf_fly/radio/outbox.py)."""
        self._latencies: list[float] = []
        """Seconds from a setpoint's ``origin_s`` to its hand-over to cflib, not yet taken."""
        self._feeder: threading.Thread | None = None
        """Feeds the armed drones' emergency-stop watchdogs (`arm_watchdog`), started by the first of them."""
        self._feeder_stop = threading.Event()

    @classmethod
    def for_mission(cls, mission: Mission, cache_dir: str | Path | None) -> CflibBackend:
        """The backend a flight or a check of ``mission`` uses: ``use_extpose`` when its mocap poses go to the
        drones whole (``radio.extpos: extpose``), so the estimator gets `locSrv.extQuatStdDev`; packed extpos
        (``radio.extpos: packed``) with `PACKED_EXT_POS_STD_DEV_M` as ``locSrv.extPosStdDev`` (each drone hears
        every broadcast four times); every ``radio://`` link's ``rate_limit`` from the budget. Every flight path
        (the CLI's check and flight, a distributed worker) builds its backend here, so none forgets it."""
        from rpf_fly.radio.budget import connect_timeouts, link_rate_limits

        packed = mission.radio.extpos == "packed"
        return cls(
            cache_dir=cache_dir,
            use_extpose=mission.radio.extpos == "extpose",
            packed_extpos=packed,
            ext_pos_std_dev=PACKED_EXT_POS_STD_DEV_M if packed else None,
            rate_limits=link_rate_limits(mission),
            connect_timeouts=connect_timeouts(mission, cls.CONNECT_TIMEOUT_S),
        )

    def close(self) -> None:
        """Close every link (on the ground only: cflib sends a zero-thrust setpoint when closing). A drone whose
        emergency-stop watchdog was armed (`arm_watchdog`) and whose telemetry then says neither flying nor locked
        is rebooted first (`_reboot_if_down`), so the next connection finds it ready, not locked by the watchdog
        that nobody feeds any more."""
        with self._lock:
            drones = list(self._drones.values())
            for drone in drones:
                drone.closing = True

        def close_one(drone: CflibDrone) -> None:
            flushed = True
            if drone.outbox is not None:  # what was queued (a disarm after touchdown) goes out first
                flushed = drone.outbox.close(flush_s=1.0)
            if drone.watchdog:
                if flushed:
                    self._reboot_if_down(drone)
                else:
                    logger.warning("drone %s: its link is stuck: not rebooted (its watchdog stops it)", drone.name)
            # also for lost links: cflib keeps their receive thread until close_link (which sends nothing then)
            if drone.scf is not None:
                drone.scf.cf.close_link()

        if self._packed is not None:
            self._packed.close()
        self._parallel(close_one, drones, 5.0)
        self._stop_feeder()
        self._pool.close()
        with self._lock:
            for drone in drones:
                drone.up = False

    def _reboot_if_down(self, drone: CflibDrone) -> None:
        """`close`, for a drone whose watchdog was armed, once its outbox is flushed: feed the watchdog directly
        (the outbox is closed) until a status packet newer than the last command arrives, then reboot the drone over
        its own link when that status says neither flying (the supervisor's flag: thrust above idle within 2 s)
        nor locked. A flying drone is left to its watchdog; a locked one (an emergency stop, a crash) stays locked
        for a person to look at. A reboot is the nRF51's reset to firmware (cflib's `PowerSwitch.reboot_to_fw`,
        sent on this link): the drone is silent for 1-2 s, then boots fresh on the floor."""
        cf = self._live_cf(drone.name)
        if cf is None:
            return
        asked = time.monotonic()
        fed_at = -math.inf
        while True:
            now = time.monotonic()
            with self._lock:
                fresh = drone.stamp_s is not None and drone.stamp_s > asked
                bits = drone.sup_bits
            if fresh:
                break
            if now - asked > REBOOT_STATUS_WAIT_S:
                logger.warning(
                    "drone %s: no status since its last command: not rebooted (its watchdog stops it)", drone.name
                )
                return
            if now - fed_at >= KEEPALIVE_PERIOD_S:
                fed_at = now
                with drone.command_lock:
                    cf.supervisor.send_emergency_stop_watchdog()
            time.sleep(0.01)
        supervisor = SupervisorState(bits or 0)
        if supervisor.flying or supervisor.locked:
            logger.warning(
                "drone %s: %s at the end: not rebooted",
                drone.name,
                "locked" if supervisor.locked else "still flying (its watchdog stops it)",
            )
            return
        with drone.command_lock:
            cf.send_packet(CRTPPacket(BOOTLOADER_HEADER, [NRF_TARGET, BOOTLOADER_CMD_RESET_INIT]))
            cf.send_packet(CRTPPacket(BOOTLOADER_HEADER, [NRF_TARGET, BOOTLOADER_CMD_RESET, RESET_TO_FIRMWARE]))
        with self._lock:
            drone.rebooted = True
        logger.info("drone %s: rebooted at the end (its emergency-stop watchdog was armed)", drone.name)

    def rebooted(self) -> tuple[str, ...]:
        """The drones `close` rebooted (module docstring, "Emergency-stop watchdog")."""
        with self._lock:
            return tuple(d.name for d in self._drones.values() if d.rebooted)

    def __enter__(self) -> CflibBackend:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # Commands -------------------------------------------------------------------------------------------------

    def _live_cf(self, name: str) -> Any | None:
        """The drone's Crazyflie if its link is up, else None (KeyError for an unknown name)."""
        with self._lock:
            drone = self._drones[name]
            if not drone.up or drone.scf is None or drone.scf.cf.link is None:
                return None
            return drone.scf.cf

    def _queue(self, name: str, action: _Command, kind: str, received_s: float | None = None) -> bool:
        """Queue one command in the drone's outbox (``kind``: ``setpoint``, ``extpos``, ``keepalive``, ``command``
        or ``ends_stream``; an extpos with its pose's ``received_s``: `Outbox.extpos`); False when its link is not
        up (KeyError for an unknown name)."""
        drone = self._drones[name]
        outbox = drone.outbox
        if outbox is None or self._live_cf(name) is None:
            return False
        bound: Action = partial(action, drone=drone)
        if kind == "setpoint":
            return outbox.setpoint(bound)
        if kind == "extpos":
            return outbox.extpos(bound, received_s)
        if kind == "keepalive":
            return outbox.keepalive(bound)
        return outbox.command(bound, ends_stream=kind == "ends_stream")

    def _send(self, drone: CflibDrone, action: Callable[..., None]) -> None:
        """A pool thread: hand one queued command to cflib (dropped when the link went down since). ``action``: a
        `_Command` bound to its drone, given the Crazyflie as ``cf``."""
        cf = self._live_cf(drone.name)
        if cf is None:
            return
        try:
            with drone.command_lock:
                action(cf=cf)
        except Exception:  # one drone's failure must not propagate
            logger.exception("drone %s: command failed", drone.name)

    def wait_sent(self, names: list[str] | None = None, timeout_s: float = 1.0) -> bool:
        """Wait until every command queued so far to ``names`` (default: all) went out to cflib or was dropped;
        False on timeout. Commands return once queued; tests and scripts that need the packet sent call this."""
        with self._lock:
            boxes = [
                d.outbox for n, d in self._drones.items() if d.outbox is not None and (names is None or n in names)
            ]
        return self._pool.wait_idle(boxes, timeout_s)

    def take_setpoint_latencies(self) -> list[float]:
        """Seconds from each setpoint's ``origin_s`` to the moment cflib had taken it, since the last call."""
        with self._lock:
            taken, self._latencies = self._latencies, []
        return taken

    @staticmethod
    def _release_stream(cf: Any, drone: CflibDrone) -> None:
        """Hand the priority back to the high-level commander; call it right after the high-level command."""
        if drone.streaming:
            cf.commander.send_notify_setpoint_stop()
            drone.streaming = False

    def arm(self, name: str, armed: bool = True) -> bool:
        return self._queue(name, lambda cf, drone: cf.supervisor.send_arming_request(armed), "command")

    def arm_watchdog(self, name: str) -> bool:
        """Arm the drone's emergency-stop watchdog: from now until `close` the backend's feeder thread queues a
        keep-alive (`Supervisor.send_emergency_stop_watchdog`) every `KEEPALIVE_PERIOD_S`, the first at once;
        after its first keep-alive the firmware stops the drone (motors off, locked) 1 s after the last one
        arrived. False when the link is down (nothing armed); KeyError for an unknown name. See the module
        docstring, "Emergency-stop watchdog"."""
        drone = self._drones[name]
        if not self._queue(name, self._keepalive, "keepalive") and self._live_cf(name) is None:
            return False
        with self._lock:
            drone.watchdog = True
            if self._feeder is None:
                self._feeder = threading.Thread(target=self._feed, name="rpf-keepalive", daemon=True)
                self._feeder.start()
        return True

    @staticmethod
    def _keepalive(cf: Any, drone: CflibDrone) -> None:
        cf.supervisor.send_emergency_stop_watchdog()

    def _feed(self) -> None:
        """The feeder thread: every `KEEPALIVE_PERIOD_S` (on a fixed cadence; a tick missed by a stalled thread is
        skipped, never made up in a burst) one keep-alive into each armed drone's outbox, skipped there while the
        previous one still waits."""
        next_at = time.monotonic() + KEEPALIVE_PERIOD_S
        while not self._feeder_stop.wait(max(next_at - time.monotonic(), 0.0)):
            with self._lock:
                names = [d.name for d in self._drones.values() if d.watchdog and not d.closing]
            for name in names:
                self._queue(name, self._keepalive, "keepalive")
            next_at += KEEPALIVE_PERIOD_S
            now = time.monotonic()
            if next_at < now:
                next_at = now + KEEPALIVE_PERIOD_S

    def _stop_feeder(self) -> None:
        """End the feeder thread (`close`; a test that plays a dead ground station calls it alone)."""
        self._feeder_stop.set()
        feeder = self._feeder
        if feeder is not None and feeder is not threading.current_thread():
            feeder.join(1.0)

    def takeoff(self, name: str, height_m: float, duration_s: float) -> bool:
        def action(cf: Any, drone: CflibDrone) -> None:
            cf.high_level_commander.takeoff(height_m, duration_s, yaw=None)
            if drone.streaming:
                self._release_stream(cf, drone)
            else:  # a drone on the floor: a priority latched since the connection (another program) released too
                cf.commander.send_notify_setpoint_stop()

        return self._queue(name, action, "ends_stream")

    def go_to(self, name: str, position: Vec3, yaw_deg: float, duration_s: float) -> bool:
        def action(cf: Any, drone: CflibDrone) -> None:
            x, y, z = position
            cf.high_level_commander.go_to(x, y, z, math.radians(yaw_deg), duration_s)
            self._release_stream(cf, drone)

        return self._queue(name, action, "ends_stream")

    def send_position_setpoint(
        self, name: str, x: float, y: float, z: float, yaw_deg: float, origin_s: float | None = None
    ) -> bool:
        """Queue one streamed setpoint (latest wins). ``origin_s``: the `time.monotonic()` its data came from
        (the mocap frame's receipt); the time from it to cflib taking the packet is kept for
        `take_setpoint_latencies`."""

        def action(cf: Any, drone: CflibDrone) -> None:
            cf.commander.send_position_setpoint(x, y, z, yaw_deg)
            drone.streaming = True
            drone.last_setpoint = (x, y, z, yaw_deg)
            if origin_s is not None:
                latency = time.monotonic() - origin_s
                with self._lock:
                    self._latencies.append(latency)

        return self._queue(name, action, "setpoint")

    def hand_over(self, name: str, hold_duration_s: float = 1.0) -> bool:
        def action(cf: Any, drone: CflibDrone) -> None:
            if not drone.streaming or drone.last_setpoint is None:
                return
            x, y, z, yaw_deg = drone.last_setpoint
            cf.high_level_commander.go_to(x, y, z, math.radians(yaw_deg), hold_duration_s)
            self._release_stream(cf, drone)

        return self._queue(name, action, "ends_stream")

    def land(self, name: str, height_m: float = 0.0, duration_s: float = 2.0) -> bool:
        def action(cf: Any, drone: CflibDrone) -> None:
            cf.high_level_commander.land(height_m, duration_s, yaw=None)
            self._release_stream(cf, drone)

        return self._queue(name, action, "ends_stream")

    def stop(self, name: str) -> bool:
        def action(cf: Any, drone: CflibDrone) -> None:
            if drone.streaming:
                cf.commander.send_stop_setpoint()
            drone.streaming = False
            cf.high_level_commander.stop()

        return self._queue(name, action, "ends_stream")

    EMERGENCY_DEADLINE_S = 2.5
    """How long `emergency_stop` waits by default for each drone's packets: cflib's send blocks up to 2 s on a
    link whose queue is full (and a pool thread stuck there holds cflib's send lock); each drone's stop goes out
    from a thread of its own meanwhile."""

    def emergency_stop(
        self, name: str | Iterable[str] | None = None, repeats: int = 3, wait_s: float = EMERGENCY_DEADLINE_S
    ) -> dict[str, str]:
        """Emergency stop (latched until reboot) of one drone, several, or (None) all, sent `repeats` times
        (idempotent, safety critical). Each drone's queued commands are dropped and its outbox refuses anything
        more; the packets go out at once, not through the outbox (no command lock: cflib's send lock alone orders
        them), each drone's from a thread of its own, so a blocked link delays no other drone's stop. Waits
        ``wait_s`` at most (the flight loop waits little: a stuck link must not stall it); a drone whose stop is
        still being sent then is reported as such (its thread goes on sending)."""
        if name is None:
            targets = list(self._drones)
        elif isinstance(name, str):
            targets = [self._drones[name].name]
        else:
            targets = [self._drones[n].name for n in name]

        def stop_one(drone: CflibDrone) -> None:
            if drone.outbox is not None:
                drone.outbox.clear(refuse=True)
            cf = self._live_cf(drone.name)
            if cf is None:
                raise RuntimeError("link down")
            for _ in range(repeats):
                cf.supervisor.send_emergency_stop()

        errors = self._parallel(stop_one, [self._drones[t] for t in targets], wait_s)
        errors = {
            t: (
                "emergency stop still being sent (its link is blocked)"
                if why == "timed out"
                else f"emergency stop not delivered: {why}"
            )
            for t, why in errors.items()
        }
        for target, why in errors.items():
            logger.error("drone %s: %s", target, why)
        return errors

    def _start_packed(self, names: list[str]) -> dict[str, str]:
        """Open the packed extpos broadcasts of the connected drones' dongles; a drone whose broadcast cannot be
        opened gets no mocap, so it is given up (name -> error)."""
        self._packed = PackedExtposSender({n: self._drones[n].uri for n in names})
        errors = self._packed.start()
        for name, message in errors.items():
            self._give_up(self._drones[name], message)
        return errors

    def _extpos_sent_s(self, d: CflibDrone) -> float | None:
        """Under packed extpos, when a broadcast carrying this drone's position last went out."""
        if self._packed is not None:
            return self._packed.sent_s(d.name)
        return super()._extpos_sent_s(d)

    def send_extpos(self, name: str, position: Vec3, received_s: float | None = None) -> bool:
        """Queue a mocap position for the estimator (latest wins): in the drone's outbox, or under packed extpos in
        its group's next broadcast. ``received_s``: when its pose was received (`time.monotonic()`): a pose that
        waited longer than `outbox.EXTPOS_MAX_WAIT_S` by the time it would go out is dropped."""
        if self._packed is not None:
            return self._live_cf(name) is not None and self._packed.put(name, position, received_s)
        return self._queue(name, lambda cf, drone: cf.extpos.send_extpos(*position), "extpos", received_s)

    def send_extpose(self, name: str, position: Vec3, quaternion: Quaternion, received_s: float | None = None) -> bool:
        """Queue a mocap pose for the estimator (latest wins; ``received_s`` as for `send_extpos`)."""
        return self._queue(name, lambda cf, drone: cf.extpos.send_extpose(*position, *quaternion), "extpos", received_s)
