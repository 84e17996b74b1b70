"""A world of fake Crazyflies: their firmwares, radio-side fault configuration and a real-time dynamics thread.

`FakeWorld` owns one `FakeFirmware` per radio address and a thread that steps them all every `step_s` (10 ms) on
the world clock (seconds since `start()`), queueing their log packets for the radio links (`fake_radio`). After
each step it checks contacts between the drones and with the mission's obstacles (`fake_contact`: a drone that
touched something crashes) and keeps the step's truth (`FakeWorld.truth_samples`, for a dry run's log). It also
exposes the true poses of all drones (for a NatNet emulator) and firmware snapshots (for test assertions). Each
drone's radio side is a `SimDrone` reached through a `DronePort` (`sim_drone`); its link's bursty loss is
`burst_loss`'s, the emulated Crazyradio's timing and shared air `dongle_air`'s.

Addresses are the 5-byte radio addresses as integers (0xE7E7E7E701); strings are read as hexadecimal.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from rpf_fly.mission.model import Obstacle

from .burst_loss import BurstLoss
from .dongle_air import DongleAir, RadioTiming
from .fake_contact import ContactModel
from .fake_firmware import FakeFirmware, FirmwareSnapshot
from .fake_vehicle import VehicleConfig
from .host_lag import LagMeter
from .sim_drone import DronePort, PacketObserver, RadioCounters, SimDrone

logger = logging.getLogger(__name__)

BOOT_S = 1.0
"""Each firmware runs this long (synthetic time, at `start`) before world time 0, so drones are booted, through
their pre-flight checks and (auto-)armed when cflib connects, as real drones powered on beforehand are."""

TRUTH_BUFFER_S = 5.0
"""Seconds of truth samples the world keeps for `FakeWorld.truth_samples` (older ones are dropped): a dry run's log
fetches them ten times a second; a world nobody reads from does not grow."""

TruthState = tuple[tuple[float, float, float], float, bool, bool, tuple[float, float, float]]
"""``(position, yaw, motors, crashed, estimate)`` of one drone: true centre (m), true yaw (rad), motors spinning,
crashed (`fake_contact`), the firmware's estimated position (m). Plain tuples: they cross to the flight's process
as a cheap pickle and go into the log as they are (`rpf_fly.log.encoding.truth_json`)."""

TruthSample = tuple[float, dict[int, TruthState]]
"""``(monotonic_s, {address: state})``: every drone's true state after one world step, stamped with the
``time.monotonic()`` the step advanced the drones to (one clock for all processes of a machine)."""


@dataclass(frozen=True)
class LinkFaults:
    """Radio faults of one drone."""

    packet_loss: float = 0.0
    """Probability that one radio transmission attempt is lost (0-1), independently of every other. The radio
    retries each packet up to 3 times within a transaction (lowering link quality); a transaction whose 4 attempts
    are all lost is a lost ack, and 100 lost acks in a row drop the link, as cflib's radio driver does."""
    burst: BurstLoss | None = None
    """Bursty loss (`BurstLoss`) on top of `packet_loss` (an attempt gets through only if neither loses it); None:
    none. Off in a bare `FakeWorld` (the emulator's tests count exact retries), on in a dry run (`DryRun`'s
    ``radio_loss``)."""
    latency_s: float = 0.0
    """Added one-way delay in seconds, applied to each direction (the round trip grows by twice this)."""
    drop_link_at_s: float | None = None
    """World time (seconds since the world started) at which the drone stops answering the radio for good."""

    def __post_init__(self) -> None:
        if not 0.0 <= self.packet_loss <= 1.0:
            raise ValueError(f"packet_loss must be in [0, 1], not {self.packet_loss}")
        if self.latency_s < 0.0:
            raise ValueError(f"latency_s must be >= 0, not {self.latency_s}")


@dataclass(frozen=True)
class FakeDroneConfig:
    """One fake drone: initial state (see `VehicleConfig`), radio faults and radio settings."""

    vehicle: VehicleConfig = field(default_factory=VehicleConfig)
    faults: LinkFaults = field(default_factory=LinkFaults)
    rssi_dbm: int = 35
    """Reported RSSI (-dBm, as the firmware's `radio.rssi`)."""
    channel: int | None = None
    """Radio channel the drone listens on (None: any), so a URI with another channel gets no answer."""

    @classmethod
    def at(cls, x: float, y: float, z: float = 0.0, **kwargs: Any) -> FakeDroneConfig:
        """Shorthand: a drone at (x, y, z) metres; keyword arguments go to `VehicleConfig` (yaw_deg, initial_vbat_v,
        auto_arm, positioning) or to this class (faults, rssi_dbm, channel)."""
        own = {k: kwargs.pop(k) for k in ("faults", "rssi_dbm", "channel") if k in kwargs}
        return cls(vehicle=VehicleConfig(position=(x, y, z), **kwargs), **own)


