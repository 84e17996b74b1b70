"""A simulated Crazyflie firmware at the CRTP level: packets in, reply packets out, dynamics on `step`.

`FakeFirmware.handle(port, channel, data, now_s)` acts on one uplink packet and returns the reply packets;
`FakeFirmware.step(now_s)` advances the vehicle (`fake_vehicle.Vehicle`) and returns the log data packets due.
Time is the caller's clock in seconds (the fake world's clock); nothing here sleeps or starts threads, so tests can
drive it with synthetic time. All methods are thread-safe (one lock per firmware).

Services answered, as crazyflie-firmware 2026.08 (CRTP protocol version 12) answers cflib 0.1.34:
- link (15): echo (channel 0) returns the payload; source (channel 1) returns "Bitcraze Crazyflie"; the nRF51's
  bootloader commands (channel 3, ``[0xFE, cmd, ...]``, as cflib's `PowerSwitch` sends them on an open link):
  reset-init (answered with the nRF's device address) then reset to firmware reboots the drone (`reboot`);
- platform (13): protocol version 12, firmware version string; legacy arming and crash recovery;
- log (5): TOC v2 with a stable CRC, reset, block create/append (v1 and v2), start, stop, delete, periodic data;
- param (2): TOC v2, read (``[id, 0, value]``), write (echo; read-only: no answer), set-by-name, extended types,
  default values, persistent store / state / clear (stored values survive a reboot and apply at boot, as the
  firmware's storage does);
- memory (4): the memories of a Crazyflie 2.1 without decks (`fake_memory`): EEPROM, trajectory memory (the
  high-level commander's), memory tester, deck memory, deck-controller DFU memory;
- commander (3, 7), high-level commander (8), localization (6), supervisor (9): decoded and acted on.

Parts: the ports and the packet tuple are crtp.py; the log and parameter tables firmware_tables.py; `FakeFirmware`
is made of the log service (firmware_log.py), the parameter service (firmware_params.py) and the flight services
(firmware_flight.py); this module keeps the firmware's state, boot and reboot, the link, platform and memory ports,
the fault hooks and the snapshot.
"""

from __future__ import annotations

import logging
import math
import struct
import threading
from collections import Counter
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from types import MappingProxyType
from typing import NamedTuple

from .crtp import (
    PORT_COMMANDER,
    PORT_COMMANDER_GENERIC,
    PORT_LINK,
    PORT_LOCALIZATION,
    PORT_LOG,
    PORT_MEM,
    PORT_PARAM,
    PORT_PLATFORM,
    PORT_SETPOINT_HL,
    PORT_SUPERVISOR,
    Packet,
)
from .fake_memory import (
    MEM_TYPE_EEPROM,
    MEM_TYPE_TRAJ,
    BufferMemory,
    DeckCtrlDfuMemory,
    DeckMemory,
    MemorySubsystem,
    MemoryTester,
    eeprom_image,
)
from .fake_setpoint import wrap_angle
from .fake_supervisor import Transition
from .fake_vehicle import Vehicle, VehicleConfig
from .firmware_flight import FirmwareFlight
from .firmware_log import FirmwareLog, LogBlock
from .firmware_params import FirmwareParams
from .firmware_tables import PARAM_DEFAULTS

logger = logging.getLogger(__name__)
PROTOCOL_VERSION = 12
FIRMWARE_VERSION = "rpf-fake-2026.08"
REBOOT_BOOT_S = 1.5
"""Radio silence of a reboot: a Crazyflie 2.x takes about 1-2 s from power-on (nRF51 and STM32 bootloaders, then
the firmware's start-up) until its radio answers again. The fake's choice within that range."""
NRF_TARGET = 0xFE
"""First payload byte of a link channel-3 packet the nRF51 takes for itself (crazyflie2-nrf-firmware main.c)."""
BOOTLOADER_CMD_RESET_INIT, BOOTLOADER_CMD_RESET = 0xFF, 0xF0
RESET_TO_FIRMWARE = 1


class Body(NamedTuple):
    """One drone's body as the fake world sees it each step. Metres, radians."""

    position: tuple[float, float, float]
    yaw: float
    """Radians, wrapped to (-pi, pi]."""
    motors_on: bool
    airborne: bool
    """Above its floor or motors on (only then can it hit something)."""
    crashed: bool
    estimate: tuple[float, float, float]


