"""A piped link: a drone of a world in another process (rpf_fly/emulator/world_process.py) reached without a round
trip per radio transaction.

Why: a real Crazyflie's radio answers a packet within the air time (about 0.5 ms at 2M), whatever its flight
firmware is doing. A fake link or an emulated Crazyradio that asks the world's process for each acknowledgement
(`remote_world.RemotePort`) waits for that process to be scheduled: on a 2-core host flying eight drones, 2.4 ms on
average and 6 ms at the 90th percentile, so one emulated dongle carried a third of its figures and the dry run was
harsher than the radio (docs/radio.md, "A full dongle through it"). A piped link decides each transaction here,
from the same figures the world would use, and tells the world afterwards:

- whether the drone answers (powered, its link not dropped, on its channel) and the runtime loss fault come from
  the world's pushes (`radio_wire.STATE`, after the world step that changed it and every 0.1 s); the configured
  attempt loss and the bursty-loss channel (`BurstChannel`, the drone's own seed on the world clock, the same bursts
  as the world's) are given at open, and each attempt is drawn here;
- each transaction goes to the world as one unanswered request (`radio_wire.RECORD`): the world counts it as its
  own transactions are counted and hands an acknowledged packet to the firmware, a moment later (the UART between
  a Crazyflie's radio chip and its STM32 takes about as long);
- the firmware's downlink packets are pushed here as it queues them (`radio_wire.DOWN`) and wait in this link's
  queue (the firmware's `TX_QUEUE_SIZE`, overflow dropped and counted) for an acknowledgement to carry them;
- a drone rebooted (its queue flushed) flushes this queue too; a world gone (its port closed, or silent for
  `PIPE_SILENT_S`) answers nothing, as a dead drone does.

Two links to one drone (a second program on it, two dongles): each downlink packet goes to the link that transacted
last, as a Crazyflie's next acknowledgement goes to whichever link's packet comes next.
"""

from __future__ import annotations

import random
import socket
import threading
import time
from collections import deque

from .burst_loss import BurstChannel, BurstLoss
from .crtp import Packet
from .fake_world import LinkFaults
from .radio_wire import (
    CLOSE,
    DOWN,
    INFO,
    LINK_STATE,
    OPEN,
    PIPE_INFO,
    PIPE_SILENT_S,
    PIPED,
    PUSH,
    PUSH_MARK,
    RECORD,
    RECORDED,
    REPLY,
    REPLY_TIMEOUT_S,
    REQUEST,
    STATE,
)
from .sim_drone import TX_QUEUE_SIZE


