"""An emulated Crazyradio at the USB boundary: cflib's own ``radio://`` driver runs unchanged against simulated drones.

``plug(world=None, dongles=1, radio="crazyradio_2")`` makes ``libusb_package.get_libusb1_backend()`` (where cflib's
``cflib/drivers/crazyradio.py`` ``_find_devices`` gets its pyusb backend) return an emulated backend
(`crazyradio_usb.EmulatedBackend`) on which ``dongles`` Crazyradios (USB 0x1915:0x7777) are plugged in. From then
on any cflib program opens ``radio://0/80/2M/E7E7E7E7E1``: cflib's ``RadioDriver``, ``_SharedRadio`` and
``Crazyradio`` classes send their vendor requests and bulk transfers, and `EmulatedCrazyradio` below answers them
as the dongle's firmware does, spending the dongle's time (`crazyradio_timing`), and carries each packet into the
simulated world (`crazyradio_air.Air`: the drones' own radio chips in front of the same `DronePort` a ``fake://``
link reaches). Without a world, drones appear on their first connection, as ``fake_radio.register()`` does.
``unplug()`` gives the real backend back; ``pull_out(devid)`` makes one plugged dongle vanish from USB (the
``dongle_unplug`` fault), and cflib does with it what it does with a real one (docs/radio.md, "A dongle pulled out").

The firmware behaviour emulated (crazyradio-firmware ``main.c`` for the PA, crazyradio2-firmware ``legacy_usb.c``
for the 2.0; details in docs/radio.md, "The emulated Crazyradio"):
- vendor requests SET_RADIO_CHANNEL, SET_RADIO_ADDRESS, SET_DATA_RATE, SET_RADIO_POWER, SET_RADIO_ARD,
  SET_RADIO_ARC, ACK_ENABLE, SET_CONT_CARRIER, the firmware channel scan (0x21 OUT, then IN for its result) and
  LAUNCH_BOOTLOADER (acknowledged, not simulated); any other vendor request stalls;
- a bulk OUT carries one packet (at most 32 bytes) at the current channel, address and data rate with up to ARC
  retransmissions; the bulk IN returns the status byte (bit 0 acknowledged, bit 1 power detector, bits 4-7 the
  retransmissions) and the acknowledgement's payload, or a single 0 when nothing acknowledged it; with ACK_ENABLE
  off nothing is read back (a read times out), and what is sent reaches no simulated drone unless it goes to the
  broadcast address 0xFFE7E7E7E7: that reaches every drone on the channel at each of its attempts (once with
  ACK_ENABLE off; ARC + 1 times with it on, as nobody acknowledges it: rpf_fly/radio/broadcast.py's packed extpos);
- the PA ignores a channel above 125 or a data rate above 2 (keeps the old one); the 2.0 takes them but never
  acknowledges a packet on a channel above 100 or at 250 kbps; the PA in continuous-carrier mode takes no packet
  (the write times out), the 2.0 answers every one unacknowledged.
"""

from __future__ import annotations

import errno
import logging
import threading
import time
from collections import Counter, deque
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

from .crazyradio_air import BROADCAST_ADDRESS, Air
from .crazyradio_timing import (
    DR_2M,
    RADIO_TYPES,
    RadioType,
    ard_s,
    radio_s,
    time_on_air_s,
)
from .fake_world import DongleAir
from .host_lag import LINKS

logger = logging.getLogger(__name__)

VENDOR_OUT, VENDOR_IN = 0x40, 0xC0
SET_RADIO_CHANNEL, SET_RADIO_ADDRESS, SET_DATA_RATE, SET_RADIO_POWER = 0x01, 0x02, 0x03, 0x04
SET_RADIO_ARD, SET_RADIO_ARC, ACK_ENABLE, SET_CONT_CARRIER, CHANNEL_SCAN = 0x05, 0x06, 0x10, 0x20, 0x21
LAUNCH_BOOTLOADER = 0xFF
OUT_ENDPOINT, IN_ENDPOINT = 0x01, 0x81
MAX_SCAN_RESULTS = 63
"""Channels one firmware scan reports at most (crazyradio-firmware ``MAX_SCANN_LENGTH``)."""


class UsbFailure(Exception):
    """A USB transfer the dongle fails: the backend raises pyusb's ``USBError`` (or ``USBTimeoutError``) with
    libusb's code, errno and message."""

    def __init__(self, libusb_code: int, errno_: int, message: str) -> None:
        super().__init__(message)
        self.libusb_code, self.errno, self.message = libusb_code, errno_, message


