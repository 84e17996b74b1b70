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
"""

from __future__ import annotations

import errno
import logging
import math
import struct
import threading
from collections import Counter
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from types import MappingProxyType
from typing import NamedTuple

from .fake_memory import (
    MEM_TYPE_EEPROM, MEM_TYPE_TRAJ, BufferMemory, DeckCtrlDfuMemory, DeckMemory, MemorySubsystem, MemoryTester,
    eeprom_image,
)
from .fake_setpoint import AxisMode, decode_generic, decode_rpyt, wrap_angle
from .fake_supervisor import Transition
from .fake_toc import EXTENDED_TYPE_PERSISTENT, LOG_TYPE_NAMES, Toc, make_toc, pack_value, unpack_value, value_size
from .cf_controller import CfGains
from .fake_vehicle import Vehicle, VehicleConfig
from .vehicle_figures import HOVER_THRUST
from .vehicle_firmware import CONTROLLER_PARAMS

logger = logging.getLogger(__name__)

Packet = tuple[int, int, bytes]
"""(port, channel, payload) of one CRTP packet."""

PROTOCOL_VERSION = 12
PERSISTENT_NOT_STORED, PERSISTENT_STORED = 0, 1
"""`PARAM_PERSISTENT_NOT_STORED` / `_STORED` of param.h."""
FIRMWARE_VERSION = "rpf-fake-2026.08"
LOG_MAX_BLOCKS = 16
LOG_MAX_PAYLOAD = 26
REBOOT_BOOT_S = 1.5
"""Radio silence of a reboot: a Crazyflie 2.x takes about 1-2 s from power-on (nRF51 and STM32 bootloaders, then
the firmware's start-up) until its radio answers again. The fake's choice within that range."""

PORT_CONSOLE, PORT_PARAM, PORT_COMMANDER, PORT_MEM, PORT_LOG = 0, 2, 3, 4, 5
PORT_LOCALIZATION, PORT_COMMANDER_GENERIC, PORT_SETPOINT_HL, PORT_SUPERVISOR = 6, 7, 8, 9
_PACKED_ITEM = struct.Struct("<Bhhh")
"""One item of a packed external position (crazyflie-firmware crtp_localization_service.c lines 105-111,
``extPositionPackedItem``; read by ``extPositionPackedHandler``, lines 350-369)."""
PORT_PLATFORM, PORT_LINK = 13, 15
NRF_TARGET = 0xFE
"""First payload byte of a link channel-3 packet the nRF51 takes for itself (crazyflie2-nrf-firmware main.c)."""
BOOTLOADER_CMD_RESET_INIT, BOOTLOADER_CMD_RESET = 0xFF, 0xF0
RESET_TO_FIRMWARE = 1

def _thrust(vehicle: Vehicle) -> float:
    """`stabilizer.thrust`: an attitude mode's raw thrust, else the hover thrust while the motors spin."""
    if not vehicle.motors_on:
        return 0.0
    setpoint = vehicle.control_setpoint
    return float(setpoint.thrust) if setpoint.modes[2] is AxisMode.DISABLE else float(HOVER_THRUST)


_LOG_VARIABLES: tuple[tuple[str, str, Callable[[FakeFirmware], float]], ...] = (
    ("stateEstimate.x", "float", lambda f: f.vehicle.estimate[0]),
    ("stateEstimate.y", "float", lambda f: f.vehicle.estimate[1]),
    ("stateEstimate.z", "float", lambda f: f.vehicle.estimate[2]),
    ("stateEstimate.vx", "float", lambda f: f.vehicle.estimate_velocity[0]),
    ("stateEstimate.vy", "float", lambda f: f.vehicle.estimate_velocity[1]),
    ("stateEstimate.vz", "float", lambda f: f.vehicle.estimate_velocity[2]),
    ("stateEstimate.roll", "float", lambda f: 0.0),
    ("stateEstimate.pitch", "float", lambda f: 0.0),
    ("stateEstimate.yaw", "float", lambda f: math.degrees(f.vehicle.estimate_yaw)),
    ("pm.vbat", "float", lambda f: f.vehicle.battery.vbat_v),
    ("pm.state", "int8_t", lambda f: f.vehicle.battery.pm_state),
    ("pm.batteryLevel", "uint8_t", lambda f: min(max((f.vehicle.battery.vbat_v - 3.0) / 1.2, 0.0), 1.0) * 100.0),
    ("supervisor.info", "uint16_t", lambda f: f.supervisor_bits()),
    ("sys.canfly", "uint8_t", lambda f: f.vehicle.supervisor.motors_allowed),
    ("sys.isFlying", "uint8_t", lambda f: f.vehicle.supervisor.is_flying),
    ("sys.isTumbled", "uint8_t", lambda f: f.vehicle.supervisor.tumbled),
    ("kalman.stateX", "float", lambda f: f.vehicle.estimate[0]),
    ("kalman.stateY", "float", lambda f: f.vehicle.estimate[1]),
    ("kalman.stateZ", "float", lambda f: f.vehicle.estimate[2]),
    ("kalman.varPX", "float", lambda f: f.vehicle.variance_m2),
    ("kalman.varPY", "float", lambda f: f.vehicle.variance_m2),
    ("kalman.varPZ", "float", lambda f: f.vehicle.variance_m2),
    ("radio.rssi", "uint8_t", lambda f: f.rssi),
    ("radio.isConnected", "uint8_t", lambda f: 1),
    ("ctrltarget.x", "float", lambda f: f.vehicle.control_setpoint.position[0]),
    ("ctrltarget.y", "float", lambda f: f.vehicle.control_setpoint.position[1]),
    ("ctrltarget.z", "float", lambda f: f.vehicle.control_setpoint.position[2]),
    ("ctrltarget.yaw", "float", lambda f: f.vehicle.control_setpoint.yaw_deg),
    # the compressed groups (stabilizer.c: mm and mm/s as int16, the C cast truncating toward zero): a status log
    # block fits the estimate and the controller's target in one 26-byte packet
    ("stateEstimateZ.x", "int16_t", lambda f: f.vehicle.estimate[0] * 1000.0),
    ("stateEstimateZ.y", "int16_t", lambda f: f.vehicle.estimate[1] * 1000.0),
    ("stateEstimateZ.z", "int16_t", lambda f: f.vehicle.estimate[2] * 1000.0),
    ("stateEstimateZ.vx", "int16_t", lambda f: f.vehicle.estimate_velocity[0] * 1000.0),
    ("stateEstimateZ.vy", "int16_t", lambda f: f.vehicle.estimate_velocity[1] * 1000.0),
    ("stateEstimateZ.vz", "int16_t", lambda f: f.vehicle.estimate_velocity[2] * 1000.0),
    ("ctrltargetZ.x", "int16_t", lambda f: f.vehicle.control_setpoint.position[0] * 1000.0),
    ("ctrltargetZ.y", "int16_t", lambda f: f.vehicle.control_setpoint.position[1] * 1000.0),
    ("ctrltargetZ.z", "int16_t", lambda f: f.vehicle.control_setpoint.position[2] * 1000.0),
    ("ctrltargetZ.vx", "int16_t", lambda f: f.vehicle.control_setpoint.velocity[0] * 1000.0),
    ("ctrltargetZ.vy", "int16_t", lambda f: f.vehicle.control_setpoint.velocity[1] * 1000.0),
    ("ctrltargetZ.vz", "int16_t", lambda f: f.vehicle.control_setpoint.velocity[2] * 1000.0),
    ("stabilizer.roll", "float", lambda f: f.vehicle.attitude_deg[0]),
    ("stabilizer.pitch", "float", lambda f: f.vehicle.attitude_deg[1]),
    ("stabilizer.yaw", "float", lambda f: math.degrees(f.vehicle.estimate_yaw)),
    ("stabilizer.thrust", "float", lambda f: _thrust(f.vehicle)),
    ("memTst.errCntW", "uint32_t", lambda f: f.memory_tester.write_errors),
)

_CONTROLLER_PARAM_TYPES: Mapping[str, str] = MappingProxyType({"posCtlPid.thrustBase": "uint16_t",
                                                                "posCtlPid.thrustMin": "uint16_t"})
"""The controller parameters that are not floats (`position_controller_pid.c:521-603`: PARAM_UINT16)."""
_CONTROLLER_PARAMS: tuple[tuple[str, str, float, bool, bool], ...] = tuple(
    (name, _CONTROLLER_PARAM_TYPES.get(name, "float"), default, False, True)
    for name, default in CfGains().params().items())
"""The PID controller's gains and limits under their firmware names, types and defaults (cf_controller.CfGains,
checked against the PARAM_GROUP blocks of `position_controller_pid.c:462-603` (velCtlPid, posCtlPid) and
`attitude_pid_controller.c:318-450` (pid_attitude, pid_rate) at crazyflie-firmware 2a18fc29: every one
PARAM_PERSISTENT, floats but posCtlPid.thrustBase and thrustMin, uint16). Written, they act on the simulated
drone's controller at once (`Vehicle.set_controller_param`: all of them with the "firmware" dynamics, the velocity
limits with the first-order one); the filter switches and cut-offs of those groups are not here (not modelled)."""

# (name, ctype, default, read_only, persistent). Names and defaults of the firmware's groups that cflib programs and
# Bitcraze's examples touch (crazyflie-firmware's param definitions and platform defaults), the controller's with
# them (`_CONTROLLER_PARAMS`).
_PARAMS: tuple[tuple[str, str, float, bool, bool], ...] = (
    ("stabilizer.estimator", "uint8_t", 0, False, False),
    ("stabilizer.controller", "uint8_t", 0, False, False),
    ("stabilizer.stop", "uint8_t", 0, False, False),
    ("commander.enHighLevel", "uint8_t", 0, False, False),
    ("locSrv.extPosStdDev", "float", 0.01, False, False),
    ("locSrv.extQuatStdDev", "float", 4.5e-3, False, False),
    ("kalman.resetEstimation", "uint8_t", 0, False, False),
    ("kalman.initialX", "float", 0.0, False, False),
    ("kalman.initialY", "float", 0.0, False, False),
    ("kalman.initialZ", "float", 0.0, False, False),
    ("kalman.initialYaw", "float", 0.0, False, False),
    ("hlCommander.vtoff", "float", 0.5, False, False),
    ("hlCommander.vland", "float", 0.5, False, False),
    ("pm.lowVoltage", "float", 3.2, False, True),
    ("pm.criticalLowVoltage", "float", 3.0, False, True),
    ("led.bitmask", "uint8_t", 0, False, False),
    *_CONTROLLER_PARAMS,
    ("memTst.resetW", "uint8_t", 0, False, False),
    # deck drivers of the default build register their parameters whether or not their deck is there
    # (ledring12.c: effect 6, CONFIG_DECK_LEDRING_DEFAULT_EFFECT, neffect 18; activeMarkerDeck.c: ids 1 3 4 2, mode 3
    # Qualisys); deck.bc*: 1 when that deck was found and initialised, so 0 on a deckless drone
    ("ring.effect", "uint8_t", 6, False, True),
    ("ring.neffect", "uint32_t", 18, True, False),
    ("activeMarker.front", "uint8_t", 1, False, True),
    ("activeMarker.back", "uint8_t", 3, False, True),
    ("activeMarker.left", "uint8_t", 4, False, True),
    ("activeMarker.right", "uint8_t", 2, False, True),
    ("activeMarker.mode", "uint8_t", 3, False, True),
    ("activeMarker.poll", "uint8_t", 0, False, False),
    *((f"deck.{flag}", "uint8_t", 0, True, False) for flag in (
        "bcActiveMarker", "bcAI", "bcBuzzer", "bcDWM1000", "bcFlow", "bcFlow2", "bcLedRing", "bcLighthouse4",
        "bcLoco", "bcMultiranger", "bcUSD", "bcZRanger", "bcZRanger2")),
    # system.c: the MCU's flash size in kB (STM32F405: 1024) and unique id
    ("cpu.flash", "uint16_t", 1024, True, False),
    ("cpu.id0", "uint32_t", 0x0033_0047, True, False),
    ("cpu.id1", "uint32_t", 0x3236_5104, True, False),
    ("cpu.id2", "uint32_t", 0x3038_3533, True, False),
    ("firmware.revision0", "uint32_t", 0x2026_0800, True, False),
    ("firmware.modified", "uint8_t", 0, True, False),
)

LOG_TOC: Toc = make_toc([(name, ctype) for name, ctype, _ in _LOG_VARIABLES], is_param=False)
PARAM_TOC: Toc = make_toc([(n, c, ro, pers) for n, c, _, ro, pers in _PARAMS], is_param=True)
_LOG_GETTERS = tuple(getter for _, _, getter in _LOG_VARIABLES)
_PARAM_DEFAULTS: Mapping[str, float] = MappingProxyType({name: float(default) for name, _, default, _, _ in _PARAMS})


@dataclass
class _LogBlock:
    block_id: int
    variables: list[tuple[int, str]]
    """(log TOC id, fetch C type)."""
    period_s: float = 0.0
    started: bool = False
    next_due_s: float = 0.0


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


class FakeFirmware:
    """One simulated Crazyflie. See the module docstring for what it answers."""

    vehicle: Vehicle
    rssi: int

    def __init__(self, config: VehicleConfig | None = None, *, now_s: float = 0.0, rssi: int = 35,
                 seed: int = 0, radio_address: int = 0xE7E7E7E7E7, radio_channel: int = 80) -> None:
        """`seed` draws the drone's IMU bias and noise (`fake_vehicle`): give each drone of a world its own.
        `radio_address` and `radio_channel` go into the EEPROM's config block, as a real drone's do."""
        self.config = config or VehicleConfig()
        self.rssi = rssi
        self.seed = seed
        self._lock = threading.RLock()
        self._boot_s = now_s
        self._now_s = now_s
        self.vehicle = Vehicle(self.config, now_s, seed)
        self._params: dict[str, float] = dict(_PARAM_DEFAULTS)
        self._stored: dict[str, float] = {}
        """Persistent parameters stored (the firmware's storage in EEPROM): they survive reboots and are applied at
        boot."""
        self._blocks: dict[int, _LogBlock] = {}
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
        return MemorySubsystem([
            BufferMemory(MEM_TYPE_EEPROM, lambda: self._eeprom),
            BufferMemory(MEM_TYPE_TRAJ, lambda: self.vehicle.hl.trajectory_memory),
            self.memory_tester,
            DeckMemory(),
            DeckCtrlDfuMemory(),
        ])

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
        self.config = replace(self.config, position=(old.pos[0], old.pos[1], old.floor_z),
                              yaw_deg=math.degrees(old.yaw), initial_vbat_v=old.battery.open_v)
        self.vehicle = Vehicle(self.config, now_s, self.seed)
        self.vehicle.gust(old.gust_accel, old.gust_until_s)  # the wind does not care
        self._params = dict(_PARAM_DEFAULTS)
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
            return Body((v.pos[0], v.pos[1], v.pos[2]), wrap_angle(v.yaw), v.motors_on, v.airborne,
                        v.crash_s is not None, v.estimate)

    def crash(self, now_s: float, reason: str, at: tuple[float, float, float] | None = None) -> bool:
        """The drone hit something at true position `at` (see `Vehicle.crash`); True if this was its first crash."""
        with self._lock:
            return self.vehicle.crash(max(now_s, self._now_s), reason, at)

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

    # Log ------------------------------------------------------------------------------------------------------

    def _log(self, channel: int, data: bytes, now_s: float) -> list[Packet]:
        if channel == 0:
            return self._toc(PORT_LOG, LOG_TOC, data)
        if channel != 1 or not data:
            return []
        cmd = data[0]
        if cmd == 5:  # reset
            self._blocks.clear()
            return [(PORT_LOG, 1, bytes([5, 0, 0]))]
        block_id = data[1]
        if cmd in (0, 6, 1, 7):  # create / append, v1 and v2
            result = self._log_add(cmd, block_id, data[2:])
        elif cmd == 3:  # start
            block = self._blocks.get(block_id)
            if block is None:
                result = errno.ENOENT
            else:
                block.period_s = max(data[2], 1) * 0.01
                block.started = True
                block.next_due_s = now_s + block.period_s
                result = 0
        elif cmd == 4:  # stop
            block = self._blocks.get(block_id)
            result = errno.ENOENT if block is None else 0
            if block is not None:
                block.started = False
        elif cmd == 2:  # delete
            result = 0 if self._blocks.pop(block_id, None) is not None else errno.ENOENT
        else:
            result = errno.ENOEXEC
        return [(PORT_LOG, 1, bytes([cmd, block_id, result]))]

    def _log_add(self, cmd: int, block_id: int, specs: bytes) -> int:
        create = cmd in (0, 6)
        step = 3 if cmd in (6, 7) else 2
        if create and block_id in self._blocks:
            return errno.EEXIST
        if not create and block_id not in self._blocks:
            return errno.ENOENT
        if create and len(self._blocks) >= LOG_MAX_BLOCKS:
            return errno.ENOMEM
        variables = [] if create else list(self._blocks[block_id].variables)
        for i in range(0, len(specs) - step + 1, step):
            type_byte = specs[i]
            ident = struct.unpack("<H", specs[i + 1 : i + 3])[0] if step == 3 else specs[i + 1]
            fetch = LOG_TYPE_NAMES.get(type_byte & 0x0F)
            if fetch is None or ident >= len(LOG_TOC):
                return errno.ENOENT
            variables.append((ident, fetch))
        if sum(value_size(ctype) for _, ctype in variables) > LOG_MAX_PAYLOAD:
            return errno.E2BIG
        if create:
            self._blocks[block_id] = _LogBlock(block_id, variables)
        else:
            self._blocks[block_id].variables = variables
        return 0

    def _log_data_due(self, now_s: float) -> list[Packet]:
        packets = []
        stamp = round((now_s - self._boot_s) * 1000.0) & 0xFFFFFF
        for block in self._blocks.values():
            if not block.started or now_s + 1e-6 < block.next_due_s:
                continue
            block.next_due_s += block.period_s
            if block.next_due_s < now_s:
                block.next_due_s = now_s + block.period_s
            payload = bytearray([block.block_id]) + stamp.to_bytes(3, "little")
            for ident, ctype in block.variables:
                payload += pack_value(ctype, _LOG_GETTERS[ident](self))
            packets.append((PORT_LOG, 2, bytes(payload)))
        return packets

    # Param ----------------------------------------------------------------------------------------------------

    def _toc(self, port: int, toc: Toc, data: bytes) -> list[Packet]:
        if not data:
            return []
        if data[0] == 3:
            return [(port, 0, toc.info_reply())]
        if data[0] == 2 and len(data) >= 3:
            self._toc_item_requests += 1
            return [(port, 0, toc.item_reply(struct.unpack("<H", data[1:3])[0]))]
        return []

    def _param(self, channel: int, data: bytes, now_s: float) -> list[Packet]:
        if channel == 0:
            return self._toc(PORT_PARAM, PARAM_TOC, data)
        if channel == 3:
            return self._param_misc(data)
        ident = struct.unpack("<H", data[:2])[0]
        if ident >= len(PARAM_TOC):
            return [(PORT_PARAM, channel, data[:2] + bytes([errno.ENOENT]))]
        entry = PARAM_TOC.entries[ident]
        if channel == 1:
            return [(PORT_PARAM, 1, data[:2] + b"\0" + pack_value(entry.ctype, self._params[entry.full_name]))]
        if channel == 2:
            if entry.read_only:
                return []
            self._param_set(entry.full_name, unpack_value(entry.ctype, data[2:]))
            return [(PORT_PARAM, 2, data)]
        return []

    def _param_misc(self, data: bytes) -> list[Packet]:
        cmd = data[0]
        if cmd == 0:  # set by name: [0, group\0name\0, type, value]
            group_end = data.index(0, 1)
            name_end = data.index(0, group_end + 1)
            full_name = f"{data[1:group_end].decode()}.{data[group_end + 1:name_end].decode()}"
            entry = PARAM_TOC.by_name.get(full_name)
            result = errno.ENOENT if entry is None else (errno.EACCES if entry.read_only else 0)
            if entry is not None and not entry.read_only:
                self._param_set(full_name, unpack_value(entry.ctype, data[name_end + 2 :]))
            return [(PORT_PARAM, 3, data[: name_end + 1] + bytes([result]))]
        ident = struct.unpack("<H", data[1:3])[0]
        entry = PARAM_TOC.entries[ident] if ident < len(PARAM_TOC) else None
        head = data[:3]
        if entry is None:
            return [(PORT_PARAM, 3, head + bytes([errno.ENOENT]))]
        default = pack_value(entry.ctype, _PARAM_DEFAULTS[entry.full_name])
        if cmd in (2, 7):  # extended type (v1, v2)
            ext = EXTENDED_TYPE_PERSISTENT if entry.persistent else 0
            return [(PORT_PARAM, 3, head + (bytes([ext]) if cmd == 2 else bytes([0, ext])))]
        if cmd in (6, 8):  # default value (v1, v2)
            return [(PORT_PARAM, 3, head + (default if cmd == 6 else b"\0" + default))]
        if cmd == 4:  # persistent state (paramPersistentGetState): stored flag, default value, stored value
            stored = self._stored.get(entry.full_name)
            if stored is None:
                return [(PORT_PARAM, 3, head + bytes([PERSISTENT_NOT_STORED]) + default)]
            return [(PORT_PARAM, 3, head + bytes([PERSISTENT_STORED]) + default + pack_value(entry.ctype, stored))]
        if cmd == 3:  # persistent store: the current value, for persistent parameters only
            if not entry.persistent:
                return [(PORT_PARAM, 3, head + bytes([errno.ENOENT]))]
            self._stored[entry.full_name] = self._params[entry.full_name]
            return [(PORT_PARAM, 3, head + b"\0")]
        if cmd == 5:  # persistent clear
            self._stored.pop(entry.full_name, None)
            return [(PORT_PARAM, 3, head + b"\0")]
        return []

    def _param_set(self, full_name: str, value: float) -> None:
        v = self.vehicle
        self._params[full_name] = float(value)
        if full_name == "kalman.resetEstimation" and value:
            v.reset_estimator()
            self._params[full_name] = 0.0
        elif full_name == "stabilizer.stop":
            v.param_emergency_stop = bool(value)
        elif full_name == "locSrv.extPosStdDev":
            v.ext_pos_std_dev = float(value)
        elif full_name == "kalman.initialYaw":  # used at the next reset, as in the firmware
            v.initial_yaw = float(value)
        elif full_name.startswith("kalman.initial"):
            v.initial_estimate = (self._params["kalman.initialX"], self._params["kalman.initialY"],
                                  self._params["kalman.initialZ"])
        elif full_name in CONTROLLER_PARAMS:
            v.set_controller_param(full_name, float(value))
        elif full_name == "pm.lowVoltage":
            v.low_voltage_v = float(value)
        elif full_name == "pm.criticalLowVoltage":
            v.critical_voltage_v = float(value)
        elif full_name == "memTst.resetW":
            self.memory_tester.reset_requested = bool(value)

    # Flight ---------------------------------------------------------------------------------------------------

    def _commander(self, channel: int, data: bytes, now_s: float) -> list[Packet]:
        if channel != 0:
            return []
        setpoint, self.vehicle.rpyt_thrust_locked = decode_rpyt(data, now_s, self.vehicle.rpyt_thrust_locked)
        if setpoint is not None:
            self.vehicle.crtp_setpoint(setpoint, now_s)
        return []

    def _commander_generic(self, channel: int, data: bytes, now_s: float) -> list[Packet]:
        if channel == 0:
            setpoint = decode_generic(data, now_s, self.vehicle.estimate_yaw)
            if setpoint is not None:
                self.vehicle.crtp_setpoint(setpoint, now_s)
        elif channel == 1 and data and data[0] == 0:
            remain_ms = struct.unpack("<I", data[1:5])[0] if len(data) >= 5 else 0
            self.vehicle.notify_setpoint_stop(remain_ms)
        return []

    def _high_level(self, channel: int, data: bytes, now_s: float) -> list[Packet]:
        answer = self.vehicle.hl.handle(data, now_s)
        return [(PORT_SETPOINT_HL, channel, answer)] if answer else []

    def _localization(self, channel: int, data: bytes, now_s: float) -> list[Packet]:
        v = self.vehicle
        if channel == 0:
            v.external_position(struct.unpack("<fff", data[:12]), now_s)
        elif channel == 2:  # EXT_POSITION_PACKED: size / 7 items of id, int16 mm x, y, z; its own id only
            for k in range(len(data) // _PACKED_ITEM.size):  # (others go to peer localization: not simulated)
                ident, x, y, z = _PACKED_ITEM.unpack_from(data, k * _PACKED_ITEM.size)
                if ident == self.packed_id:
                    v.external_position((x / 1000.0, y / 1000.0, z / 1000.0), now_s)
        elif channel == 1 and data:
            kind = data[0]
            if kind == 8:
                x, y, z, qx, qy, qz, qw = struct.unpack("<fffffff", data[1:29])
                v.external_pose((x, y, z), (qx, qy, qz, qw), now_s)
            elif kind == 3:
                v.supervisor.request_emergency_stop()
            elif kind == 4:
                v.supervisor.notify_emergency_stop_watchdog(now_s)
        return []

    def _supervisor(self, channel: int, data: bytes, now_s: float) -> list[Packet]:
        if not data:
            return []
        sup = self.vehicle.supervisor
        cmd = data[0]
        if channel == 0:
            bits = self.supervisor_bits()
            if cmd == 0x0C:
                return [(PORT_SUPERVISOR, 0, bytes([0x80 | cmd]) + struct.pack("<H", bits))]
            if 0x01 <= cmd <= 0x0B:
                return [(PORT_SUPERVISOR, 0, bytes([0x80 | cmd, (bits >> (cmd - 1)) & 1]))]
            return []
        if channel == 1:
            if cmd == 0x01:
                success = sup.request_arming(bool(data[1]) if len(data) > 1 else True)
                return [(PORT_SUPERVISOR, 1, bytes([0x81, int(success), int(sup.armed)]))]
            if cmd == 0x02:  # crash recovery: refused while tumbled (the firmware's rule); a crash here tumbles for good
                recovered = not sup.tumbled
                return [(PORT_SUPERVISOR, 1, bytes([0x82, int(recovered), int(recovered)]))]
            if cmd == 0x03:
                sup.request_emergency_stop()
            elif cmd == 0x04:
                sup.notify_emergency_stop_watchdog(now_s)
        return []

    _HANDLERS: Mapping[int, Callable[[FakeFirmware, int, bytes, float], list[Packet]]] = MappingProxyType({
        PORT_LINK: _link,
        PORT_PLATFORM: _platform,
        PORT_MEM: _mem,
        PORT_LOG: _log,
        PORT_PARAM: _param,
        PORT_COMMANDER: _commander,
        PORT_COMMANDER_GENERIC: _commander_generic,
        PORT_SETPOINT_HL: _high_level,
        PORT_LOCALIZATION: _localization,
        PORT_SUPERVISOR: _supervisor,
    })
