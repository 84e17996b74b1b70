"""The fake radio: a cflib link driver for ``fake://`` URIs that reaches the drones of a `FakeWorld`.

``register(world)`` appends a driver class bound to `world` to ``cflib.crtp.CLASSES`` (replacing any fake driver
registered before); from then on any cflib program opens ``fake://<dongle>/<channel>/<rate>/<address>`` exactly as
it opens the same ``radio://`` URI. ``unregister()`` removes it. ``cflib.crtp.init_drivers()`` may be called before
or after: the radio drivers refuse ``fake://`` URIs.

Each link runs a thread that emulates cflib's Crazyradio driver with safelink (so `needs_resending` is False):
- every transaction carries one uplink packet (or an empty poll every 10 ms when idle, back to back while the drone
  has data queued) and is acknowledged with at most one downlink packet;
- a transaction fails when the drone does not answer (unknown address, wrong channel, link dropped, drone powered
  off) or when each of its 4 attempts is lost (`LinkFaults.packet_loss`, bursts of `LinkFaults.burst`, a runtime
  `packet_loss` fault); a failed transaction is retried with the same packet after 1 ms, and 100 failures in a
  row call cflib's link-error callback with "Too many packets lost" (so an unknown address fails to connect after
  about 0.1 s instead of hanging);
- successful transactions feed cflib's own `RadioLinkStatistics` with the attempt count as the retry count and an
  empty ack as the default nRF51 build sends it (the one byte 0xF3: no RSSI, as the emulated Crazyradio's drones
  answer), so link quality, rates and congestion reach `cf.link_statistics` as with a Crazyradio and `uplink_rssi`
  does not, as it does not from a real Crazyflie; cflib's latency pings are answered by the firmware's echo;
- `LinkFaults.latency_s` delays both directions;
- the links of one dongle number take turns on its air (`fake_world.DongleAir`): each transaction holds the dongle
  for `RadioTiming.transaction_s` only, the drone's answer being computed outside that slot (a dry run's UDP
  round trip to the world process is emulation, not radio);
- the link holds at most `DRIVER_PACKETS` (2) uplink packets, as cflib's radio driver does (an out queue of one,
  one in the radio thread's transaction): a further `send` blocks the sender until the radio has taken one (a
  radio over its budget slows the sender down, never builds an ever-longer queue of stale setpoints), and fails
  the link after `SEND_TIMEOUT_S` (2 s), with cflib's message;
- closing a link first transmits the uplink packets already queued, so the zero-thrust setpoint that cflib's
  `close_link` sends always reaches the drone (with a Crazyradio it is a race): the fake takes the pessimistic side;
- `unplug(devid)` pulls that dongle out (the ``dongle_unplug`` fault): every open link on it fails at once with
  cflib's link-error callback and the message cflib's radio driver gives on a USB error (`UNPLUGGED`), nothing more
  reaches its drones, and a link opened on it later fails the same way on its first transaction; `replug(devid)`
  puts it back for links opened after, and `register` / `unregister` put every dongle back.
Empty acks are not queued to cflib (the real driver queues them as port-15 channel-3 packets, which cflib ignores).

Broadcasts (packed extpos, rpf_fly/radio/broadcast.py): `register` also registers `FakeBroadcast` for ``fake://``
links. A broadcast holds its dongle's air for one transaction and reaches every drone listening on its channel as
cflib's does on a Crazyradio (`packed_extpos.BROADCAST_COPIES` transmissions, each heard unless the drone's link
loses it: `FakeWorld.broadcast`).
"""

from __future__ import annotations

import logging
import queue
import threading
import time
import weakref
from collections import deque
from dataclasses import dataclass
from typing import Any, ClassVar, Protocol
from urllib.parse import urlparse

import cflib.crtp
from cflib.crtp.crtpdriver import CRTPDriver
from cflib.crtp.crtpstack import CRTPPacket
from cflib.crtp.exceptions import WrongUriType
from cflib.crtp.radio_link_statistics import RadioLinkStatistics

from rpf_fly.radio import broadcast as radio_broadcast
from rpf_fly.radio.packed_extpos import BROADCAST_COPIES

