"""A world of fake Crazyflies: their firmwares, radio-side fault configuration and a real-time dynamics thread.

`FakeWorld` owns one `FakeFirmware` per radio address and a thread that steps them all every `step_s` (10 ms) on
the world clock (seconds since `start()`), queueing their log packets for the radio links (`fake_radio`). After
each step it checks contacts between the drones and with the mission's obstacles (`fake_contact`: a drone that
touched something crashes) and keeps the step's truth (`FakeWorld.truth_samples`, for a dry run's log). It also
exposes the true poses of all drones (for a NatNet emulator) and firmware snapshots (for test assertions).

Addresses are the 5-byte radio addresses as integers (0xE7E7E7E701); strings are read as hexadecimal.
"""

from __future__ import annotations

import bisect
import logging
import math
import random
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

from rpf_fly.mission.model import Obstacle

from .fake_contact import ContactModel
from .fake_firmware import FakeFirmware, FirmwareSnapshot, Packet
from .host_lag import LagMeter
from .fake_vehicle import VehicleConfig

logger = logging.getLogger(__name__)

BOOT_S = 1.0
"""Each firmware runs this long (synthetic time, at `start`) before world time 0, so drones are booted, through
their pre-flight checks and (auto-)armed when cflib connects, as real drones powered on beforehand are."""

TX_QUEUE_SIZE = 64
"""Downlink packets a firmware buffers; when full, new packets (log data) are dropped, as the firmware's CRTP queue
does."""

TRUTH_BUFFER_S = 5.0
"""Seconds of truth samples the world keeps for `FakeWorld.truth_samples` (older ones are dropped): a dry run's log
fetches them ten times a second; a world nobody reads from does not grow."""

TruthState = tuple[tuple[float, float, float], float, bool, bool, tuple[float, float, float]]
"""``(position, yaw, motors, crashed, estimate)`` of one drone: true centre (m), true yaw (rad), motors spinning,
crashed (`fake_contact`), the firmware's estimated position (m). Plain tuples: they cross to the flight's process
as a cheap pickle and go into the log as they are (`rpf_fly.log.schemas.truth_json`)."""

TruthSample = tuple[float, dict[int, TruthState]]
"""``(monotonic_s, {address: state})``: every drone's true state after one world step, stamped with the
``time.monotonic()`` the step advanced the drones to (one clock for all processes of a machine)."""

PacketObserver = Callable[[int, int, bytes, float], None]
"""``observer(port, channel, payload, monotonic_s)``, called after the firmware handled an uplink packet."""


@dataclass(frozen=True)
class BurstLoss:
    """Bursty radio loss of one link: a two-state (Gilbert-Elliott) channel in continuous time.

    Why: a 2.4 GHz link loses packets in bursts (a WiFi burst on the channel, a body or the drone's own frame in the
    line of sight, a multipath fade, motor noise), not independently; a burst of tens of milliseconds costs a
    streamed setpoint or a few extpos in a row, which independent loss of the same mean rarely does. The link is in
    a *good* or a *bad* state; each state lasts an exponentially distributed time of mean `mean_good_s` /
    `mean_bad_s` (world time, whatever the traffic), and each radio attempt is lost with that state's probability.
    The defaults are a Crazyradio PA in a lab on a channel clear of the lab's WiFi (docs/radio.md, "Bursty loss",
    gives each figure's source or says it is an assumption):

    - long-run share of time in the bad state ``mean_bad_s / (mean_good_s + mean_bad_s)`` = 2.9 %;
    - long-run loss of an attempt at an arbitrary moment ``0.971 * 1 % + 0.029 * 60 %`` = 2.7 % (`mean_loss`);
      of all attempts, retries included (which crowd into the bursts), 4.6 % (`retried_loss`);
    - cflib's link quality (10 points a retry, averaged over the last 100 acks) reads 99.9 % in the good state and
      dips by about 1 point in a 30 ms burst, by 3 in a 100 ms one: below 100 %, never near the supervisor's 95 %.
    """

    good_loss: float = 0.01
    """Attempt loss in the good state (assumption: a line-of-sight Crazyradio PA link at lab range, 1 %)."""
    bad_loss: float = 0.6
    """Attempt loss in the bad state (assumption: most attempts collide with a WiFi frame burst or sit in a fade).
    A transaction then loses all its 4 attempts with 0.6^4 = 13 %: a burst costs retries and lost acks, while the
    100 lost acks in a row that drop cflib's link need a burst of near 100 % loss lasting over 0.1 s."""
    mean_good_s: float = 1.0
    """Mean time between bursts, seconds (assumption: about one burst a second)."""
    mean_bad_s: float = 0.03
    """Mean burst length, seconds (tens of ms: a WiFi TXOP burst or block-ack exchange lasts 2-10 ms and comes in
    trains; a fade at walking or flying speed lasts about half a wavelength, 6 cm, over 1 m/s: 60 ms)."""

    def __post_init__(self) -> None:
        for name in ("good_loss", "bad_loss"):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise ValueError(f"{name} must be in [0, 1], not {value}")
        for name in ("mean_good_s", "mean_bad_s"):
            value = getattr(self, name)
            if not value > 0.0:
                raise ValueError(f"{name} must be > 0 s, not {value}")

    @property
    def bad_share(self) -> float:
        """Long-run share of time in the bad state."""
        return self.mean_bad_s / (self.mean_good_s + self.mean_bad_s)

    @property
    def mean_loss(self) -> float:
        """Long-run probability that an attempt made at an arbitrary moment is lost (a transaction's first
        attempt): the time average of the two states' losses."""
        return (1.0 - self.bad_share) * self.good_loss + self.bad_share * self.bad_loss

    def retried_loss(self, arc_retries: int) -> float:
        """Long-run share of all attempts lost, retries included, for transactions at arbitrary moments that retry
        up to ``arc_retries`` times: higher than `mean_loss`, because the retries crowd into the bursts (a
        transaction makes 1.01 attempts in the good state, 2.18 in the bad one with the defaults)."""
        lost = made = 0.0
        for share, p in ((1.0 - self.bad_share, self.good_loss), (self.bad_share, self.bad_loss)):
            tries = sum(p**n for n in range(arc_retries + 1))  # attempt n+1 is made if the first n were lost
            made += share * tries
            lost += share * (tries - (1.0 - p ** (arc_retries + 1)))
        return lost / made