def no_device() -> UsbFailure:
    return UsbFailure(-4, errno.ENODEV, "No such device (it may have been disconnected)")


def timed_out() -> UsbFailure:
    return UsbFailure(-7, errno.ETIMEDOUT, "Operation timed out")


def stall() -> UsbFailure:
    return UsbFailure(-9, errno.EPIPE, "Pipe error")


CATCH_UP_S = 0.002
"""How much of its own lateness the emulated dongle makes up: a wake-up after a transfer's time that came late (the
host's timer and the flight process's other threads), or the emulation's own work for a packet (the simulated
drone's radio, which a real one does in parallel with the host), is taken off the next operation's start, up to
this; beyond it the host held the flight's process, and the dongle waited as a real one would have (docs/radio.md,
"The emulated Crazyradio")."""


def _sleep_until(t_s: float) -> None:
    delay = t_s - time.monotonic()
    if delay > 0.0:
        time.sleep(delay)


@dataclass
class DongleCounters:
    """What one emulated dongle did, for tests and tools."""

    vendor_requests: Counter[int] = field(default_factory=Counter)
    """Vendor control transfers by request code."""
    standard_requests: int = 0
    """Standard control transfers (descriptors, configuration)."""
    bulk_writes: int = 0
    bulk_reads: int = 0
    packets: Counter[int] = field(default_factory=Counter)
    """Bulk writes by radio address that carried more than a null packet (safelink packets included)."""
    polls: Counter[int] = field(default_factory=Counter)
    """Bulk writes by radio address that carried a null packet (``0xFF`` with its safelink bits)."""
    acked: int = 0
    unacked: int = 0
    address_switches: int = 0
    """Bulk writes to another address than the bulk write before."""
    channel_switches: int = 0
    broadcasts: int = 0
    """Bulk writes to the broadcast address (`crazyradio_air.BROADCAST_ADDRESS`): each goes out ARC + 1 times."""
    busy_s: float = 0.0
    """Time the dongle spent on transfers (USB and radio)."""