from .fake_world import DongleAir, LinkFaults, RadioTiming
from .host_lag import LINKS

logger = logging.getLogger(__name__)

SCHEME = "fake://"
DEFAULT_ADDRESS = 0xE7E7E7E7E7
DATARATES = ("250K", "1M", "2M")

DRIVER_PACKETS = 2
"""Uplink packets one link's driver holds before `send` blocks: cflib's radio driver has an out queue of one
packet (``RadioDriver.out_queue = Queue(1)``) and its radio thread one more in its transaction (retried there until
acknowledged)."""

SEND_TIMEOUT_S = 2.0
"""How long `send` waits for room before failing the link, as cflib's ``RadioDriver.send_packet`` does
(``out_queue.put(pk, True, 2)``, then the link error "RadioDriver: Could not send packet to copter")."""


UNPLUGGED = (
    "Error communicating with crazy radio ,it has probably been unplugged!\n"
    "Exception:[Errno 19] No such device (it may have been disconnected)\n\n"
)
"""The link error of a link whose dongle was pulled out: cflib's ``RadioDriver`` thread says this (with the traceback
of pyusb's ``USBError``) when a transaction raises."""

_dongles_lock = threading.Lock()
_unplugged: set[int] = set()
_links: weakref.WeakSet[FakeLink] = weakref.WeakSet()


def unplug(devid: int) -> int:
    """Pull dongle ``devid`` out: each open fake link on it fails at once (its thread calls cflib's link-error
    callback with `UNPLUGGED`, sends nothing more, flushes nothing at close), and so does every link opened on it
    until `replug`. Returns how many open links it failed."""
    with _dongles_lock:
        _unplugged.add(devid)
        links = [link for link in _links if link.devid == devid and not link.closed]
    for link in links:
        link.wake()
    return len(links)


def replug(devid: int | None = None) -> None:
    """Plug dongle ``devid`` back in (None: every dongle) for the links opened from now on (a failed link stays
    failed, as cflib's does)."""
    with _dongles_lock:
        if devid is None:
            _unplugged.clear()
        else:
            _unplugged.discard(devid)


def unplugged() -> frozenset[int]:
    """The dongles pulled out (`unplug`) and not put back."""
    with _dongles_lock:
        return frozenset(_unplugged)


class RadioPort(Protocol):
    """What a fake link reaches of one drone: a `DronePort` (the drone in this process) or a
    :class:`rpf_fly.emulator.remote_world.RemotePort` (a drone of a world in another process)."""

    @property
    def faults(self) -> LinkFaults: ...
    @property
    def rssi_dbm(self) -> int: ...
    def transact(
        self, channel: int, uplink: tuple[int, bytes] | None
    ) -> tuple[bool, int, tuple[int, int, bytes] | None]: ...
    def has_downlink(self) -> bool: ...
    def attach(self, waker: threading.Event) -> None: ...
    def detach(self, waker: threading.Event) -> None: ...


class RadioWorld(Protocol):
    """What the fake radio needs of a world of drones: a `FakeWorld` in this process, or a
    :class:`rpf_fly.emulator.world_process.RemoteWorld` reaching one in another process."""

    timing: RadioTiming

    @property
    def addresses(self) -> tuple[int, ...]: ...
    def start(self) -> Any: ...
    def port(self, address: int) -> RadioPort | None: ...
    def dongle(self, devid: int) -> DongleAir: ...
    def uri(self, address: int) -> str: ...
    def broadcast(self, channel: int, uplink: tuple[int, bytes], copies: int) -> Any: ...


@dataclass(frozen=True)
class FakeUri:
    """A parsed ``fake://`` URI (the path of a ``radio://`` URI)."""

    devid: int
    channel: int
    datarate: str
    address: int
    place: tuple[float, float] | None = None
    """Where a drone appearing on this URI's first connection stands (``?x=..&y=..``), None: the next grid spot."""


