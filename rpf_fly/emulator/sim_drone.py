"""One simulated drone as the radio reaches it (rpf_fly/emulator/fake_world.py holds them): its firmware, its
downlink queue, its link's loss and counters (:class:`SimDrone`), and the port a fake link transacts through
(:class:`DronePort`).
"""

from __future__ import annotations

import logging
import random
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from .burst_loss import BurstChannel
from .crtp import Packet
from .fake_firmware import FakeFirmware

if TYPE_CHECKING:
    from .fake_world import FakeDroneConfig, FakeWorld

logger = logging.getLogger(__name__)

TX_QUEUE_SIZE = 64
"""Downlink packets a firmware buffers; when full, new packets (log data) are dropped, as the firmware's CRTP queue
does."""

PacketObserver = Callable[[int, int, bytes, float], None]
"""``observer(port, channel, payload, monotonic_s)``, called after the firmware handled an uplink packet."""

DownlinkSink = Callable[[Packet], None]
"""Where a drone's downlink packets go as the firmware queues them, instead of its own queue: a piped link's
radio server pushes each to the link's process (rpf_fly/emulator/remote_world.py, "Piped links")."""


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


class SimDrone:
    """World-side state of one drone: its firmware, downlink queue, faults and attached links. Thread-safe."""

    def __init__(self, address: int, config: FakeDroneConfig, now_s: float, seed: int) -> None:
        self.address = address
        self.config = config
        self.firmware = FakeFirmware(
            config.vehicle,
            now_s=now_s,
            rssi=config.rssi_dbm,
            seed=seed,
            radio_address=address,
            radio_channel=config.channel or 80,
        )
        self.seed = seed
        self.rng = random.Random(seed)
        self._lock = threading.Lock()
        self._tx: deque[Packet] = deque()
        self._wakers: set[threading.Event] = set()
        self._observers: list[PacketObserver] = []
        self._sinks: list[DownlinkSink] = []
        self.flushes = 0
        """How many times its downlink queue was forgotten (a reboot): a piped link forgets its copy too."""
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
            self.flushes += 1

    def reachable(self, channel: int) -> bool:
        """True if the drone answers the radio on `channel` now."""
        wanted = self.config.channel
        return self.firmware.powered and not self.link_dropped and (wanted is None or wanted == channel)

    def link_state(self) -> tuple[bool, tuple[float, float] | None, int]:
        """What a piped link needs to decide its transactions itself: (answering the radio at all now, on its
        channel: powered and its link not dropped; the runtime loss fault as (rate, until world time) or None;
        `flushes`)."""
        return self.firmware.powered and not self.link_dropped, self._loss_override, self.flushes

    def record(self, acked: bool, retries: int, uplink: tuple[int, bytes] | None, now_s: float) -> None:
        """A transaction a piped link decided itself (acknowledged or not after ``retries``): counted as
        `DronePort.transact` counts its own, and an acknowledged uplink packet handed to the firmware."""
        if not acked:
            self.count_lost(1, retries + 1)
            return
        if retries:
            self.count_lost(0, retries)
        if uplink is not None:
            self.deliver(uplink, now_s)
        with self._lock:
            self.transactions += 1

    def attach_sink(self, sink: DownlinkSink) -> None:
        """Piped links opened: from now on the downlink packets go to ``sink`` (the radio server's one for this
        drone, which picks the link: rpf_fly/emulator/world_server.py), not to this drone's queue; those already
        queued go first."""
        with self._lock:
            self._sinks.append(sink)
            queued = list(self._tx)
            self._tx.clear()
        for packet in queued:
            sink(packet)

    def detach_sink(self, sink: DownlinkSink) -> None:
        with self._lock:
            if sink in self._sinks:
                self._sinks.remove(sink)

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
            sink = self._sinks[-1] if self._sinks else None
            if sink is None and not self._wakers:
                return  # no link attached: nobody polls, the firmware's queue would only fill with stale data
        if sink is not None:  # the piped link's process keeps the queue (and its limit)
            for packet in packets:
                sink(packet)
            return
        with self._lock:
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

    This one calls the drone in the same process; :class:`rpf_fly.emulator.remote_world.RemotePort` reaches a drone
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

    @property
    def drone(self) -> SimDrone:
        """The drone itself (a piped link's radio server reaches its queue, loss and counters)."""
        return self._drone