class EmulatedCrazyradio:
    """One emulated dongle's firmware: its radio settings, vendor requests and bulk transfers, each spending the
    dongle's time in the calling thread (under the dongle's lock: the firmware does one thing at a time).
    ``index`` is its place in the enumeration (cflib's dongle number); its air time is reserved on the world's
    `DongleAir` of that number (shared with ``fake://`` links of the same number, if any)."""

    def __init__(self, index: int, radio: RadioType, air: Air, dongle_air: DongleAir, serial: str) -> None:
        self.index = index
        self.radio = radio
        self.air = air
        self.dongle_air = dongle_air
        self.serial = serial
        self.counters = DongleCounters()
        self.present = True
        self.configuration = 0
        self._lock = threading.RLock()
        self._free_at = 0.0
        self._behind = 0.0
        """How far the host's clock ran ahead of the dongle's timeline when its last operation returned (the
        emulation's own lateness, at most `CATCH_UP_S`): the next operation starts that much earlier."""
        self._in: deque[tuple[float, bytes]] = deque()
        self._last_address: int | None = None
        self._last_channel: int | None = None
        self._power_on()

    def _power_on(self) -> None:
        self.channel = self.radio.default_channel
        self.address = bytes((0xE7,) * 5)
        self.rate = DR_2M
        self.power = 3
        self.arc = 3
        self.ard = 0x80 | 32
        self.ack_enabled = True
        self.carrier = False
        self.scan_result = b""

    @property
    def address_int(self) -> int:
        """The current address as a URI writes it (``E7E7E7E7E1``: the bytes cflib sends, in that order)."""
        return int.from_bytes(self.address, "big")

    # Time ---------------------------------------------------------------------------------------------------

    def _occupy(self, duration_s: float, due_s: float | None = None) -> float:
        """Hold the dongle for ``duration_s`` from when it is free; returns the end (slept until). The time the
        host held the caller past that end (a late wake-up), and past ``due_s`` (an answer ready since then that
        cflib's thread came for late), is recorded as the links' (`host_lag.LINKS`)."""
        now = time.monotonic()
        start = max(now - self._behind, self._free_at)
        self._free_at = start + duration_s
        self.counters.busy_s += duration_s
        _sleep_until(self._free_at)
        after = time.monotonic()
        self._behind = min(CATCH_UP_S, max(0.0, after - self._free_at))
        LINKS.record(max(0.0, after - self._free_at) + (max(0.0, now - due_s) if due_s is not None else 0.0), after)
        return self._free_at

    def _check(self) -> None:
        if not self.present:
            raise no_device()

    def standard_request(self) -> None:
        """Spend one control transfer on a standard request (the backend answers it from the descriptors)."""
        with self._lock:
            self._check()
            self.counters.standard_requests += 1
            self._occupy(self.radio.control_s)

    def reset(self) -> None:
        """A USB port reset: the firmware keeps running (its radio settings stay), the configuration comes back."""
        with self._lock:
            self._check()
            self._occupy(self.radio.reset_s)
            self._in.clear()

    # Control transfers ----------------------------------------------------------------------------------------

    def vendor_request(
        self, request_type: int, request: int, value: int, index: int, data: bytes, length: int
    ) -> bytes | int:
        """One vendor control transfer: OUT returns the bytes taken, IN the bytes read. Stalls (`UsbFailure`)
        what the firmware does not handle."""
        with self._lock:
            self._check()
            self.counters.vendor_requests[request] += 1
            end = self._occupy(self.radio.control_s)
            if self.configuration == 0:
                raise stall()  # vendor requests are valid only once the device is configured
            if request_type == VENDOR_IN:
                if request != CHANNEL_SCAN:
                    raise stall()
                return self.scan_result[:length]
            if request_type != VENDOR_OUT:
                raise stall()
            self._apply(request, value, index, data, end)
            return len(data)

    def _apply(self, request: int, value: int, index: int, data: bytes, now: float) -> None:
        pa = self.radio.name == "crazyradio_pa"
        if request == SET_RADIO_CHANNEL:
            if not pa or value <= self.radio.max_channel:
                self.channel = value
        elif request == SET_RADIO_ADDRESS:
            if pa and not 3 <= len(data) <= 5 or not pa and len(data) != 5:
                raise stall()
            self.address = bytes(data) + self.address[len(data) :]
        elif request == SET_DATA_RATE:
            if value < 3:
                self.rate = value
        elif request == SET_RADIO_POWER:
            self.power = min(value, 3)
        elif request == SET_RADIO_ARD:
            self.ard = value & 0xFF
        elif request == SET_RADIO_ARC:
            self.arc = value & 0x0F
        elif request == ACK_ENABLE:
            self.ack_enabled = value != 0
        elif request == SET_CONT_CARRIER:
            self.carrier = value != 0
        elif request == CHANNEL_SCAN:
            if not data:
                raise stall()
            self._firmware_scan(value, index, bytes(data[:32]), now)
        elif request == LAUNCH_BOOTLOADER:
            logger.warning(
                "emulated Crazyradio %d: LAUNCH_BOOTLOADER is not simulated (it stays in its firmware)", self.index
            )
        else:
            raise stall()

    def _firmware_scan(self, start: int, stop: int, packet: bytes, now: float) -> None:
        """START_SCAN_CHANNELS: the packet on each channel from ``start`` to ``stop`` (every second one at 2M on a
        PA), the acknowledged channels kept for GET_SCAN_CHANNELS; the dongle stays on the last channel."""
        step = 2 if self.radio.name == "crazyradio_pa" and self.rate == DR_2M else 1
        found = []
        spent = 0.0
        for channel in range(start, min(stop, self.radio.max_channel) + 1, step):
            self.channel = channel
            status, _, air_s = self._transmit(packet)
            spent += air_s
            if status & 0x01:
                found.append(channel)
                if len(found) >= MAX_SCAN_RESULTS:
                    break
        self.scan_result = bytes(found)
        self._occupy(spent)

    # Bulk transfers -------------------------------------------------------------------------------------------

    def bulk_out(self, endpoint: int, data: bytes, timeout_ms: int) -> int:
        """A packet to send: the write returns once USB has taken it; the radio then works while the host waits
        for the answer on the IN endpoint."""
        with self._lock:
            self._check()
            if endpoint != OUT_ENDPOINT:
                raise stall()
            self.counters.bulk_writes += 1
            taken = self._occupy(self.radio.bulk_out_s)
            if self.carrier and self.radio.name == "crazyradio_pa":
                self._free_at = taken + timeout_ms / 1000.0  # the PA's main loop takes no packet meanwhile
                _sleep_until(self._free_at)
                raise timed_out()
            packet = bytes(data[:32])
            status, payload, air_s = self._transmit(packet)
            start, end = self.dongle_air.reserve(air_s, taken)
            self.counters.busy_s += end - taken
            self._free_at = end
            self._behind = min(CATCH_UP_S, max(0.0, time.monotonic() - taken))  # the write returned at `taken`
            if self.ack_enabled:
                self._in.append((end, bytes((status,)) + payload))
            return len(data)

    def _transmit(self, packet: bytes) -> tuple[int, bytes, float]:
        """Send ``packet`` as the radio would now: (status byte, ack payload, radio time)."""
        rate, channel = self.rate, self.channel
        if packet:
            address = self.address_int
            if self._last_address is not None and address != self._last_address:
                self.counters.address_switches += 1
            if self._last_channel is not None and channel != self._last_channel:
                self.counters.channel_switches += 1
            self._last_address, self._last_channel = address, channel
            is_poll = len(packet) == 1 and packet[0] & 0xF3 == 0xF3
            (self.counters.polls if is_poll else self.counters.packets)[address] += 1
        if not self.ack_enabled:
            if self.address_int == BROADCAST_ADDRESS and rate in self.radio.rates and packet:
                self.counters.broadcasts += 1
                self.air.broadcast(channel, packet, 1)
            return 0, b"", self.radio.ramp_s + time_on_air_s(len(packet), rate)
        if self.carrier or rate not in self.radio.rates or channel > self.radio.max_channel or not packet:
            self.counters.unacked += 1
            return 0, b"", 0.0
        if self.address_int == BROADCAST_ADDRESS:  # heard by every drone on the channel, acknowledged by none
            self.counters.broadcasts += 1
            self.counters.unacked += 1
            self.air.broadcast(channel, packet, self.arc + 1)
            return 0, b"", radio_s(self.radio, rate, len(packet), 0, self.arc + 1, False, ard_s(self.ard, rate))
        heard = self.air.transmit(self.address_int, channel, rate, packet, self.arc)
        attempts = heard.retries + 1 if heard.acked else self.arc + 1
        air_s = radio_s(self.radio, rate, len(packet), len(heard.payload), attempts, heard.acked, ard_s(self.ard, rate))
        if not heard.acked:
            self.counters.unacked += 1
            return 0, b"", air_s
        self.counters.acked += 1
        status = 0x01 | (0x02 if heard.strong else 0) | (min(heard.retries, 15) << 4)
        return status, heard.payload, air_s

    def bulk_in(self, endpoint: int, size: int, timeout_ms: int) -> bytes:
        """The answer to the last packet once the radio is done, or a timeout when there is none."""
        with self._lock:
            self._check()
            if endpoint != IN_ENDPOINT:
                raise stall()
            self.counters.bulk_reads += 1
            if not self._in:
                self._free_at = max(time.monotonic(), self._free_at) + timeout_ms / 1000.0
                _sleep_until(self._free_at)
                raise timed_out()
            ready, answer = self._in.popleft()
            self._free_at = max(self._free_at, ready)
            self._occupy(self.radio.bulk_in_s, due_s=ready)
            return answer[:size]