def parse_fake_uri(uri: str) -> FakeUri:
    """Parse ``fake://<dongle>/<channel>/<250K|1M|2M>/<hex address>``; missing parts default as for radio URIs
    (channel 2, 2M, address E7E7E7E7E7). Raises WrongUriType for other schemes, ValueError for malformed ones."""
    if not isinstance(uri, str) or not uri.startswith(SCHEME):
        raise WrongUriType("Not a fake radio URI")
    parsed = urlparse(uri)
    if not parsed.netloc.isdigit():
        raise ValueError(f"fake URI {uri!r}: the dongle number must be an integer")
    parts = [p for p in parsed.path.strip("/").split("/") if p]
    channel = int(parts[0]) if len(parts) > 0 else 2
    datarate = parts[1] if len(parts) > 1 else "2M"
    if datarate not in DATARATES:
        raise ValueError(f"fake URI {uri!r}: data rate must be one of {DATARATES}")
    address = int(parts[2], 16) if len(parts) > 2 else DEFAULT_ADDRESS
    if not 0 <= channel <= 125 or not 0 <= address < 1 << 40:
        raise ValueError(f"fake URI {uri!r}: channel or address out of range")
    place = None
    if parsed.query:
        query = dict(part.partition("=")[::2] for part in parsed.query.split("&"))
        try:
            place = (float(query.get("x", 0.0)), float(query.get("y", 0.0)))
        except ValueError:
            raise ValueError(f"fake URI {uri!r}: ?x=..&y=.. must be numbers (metres)") from None
    return FakeUri(int(parsed.netloc), channel, datarate, address, place)


class _Ack:
    """What `RadioLinkStatistics.update` reads from a Crazyradio ack."""

    __slots__ = ("ack", "data", "retry")

    def __init__(self, ack: bool, retry: int, data: tuple[int, ...]) -> None:
        self.ack, self.retry, self.data = ack, retry, data