@dataclass(frozen=True)
class FirmwareSnapshot:
    """A consistent copy of one fake Crazyflie's state, for tests and tools. Metres, seconds, degrees, volts."""

    time_s: float
    powered: bool
    supervisor_state: str
    supervisor_bits: int
    armed: bool
    locked: bool
    crashed: bool
    """The drone hit another drone or an obstacle (the fake world's contact model); it is locked until reboot."""
    crash_time_s: float | None
    """World time of the crash, None if it never crashed."""
    crash_reason: str | None
    """``"contact with <other address>"`` (10 hex digits) or ``"obstacle"``, None if it never crashed."""
    flying: bool
    motors_on: bool
    emergency_stop_latched: bool
    position: tuple[float, float, float]
    velocity: tuple[float, float, float]
    yaw_deg: float
    estimate: tuple[float, float, float]
    estimate_yaw_deg: float
    """The estimator's yaw (`stateEstimate.yaw`); `yaw_deg` is the true one."""
    setpoint_source: str
    setpoint_position: tuple[float, float, float]
    setpoint_velocity: tuple[float, float, float]
    """The commander's setpoint velocity (m/s): a high-level trajectory's derivative, its feed-forward."""
    setpoint_yaw_deg: float
    control_source: str
    hl_state: str
    hl_plan_start_s: float | None
    """World time the high-level commander's current plan (take-off, go-to, uploaded trajectory...) began."""
    vbat_v: float
    pm_state: int
    variance_m2: float
    estimator_diverging: bool
    """The estimator ignores extpos and runs away (`FakeFirmware.estimator_divergence`); `estimate` shows it
    against `position`."""
    gust_m_s2: tuple[float, float, float]
    """The external acceleration pushing the true body now (m/s^2; zeros when no gust blows)."""
    booting: bool
    """Power was cut (`FakeFirmware.reboot`) and the new flight stack has not started: radio silent."""
    boots: int
    """Reboots completed since the first power-on (0: still the first flight stack)."""
    last_crtp_setpoint_s: float | None
    transitions: tuple[Transition, ...]
    params: dict[str, float]
    log_blocks: dict[int, tuple[float, bool]]
    """block id -> (period in seconds, started)."""
    packets_received: dict[tuple[int, int], int]
    toc_item_requests: int
    hl_commands_rejected: int

    def entered(self, state: str) -> float | None:
        """Time the supervisor last entered `state` (e.g. "Locked"), None if it never did."""
        times = [t.time_s for t in self.transitions if t.new.value == state]
        return times[-1] if times else None