@dataclass
class Plugged:
    """The emulated dongles of one `plug`: the world they reach, its air, the dongles in enumeration order."""

    world: Any
    air: Air
    dongles: list[EmulatedCrazyradio]
    backend: Any
    radio: RadioType


_lock = threading.Lock()
_plugged: Plugged | None = None
_real_getter: Any = None


def serial_number(radio: RadioType, index: int) -> str:
    """A made-up serial number of the type's length (upper-case hex, as the firmwares write the chip id)."""
    return f"{0xC0FFEE0000 + index:0{radio.serial_digits}X}"[-radio.serial_digits :]


def plug(world: Any = None, dongles: int = 1, radio: str = "crazyradio_2") -> Plugged:
    """Plug ``dongles`` emulated Crazyradios of type ``radio`` (`crazyradio_timing.RADIO_TYPES`) into this
    process's USB as cflib sees it (replacing an earlier `plug`). ``world``: a `fake_radio.RadioWorld` (a
    `FakeWorld`, a `RemoteWorld`), a running lab's `LabInfo`, or None for a world whose drones appear on their first
    connection (``FakeWorld({}, appear_on_connect=True)``, as ``fake_radio.register()``)."""
    import libusb_package

    from .crazyradio_usb import EmulatedBackend

    global _plugged, _real_getter
    if radio not in RADIO_TYPES:
        raise ValueError(f"radio must be one of {sorted(RADIO_TYPES)}, not {radio!r}")
    if dongles < 1:
        raise ValueError(f"dongles must be >= 1, not {dongles}")
    if world is None:
        from .fake_world import FakeWorld

        world = FakeWorld({}, appear_on_connect=True)
    elif not hasattr(world, "port") and hasattr(world, "radio") and hasattr(world, "addresses"):
        from rpf_fly.flight.lab import lab_world

        world = lab_world(world)
    unplug()
    # a link closed a moment ago is still open on cflib's shared radio thread: a link opened now would join that
    # thread's (earlier) dongle and never reach these ones. Wait for cflib to close them; a link an earlier plug's
    # user never closed keeps its own (earlier) dongle, and the new links get these (as after a real re-plug)
    if not wait_released(range(_shared_radio_count()), RELEASE_WAIT_S):
        logger.warning("links of an earlier plug are still open: they keep its dongles, new links get these")
    _forget_radios()
    kind = RADIO_TYPES[radio]
    air = Air(world)
    devices = [EmulatedCrazyradio(i, kind, air, world.dongle(i), serial_number(kind, i)) for i in range(dongles)]
    backend = EmulatedBackend(devices)
    plugged = Plugged(world, air, devices, backend, kind)
    with _lock:
        _real_getter = libusb_package.get_libusb1_backend
        # replacing the package's cached getter by the emulated dongles' backend (restored by unplug())
        libusb_package.get_libusb1_backend = backend.getter  # type: ignore[assignment]
        _plugged = plugged
    return plugged