class FakeLink:
    """One open fake radio link and its transaction thread."""

    def __init__(self, world: RadioWorld, uri: FakeUri, stats_callback: Any, error_callback: Any) -> None:
        self._world = world
        self._uri = uri
        spawn = getattr(world, "spawn", None)
        self._drone = spawn(uri.address, uri.place) if spawn is not None else world.port(uri.address)
        self._faults = self._drone.faults if self._drone else LinkFaults()
        self._timing = world.timing
        self._dongle = world.dongle(uri.devid)
        self._stats = RadioLinkStatistics(stats_callback) if stats_callback else None
        self._error_callback = error_callback
        self._in: queue.Queue[CRTPPacket | None] = queue.Queue()
        self._up: deque[tuple[float, int, bytes]] = deque()
        self._down_delayed: deque[tuple[float, CRTPPacket]] = deque()
        self._wake = threading.Event()
        self._room = threading.Condition()
        """Notified when an uplink packet leaves `_up` or the link closes (a blocked `send` waits on it)."""
        self._closed = threading.Event()
        self._flush_on_close = False
        self._held_s = 0.0
        """The host's time in the last transaction (`_transact`; `rpf_fly.emulator.host_lag.LINKS`)."""
        self._failed = False
        self._fail_lock = threading.Lock()
        with _dongles_lock:
            _links.add(self)
            self._opened_unplugged = uri.devid in _unplugged
        if self._drone is not None:
            self._drone.attach(self._wake)
        self._thread = threading.Thread(target=self._run, name=f"FakeLink-{uri.address:010X}", daemon=True)
        self._thread.start()

    @property
    def devid(self) -> int:
        return self._uri.devid

    @property
    def closed(self) -> bool:
        return self._closed.is_set()

    def wake(self) -> None:
        """Wake the transaction thread (it finds its dongle unplugged at once)."""
        self._wake.set()

    def _pulled_out(self) -> bool:
        return self._uri.devid in _unplugged

    # Called by cflib ------------------------------------------------------------------------------------------

    def send(self, pk: CRTPPacket) -> bool:
        """Queue one uplink packet; blocks while the driver holds `DRIVER_PACKETS` already (packets still in their
        `LinkFaults.latency_s` are on their way, not waiting), for `SEND_TIMEOUT_S` at most: then the link fails with
        cflib's "RadioDriver: Could not send packet to copter" and False is returned, as cflib's radio driver does."""
        if self._closed.is_set():
            return False
        deadline = time.monotonic() + SEND_TIMEOUT_S
        with self._room:
            while self._waiting(time.monotonic()) >= DRIVER_PACKETS and not self._closed.is_set():
                left = deadline - time.monotonic()
                if left <= 0.0:
                    break
                self._room.wait(left)
            full = self._waiting(time.monotonic()) >= DRIVER_PACKETS
            if not self._closed.is_set() and not full:
                self._up.append((time.monotonic() + self._faults.latency_s, pk.header, bytes(pk.data)))
        if self._closed.is_set():
            return False
        if full:
            self._fail("RadioDriver: Could not send packet to copter")
            return False
        self._wake.set()
        return True

    def _waiting(self, now: float) -> int:
        """Uplink packets due and not yet acknowledged (the head may be in its transaction). Reads a copy of the
        queue taken in one C call (``deque.copy``): the transaction thread pops it without `_room`, and iterating
        the deque itself can raise "deque mutated during iteration" in cflib's send (a 10-drone dry run does)."""
        n = 0
        for due, _, _ in self._up.copy():
            if due > now or n >= DRIVER_PACKETS:
                break
            n += 1
        return n

    def _taken(self) -> None:
        with self._room:
            self._room.notify_all()

    def receive(self, wait: float) -> CRTPPacket | None:
        """Next downlink packet; `wait` 0 polls, < 0 blocks until one arrives or the link closes, > 0 is a timeout.
        Returns None at once when the link is closed."""
        if self._closed.is_set():
            return None
        try:
            packet = self._in.get_nowait() if wait == 0 else self._in.get(timeout=wait if wait > 0 else None)
        except queue.Empty:
            return None
        return packet

    def close(self) -> None:
        """Stop the thread, after it transmitted the uplink packets already queued (cflib's `close_link` queues a
        zero-thrust setpoint just before closing; the real driver may or may not send it: the fake always does).
        Safe from the link's own thread, as cflib closes from the error callback (then nothing is flushed)."""
        self._flush_on_close = threading.current_thread() is not self._thread
        self._closed.set()
        self._taken()
        self._wake.set()
        self._in.put(None)  # wakes a receive() blocked in cflib's receive thread
        self._error_callback = None
        if threading.current_thread() is not self._thread:
            self._thread.join(timeout=1.0)
        if self._drone is not None:
            self._drone.detach(self._wake)

    # Transaction thread ---------------------------------------------------------------------------------------

    def _release_downlink(self, now: float) -> None:
        while self._down_delayed and self._down_delayed[0][0] <= now:
            self._in.put(self._down_delayed.popleft()[1])

    def _wait_time(self, now: float, last_tx: float) -> float:
        timeout = last_tx + self._timing.idle_poll_s - now
        if self._up:
            timeout = min(timeout, self._up[0][0] - now)
        if self._down_delayed:
            timeout = min(timeout, self._down_delayed[0][0] - now)
        return max(timeout, 0.0)

    def _flush(self) -> None:
        """On close: transmit the uplink packets already queued (a few tries each, no latency), drop the rest (all
        of them when the dongle is unplugged)."""
        while self._up and self._drone is not None and not self._pulled_out():
            _, header, payload = self._up.popleft()
            for _ in range(3):
                ok, _retry, _down = self._transact((header, payload))
                if ok:
                    break

    def _run(self) -> None:
        lost = 0
        last_tx = -float("inf")
        ready_s = time.monotonic()
        """When the link could next transact: the end of its last transaction (or its wait after a failed one)."""
        timing = self._timing
        if self._opened_unplugged:
            # opened on a dongle already pulled out: its first transaction fails, one idle poll on (not at once:
            # cflib's open_link stores the driver only after connect returns, and its error callback expects that)
            self._closed.wait(timing.idle_poll_s)
        while True:
            if self._closed.is_set():
                if self._flush_on_close:
                    self._flush()
                return
            if self._pulled_out():
                self._fail(UNPLUGGED)
                return
            now = time.monotonic()
            self._release_downlink(now)
            up_due = bool(self._up) and self._up[0][0] <= now
            down_waiting = self._drone is not None and self._drone.has_downlink()
            if not (up_due or down_waiting or now - last_tx >= timing.idle_poll_s):
                self._wake.wait(self._wait_time(now, last_tx))
                self._wake.clear()
                continue
            item = self._up[0] if up_due else None
            # due: the packet's time (or, idle, the poll's), not before the link was free: beyond it the host held
            # the thread (a wake-up that came late); `_transact` adds what it held the transaction itself
            due_s = max(item[0] if item else last_tx + timing.idle_poll_s if not down_waiting else now, ready_s)
            last_tx = now
            ok, retry, down = self._transact((item[1], item[2]) if item else None)
            ready_s = time.monotonic()
            LINKS.record(max(0.0, now - due_s) + self._held_s, ready_s)
            if ok and item is not None:
                self._up.popleft()
                self._taken()
            if not ok:
                lost += 1
                if lost >= timing.max_lost_acks:
                    self._fail("Too many packets lost")
                    return
                self._closed.wait(timing.failed_attempt_s)
                ready_s = time.monotonic()
                continue
            lost = 0
            self._deliver(down, item is not None, retry)

    def _transact(self, uplink: tuple[int, bytes] | None) -> tuple[bool, int, tuple[int, int, bytes] | None]:
        """One radio transaction through the dongle: wait for its air slot (`DongleAir.reserve`), reach the drone
        (outside the slot: other links' slots run meanwhile), and hand the ack back no earlier than the slot's end.
        Sets `_held_s`: how long past the slot's end the ack came back (the host's time: a late wake-up, a slow
        round trip to the world's process), the whole round trip when the air takes no time."""
        air_s = self._timing.transaction_s
        end = began = time.monotonic()
        if air_s > 0.0:
            start, end = self._dongle.reserve(air_s, began)
            _sleep_until(start)
        if self._drone is None:  # nobody at this address: the radio's attempts all go unanswered
            result: tuple[bool, int, tuple[int, int, bytes] | None] = (False, self._timing.arc_retries, None)
        else:
            result = self._drone.transact(self._uri.channel, uplink)
        if air_s > 0.0:
            _sleep_until(end)
        self._held_s = max(0.0, time.monotonic() - end)
        return result

    def _deliver(self, down: tuple[int, int, bytes] | None, had_uplink: bool, retry: int) -> None:
        if down is None:
            ack_data: tuple[int, ...] = (0xF3,)  # the nRF51's empty ack: no RSSI in the default build
        else:
            port, channel, payload = down
            header = ((port & 0x0F) << 4) | 0x0C | (channel & 0x03)
            ack_data = (header, *payload)
            packet = CRTPPacket(header, payload)
            if self._faults.latency_s > 0.0:
                self._down_delayed.append((time.monotonic() + self._faults.latency_s, packet))
            else:
                self._in.put(packet)
        if self._stats is not None:
            try:
                self._stats.update(_Ack(True, retry, ack_data), had_uplink or None)
            except Exception:  # statistics must not kill the link
                logger.exception("radio link statistics failed")

    def _fail(self, message: str) -> None:
        with self._fail_lock:
            if self._failed:
                return
            self._failed = True
        callback = self._error_callback
        logger.info("fake link %010X: %s", self._uri.address, message.splitlines()[0])
        self._closed.set()
        self._taken()
        self._in.put(None)
        if callback is not None:  # first, as cflib's driver does: a world process slow to answer the detach's
            callback(message)  # round trip must not delay the link error
        if self._drone is not None:
            self._drone.detach(self._wake)


