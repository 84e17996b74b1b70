"""What one Crazyradio does with a mission's traffic under cflib 0.1.34: a discrete-event model (pure) of its
shared radio thread and the links taking turns on it, timed by the dongle's figures.

The mechanism modelled, as cflib 0.1.34 has it (``cflib/crtp/radiodriver.py``):
- one ``_SharedRadio`` thread per dongle serves every link's transactions in the order they were queued (a FIFO),
  and before each one sets the channel, address and data rate, each a USB control transfer when it differs from the
  last (``Crazyradio.set_channel`` / ``set_address`` / ``set_data_rate``): links taking turns pay an address switch
  on almost every transaction;
- each link's thread (``_RadioDriverThread``) queues one transaction, waits for it, sleeps ``1 / rate_limit``
  when the URI gives ``?rate_limit=N``, then takes its next packet (or a null packet: a poll) and queues again. A
  Crazyflie's acknowledgement is never empty, so without a rate limit a link never relaxes: it polls back to back
  and keeps a transaction in the queue at all times;
- a transaction the radio could not get acknowledged in its ARC + 1 attempts is retried at once with the same
  packet (safelink);
- what the flight hands cflib waits in the link's out queue, the newest setpoint and the newest extpos replacing
  older ones not yet taken (the backend's outbox, rpf_fly/radio/outbox.py);
- packed extpos broadcasts (rpf_fly/radio/broadcast.py) are queued on the same thread from their own, one at a
  time, each an address switch and `BROADCAST_COPIES` unanswered attempts.

Times: :class:`Timing` from a `RadioType` (rpf_fly/emulator/crazyradio_timing.py: control transfer, bulk
transfers, the Enhanced ShockBurst cycle per attempt). Attempts are lost at random with ``loss`` each.

The host's own time per transaction is modelled as a fixed figure (`HOST_TRANSACTION_S`, `HOST_SWITCH_S`): cflib
hands every transaction from the link's thread to the shared radio thread and back through two queues, and pyusb
wraps each USB call in Python layers; that time passes between the dongle's transfers, so the dongle carries less
than its own figures allow. Not modelled: a loaded host's further delays (thread wake-ups, the GIL), the flight's
commands (take-off, landing) and parameter writes.
"""

from __future__ import annotations

import heapq
import math
import random
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

BROADCAST = -1
"""The broadcaster's place of a link index, and the broadcast address in an air key."""


HOST_TRANSACTION_S = 0.3e-3
"""The host's time per transaction, between the dongle's transfers: cflib 0.1.34's two queue hand-overs (the link's
thread to the shared radio thread and back) and pyusb's Python layers around the bulk write and read. Measured
through the emulated dongles (`rpf-fly radio probe --dry-run --links 8`, docs/radio.md "Radio budget"): one link
carries 951 transactions/s on a PA and 1136 on a 2.0 where the dongles' own figures allow 1337 and 1675, 0.30 and
0.28 ms more each. A lab's probe (``radio.budget_packets_s``) replaces it with what its own host does."""
HOST_SWITCH_S = 0.2e-3
"""The host's time per address switch on top of the control transfer (pyusb's layers around it, the shared radio
thread serving many links): eight links through the emulated dongles carry 450 transactions/s on a PA and 277 on a
2.0 where the figures allow 572 and 323, 0.47 and 0.51 ms more each."""