class FakeFirmware(FirmwareLog, FirmwareParams, FirmwareFlight):
    """One simulated Crazyflie. See the module docstring for what it answers."""

    vehicle: Vehicle
    rssi: int

    def __init__(
        self,
        config: VehicleConfig | None = None,
        *,
        now_s: float = 0.0,
        rssi: int = 35,
        seed: int = 0,
        radio_address: int = 0xE7E7E7E7E7,
        radio_channel: int = 80,
    ) -> None:
        """`seed` draws the drone's IMU bias and noise (`fake_vehicle`): give each drone of a world its own.
        `radio_address` and `radio_channel` go into the EEPROM's config block, as a real drone's do."""
        self.config = config or VehicleConfig()
        self.rssi = rssi
        self.seed = seed
        self._lock = threading.RLock()
        self._boot_s = now_s
        self._now_s = now_s
        self.vehicle = Vehicle(self.config, now_s, seed)
        self._params: dict[str, float] = dict(PARAM_DEFAULTS)
        self._stored: dict[str, float] = {}
        """Persistent parameters stored (the firmware's storage in EEPROM): they survive reboots and are applied at
        boot."""
        self._blocks: dict[int, LogBlock] = {}
        self._counts: Counter[tuple[int, int]] = Counter()
        self._toc_item_requests = 0
        self._booting_until: float | None = None
        self._boots = 0
        self._reset_init = False
        """The nRF51 took a reset-init command: a reset command now reboots (a static of its main loop, so a reboot
        clears it)."""
        self.packed_id = radio_address & 0xFF
        """The id packed external positions address it by: the radio address's last byte (crazyflie-firmware
        crtp_localization_service.c lines 168-169, ``configblockGetRadioAddress() & 0xFF``)."""
        self._device_address = radio_address.to_bytes(6, "little")
        """What reset-init answers: a real nRF51's factory DEVICEADDR (6 bytes); the fake's is its radio address."""
        self._eeprom = eeprom_image(radio_channel, 2, radio_address)
        """Survives reboots (it is the EEPROM); everything else on the memory port is RAM."""
        self._memories = self._memory_subsystem()
        for name, value in self.config.stored_params:  # stored at power-on (a vehicle profile): paramInit applies them
            if name not in self._params:
                raise ValueError(f"stored parameter {name!r}: not a parameter of the simulated firmware")
            self._stored[name] = float(value)
            self._param_set(name, float(value))

    def _memory_subsystem(self) -> MemorySubsystem:
        """The memory table of a fresh flight stack, in the firmware's registration order (`fake_memory`)."""
        self.memory_tester = MemoryTester(on_reset=lambda: self._params.__setitem__("memTst.resetW", 0.0))
        return MemorySubsystem(
            [
                BufferMemory(MEM_TYPE_EEPROM, lambda: self._eeprom),
                BufferMemory(MEM_TYPE_TRAJ, lambda: self.vehicle.hl.trajectory_memory),
                self.memory_tester,
                DeckMemory(),
                DeckCtrlDfuMemory(),
            ]
        )

    # Public API -----------------------------------------------------------------------------------------------

    @property
    def powered(self) -> bool:
        """False once the battery shut the firmware down, and while it reboots: it then answers nothing."""
        return self.vehicle.powered

    @property
    def booting(self) -> bool:
        """True from a `reboot` until the new flight stack runs."""
        return self._booting_until is not None

    def reboot(self, now_s: float, boot_s: float = REBOOT_BOOT_S) -> None:
        """Power-cycle as a brown-out or the power button does: the motors stop at once and a flying drone falls
        under gravity to the floor; the radio is silent for ``boot_s`` (`REBOOT_BOOT_S`, so a connected cflib link
        loses its acks and fails with "Too many packets lost"); then a new flight stack starts on the floor where
        the drone lies (once it has landed there): same battery and IMU, fresh supervisor, no log blocks, default
        parameters (so the estimator restarts at `kalman.initialX/Y/Z/Yaw` = 0). A new connection reaches it."""
        with self._lock:
            self.vehicle.cut_power()
            self._blocks.clear()
            self._reset_init = False
            self._booting_until = now_s + max(0.0, boot_s)
            self._finish_boot(now_s)

    def _finish_boot(self, now_s: float) -> None:
        """Start the new flight stack of a reboot once its boot time is over and the body rests on the floor."""
        old = self.vehicle
        if self._booting_until is None or now_s < self._booting_until:
            return
        if old.pos[2] > old.floor_z or old.vel[2] != 0.0:
            return  # still falling: it boots where it lands
        self.config = replace(
            self.config,
            position=(old.pos[0], old.pos[1], old.floor_z),
            yaw_deg=math.degrees(old.yaw),
            initial_vbat_v=old.battery.open_v,
        )
        self.vehicle = Vehicle(self.config, now_s, self.seed)
        self.vehicle.gust(old.gust_accel, old.gust_until_s)  # the wind does not care
        self._params = dict(PARAM_DEFAULTS)
        for name, value in self._stored.items():  # paramInit: stored persistent values replace the defaults
            self._param_set(name, value)
        self._blocks.clear()
        self._memories = self._memory_subsystem()
        self._boot_s = self._now_s = max(self._now_s, now_s)
        self._booting_until = None
        self._boots += 1
        logger.info("fake Crazyflie rebooted at %.3f s", now_s)

    def supervisor_bits(self) -> int:
        """Current `supervisor.info`."""
        return self.vehicle.supervisor.info_bits(self.vehicle.hl.info_bits(self._now_s))

    def step(self, now_s: float) -> list[Packet]:
        """Advance the vehicle to `now_s` and return the log data packets that fell due."""
        with self._lock:
            if now_s <= self._now_s:
                return []
            self._now_s = now_s
            self.vehicle.step(now_s)
            if self._booting_until is not None:
                self._finish_boot(now_s)
            if not self.powered:
                return []
            return self._log_data_due(now_s)

    def handle(self, port: int, channel: int, data: bytes, now_s: float) -> list[Packet]:
        """Act on one uplink packet received at `now_s`; return the replies (possibly none)."""
        data = bytes(data)
        with self._lock:
            if not self.powered:
                return []
            self._counts[(port, channel)] += 1
            handler = self._HANDLERS.get(port)
            if handler is None:
                return []
            try:
                return handler(self, channel, data, max(now_s, self._now_s))
            except (struct.error, IndexError, ValueError) as exc:
                logger.warning("fake firmware: malformed packet on %d:%d (%s): %s", port, channel, data.hex(), exc)
                return []

    def disturb(self, offset_m: tuple[float, float, float]) -> None:
        """Move the true position by ``offset_m`` at once (a gust or a bump; the onboard estimate moves with it,
        as an IMU-fused estimate would; the controller then steers back to its setpoint). For fault tests."""
        with self._lock:
            for axis in range(3):
                self.vehicle.pos[axis] += offset_m[axis]

    def gust(self, accel_m_s2: tuple[float, float, float], seconds: float, now_s: float) -> None:
        """An external acceleration ``accel_m_s2`` (m/s^2, world frame) on the true drone for ``seconds`` from
        ``now_s``, which its position controller fights (`fake_vehicle`, "Gust": 1.5 m/s^2 holds a hovering drone
        17.6 cm downwind; it comes back when the gust ends). Unlike `disturb`, nothing is teleported. For fault
        tests."""
        with self._lock:
            self.vehicle.gust(accel_m_s2, max(now_s, self._now_s) + seconds)

    def estimator_divergence(self, rate_m_s: float) -> None:
        """From now until a reboot the estimator takes no extpos/extpose and its position estimate runs away at
        ``rate_m_s`` in a fixed horizontal direction (seeded): under position control the true drone drifts the
        other way while `stateEstimate` looks right (`fake_vehicle`, "Estimator divergence"). For fault tests."""
        if not rate_m_s >= 0.0:
            raise ValueError(f"rate_m_s must be >= 0, not {rate_m_s}")
        with self._lock:
            self.vehicle.diverge(float(rate_m_s))

    def set_battery(self, open_circuit_v: float) -> None:
        """Set the battery's open-circuit voltage now (a failing cell; for fault tests)."""
        with self._lock:
            self.vehicle.battery.open_v = float(open_circuit_v)

    def body(self) -> Body:
        """The little the fake world needs every step (contact, truth), read under the lock: far cheaper than a
        snapshot."""
        with self._lock:
            v = self.vehicle
            return Body(
                (v.pos[0], v.pos[1], v.pos[2]),
                wrap_angle(v.yaw),
                v.motors_on,
                v.airborne,
                v.crash_s is not None,
                v.estimate,
            )

    def crash(self, now_s: float, reason: str, at: tuple[float, float, float] | None = None) -> bool:
        """The drone hit something at true position `at` (see `Vehicle.crash`); True if this was its first crash."""
        with self._lock:
            return self.vehicle.crash(max(now_s, self._now_s), reason, at)

    def true_pose(self) -> tuple[tuple[float, float, float], float]:
        """The true position (m) and yaw (degrees), as `snapshot` has them: what mocap sees each frame, without the
        whole snapshot's cost (a world's frames read every drone's at 100-120 Hz)."""
        with self._lock:
            v = self.vehicle
            return (v.pos[0], v.pos[1], v.pos[2]), math.degrees(v.yaw)

    def snapshot(self) -> FirmwareSnapshot:
        """A consistent copy of the state."""
        with self._lock:
            v = self.vehicle
            sup = v.supervisor
            return FirmwareSnapshot(
                time_s=self._now_s,
                powered=self.powered,
                supervisor_state=sup.state.value,
                supervisor_bits=self.supervisor_bits(),
                armed=sup.armed,
                locked=sup.is_locked,
                crashed=v.crash_s is not None,
                crash_time_s=v.crash_s,
                crash_reason=v.crash_reason,
                flying=sup.is_flying,
                motors_on=v.motors_on,
                emergency_stop_latched=sup.emergency_stop_requested,
                position=(v.pos[0], v.pos[1], v.pos[2]),
                velocity=(v.vel[0], v.vel[1], v.vel[2]),
                yaw_deg=math.degrees(v.yaw),
                estimate=v.estimate,
                estimate_yaw_deg=math.degrees(v.estimate_yaw),
                setpoint_source=v.setpoint.source,
                setpoint_position=v.setpoint.position,
                setpoint_velocity=v.setpoint.velocity,
                setpoint_yaw_deg=v.setpoint.yaw_deg,
                control_source=v.control_setpoint.source,
                hl_state=v.hl.state.name,
                hl_plan_start_s=v.hl.plan_start_s,
                vbat_v=v.battery.vbat_v,
                pm_state=v.battery.pm_state,
                variance_m2=v.variance_m2,
                estimator_diverging=v.divergence_velocity is not None,
                gust_m_s2=v.gust_accel if self._now_s <= v.gust_until_s else (0.0, 0.0, 0.0),
                booting=self._booting_until is not None,
                boots=self._boots,
                last_crtp_setpoint_s=v.last_crtp_setpoint_s,
                transitions=tuple(sup.transitions),
                params=dict(self._params),
                log_blocks={b.block_id: (b.period_s, b.started) for b in self._blocks.values()},
                packets_received=dict(self._counts),
                toc_item_requests=self._toc_item_requests,
                hl_commands_rejected=v.hl.commands_rejected,
            )

    # Link, platform, memory -----------------------------------------------------------------------------------

    def _link(self, channel: int, data: bytes, now_s: float) -> list[Packet]:
        if channel == 0:
            return [(PORT_LINK, 0, data)]
        if channel == 1:
            return [(PORT_LINK, 1, b"Bitcraze Crazyflie".ljust(30, b"\0"))]
        if channel == 3 and len(data) >= 2 and data[0] == NRF_TARGET:
            return self._nrf_command(data, now_s)
        return []

    def _nrf_command(self, data: bytes, now_s: float) -> list[Packet]:
        """The nRF51's own commands (crazyflie2-nrf-firmware main.c ``handleBootloaderCmd``): reset-init answers
        ``[0xFE, 0xFF, device address]``; a reset after it (``[0xFE, 0xF0, 1]``, exactly three bytes) reboots into
        the firmware, as `reboot` does. Reset into the bootloader (argument 0) and the power commands are not
        simulated (ignored). The reboot here is the firmware's own: the world's downlink queue is not flushed
        (the link that asked closes, and a detached link's queue is flushed then)."""
        cmd = data[1]
        if cmd == BOOTLOADER_CMD_RESET_INIT:
            self._reset_init = True
            return [(PORT_LINK, 3, bytes([NRF_TARGET, BOOTLOADER_CMD_RESET_INIT]) + self._device_address)]
        if cmd == BOOTLOADER_CMD_RESET and self._reset_init and len(data) == 3:
            if data[2] == RESET_TO_FIRMWARE:
                logger.info("fake Crazyflie: reset to firmware over the radio at %.3f s", now_s)
                self.reboot(now_s)
            else:
                logger.warning("fake Crazyflie: reset into the bootloader is not simulated: ignored")
        return []

    def _platform(self, channel: int, data: bytes, now_s: float) -> list[Packet]:
        if channel == 1 and data:
            if data[0] == 0:
                return [(PORT_PLATFORM, 1, bytes([0, PROTOCOL_VERSION]))]
            if data[0] == 1:
                return [(PORT_PLATFORM, 1, bytes([1]) + FIRMWARE_VERSION.encode("ascii"))]
        if channel == 0 and len(data) > 1 and data[0] == 1:  # legacy arming request
            self.vehicle.supervisor.request_arming(bool(data[1]))
        return []

    def _mem(self, channel: int, data: bytes, now_s: float) -> list[Packet]:
        return self._memories.handle(channel, data)

    _HANDLERS: Mapping[int, Callable[[FakeFirmware, int, bytes, float], list[Packet]]] = MappingProxyType(
        {
            PORT_LINK: _link,
            PORT_PLATFORM: _platform,
            PORT_MEM: _mem,
            PORT_LOG: FirmwareLog._log,
            PORT_PARAM: FirmwareParams._param,
            PORT_COMMANDER: FirmwareFlight._commander,
            PORT_COMMANDER_GENERIC: FirmwareFlight._commander_generic,
            PORT_SETPOINT_HL: FirmwareFlight._high_level,
            PORT_LOCALIZATION: FirmwareFlight._localization,
            PORT_SUPERVISOR: FirmwareFlight._supervisor,
        }
    )
