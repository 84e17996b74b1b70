"""The Crazyflies' side of the air an emulated Crazyradio transmits into: each simulated drone's nRF51 radio.

Why: cflib's own radio driver speaks to the Crazyflie's radio chip, not to its flight firmware. Before it sends
anything it switches on *safelink* (a packet ``[0xFF, 0x05, 0x01]`` whose acknowledgement must echo it), then
stamps every packet with two toggle bits, and reads the toggle bit of each acknowledgement; the Crazyflie's nRF51
keeps the matching state. The emulated dongle (`crazyradio.py`) hands each packet to `Air.transmit`, which plays
that nRF51 (crazyflie2-nrf-firmware at 32b6ecb, ``src/esb.c`` ``esbInterruptHandler`` and ``setupTx``, read for
its facts):

- a safelink packet (3 bytes, ``(b0 & 0xF3) == 0xF3``, ``b1 == 0x05``) sets safelink from its third byte, is
  answered by its own echo (a "service packet") and resets both counters to 1; two in a row: the second gets the
  queue's next packet instead (the firmware clears a service packet just sent);
- with safelink, a packet whose up bit (0x08) equals the last one is a resend and is not passed on; an
  acknowledgement moves on to the next queued downlink packet only when the packet's down bit (0x04) differs from
  the nRF's, else the last one is sent again; the chosen packet's header carries the down bit;
- when nothing is queued the acknowledgement is one byte, ``0xF3 | down << 2`` (the default build: no
  ``RSSI_ACK_PACKET``), so an acknowledgement is never empty;
- moving on drops the head of the nRF's transmit queue unless the last acknowledgement was the empty one (as the
  firmware does, which also drops one never-sent packet after a service packet);
- the acknowledgement is chosen before the drone's firmware answers the packet it acknowledges: the nRF51 loads its
  acknowledgement payload before the packet arrives and sends it 130 us after, while the STM32 gets the packet and
  sends its answer over syslink (the UART between the two chips) later. So an answer (an echo, a parameter value)
  rides on the link's next acknowledgement at the earliest, never on its own packet's.

What the drone's firmware receives, and whether a transmission is heard at all (its channel, a dropped link, its
packet loss and retries), stays the world's: `DronePort.transact` (fake_world.py), the same call a ``fake://`` link
makes, so the same simulated firmware answers both. A null packet (one byte, port 15 channel 3) is a poll.

Channels and data rates: a drone configured with a channel (``FakeDroneConfig.channel``) answers only there; one
without answers the first link opened to it (its safelink packet) on whatever channel and data rate that link uses,
as the ``fake://`` radio answers any URI, and keeps them (a Crazyflie listens on one channel and data rate). Until
then it answers other packets (a scan's) only on its configured channel or 80, at 2M: the radio settings of a
Crazyflie out of the box (the fake firmware's EEPROM, as crazyflie-firmware's config block defaults).
"""

from __future__ import annotations

import threading
from collections import deque
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from .crazyradio_timing import DR_2M

if TYPE_CHECKING:
    from .fake_radio import RadioPort, RadioWorld

BROADCAST_ADDRESS = 0xFFE7E7E7E7
"""The address every Crazyflie's nRF51 also listens on and never acknowledges (crazyflie2-nrf-firmware ``esb.c``):
a packet sent there reaches every drone on the channel (packed extpos, rpf_fly/radio/broadcast.py)."""

DEFAULT_CHANNEL = 80
"""A Crazyflie's channel out of the box (the fake firmware's EEPROM; FakeWorld gives a drone without a configured
channel this one)."""

SAFELINK_HEADER_MASK = 0xF3
EMPTY, SERVICE, DATA = "empty", "service", "data"


@dataclass(frozen=True)
class Heard:
    """What the dongle gets back for one packet: acknowledged or not, the retransmissions used, the
    acknowledgement's payload (at least one byte when acknowledged), and whether its power was above the
    dongle's -64 dBm power detector."""

    acked: bool
    retries: int
    payload: bytes = b""
    strong: bool = False


def is_safelink(packet: bytes) -> bool:
    return len(packet) == 3 and packet[0] & SAFELINK_HEADER_MASK == 0xF3 and packet[1] == 0x05


def is_null(packet: bytes) -> bool:
    return len(packet) == 1 and packet[0] & SAFELINK_HEADER_MASK == 0xF3