def parse_address(address: int | str) -> int:
    """A radio address as an integer (hexadecimal strings accepted)."""
    return int(address, 16) if isinstance(address, str) else int(address)


class FakeWorld:
    """Fake Crazyflies keyed by radio address, stepped in real time by one thread.

    Use as a context manager or call `start()` / `close()`; `fake_radio.register(world)` makes cflib reach it
    through ``fake://`` URIs (the first link to connect starts it). Closing the world powers every drone off:
    connected cflib links then fail with a link error.
    """

    def __init__(
        self,
        drones: Mapping[int, FakeDroneConfig] | Mapping[str, FakeDroneConfig],
        *,
        step_s: float = 0.01,
        timing: RadioTiming | None = None,
        seed: int = 0,
        obstacles: Sequence[Obstacle] = (),
        appear_on_connect: bool = False,
    ) -> None:
        """``obstacles``: the mission's vertical obstacles (`CircleObstacle`, `BoxObstacle`), for contacts.
        ``appear_on_connect``: a link to an unknown address brings a drone into the world (:meth:`spawn`)."""
        self.step_s = step_s
        self.timing = timing or RadioTiming()
        self.seed = seed
        self._t0 = time.monotonic()
        self._drones = {
            parse_address(a): SimDrone(parse_address(a), cfg, -BOOT_S, seed * 1_000_003 + parse_address(a) % 1_000_003)
            for a, cfg in drones.items()
        }
        self._lock = threading.Lock()
        self._dongles: dict[int, DongleAir] = {}
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._started = False
        self._contacts = ContactModel(obstacles)
        self.appear_on_connect = appear_on_connect
        self.after_step: list[Callable[[float], None]] = []
        """Called on the dynamics thread after each step with its world time (the radio server pushes the piped
        links' drone states there: rpf_fly/emulator/world_server.py)."""
        self._truth: deque[TruthSample] = deque(maxlen=max(1, round(TRUTH_BUFFER_S / step_s)))
        self.lag = LagMeter()
        """How late the dynamics thread's steps run (`rpf_fly.emulator.host_lag`)."""

    # Life cycle -----------------------------------------------------------------------------------------------

    def start(self) -> FakeWorld:
        """Boot the firmwares (`BOOT_S`), then start the clock and the dynamics thread (idempotent). World time 0 is
        the first start."""
        with self._lock:
            if self._started:
                return self
            self._started = True
            ticks = round(BOOT_S / self.step_s)
            for drone in self._drones.values():
                for tick in range(1, ticks + 1):
                    drone.firmware.step(-BOOT_S + tick * self.step_s)
            self._t0 = time.monotonic()
            self._thread = threading.Thread(target=self._run, name="FakeWorld", daemon=True)
            self._thread.start()
        return self

    def close(self) -> None:
        """Stop the dynamics thread and power every drone off (links fail with a link error)."""
        self._stop.set()
        with self._lock:
            for drone in self._drones.values():
                drone.link_dropped = True
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=2.0)

    def __enter__(self) -> FakeWorld:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def running(self) -> bool:
        return self._started and not self._stop.is_set()

    def time_s(self) -> float:
        """World time in seconds (0 before `start`)."""
        return time.monotonic() - self._t0 if self._started else 0.0

    # Drones ---------------------------------------------------------------------------------------------------

    @property
    def addresses(self) -> tuple[int, ...]:
        return tuple(self._drones)

    def drone(self, address: int | str) -> SimDrone | None:
        """The drone at `address`, None if there is none."""
        return self._drones.get(parse_address(address))

    GRID_M = 0.5
    """Spacing of the grid drones appear on (``appear_on_connect``), ten a row."""

    def spawn(self, address: int | str, place: tuple[float, float] | None = None) -> DronePort | None:
        """The radio side of the drone at ``address``; with ``appear_on_connect`` an unknown address first brings a
        booted drone onto the floor at ``place`` or the next grid spot. The drone table is replaced, not changed,
        so the dynamics thread's loop over it is never disturbed."""
        addr = parse_address(address)
        if addr not in self._drones and self.appear_on_connect:
            with self._lock:
                if addr not in self._drones:
                    n = len(self._drones)
                    x, y = place if place is not None else ((n % 10) * self.GRID_M, (n // 10) * self.GRID_M)
                    now = self.time_s()
                    drone = SimDrone(
                        addr, FakeDroneConfig.at(x, y, 0.0), now - BOOT_S, self.seed * 1_000_003 + addr % 1_000_003
                    )
                    ticks = round(BOOT_S / self.step_s)
                    for tick in range(1, ticks + 1):
                        drone.firmware.step(now - BOOT_S + tick * self.step_s)
                    self._drones = {**self._drones, addr: drone}
        return self.port(addr)

    def port(self, address: int | str) -> DronePort | None:
        """The radio side of the drone at `address` for a fake link, None if there is none."""
        drone = self._drones.get(parse_address(address))
        return DronePort(self, drone) if drone is not None else None

    def broadcast(self, channel: int, uplink: tuple[int, bytes], copies: int) -> int:
        """One broadcast (a packed extpos) on ``channel``: every drone listening there hears each of its ``copies``
        transmissions unless its link loses it (`SimDrone.hear`); returns the copies heard in all."""
        now = self.time_s()
        return sum(drone.hear(channel, uplink, now, copies) for drone in self._drones.values())

    def firmware(self, address: int | str) -> FakeFirmware:
        """The firmware at `address` (KeyError if none)."""
        return self._drones[parse_address(address)].firmware

    def snapshot(self, address: int | str) -> FirmwareSnapshot:
        return self.firmware(address).snapshot()

    def snapshots(self) -> dict[int, FirmwareSnapshot]:
        return {address: drone.firmware.snapshot() for address, drone in self._drones.items()}

    def true_poses(self) -> dict[int, tuple[tuple[float, float, float], tuple[float, float, float, float]]]:
        """address -> (position m, quaternion qx, qy, qz, qw) of every drone's true pose (yaw only)."""
        poses = {}
        for address, drone in self._drones.items():
            position, yaw_deg = drone.firmware.true_pose()
            half = math.radians(yaw_deg) / 2.0
            poses[address] = (position, (0.0, 0.0, math.sin(half), math.cos(half)))
        return poses

    def truth_samples(self) -> list[TruthSample]:
        """The truth samples taken since the previous call, oldest first (one per world step, at most the last
        `TRUTH_BUFFER_S`); each call hands them over once (one reader: the dry run's log)."""
        out = []
        pop = self._truth.popleft
        for _ in range(len(self._truth)):
            out.append(pop())
        return out

    def uri(self, address: int | str, *, devid: int = 0, channel: int | None = None, datarate: str = "2M") -> str:
        """The ``fake://`` URI of a drone."""
        addr = parse_address(address)
        drone = self._drones.get(addr)
        chan = channel if channel is not None else (drone.config.channel if drone and drone.config.channel else 80)
        return f"fake://{devid}/{chan}/{datarate}/{addr:010X}"

    def drop_link(self, address: int | str) -> None:
        """The drone stops answering the radio now (it keeps flying on its own)."""
        self._drones[parse_address(address)].link_dropped = True

    def restore_link(self, address: int | str) -> None:
        """The drone answers the radio again (a new connection is needed after cflib dropped the link)."""
        self._drones[parse_address(address)].link_dropped = False

    def disturb(self, address: int | str, offset_m: tuple[float, float, float]) -> None:
        """Push one drone's true position by ``offset_m`` metres now (a gust; see `FakeFirmware.disturb`)."""
        self._drones[parse_address(address)].firmware.disturb(offset_m)

    def set_battery(self, address: int | str, open_circuit_v: float) -> None:
        """Set one drone's battery open-circuit voltage now (see `FakeFirmware.set_battery`)."""
        self._drones[parse_address(address)].firmware.set_battery(open_circuit_v)

    def reboot(self, address: int | str) -> None:
        """Power-cycle one drone now, as a brown-out would (see `FakeFirmware.reboot`): motors off at once and a
        flying drone falls to the floor; radio silent for `REBOOT_BOOT_S` (1.5 s), so a connected cflib link fails
        with "Too many packets lost"; then a fresh flight stack on the floor where it fell (default parameters,
        estimator at `kalman.initial*` = 0, supervisor fresh, a lock cleared), reachable by a new connection."""
        drone = self._drones[parse_address(address)]
        drone.firmware.reboot(self.time_s())
        drone.flush_downlink()

    def packet_loss(self, address: int | str, rate: float, seconds: float) -> None:
        """For ``seconds`` from now each radio attempt with this drone is lost with probability ``rate`` (0-1),
        independently, instead of its configured `LinkFaults.packet_loss` and bursts (interference, a drone flying
        behind an obstacle); the burst channel runs on meanwhile and is back when the fault expires. The
        same model: the radio retries each packet 3 times, a transaction whose 4 attempts are all lost is a lost
        ack, 100 in a row drop cflib's link; retries lower cflib's link quality. The fault then expires."""
        if seconds < 0.0:
            raise ValueError(f"seconds must be >= 0, not {seconds}")
        self._drones[parse_address(address)].set_packet_loss(rate, self.time_s() + seconds)

    def gust(self, address: int | str, accel_m_s2: tuple[float, float, float], seconds: float) -> None:
        """An external acceleration on one drone's true body for ``seconds``, fought by its position controller
        (see `FakeFirmware.gust`; 1.5 m/s^2 holds a hovering drone 17.6 cm off its setpoint). `disturb` is the
        teleport."""
        if seconds < 0.0:
            raise ValueError(f"seconds must be >= 0, not {seconds}")
        self._drones[parse_address(address)].firmware.gust(accel_m_s2, seconds, self.time_s())

    def estimator_divergence(self, address: int | str, rate_m_s: float) -> None:
        """From now until a reboot one drone's estimator ignores extpos/extpose and its estimate runs away at
        ``rate_m_s`` horizontally (see `FakeFirmware.estimator_divergence`): the true drone drifts the other way
        while its telemetry looks fine."""
        self._drones[parse_address(address)].firmware.estimator_divergence(rate_m_s)

    def radio_counters(self, address: int | str) -> RadioCounters:
        """One drone's acknowledged and lost radio transactions and lost attempts so far."""
        return self._drones[parse_address(address)].counters()

    def radio_bursts(self, address: int | str, start_s: float, end_s: float) -> list[tuple[float, float]]:
        """The bad states of one drone's bursty-loss channel (`LinkFaults.burst`) overlapping world times
        [start_s, end_s], as (start, end) world times; [] without one. Deterministic per world seed and address,
        and may look ahead of the world clock."""
        channel = self._drones[parse_address(address)].channel
        return channel.bad_intervals(start_s, end_s) if channel is not None else []

    def add_packet_observer(self, address: int | str, observer: PacketObserver) -> None:
        """Call `observer` after the firmware at `address` handled each uplink packet (on the link's thread)."""
        self._drones[parse_address(address)].add_observer(observer)

    def remove_packet_observer(self, address: int | str, observer: PacketObserver) -> None:
        self._drones[parse_address(address)].remove_observer(observer)

    def wait_until(self, predicate: Callable[[FakeWorld], bool], timeout_s: float, poll_s: float = 0.01) -> bool:
        """Poll `predicate(world)` until it is true (returns True) or `timeout_s` passes (returns False)."""
        deadline = time.monotonic() + timeout_s
        while True:
            if predicate(self):
                return True
            if time.monotonic() >= deadline:
                return False
            time.sleep(poll_s)

    def dongle(self, devid: int) -> DongleAir:
        """The air of one dongle number, shared by its links (`DongleAir`)."""
        with self._lock:
            return self._dongles.setdefault(devid, DongleAir())

    # Dynamics thread ------------------------------------------------------------------------------------------

    def _run(self) -> None:
        next_s = self.step_s
        while not self._stop.is_set():
            now = self.time_s()
            if now < next_s:
                self._stop.wait(next_s - now)
                continue
            self.lag.record(now - next_s, now, self.step_s)
            next_s = now + self.step_s if now - next_s > 0.1 else next_s + self.step_s
            for drone in self._drones.values():
                faults = drone.config.faults
                if faults.drop_link_at_s is not None and now >= faults.drop_link_at_s and not drone.drop_fault_applied:
                    logger.info("fake drone %010X: link dropped at %.3f s (fault)", drone.address, now)
                    drone.drop_fault_applied = drone.link_dropped = True
                drone.enqueue(drone.firmware.step(now))
            self._after_step(now)
            for listener in self.after_step:
                listener(now)

    def _after_step(self, now: float) -> None:
        """Contacts, then the truth sample of the step that advanced every drone to world time ``now``."""
        bodies = {address: drone.firmware.body() for address, drone in self._drones.items()}
        for contact in self._contacts.check(bodies):
            firmware = self._drones[contact.address].firmware
            if firmware.crash(now, contact.reason, contact.position):
                logger.warning("fake drone %010X crashed at %.3f s: %s", contact.address, now, contact.reason)
            bodies[contact.address] = firmware.body()
        self._truth.append(
            (self._t0 + now, {a: (b.position, b.yaw, b.motors_on, b.crashed, b.estimate) for a, b in bodies.items()})
        )