class PipedPort:
    """A drone of the child's world as a fake link or an emulated Crazyradio reaches it (`fake_radio.RadioPort`),
    its transactions decided here (module doc). Thread-safe."""

    def __init__(self, server: tuple[str, int], address: int) -> None:
        self._address = address
        self._lock = threading.Lock()
        self._seq = 0
        self._open = False
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.connect(server)
        self._sock.settimeout(REPLY_TIMEOUT_S)
        self._down: deque[Packet] = deque()
        self.tx_dropped = 0
        """Downlink packets dropped because this link's queue was full."""
        self._answering = True
        self._override: tuple[float, float] | None = None
        self._flushes: int | None = None
        self._dead = False
        reply = self._call(OPEN, 0, PIPED, b"")
        if reply is None or not reply[1] or len(reply[5]) < INFO.size + PIPE_INFO.size:
            self._sock.close()
            raise LookupError(f"no simulated drone at address {address:010X}")
        self._open = True
        heard = time.monotonic()
        latency_s, rssi = INFO.unpack_from(reply[5])
        self.faults = LinkFaults(latency_s=latency_s)
        self.rssi_dbm = rssi
        world_s, loss, seed, burst, good, bad, mean_good, mean_bad, channel, arc = PIPE_INFO.unpack_from(
            reply[5], INFO.size
        )
        self._t0 = heard - world_s
        self._loss = loss
        self._burst = BurstChannel(BurstLoss(good, bad, mean_good, mean_bad), f"burst:{seed}") if burst else None
        self._channel = None if channel == 255 else channel
        self._retries = arc
        self._rng = random.Random(f"piped:{seed}")
        self._heard_s = heard
        self._sock.setblocking(False)

    def _next_seq(self) -> int:
        self._seq = (self._seq + 1) & 0xFFFFFFFF
        if self._seq == PUSH_MARK:
            self._seq = 1
        return self._seq

    def _call(self, op: int, channel: int, flags: int, body: bytes) -> tuple[int, int, int, int, int, bytes] | None:
        """A request answered by the child (open, close), waiting up to `REPLY_TIMEOUT_S`; pushes that come
        meanwhile are taken."""
        seq = self._next_seq()
        deadline = time.monotonic() + REPLY_TIMEOUT_S
        try:
            self._sock.settimeout(REPLY_TIMEOUT_S)
            self._sock.send(REQUEST.pack(op, seq, self._address, channel, flags) + body)
            while True:
                self._sock.settimeout(max(1e-3, deadline - time.monotonic()))
                data = self._sock.recv(2048)
                if len(data) >= PUSH.size and PUSH.unpack_from(data)[0] == PUSH_MARK:
                    self._take(data)
                elif len(data) >= REPLY.size and REPLY.unpack_from(data)[0] == seq:
                    return (*REPLY.unpack_from(data), data[REPLY.size :])
        except OSError:  # timeout, or the drones' process is gone
            return None

    def _take(self, data: bytes) -> None:
        """One push of the child's."""
        _, op, _address = PUSH.unpack_from(data)
        self._heard_s = time.monotonic()
        if op == DOWN:
            if len(self._down) >= TX_QUEUE_SIZE:
                self.tx_dropped += 1
                return
            body = data[PUSH.size :]
            self._down.append((body[0], body[1], bytes(body[2:])))
        elif op == STATE:
            answering, rate, until, flushes = LINK_STATE.unpack_from(data, PUSH.size)
            self._answering = bool(answering)
            self._override = (rate, until) if until >= 0.0 else None
            if self._flushes is not None and flushes != self._flushes:
                self._down.clear()  # rebooted: its queue went with it
            self._flushes = flushes

    def _drain(self) -> None:
        while True:
            try:
                data = self._sock.recv(2048)
            except BlockingIOError:
                return
            except OSError:  # the child's port is closed: it is gone
                self._dead = True
                return
            if len(data) >= PUSH.size and PUSH.unpack_from(data)[0] == PUSH_MARK:
                self._take(data)

    def _attempt_loss(self, now_s: float) -> float:
        """`SimDrone.packet_loss` from this link's copy of its figures."""
        override = self._override
        if override is not None and now_s < override[1]:
            return override[0]
        loss = self._loss
        if self._burst is not None:
            loss = 1.0 - (1.0 - loss) * (1.0 - self._burst.loss_at(now_s))
        return loss

    def transact(self, channel: int, uplink: tuple[int, bytes] | None) -> tuple[bool, int, Packet | None]:
        """One radio transaction, decided here (`DronePort.transact`'s rules) and recorded in the child."""
        retries = self._retries
        with self._lock:
            if not self._open:
                return False, retries, None
            self._drain()
            now = time.monotonic()
            if self._dead or now - self._heard_s > PIPE_SILENT_S:
                return False, retries, None
            if not self._answering or (self._channel is not None and channel != self._channel):
                self._record(channel, False, retries, None)
                return False, retries, None
            loss = self._attempt_loss(now - self._t0)
            for retry in range(retries + 1):
                if loss <= 0.0 or self._rng.random() >= loss:
                    self._record(channel, True, retry, uplink)
                    return True, retry, self._down.popleft() if self._down else None
            self._record(channel, False, retries, None)
            return False, retries, None

    def _record(self, channel: int, acked: bool, retries: int, uplink: tuple[int, bytes] | None) -> None:
        body = b"" if uplink is None else bytes((uplink[0],)) + uplink[1]
        request = REQUEST.pack(RECORD, 0, self._address, channel, 1 if uplink is not None else 0)
        try:
            self._sock.send(request + RECORDED.pack(acked, min(retries, 255)) + body)
        except BlockingIOError:
            pass  # the socket's buffer is full (the child stopped reading): as a packet lost on the way
        except OSError:
            self._dead = True

    def has_downlink(self) -> bool:
        with self._lock:
            if self._open:
                self._drain()
            return bool(self._down)

    def attach(self, waker: threading.Event) -> None:
        """Attached at open; a link finds pushed packets at its next poll."""

    def detach(self, waker: threading.Event) -> None:
        with self._lock:
            if not self._open:
                return
            self._open = False
            self._call(CLOSE, 0, 0, b"")
            self._sock.close()
