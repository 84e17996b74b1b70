"""Packed extpos on the air: broadcasts on a dongle's channel (`Broadcaster`), and the sender that packs each
frame's positions into them (`PackedExtposSender`).

What cflib 0.1.34 offers (read in ``cflib/crtp/radiodriver.py`` and ``cflib/drivers/crazyradio.py``): no broadcast
link and no way to send without reading an acknowledgement. ``Crazyradio.set_ack_enable(False)`` exists, but
``Crazyradio.send_packet`` always reads the dongle's answer after writing, and without acknowledgements the
Crazyradio PA firmware answers nothing (crazyradio-firmware ``firmware/src/main.c`` lines 514-530), so every
broadcast would block cflib's shared radio thread for the read's 1 s timeout. What it does offer is
``RadioManager.open(devid)``: an instance on the dongle's shared radio thread (``_SharedRadio``) with its own
channel, data rate and address, whose ``send_packet`` goes through the same queue as the links' transactions. A
packet to the broadcast address 0xFFE7E7E7E7 that way is heard by every Crazyflie on the channel, acknowledged by
none, so the dongle sends it ARC + 1 = 4 times and reports it lost (`packed_extpos.BROADCAST_COPIES`): it costs
one address switch and four unanswered attempts of the dongle's time (the budget counts them), and each drone
takes up to four copies (the backend sets ``locSrv.extPosStdDev`` so that four weigh as one).

``radio://`` drones broadcast that way (`CflibBroadcast`); another link driver registers its own opener (the fake
radio does, for ``fake://``: rpf_fly/emulator/fake_radio.py) with `register`. A dongle that vanishes leaves a
broadcast blocked in cflib's shared radio thread, which dies with it; the drones' links fail as they do without
packed extpos (docs/radio.md, "The emulated Crazyradio").
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Protocol

from rpf_fly.radio.outbox import EXTPOS_MAX_WAIT_S, EXTPOS_STALE_WARN_EVERY_S
from rpf_fly.radio.packed_extpos import (
    BROADCAST_ADDRESS,
    BROADCAST_COPIES,
    HEADER,
    PackedGroup,
    Vec3,
    encode,
    packed_groups,
)

logger = logging.getLogger(__name__)

GROUP_WAIT_S = 0.002
"""How long a group's packet waits for the rest of its drones' positions after the first arrived: the flight loop
forwards one frame's positions back to back (microseconds apart), so a group's packet goes out complete; a drone of
the group that gets none this frame (landed, untracked) delays the others by this much."""


class Broadcaster(Protocol):
    """One dongle's broadcasts on one channel and data rate."""

    def send(self, packet: bytes) -> bool:
        """Transmit one CRTP packet (header byte first) to every drone listening; False when the dongle failed."""
        ...

    def close(self) -> None: ...


Opener = Callable[[int, int, str], Broadcaster]
"""(dongle number, channel, data rate "250K" | "1M" | "2M") -> a `Broadcaster`."""

_openers: dict[str, Opener] = {}


def register(scheme: str, opener: Opener) -> None:
    """Broadcasts for URIs of ``scheme`` (``"fake"``) go through ``opener`` from now on."""
    _openers[scheme] = opener


def unregister(scheme: str) -> None:
    _openers.pop(scheme, None)


def open_broadcast(scheme: str, dongle: int, channel: int, rate: str) -> Broadcaster:
    """A broadcaster on ``dongle``'s ``channel`` at ``rate`` for links of ``scheme`` (``radio``: cflib's)."""
    if scheme in _openers:
        return _openers[scheme](dongle, channel, rate)
    if scheme == "radio":
        return CflibBroadcast(dongle, channel, rate)
    raise ValueError(f"no broadcast for {scheme}:// links")