class FakeBroadcast:
    """Broadcasts of one fake dongle on one channel (`rpf_fly.radio.broadcast.Broadcaster`): each holds the dongle's
    air for one transaction (`RadioTiming.transaction_s`), then every drone listening on the channel hears it
    (`FakeWorld.broadcast`); nothing when the dongle is unplugged."""

    def __init__(self, world: RadioWorld, devid: int, channel: int) -> None:
        self._world, self._devid, self._channel = world, devid, channel
        self.sent = 0

    def send(self, packet: bytes) -> bool:
        if self._devid in _unplugged:
            return False
        air_s = self._world.timing.transaction_s
        end = 0.0
        if air_s > 0.0:
            start, end = self._world.dongle(self._devid).reserve(air_s, time.monotonic())
            _sleep_until(start)
        self._world.broadcast(self._channel, (packet[0], bytes(packet[1:])), BROADCAST_COPIES)
        self.sent += 1
        if air_s > 0.0:
            _sleep_until(end)
        return True

    def close(self) -> None:
        pass


def _sleep_until(t_s: float) -> None:
    delay = t_s - time.monotonic()
    if delay > 0.0:
        time.sleep(delay)


class FakeRadioDriver(CRTPDriver):
    """cflib link driver for ``fake://`` URIs. Use `register(world)`, which binds a subclass to a world."""

    world: ClassVar[RadioWorld | None] = None

    def __init__(self) -> None:
        super().__init__()
        self.needs_resending = False
        self.uri = ""
        self._link: FakeLink | None = None

    def connect(self, uri: str, radio_link_statistics_callback: Any, link_error_callback: Any) -> None:
        if not isinstance(uri, str) or not uri.startswith(SCHEME):
            raise WrongUriType("Not a fake radio URI")
        world = type(self).world
        if world is None:
            raise RuntimeError("no FakeWorld registered: call rpf_fly.emulator.fake_radio.register(world)")
        parsed = parse_fake_uri(uri)
        if self._link is not None:
            raise RuntimeError("Link already open!")
        world.start()
        self.uri = uri
        self._link = FakeLink(world, parsed, radio_link_statistics_callback, link_error_callback)

    def send_packet(self, pk: CRTPPacket) -> bool:
        return self._link.send(pk) if self._link is not None else False

    def receive_packet(self, wait: float = 0) -> CRTPPacket | None:
        if self._link is None:
            return None
        return self._link.receive(wait)

    def close(self) -> None:
        if self._link is not None:
            self._link.close()
            self._link = None

    def get_status(self) -> str:
        world = type(self).world
        return "No fake world registered" if world is None else f"Fake radio, {len(world.addresses)} drones"

    def get_name(self) -> str:
        return "fakeradio"

    def get_help(self) -> str:
        return "fake://<dongle>/<channel>/<250K|1M|2M>/<address>: a drone of the registered FakeWorld"

    def scan_interface(self, address: int | None = None) -> list[list[str]]:
        world = type(self).world
        if world is None:
            return []
        return [[world.uri(a), ""] for a in world.addresses if address is None or a == address]

    def enum(self) -> list[list[str]]:
        return self.scan_interface()


