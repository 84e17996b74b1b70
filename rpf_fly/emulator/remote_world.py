"""The flight's process's side of the fake radio when the simulated drones run in a process of their own
(rpf_fly/emulator/world_process.py): each drone a `PipedPort` that decides its transactions here and tells that
process (rpf_fly/emulator/piped_port.py), or a :class:`RemotePort` whose transactions are UDP requests to it
(rpf_fly/emulator/radio_wire.py), the whole a :class:`RemoteWorld` as the fake radio needs it
(``fake_radio.RadioWorld``).
"""

from __future__ import annotations

import os
import socket
import threading

from .crtp import Packet
from .dongle_air import DongleAir, RadioTiming
from .fake_world import LinkFaults
from .piped_port import PipedPort
from .radio_wire import BROADCAST, BROADCAST_QUIET, CLOSE, INFO, OPEN, REPLY, REPLY_TIMEOUT_S, REQUEST, TRANSACT

PIPED_BY_DEFAULT = os.environ.get("RPF_FLY_PIPED_RADIO", "1") != "0"
"""Whether a `RemoteWorld`'s links are piped (rpf_fly/emulator/piped_port.py); ``RPF_FLY_PIPED_RADIO=0`` gives
every link a round trip per transaction instead (for comparison)."""


class RemotePort:
    """A drone of the child's world, reached over UDP (the fake link's `DronePort`). Thread-safe."""

    def __init__(self, server: tuple[str, int], address: int, timing: RadioTiming) -> None:
        self._address = address
        self._retries = timing.arc_retries
        self._lock = threading.Lock()
        self._seq = 0
        self._more = False
        self._open = False
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.connect(server)
        self._sock.settimeout(REPLY_TIMEOUT_S)
        reply = self._call(OPEN, 0, b"")
        if reply is None or not reply[1]:
            self._sock.close()
            raise LookupError(f"no simulated drone at address {address:010X}")
        self._open = True
        latency_s, rssi = INFO.unpack_from(reply[5])
        self.faults = LinkFaults(latency_s=latency_s)
        self.rssi_dbm = rssi

    def _call(self, op: int, channel: int, body: bytes) -> tuple[int, int, int, int, int, bytes] | None:
        with self._lock:
            self._seq = (self._seq + 1) & 0xFFFFFFFF
            seq = self._seq
            try:
                self._sock.send(REQUEST.pack(op, seq, self._address, channel, 1 if body else 0) + body)
                while True:
                    data = self._sock.recv(2048)
                    if len(data) >= REPLY.size and REPLY.unpack_from(data)[0] == seq:
                        return (*REPLY.unpack_from(data), data[REPLY.size :])
            except OSError:  # timeout (a lost ack), or the drones' process is gone
                return None

    def transact(self, channel: int, uplink: tuple[int, bytes] | None) -> tuple[bool, int, Packet | None]:
        body = b"" if uplink is None else bytes((uplink[0],)) + uplink[1]
        reply = self._call(TRANSACT, channel, body)
        if reply is None:
            return False, self._retries, None
        _, ok, retry, more, has_down, rest = reply
        self._more = bool(more)
        down = (rest[0], rest[1], bytes(rest[2:])) if has_down else None
        return bool(ok), retry, down

    def has_downlink(self) -> bool:
        return self._more

    def attach(self, waker: threading.Event) -> None:
        """Attached at open (the child queues downlink packets only while a link is open); polls find them."""

    def detach(self, waker: threading.Event) -> None:
        if self._open:
            self._open = False
            self._call(CLOSE, 0, b"")
            self._sock.close()


class RemoteWorld:
    """What the fake radio needs of a world (`fake_radio.RadioWorld`) for the drones of a child process."""

    def __init__(
        self,
        radio: tuple[str, int],
        addresses: tuple[int, ...],
        timing: RadioTiming | None = None,
        piped: bool = PIPED_BY_DEFAULT,
    ) -> None:
        """``piped``: each link decides its transactions in this process (`PipedPort`); else each is a round trip
        to the child (`RemotePort`)."""
        self.piped = piped
        self._radio = radio
        self._addresses = tuple(addresses)
        self.timing = timing or RadioTiming()
        self._dongles: dict[int, DongleAir] = {}
        self._lock = threading.Lock()
        self._sock: socket.socket | None = None
        self._seq = 0

    @property
    def addresses(self) -> tuple[int, ...]:
        return self._addresses

    def start(self) -> RemoteWorld:
        return self  # the child started its world before it reported ready

    def port(self, address: int) -> RemotePort | PipedPort | None:
        if address not in self._addresses:
            return None
        try:
            if self.piped:
                return PipedPort(self._radio, address)
            return RemotePort(self._radio, address, self.timing)
        except LookupError:
            return None

    def dongle(self, devid: int) -> DongleAir:
        with self._lock:
            return self._dongles.setdefault(devid, DongleAir())

    def uri(self, address: int) -> str:
        return f"fake://0/80/2M/{address:010X}"

    def broadcast(self, channel: int, uplink: tuple[int, bytes], copies: int) -> bool:
        """`FakeWorld.broadcast` in the child: one request, answered once its drones have heard it (False when the
        child did not answer in time)."""
        with self._lock:
            if self._sock is None:
                self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
                self._sock.connect(self._radio)
                self._sock.settimeout(REPLY_TIMEOUT_S)
            self._seq = (self._seq + 1) & 0xFFFFFFFF
            if self.piped:  # nobody waits for it: the radio does not
                try:
                    request = REQUEST.pack(BROADCAST_QUIET, self._seq, 0, channel, copies)
                    self._sock.send(request + bytes((uplink[0],)) + uplink[1])
                    return True
                except OSError:
                    return False
            try:
                request = REQUEST.pack(BROADCAST, self._seq, 0, channel, copies)
                self._sock.send(request + bytes((uplink[0],)) + uplink[1])
                while True:
                    data = self._sock.recv(2048)
                    if len(data) >= REPLY.size and REPLY.unpack_from(data)[0] == self._seq:
                        return True
            except OSError:
                return False