@dataclass(frozen=True)
class Timing:
    """Seconds one dongle spends per operation: ``attempt(up, ack, acked)`` is the radio's part of one attempt."""

    control_s: float
    bulk_s: float
    """Bulk OUT and IN of one packet together (USB only)."""
    upload_s_per_byte: float
    ramp_s: float
    rate_bps: int
    irq_s: float
    wait_s: float
    """After an unacknowledged attempt: the PA's ARD, the 2.0's acknowledgement timeout."""
    scale: float = 1.0
    """Every time multiplied by this (a lab's measured budget against the figures')."""
    host_s: float = HOST_TRANSACTION_S
    """The host's time per transaction (`HOST_TRANSACTION_S`)."""
    host_switch_s: float = HOST_SWITCH_S
    """The host's time per address switch (`HOST_SWITCH_S`)."""

    def on_air_s(self, payload: int) -> float:
        return (8 * (1 + 5 + payload + 2) + 9) / self.rate_bps

    def transaction_s(self, up: int, ack: int, attempts: int, acked: bool) -> float:
        """Bulk write, ``attempts`` transmissions (the last acknowledged with ``ack`` bytes if ``acked``), bulk
        read: nRF24LU1+ PS table 18, as `crazyradio_timing.radio_s`."""
        lost = attempts - 1 if acked else attempts
        radio = self.upload_s_per_byte * up + lost * (self.ramp_s + self.on_air_s(up) + self.wait_s)
        if acked:
            radio += 2 * self.ramp_s + self.on_air_s(up) + self.on_air_s(ack) + self.irq_s
        return (self.bulk_s + radio + self.host_s) * self.scale

    def switch_s(self, changes: int) -> float:
        return changes * (self.control_s + self.host_switch_s) * self.scale


def timing_of(radio: Any, rate: str, scale: float = 1.0) -> Timing:
    """`Timing` of a `crazyradio_timing.RadioType` at data rate ``rate`` ("250K", "1M", "2M"), with cflib's ARD
    setting (``set_ard_bytes(32)``) on a PA."""
    from rpf_fly.emulator import crazyradio_timing as ct  # the figures' one table (pure data, nothing emulated)

    code = {"250K": ct.DR_250K, "1M": ct.DR_1M, "2M": ct.DR_2M}[rate]
    wait = radio.ack_timeout_s if radio.ack_timeout_s is not None else ct.ard_s(0x80 | 32, code)
    return Timing(
        radio.control_s,
        radio.bulk_out_s + radio.bulk_in_s,
        radio.upload_s_per_byte,
        radio.ramp_s,
        ct.RATE_BPS[code],
        radio.irq_s[code],
        wait,
        scale,
    )


@dataclass(frozen=True)
class LinkTraffic:
    """One link's traffic (packets a second and their sizes, CRTP header included)."""

    air: tuple[int, str, int]
    """(channel, data rate, address): what the dongle must be set to for this link."""
    rate_limit: int | None
    setpoint_bytes: int = 18
    extpos_hz: float = 0.0
    extpos_phase: float = 0.0
    extpos_bytes: int = 13
    ping_hz: float = 10.0
    ping_bytes: int = 10
    keepalive_hz: float = 5.0
    keepalive_bytes: int = 2
    status_hz: float = 10.0
    status_bytes: int = 28


@dataclass(frozen=True)
class Traffic:
    """One dongle's traffic: its links, the packed broadcasts (per group: phase, bytes, channel, data rate), the
    rates."""

    links: tuple[LinkTraffic, ...]
    setpoint_hz: float
    frame_hz: float
    extpos_hz: float
    broadcasts: tuple[tuple[float, int, int, str], ...] = ()
    loss: float = 0.0
    arc: int = 3
    copies: int = 4


@dataclass
class Run:
    """What the model saw over ``seconds`` (after a warm-up)."""

    seconds: float
    busy_s: float = 0.0
    transactions: int = 0
    data_transactions: int = 0
    broadcasts: int = 0
    setpoint_latency_s: list[float] = field(default_factory=list)
    extpos_latency_s: list[float] = field(default_factory=list)
    superseded: int = 0
    """Setpoints replaced in their link's out queue by a newer one before the radio took them."""
    superseded_extpos: int = 0
    """Extpos (a link's, or a packed group's packet) replaced by a newer frame's before the radio took it."""
    made_setpoints: int = 0
    made_extpos: int = 0
    """Extpos handed to the radio (a link's, or a packed group's packet)."""

    @property
    def setpoints_superseded(self) -> float:
        """Share of the setpoints handed over that newer ones replaced before the radio took them."""
        return self.superseded / self.made_setpoints if self.made_setpoints else 0.0

    @property
    def extpos_delivered(self) -> float:
        """Share of the extpos handed over that went out (the others were replaced by newer ones)."""
        return 1.0 - self.superseded_extpos / self.made_extpos if self.made_extpos else 1.0

    @property
    def busy(self) -> float:
        """Share of the dongle's time in use (polls included)."""
        return self.busy_s / self.seconds

    def setpoint_p(self, q: float) -> float:
        return _quantile(self.setpoint_latency_s, q)

    def extpos_p(self, q: float) -> float:
        return _quantile(self.extpos_latency_s, q)