class CflibBroadcast:
    """Broadcasts through cflib 0.1.34's shared radio of one Crazyradio (module docstring): a
    ``RadioManager.open(devid)`` instance set to the channel, the data rate and the broadcast address."""

    def __init__(self, dongle: int, channel: int, rate: str) -> None:
        from cflib.crtp.radiodriver import RadioManager
        from cflib.drivers.crazyradio import Crazyradio

        rates = {"250K": Crazyradio.DR_250KPS, "1M": Crazyradio.DR_1MPS, "2M": Crazyradio.DR_2MPS}
        self._radio = RadioManager.open(dongle)
        self._radio.set_channel(channel)
        self._radio.set_data_rate(rates[rate])
        self._radio.set_address(tuple(BROADCAST_ADDRESS.to_bytes(5, "big")))

    def send(self, packet: bytes) -> bool:
        return self._radio.send_packet(packet) is not None  # never acknowledged: None only when the USB failed

    def close(self) -> None:
        self._radio.close()


@dataclass
class _Group:
    group: PackedGroup
    pending: dict[str, Vec3] = field(default_factory=dict)
    first_s: float = 0.0
    received: dict[str, float] = field(default_factory=dict)
    """name -> when its pending position's pose was received (where the caller said)."""


@dataclass
class _Air:
    """One (scheme, dongle, channel, data rate): its broadcaster, its groups and the thread that sends them."""

    key: tuple[str, int, int, str]
    groups: list[_Group]
    broadcaster: Broadcaster | None = None
    thread: threading.Thread | None = None