class BurstChannel:
    """The state sequence of one link's `BurstLoss` channel on the world clock, drawn lazily from its own seeded
    generator, so the bursts of a world seed and drone are the same in every run whatever the radio traffic (which
    attempts fall into them depends on the traffic). Thread-safe (the fake links of a world in this process call
    it from their own threads)."""

    KEEP_S = 600.0
    """Seconds of past states kept (about 1200 with the defaults): a late caller (a link thread whose clock reading
    is a little older) finds its state, and a test or tool looks a whole flight's bursts up afterwards."""

    def __init__(self, model: BurstLoss, seed: int | str) -> None:
        self.model = model
        self._rng = random.Random(seed)
        self._lock = threading.Lock()
        bad = self._rng.random() < model.bad_share  # the stationary distribution: world time 0 is any moment
        self._starts: list[float] = [0.0]
        self._bad: list[bool] = [bad]
        self._end = self._dwell(bad)

    def _dwell(self, bad: bool) -> float:
        return self._rng.expovariate(1.0 / (self.model.mean_bad_s if bad else self.model.mean_good_s))

    def _extend(self, t: float) -> None:
        while self._end <= t:
            bad = not self._bad[-1]
            self._starts.append(self._end)
            self._bad.append(bad)
            self._end += self._dwell(bad)
        if len(self._starts) > 64 and self._starts[32] < t - self.KEEP_S:
            del self._starts[:32], self._bad[:32]

    def bad_at(self, t: float) -> bool:
        """True while the link is in its bad state at world time ``t`` (seconds)."""
        with self._lock:
            self._extend(t)
            return self._bad[max(0, bisect.bisect_right(self._starts, t) - 1)]

    def loss_at(self, t: float) -> float:
        """The probability that an attempt at world time ``t`` is lost."""
        return self.model.bad_loss if self.bad_at(t) else self.model.good_loss

    def bad_intervals(self, start_s: float, end_s: float) -> list[tuple[float, float]]:
        """The bad states overlapping [start_s, end_s] as (start, end) world times, clipped to the window (only the
        last `KEEP_S` seconds are kept)."""
        with self._lock:
            self._extend(end_s)
            out = []
            bounds = self._starts[1:] + [self._end]
            for begin, end, bad in zip(self._starts, bounds, self._bad):
                if bad and end > start_s and begin < end_s:
                    out.append((max(begin, start_s), min(end, end_s)))
            return out


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
class RadioCounters:
    """One drone's radio transactions since the world was created, as its radio saw them."""

    transactions: int
    """Acknowledged transactions (packets and empty polls)."""
    lost_transactions: int
    """Transactions that got no ack (each of the radio's attempts lost, or the drone did not answer): what
    cflib's radio driver counts towards its 100 lost acks."""
    lost_attempts: int
    """Single attempts lost, retried ones included (the retries that lower cflib's link quality)."""


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
    def at(cls, x: float, y: float, z: float = 0.0, **kwargs: object) -> FakeDroneConfig:
        """Shorthand: a drone at (x, y, z) metres; keyword arguments go to `VehicleConfig` (yaw_deg, initial_vbat_v,
        auto_arm, positioning) or to this class (faults, rssi_dbm, channel)."""
        own = {k: kwargs.pop(k) for k in ("faults", "rssi_dbm", "channel") if k in kwargs}
        return cls(vehicle=VehicleConfig(position=(x, y, z), **kwargs), **own)  # type: ignore[arg-type]


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