def _quantile(values: Sequence[float], q: float) -> float:
    if not values:
        return math.nan
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, max(0, math.ceil(q * len(ordered)) - 1))]


@dataclass
class _Link:
    spec: LinkTraffic
    pending: deque = field(default_factory=deque)
    """(kind, made_s, bytes) waiting in the out queue, oldest first."""
    downlink: deque = field(default_factory=deque)


def simulate(traffic: Traffic, timing: Timing, seconds: float = 4.0, warmup_s: float = 0.5, seed: int = 1) -> Run:
    """Run the dongle for ``warmup_s + seconds``; latencies and counts over the last ``seconds``."""
    rng = random.Random(seed)
    end = warmup_s + seconds
    run = Run(seconds)
    links = [_Link(spec) for spec in traffic.links]
    events: list[tuple[float, int, str, Any]] = []
    counter = 0

    def at(t: float, kind: str, data: Any = None) -> None:
        nonlocal counter
        counter += 1
        heapq.heappush(events, (t, counter, kind, data))

    # the traffic: ticks (every link's setpoint at once), frames (extpos slots), pings, keep-alives, status
    if traffic.setpoint_hz > 0:
        for k in range(1, int(end * traffic.setpoint_hz) + 1):
            at(k / traffic.setpoint_hz, "tick")
    frames = [j / traffic.frame_hz for j in range(1, int(end * traffic.frame_hz) + 1)] if traffic.frame_hz else []
    rate = traffic.extpos_hz
    for index, link in enumerate(links):
        spec = link.spec
        for hz, kind in ((spec.ping_hz, "ping"), (spec.keepalive_hz, "keepalive"), (spec.status_hz, "status")):
            if hz > 0:
                phase = rng.random() / hz
                for k in range(int((end - phase) * hz) + 1):
                    at(phase + k / hz, kind, index)
        if spec.extpos_hz > 0:
            for t in _slot_frames(frames, spec.extpos_hz, spec.extpos_phase):
                at(t, "extpos", index)
    for group, (phase, nbytes, channel, data_rate) in enumerate(traffic.broadcasts):
        for t in _slot_frames(frames, rate, phase):
            at(t, "broadcast", (group, nbytes, (channel, data_rate, BROADCAST)))
    for index in range(len(links)):
        at(rng.random() * 1e-3, "issue", index)

    fifo: deque = deque()
    busy_until = 0.0
    current: tuple[int, str, int] | None = None
    broadcast_queue: dict[int, tuple[float, int, tuple[int, str, int]]] = {}
    """Group -> its packet waiting for the broadcaster: a newer frame's positions replace it (the sender's)."""
    broadcasting = False

    def count(t: float) -> bool:
        return t >= warmup_s

    def start_next(t: float) -> None:
        nonlocal busy_until, current
        if busy_until > t or not fifo:
            return
        who, air, up, packet = fifo.popleft()
        changes = 3 if current is None else sum(a != b for a, b in zip(current, air))
        current = air
        if who == BROADCAST:
            service = timing.switch_s(changes) + timing.transaction_s(up, 0, traffic.copies, False)
            ok, ack = True, 0
        else:
            link = links[who]
            attempts, ok = 1, False
            while attempts <= traffic.arc + 1:
                if rng.random() >= traffic.loss:
                    ok = True
                    break
                attempts += 1
            attempts = min(attempts, traffic.arc + 1)
            ack = link.downlink[0] if ok and link.downlink else 1
            service = timing.switch_s(changes) + timing.transaction_s(up, ack, attempts, ok)
        busy_until = t + service
        if count(t):
            run.busy_s += min(service, end - t)
        at(busy_until, "done", (who, ok, packet))

    def issue(t: float, index: int, retry: Any = None) -> None:
        link = links[index]
        packet = retry
        if packet is None and link.pending:
            packet = link.pending.popleft()
        up = packet[2] if packet is not None else 1
        fifo.append((index, link.spec.air, up, packet))
        start_next(t)

    def hand(link: _Link, kind: str, t: float, nbytes: int) -> None:
        if kind == "setpoint":
            run.made_setpoints += count(t)
        elif kind == "extpos":
            run.made_extpos += count(t)
        if kind in ("setpoint", "extpos"):
            for k, item in enumerate(link.pending):
                if item[0] == kind:
                    del link.pending[k]
                    if count(t) and kind == "setpoint":
                        run.superseded += 1
                    elif count(t):
                        run.superseded_extpos += 1
                    break
        link.pending.append((kind, t, nbytes))

    def send_broadcast(t: float) -> None:
        nonlocal broadcasting
        if broadcasting or not broadcast_queue:
            return
        broadcasting = True
        made, nbytes, air = broadcast_queue.pop(next(iter(broadcast_queue)))
        fifo.append((BROADCAST, air, nbytes, ("broadcast", made, nbytes)))
        start_next(t)

    while events:
        t, _, kind, data = heapq.heappop(events)
        if t > end:
            break
        if kind == "done":
            who, ok, packet = data
            if who == BROADCAST:
                broadcasting = False
                if count(packet[1]):
                    run.broadcasts += 1
                    run.extpos_latency_s.append(t - packet[1])
                send_broadcast(t)
            else:
                link = links[who]
                if not ok:
                    issue(t, who, packet)  # retried at once, same packet, no sleep
                else:
                    if link.downlink:
                        link.downlink.popleft()
                    if count(t):
                        run.transactions += 1
                        run.data_transactions += packet is not None
                    if packet is not None:
                        if packet[0] == "ping":
                            link.downlink.append(link.spec.ping_bytes)
                        if count(packet[1]) and packet[0] == "setpoint":
                            run.setpoint_latency_s.append(t - packet[1])
                        elif count(packet[1]) and packet[0] == "extpos":
                            run.extpos_latency_s.append(t - packet[1])
                    limit = link.spec.rate_limit
                    at(t + (1.0 / limit if limit else 0.0), "issue", who)
            start_next(t)
        elif kind == "issue":
            issue(t, data)
        elif kind == "tick":
            for link in links:
                hand(link, "setpoint", t, link.spec.setpoint_bytes)
        elif kind in ("ping", "keepalive", "extpos"):
            spec = links[data].spec
            nbytes = {"ping": spec.ping_bytes, "keepalive": spec.keepalive_bytes, "extpos": spec.extpos_bytes}[kind]
            hand(links[data], kind, t, nbytes)
        elif kind == "status":
            if len(links[data].downlink) < 64:
                links[data].downlink.append(links[data].spec.status_bytes)
        elif kind == "broadcast":
            group, nbytes, air = data
            run.made_extpos += count(t)
            if group in broadcast_queue and count(t):
                run.superseded_extpos += 1
            broadcast_queue.pop(group, None)
            broadcast_queue[group] = (t, nbytes, air)
            send_broadcast(t)
    return run


def _slot_frames(frames: Sequence[float], rate_hz: float, phase: float) -> list[float]:
    """The frames on which a drone (or a packed group) of ``phase`` sends: the first of each new slot
    ``floor(t * rate + phase)`` (rpf_fly/radio/schedule.py)."""
    out, last = [], None
    for t in frames:
        slot = math.floor(t * rate_hz + phase)
        if last is None or slot > last:
            out.append(t)
            last = slot
    return out