class CrazyflieRadio:
    """The nRF51 of one simulated Crazyflie: safelink state, its transmit queue and what it listens on.
    Thread-safe (two dongles may talk to one drone)."""

    def __init__(self, address: int, port: RadioPort, channel: int | None, waker: threading.Event) -> None:
        self.address = address
        self.port = port
        self._waker = waker
        self.configured_channel = channel
        self.tuned: tuple[int, int] | None = None
        """(channel, data rate) of the first link opened to it; None until then."""
        self._lock = threading.Lock()
        self._safelink = False
        self._up = 1
        self._down = 1
        self._tx: deque[tuple[int, int, bytes]] = deque()
        self._last_kind: str | None = None
        self._last_ack = b""
        self.passed_on = 0
        """Uplink packets handed to the drone's firmware (safelink resends and polls not counted)."""

    def _hears(self, channel: int, rate: int, safelink: bool) -> bool:
        if self.tuned is not None:
            return (channel, rate) == self.tuned
        if safelink:
            return True
        home = self.configured_channel if self.configured_channel is not None else DEFAULT_CHANNEL
        return channel == home and rate == DR_2M

    def receive(self, channel: int, rate: int, packet: bytes, arc: int) -> Heard:
        """One transmission of ``packet`` with up to ``arc`` retransmissions (the dongle's ARC)."""
        safelink = is_safelink(packet)
        with self._lock:
            if not self._hears(channel, rate, safelink):
                return Heard(False, arc)
            new = not self._safelink or (packet[0] & 0x08) != self._up << 3
            uplink = None if safelink or is_null(packet) or not new else (packet[0], bytes(packet[1:]))
            ok, retries, down = self.port.transact(channel, uplink)
            if not ok:
                return Heard(False, arc)
            if uplink is not None:
                self.passed_on += 1
            if safelink:
                self.tuned = (channel, rate)
                self._safelink = bool(packet[2])
                ack = self._advance(bytes(packet))
                self._up = self._down = 1
            else:
                if new:
                    self._up = 1 - self._up
                if not self._safelink or (packet[0] & 0x04) != self._down << 2:
                    self._down = 1 - self._down
                    ack = self._advance(None)
                else:
                    ack = self._last_ack
            if down is not None:  # queued behind the acknowledgement just chosen (module doc)
                self._tx.append(down)
            if retries > arc:  # the drone heard it, the dongle gave up first: a lost acknowledgement
                return Heard(False, arc)
            return Heard(True, retries, ack, self.port.rssi_dbm < 64)

    def _advance(self, service: bytes | None) -> bytes:
        """The next acknowledgement payload (``setupTx(false, false)``)."""
        if self._last_kind != EMPTY and self._tx:
            self._tx.popleft()
        if self._last_kind == SERVICE:
            service = None
        if service:
            ack, kind = service, SERVICE
        elif self._tx:
            port, channel, payload = self._tx[0]
            header = ((port & 0x0F) << 4) | 0x0C | (channel & 0x03)
            if self._safelink:
                header = (header & SAFELINK_HEADER_MASK) | self._down << 2
            ack, kind = bytes((header,)) + bytes(payload), DATA
        else:
            ack, kind = bytes((0xF3 | self._down << 2,)), EMPTY
        self._last_kind, self._last_ack = kind, ack
        return ack

    def close(self) -> None:
        self.port.detach(self._waker)


class Air:
    """The simulated drones of one world as emulated dongles reach them: one `CrazyflieRadio` per address, made on
    the first transmission to it (with ``appear_on_connect``, a first link's safelink packet brings an unknown
    drone into the world: `FakeWorld.spawn`). Thread-safe."""

    def __init__(self, world: RadioWorld) -> None:
        self.world = world
        self._lock = threading.Lock()
        self._radios: dict[int, CrazyflieRadio] = {}
        self._started = False
        self._waker = threading.Event()
        """Attached to every drone reached: nobody waits on it (cflib polls), but a `SimDrone` queues downlink
        packets only while something is attached."""

    def transmit(self, address: int, channel: int, rate: int, packet: bytes, arc: int) -> Heard:
        """One packet sent to ``address`` on ``channel`` at ``rate``; not acknowledged when nobody hears it."""
        radio = self._radio(address, is_safelink(packet))
        if radio is None:
            return Heard(False, arc)
        return radio.receive(channel, rate, packet, arc)

    def broadcast(self, channel: int, packet: bytes, copies: int) -> None:
        """``copies`` transmissions of ``packet`` to `BROADCAST_ADDRESS` on ``channel``: each reaches the firmware of
        every drone listening there unless its link loses it (the world's ``broadcast``, as the ``fake://`` radio's);
        nobody acknowledges them, nothing comes down, and no safelink bit counts (the nRF51 passes them on as they
        are)."""
        with self._lock:
            if not self._started:
                self.world.start()
                self._started = True
        hear = getattr(self.world, "broadcast", None)
        if hear is not None and packet:
            hear(channel, (packet[0], bytes(packet[1:])), copies)

    def _radio(self, address: int, may_spawn: bool) -> CrazyflieRadio | None:
        with self._lock:
            radio = self._radios.get(address)
            if radio is not None:
                return radio
            if not self._started:
                self.world.start()
                self._started = True
            spawn = getattr(self.world, "spawn", None) if may_spawn else None
            port = spawn(address, None) if spawn is not None else self.world.port(address)
            if port is None:
                return None
            port.attach(self._waker)
            radio = CrazyflieRadio(address, port, _configured_channel(self.world, address), self._waker)
            self._radios[address] = radio
            return radio

    def radio(self, address: int) -> CrazyflieRadio | None:
        """The drone radio at ``address`` if anything transmitted to it yet."""
        with self._lock:
            return self._radios.get(address)

    def close(self) -> None:
        """Detach from every drone (a `SimDrone` flushes its downlink queue when its last link detaches)."""
        with self._lock:
            radios, self._radios = list(self._radios.values()), {}
        for radio in radios:
            radio.close()


def _configured_channel(world: Any, address: int) -> int | None:
    """The drone's configured channel where the world shows it (a `FakeWorld`); None otherwise (a world in another
    process enforces its channel in `RemotePort.transact` all the same)."""
    drone_of = getattr(world, "drone", None)
    drone = drone_of(address) if drone_of is not None else None
    config = getattr(drone, "config", None)
    return getattr(config, "channel", None)