def parse_address(address: int | str) -> int:
    """A radio address as an integer (hexadecimal strings accepted)."""
    return int(address, 16) if isinstance(address, str) else int(address)


class SimDrone:
    """World-side state of one drone: its firmware, downlink queue, faults and attached links. Thread-safe."""

    def __init__(self, address: int, config: FakeDroneConfig, now_s: float, seed: int) -> None:
        self.address = address
        self.config = config
        self.firmware = FakeFirmware(config.vehicle, now_s=now_s, rssi=config.rssi_dbm, seed=seed,
                                     radio_address=address, radio_channel=config.channel or 80)
        self.rng = random.Random(seed)
        self._lock = threading.Lock()
        self._tx: deque[Packet] = deque()
        self._wakers: set[threading.Event] = set()
        self._observers: list[PacketObserver] = []
        self.link_dropped = False
        self.drop_fault_applied = False
        self.tx_dropped = 0
        """Downlink packets dropped because the queue was full."""
        self.transactions = 0
        """Acknowledged radio transactions (packets and empty polls) with this drone."""
        self.lost_transactions = 0
        self.lost_attempts = 0
        self._loss_override: tuple[float, float] | None = None
        """(rate, until world time) of a runtime packet-loss fault (`FakeWorld.packet_loss`)."""
        burst = config.faults.burst
        self.channel = BurstChannel(burst, f"burst:{seed}") if burst is not None else None
        """The link's bursty-loss channel (`LinkFaults.burst`), None without one. Its own generator (seeded from
        the drone's seed), so its bursts do not depend on how many attempts were drawn before."""

    def packet_loss(self, now_s: float) -> float:
        """The probability that one radio attempt is lost now: a runtime fault while it lasts (it replaces the
        configured loss, bursts included), else the configured `LinkFaults.packet_loss` combined with the burst
        channel's state (independent causes: an attempt survives only if neither loses it)."""
        override = self._loss_override  # one read: a fault set meanwhile is not lost
        if override is not None and now_s < override[1]:
            return override[0]
        loss = self.config.faults.packet_loss
        if self.channel is not None:
            loss = 1.0 - (1.0 - loss) * (1.0 - self.channel.loss_at(now_s))
        return loss

    def set_packet_loss(self, rate: float, until_s: float) -> None:
        if not 0.0 <= rate <= 1.0:
            raise ValueError(f"packet loss rate must be in [0, 1], not {rate}")
        self._loss_override = (float(rate), until_s)

    def count_lost(self, transactions: int, attempts: int) -> None:
        with self._lock:
            self.lost_transactions += transactions
            self.lost_attempts += attempts

    def counters(self) -> RadioCounters:
        with self._lock:
            return RadioCounters(self.transactions, self.lost_transactions, self.lost_attempts)

    def flush_downlink(self) -> None:
        """Forget the queued downlink packets (a rebooted firmware lost its queue)."""
        with self._lock:
            self._tx.clear()

    def reachable(self, channel: int) -> bool:
        """True if the drone answers the radio on `channel` now."""
        wanted = self.config.channel
        return self.firmware.powered and not self.link_dropped and (wanted is None or wanted == channel)

    def attach(self, waker: threading.Event) -> None:
        with self._lock:
            self._wakers.add(waker)

    def detach(self, waker: threading.Event) -> None:
        """Detach a link; with no link left the downlink queue is flushed (no stale data for the next one)."""
        with self._lock:
            self._wakers.discard(waker)
            if not self._wakers:
                self._tx.clear()

    def add_observer(self, observer: PacketObserver) -> None:
        with self._lock:
            self._observers.append(observer)

    def remove_observer(self, observer: PacketObserver) -> None:
        with self._lock:
            if observer in self._observers:
                self._observers.remove(observer)

    def enqueue(self, packets: list[Packet]) -> None:
        """Queue downlink packets and wake the attached links (dropped while no link is attached)."""
        if not packets:
            return
        with self._lock:
            if not self._wakers:
                return  # no link attached: nobody polls, the firmware's queue would only fill with stale data
            for packet in packets:
                if len(self._tx) >= TX_QUEUE_SIZE:
                    self.tx_dropped += 1
                    continue
                self._tx.append(packet)
            wakers = list(self._wakers)
        for waker in wakers:
            waker.set()

    def has_downlink(self) -> bool:
        return bool(self._tx)

    def hear(self, channel: int, uplink: tuple[int, bytes], now_s: float, copies: int) -> int:
        """A broadcast on ``channel`` (no acknowledgement, no downlink, no transaction counted): each of its
        ``copies`` transmissions reaches the firmware unless lost with the drone's attempt loss now; returns how
        many it heard."""
        if not self.reachable(channel):
            return 0
        loss = self.packet_loss(now_s)
        heard = sum(1 for _ in range(copies) if loss <= 0.0 or self.rng.random() >= loss)
        for _ in range(heard):
            self.deliver(uplink, now_s)
        return heard

    def deliver(self, uplink: tuple[int, bytes], now_s: float) -> None:
        """Hand one uplink packet (header, payload) to the firmware, queue its replies, tell the observers."""
        header, payload = uplink
        port, channel = (header >> 4) & 0x0F, header & 0x03
        replies = self.firmware.handle(port, channel, payload, now_s)
        self.enqueue(replies)
        with self._lock:
            observers = list(self._observers)
        stamp = time.monotonic()
        for observer in observers:
            try:
                observer(port, channel, payload, stamp)
            except Exception:  # an observer must not break the radio
                logger.exception("packet observer failed")

    def exchange(self, uplink: tuple[int, bytes] | None, now_s: float) -> Packet | None:
        """One acknowledged radio transaction: deliver `uplink` (header, payload) to the firmware, return at most one
        queued downlink packet (the ack payload)."""
        if uplink is not None:
            self.deliver(uplink, now_s)
        with self._lock:
            self.transactions += 1
            return self._tx.popleft() if self._tx else None