def unplug() -> None:
    """Give the real libusb backend back. Dongles cflib already opened keep working until it closes them (as
    ``fake_radio.unregister`` leaves open links); the drones are let go when the last one is closed."""
    import libusb_package

    global _plugged, _real_getter
    with _lock:
        plugged, _plugged = _plugged, None
        if _real_getter is not None:
            libusb_package.get_libusb1_backend = _real_getter
            _real_getter = None
    if plugged is not None:
        plugged.backend.retire(plugged.air.close)


def plugged() -> Plugged | None:
    """The current `plug`, None when none."""
    return _plugged


def pull_out(devid: int) -> bool:
    """Pull the plugged dongle ``devid`` out (the ``dongle_unplug`` fault): from now on every transfer on it fails
    with libusb's "No such device", and cflib does what it does with a vanished Crazyradio (docs/radio.md, "A
    dongle pulled out"). False when no such dongle is plugged."""
    current = _plugged
    if current is None or not 0 <= devid < len(current.dongles):
        return False
    dongle = current.dongles[devid]
    with dongle._lock:
        dongle.present = False
    return True


def wait_released(devids: Iterable[int], timeout_s: float = 2.0) -> bool:
    """Wait until cflib has closed dongles ``devids`` (its shared radio handles a link's close on its own thread, a
    moment after ``close_link``), so that the next `plug` is the one cflib opens. False when one is still open at
    ``timeout_s`` (a link still open, or a shared radio whose thread died)."""
    from cflib.crtp.radiodriver import RadioManager

    deadline = time.monotonic() + timeout_s
    wanted = sorted(set(devids))
    while True:
        radios = RadioManager._radios
        busy = [
            d
            for d in wanted
            if d < len(radios) and radios[d] is not None and radios[d]._radio is not None and radios[d].is_alive()
        ]
        if not busy:
            return True
        if time.monotonic() >= deadline:
            return False
        time.sleep(0.01)


RELEASE_WAIT_S = 5.0
"""How long `plug` waits for cflib to close the dongles of links closed just before (its shared radio closes a
dongle on its own thread, after the link's STOP reaches it: a moment, longer on a busy host)."""


def _shared_radio_count() -> int:
    from cflib.crtp.radiodriver import RadioManager

    return len(RadioManager._radios)


def _forget_radios() -> None:
    """cflib keeps one shared radio thread per dongle number for the life of the process (``RadioManager._radios``),
    and a link opened on the number joins it with the dongle it opened. A fresh `plug` starts without them, as a
    fresh process does: a thread that died on a vanished dongle (every later link would wait on it for ever), or
    one still serving an earlier plug's open links (they keep their dongle), is left to them."""
    from cflib.crtp.radiodriver import RadioManager

    with RadioManager._lock:
        for devid, radio in enumerate(RadioManager._radios):
            if radio is not None:
                RadioManager._radios[devid] = None