class PackedExtposSender:
    """Puts each drone's mocap positions (`put`) into its group's packet (up to four drones of one dongle, channel
    and data rate: `packed_extpos.packed_groups`) and broadcasts it once every drone of the group has a new
    position, or `GROUP_WAIT_S` after the first did. One thread per dongle and channel sends its groups' packets in
    turn, so a broadcast never waits in the caller's thread. Thread-safe."""

    def __init__(
        self,
        uris: Mapping[str, str],
        opener: Callable[[str, int, int, str], Broadcaster] = open_broadcast,
        group_wait_s: float = GROUP_WAIT_S,
    ) -> None:
        self._opener = opener
        self._wait_s = group_wait_s
        self._cond = threading.Condition()
        self._closed = False
        self._airs: dict[tuple[str, int, int, str], _Air] = {}
        self._group_of: dict[str, _Group] = {}
        schemes = {name: uri.partition("://")[0] for name, uri in uris.items()}
        for group in packed_groups(uris):
            key = (schemes[group.names[0]], group.dongle, group.channel, group.rate)
            entry = _Group(group)
            self._airs.setdefault(key, _Air(key, [])).groups.append(entry)
            for name in group.names:
                self._group_of[name] = entry
        self.packets = 0
        """Packets broadcast so far."""
        self.positions = 0
        """Positions they carried."""
        self.failed = 0
        """Packets the dongle failed to send."""
        self.stale = 0
        """Positions left out because their pose waited longer than `EXTPOS_MAX_WAIT_S`."""
        self._stale_warned_at: float | None = None
        self._sent_s: dict[str, float] = {}

    def start(self) -> dict[str, str]:
        """Open every dongle's broadcast and start its thread; drone name -> error for the drones whose broadcast
        could not be opened (they get no mocap: they must not fly)."""
        errors: dict[str, str] = {}
        for key, air in self._airs.items():
            scheme, dongle, channel, rate = key
            try:
                air.broadcaster = self._opener(scheme, dongle, channel, rate)
            except Exception as exc:  # noqa: BLE001 - reported per drone
                for entry in air.groups:
                    for name in entry.group.names:
                        errors[name] = f"packed extpos: no broadcast on dongle {dongle} channel {channel}: {exc}"
                continue
            air.thread = threading.Thread(
                target=self._run, args=(air,), daemon=True, name=f"rpf-packed-{dongle}-{channel}"
            )
            air.thread.start()
        return errors

    def put(self, name: str, position: Vec3, received_s: float | None = None) -> bool:
        """Queue ``name``'s newest position for its group's next packet (a newer one replaces one still waiting;
        ``received_s``: when its pose was received, so that a position that waited longer than
        `EXTPOS_MAX_WAIT_S` when its packet is made is left out). False when the drone has no group or its
        broadcast is not open."""
        entry = self._group_of.get(name)
        if entry is None:
            return False
        with self._cond:
            if self._closed:
                return False
            if not entry.pending:
                entry.first_s = time.monotonic()
            entry.pending[name] = (float(position[0]), float(position[1]), float(position[2]))
            if received_s is None:
                entry.received.pop(name, None)
            else:
                entry.received[name] = received_s
            self._cond.notify_all()
        return True

    def close(self) -> None:
        """Stop the threads (a packet being sent goes out) and close the broadcasts."""
        with self._cond:
            self._closed = True
            self._cond.notify_all()
        for air in self._airs.values():
            if air.thread is not None:
                air.thread.join(timeout=1.0)
            if air.broadcaster is not None:
                try:
                    air.broadcaster.close()
                except Exception:  # noqa: BLE001 - closing must not fail the flight's close
                    logger.exception("packed extpos: closing the broadcast failed")

    def _due(self, air: _Air, now: float) -> tuple[list[_Group], float | None]:
        ready, wake = [], None
        for entry in air.groups:
            if not entry.pending:
                continue
            deadline = entry.first_s + self._wait_s
            if len(entry.pending) == len(entry.group.names) or now >= deadline:
                ready.append(entry)
            else:
                wake = deadline if wake is None else min(wake, deadline)
        return ready, wake

    def _run(self, air: _Air) -> None:
        assert air.broadcaster is not None
        while True:
            with self._cond:
                while True:
                    if self._closed:
                        return
                    now = time.monotonic()
                    ready, wake = self._due(air, now)
                    if ready:
                        packets = [self._take(entry) for entry in ready]
                        break
                    self._cond.wait(None if wake is None else max(wake - now, 0.0))
            for packet, names in packets:
                if packet is None:
                    continue
                ok = air.broadcaster.send(packet)
                self.packets += 1
                self.positions += len(names)
                self.failed += 0 if ok else 1
                if ok:
                    sent = time.monotonic()
                    with self._cond:
                        for name in names:
                            self._sent_s[name] = sent

    def sent_s(self, name: str) -> float | None:
        """`time.monotonic()` when a broadcast carrying ``name``'s position last went out (None: none yet)."""
        with self._cond:
            return self._sent_s.get(name)

    def _take(self, entry: _Group) -> tuple[bytes | None, list[str]]:
        """The group's packet (members in group order) and the drones whose positions it carries; the pending
        positions are taken (a position that does not fit int16 millimetres is dropped, with a warning)."""
        items = []
        names: list[str] = []
        now = time.monotonic()
        for name, ident in zip(entry.group.names, entry.group.ids):
            position = entry.pending.pop(name, None)
            received = entry.received.pop(name, None)
            if position is None:
                continue
            if received is not None and now - received > EXTPOS_MAX_WAIT_S:
                self.stale += 1
                if self._stale_warned_at is None or now - self._stale_warned_at >= EXTPOS_STALE_WARN_EVERY_S:
                    self._stale_warned_at = now
                    logger.warning(
                        "packed extpos: drone %s: a mocap pose waited %.0f ms in the ground station (over %.0f ms): "
                        "left out of the broadcast (%d so far)",
                        name,
                        (now - received) * 1000.0,
                        EXTPOS_MAX_WAIT_S * 1000.0,
                        self.stale,
                    )
                continue
            try:
                encode([(ident, position)])
            except ValueError as err:
                logger.warning("packed extpos: drone %s: %s", name, err)
                continue
            items.append((ident, position))
            names.append(name)
        entry.pending.clear()
        return (bytes((HEADER,)) + encode(items), names) if items else (None, [])


__all__ = [
    "BROADCAST_COPIES",
    "Broadcaster",
    "CflibBroadcast",
    "GROUP_WAIT_S",
    "PackedExtposSender",
    "open_broadcast",
    "register",
    "unregister",
]