class DronePort:
    """What a fake radio link reaches of one drone: radio transactions, its link settings and its downlink queue.

    This one calls the drone in the same process; :class:`rpf_fly.emulator.world_process.RemotePort` reaches a drone
    of a world in another process through the same methods."""

    def __init__(self, world: FakeWorld, drone: SimDrone) -> None:
        self._world = world
        self._drone = drone
        self.faults = drone.config.faults
        self.rssi_dbm = drone.config.rssi_dbm

    def transact(self, channel: int, uplink: tuple[int, bytes] | None) -> tuple[bool, int, Packet | None]:
        """One radio transaction on ``channel``: (acknowledged, retries used, the ack's downlink packet). Lost when
        the drone does not answer on that channel or each of the radio's attempts is lost (with the drone's packet
        loss now: `SimDrone.packet_loss`, so a runtime fault acts here, in whichever process runs the world)."""
        drone, retries = self._drone, self._world.timing.arc_retries
        if not drone.reachable(channel):
            drone.count_lost(1, retries + 1)
            return False, retries, None
        now = self._world.time_s()
        loss = drone.packet_loss(now)
        for retry in range(retries + 1):
            if loss <= 0.0 or drone.rng.random() >= loss:
                if retry:
                    drone.count_lost(0, retry)
                return True, retry, drone.exchange(uplink, now)
        drone.count_lost(1, retries + 1)
        return False, retries, None

    def has_downlink(self) -> bool:
        return self._drone.has_downlink()

    def attach(self, waker: threading.Event) -> None:
        self._drone.attach(waker)

    def detach(self, waker: threading.Event) -> None:
        self._drone.detach(waker)


class FakeWorld:
    """Fake Crazyflies keyed by radio address, stepped in real time by one thread.

    Use as a context manager or call `start()` / `close()`; `fake_radio.register(world)` makes cflib reach it
    through ``fake://`` URIs (the first link to connect starts it). Closing the world powers every drone off:
    connected cflib links then fail with a link error.
    """

    def __init__(
        self,
        drones: Mapping[int | str, FakeDroneConfig],
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
                    drone = SimDrone(addr, FakeDroneConfig.at(x, y, 0.0), now - BOOT_S,
                                     self.seed * 1_000_003 + addr % 1_000_003)
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
        for address, snap in self.snapshots().items():
            half = math.radians(snap.yaw_deg) / 2.0
            poses[address] = (snap.position, (0.0, 0.0, math.sin(half), math.cos(half)))
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

    def wait_until(
        self, predicate: Callable[[FakeWorld], bool], timeout_s: float, poll_s: float = 0.01
    ) -> bool:
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

    def _after_step(self, now: float) -> None:
        """Contacts, then the truth sample of the step that advanced every drone to world time ``now``."""
        bodies = {address: drone.firmware.body() for address, drone in self._drones.items()}
        for contact in self._contacts.check(bodies):
            firmware = self._drones[contact.address].firmware
            if firmware.crash(now, contact.reason, contact.position):
                logger.warning("fake drone %010X crashed at %.3f s: %s", contact.address, now, contact.reason)
            bodies[contact.address] = firmware.body()
        self._truth.append((self._t0 + now, {a: (b.position, b.yaw, b.motors_on, b.crashed, b.estimate)
                                             for a, b in bodies.items()}))