def register(world: RadioWorld | None = None) -> type[FakeRadioDriver]:
    """Make ``fake://`` URIs reach `world` through cflib (replacing any previously registered fake driver; every
    dongle plugged in).

    Without a world, any unchanged cflib program works: a world of drones that appear on their first connection,
    on the floor, on a 0.5 m grid in the order they connect (ten a row along +x, rows along +y), or where the URI's
    query says (``fake://0/80/2M/E7E7E7E701?x=0.5&y=0``)."""
    if world is None:
        from .fake_world import FakeWorld

        world = FakeWorld({}, appear_on_connect=True)
    unregister()
    driver = type("BoundFakeRadioDriver", (FakeRadioDriver,), {"world": world})
    cflib.crtp.CLASSES.append(driver)
    bound = world
    radio_broadcast.register("fake", lambda devid, channel, rate: FakeBroadcast(bound, devid, channel))
    return driver


def unregister() -> None:
    """Remove every fake driver from cflib's driver list (open links keep working until closed) and the fake
    broadcasts, and plug every unplugged dongle back in (`replug`)."""
    replug()
    radio_broadcast.unregister("fake")
    cflib.crtp.CLASSES[:] = [
        cls for cls in cflib.crtp.CLASSES if not (isinstance(cls, type) and issubclass(cls, FakeRadioDriver))
    ]
