"""Packed external positions (``radio.extpos: packed``): several drones' mocap positions in one broadcast packet.

The layout, from crazyflie-firmware at 2a18fc2 (release 2026.08), ``src/modules/src/crtp_localization_service.c``:

- CRTP port 6 (localization), channel 2 ``EXT_POSITION_PACKED`` (lines 64-69); the handler
  ``extPositionPackedHandler`` (lines 350-369) reads ``pk->size / 7`` items from the first data byte on;
- an item (``extPositionPackedItem``, lines 105-111, "up to 4 items per CRTP packet"): ``uint8 id`` ("last 8 bit of
  the Crazyflie address"), ``int16 x, y, z`` in millimetres, little-endian, packed: 7 bytes, so 4 items are 28 of
  the 30 data bytes a CRTP packet carries (``crtp.h`` ``CRTP_MAX_DATA_SIZE``);
- a drone's id is ``configblockGetRadioAddress() & 0xFF`` (lines 168-169), the last byte of the radio address it
  listens on: the URI's last two hex digits. The item with its id goes to its estimator as an external position
  (``x / 1000.0f``, standard deviation ``locSrv.extPosStdDev``, line 150: 0.01 m by default); the others go to
  peer localization (line 366), which the flight does not use.
- The packed *pose* variant (lines 113-120 and 233-254): channel 1 (generic), first byte ``EXT_POSE_PACKED`` = 9
  (``crtp_localization_service.h`` line 67), then items of id, x, y, z (int16 mm) and a ``uint32`` compressed
  quaternion (``quatcompress.h``): 11 bytes, up to 2 a packet. Not sent by rpf_fly (position only here).

Who hears it: a Crazyflie's nRF51 listens on its own address and on the broadcast address 0xFFE7E7E7E7
(crazyflie2-nrf-firmware at 32b6ecb, ``src/esb.c`` lines 346-357: logical address 1, prefix 0xFF, base
0xE7E7E7E7) and never acknowledges a broadcast (``esb.c`` lines 271-278); the STM32 firmware queues it as CRTP
like any packet (crazyflie-firmware ``src/hal/src/radiolink.c`` lines 180-190). So one packet on the dongle's
channel and data rate reaches every drone listening there.

Pure: layout, ids and groups; sending is `rpf_fly.radio.broadcast`.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

Vec3 = tuple[float, float, float]

PORT_LOCALIZATION = 6
CHANNEL_EXT_POSITION_PACKED = 2
HEADER = (PORT_LOCALIZATION << 4) | 0x0C | CHANNEL_EXT_POSITION_PACKED
"""The CRTP header byte (port 6, channel 2, the two link bits set as cflib sets them): 0x6E."""

ITEM = struct.Struct("<Bhhh")
ITEMS_PER_PACKET = 4
MAX_MM = 32767
"""int16 millimetres: a packed position must lie within +-32.767 m on each axis."""

BROADCAST_ADDRESS = 0xFFE7E7E7E7
"""The address every Crazyflie also listens on and never acknowledges (crazyflie2-nrf-firmware ``esb.c``)."""

BROADCAST_COPIES = 4
"""How many times a Crazyradio transmits one broadcast through cflib 0.1.34: cflib's ``Crazyradio.send_packet``
always reads the dongle's answer, so a broadcast goes out with acknowledgements enabled, nobody acknowledges it,
and the dongle makes its ARC + 1 attempts (cflib sets ARC 3: ``radiodriver.py`` ``_nr_of_arc_retries``;
crazyradio2-firmware ``esb.c`` lines 340-414 retries up to ARC times, the PA's nRF24LU1+ likewise). Every drone
hears each copy: its estimator takes up to four updates of the same position."""

FIRMWARE_EXT_POS_STD_DEV_M = 0.01
"""``locSrv.extPosStdDev``'s default (crtp_localization_service.c line 150)."""

PACKED_EXT_POS_STD_DEV_M = FIRMWARE_EXT_POS_STD_DEV_M * math.sqrt(BROADCAST_COPIES)
"""What the backend sets ``locSrv.extPosStdDev`` to under packed extpos: four updates of one position at 0.02 m
carry the information of one at 0.01 m (information adds: 4 / 0.02^2 = 1 / 0.01^2), so a drone that hears every
copy weighs the mocap as it does one unicast extpos."""


def drone_id(address: int) -> int:
    """The packed-extpos id of the drone at radio ``address``: its last byte (crtp_localization_service.c 168-169)."""
    return address & 0xFF


def to_mm(value_m: float) -> int:
    """Metres to the firmware's int16 millimetres (rounded); ValueError outside +-32.767 m."""
    mm = round(value_m * 1000.0)
    if not -MAX_MM - 1 <= mm <= MAX_MM:
        raise ValueError(f"{value_m:.3f} m does not fit a packed position (int16 millimetres, +-32.767 m)")
    return mm


def encode(items: Sequence[tuple[int, Vec3]]) -> bytes:
    """The data bytes (after the header) of one packed packet: up to `ITEMS_PER_PACKET` (id, position in metres)."""
    if not 1 <= len(items) <= ITEMS_PER_PACKET:
        raise ValueError(f"a packed extpos packet carries 1 to {ITEMS_PER_PACKET} positions, not {len(items)}")
    return b"".join(ITEM.pack(ident & 0xFF, to_mm(p[0]), to_mm(p[1]), to_mm(p[2])) for ident, p in items)


def decode(data: bytes) -> list[tuple[int, Vec3]]:
    """The items of a packed packet's data as the firmware reads them: ``len(data) // 7`` items, a short tail
    ignored; positions in metres."""
    out = []
    for k in range(len(data) // ITEM.size):
        ident, x, y, z = ITEM.unpack_from(data, k * ITEM.size)
        out.append((ident, (x / 1000.0, y / 1000.0, z / 1000.0)))
    return out


@dataclass(frozen=True)
class Link:
    """What a packed broadcast needs of a URI: the dongle, channel and data rate it goes out on, the drone's id."""

    dongle: int
    channel: int
    rate: str
    address: int

    @property
    def air(self) -> tuple[int, int, str]:
        """The broadcast this drone hears: (dongle, channel, data rate)."""
        return self.dongle, self.channel, self.rate


def parse_link(uri: str) -> Link:
    """``radio://`` or ``fake://`` ``DONGLE/CHANNEL/RATE/ADDRESS[?...]`` (the mission loader has checked it)."""
    path = uri.partition("://")[2].partition("?")[0]
    dongle, channel, rate, address = path.split("/")
    return Link(int(dongle), int(channel), rate, int(address, 16))


@dataclass(frozen=True)
class PackedGroup:
    """Up to four drones whose positions share one packet, on one dongle, channel and data rate."""

    dongle: int
    channel: int
    rate: str
    names: tuple[str, ...]
    ids: tuple[int, ...]


def packed_groups(uris: Mapping[str, str]) -> list[PackedGroup]:
    """The drones (name -> URI, in mission order) in groups of up to four per (dongle, channel, data rate), in the
    order of their first drone."""
    per: dict[tuple[int, int, str], list[tuple[str, int]]] = {}
    for name, uri in uris.items():
        link = parse_link(uri)
        per.setdefault(link.air, []).append((name, drone_id(link.address)))
    groups = []
    for (dongle, channel, rate), members in per.items():
        for k in range(0, len(members), ITEMS_PER_PACKET):
            chunk = members[k : k + ITEMS_PER_PACKET]
            groups.append(PackedGroup(dongle, channel, rate, tuple(n for n, _ in chunk), tuple(i for _, i in chunk)))
    return groups


def shared_ids(uris: Mapping[str, str]) -> list[tuple[int, int, tuple[str, ...]]]:
    """(channel, id, drones) for every id two or more drones share on one channel: each of them would take the
    other's position as its own from a packed broadcast."""
    per: dict[tuple[int, int], list[str]] = {}
    for name, uri in uris.items():
        link = parse_link(uri)
        per.setdefault((link.channel, drone_id(link.address)), []).append(name)
    return [(channel, ident, tuple(names)) for (channel, ident), names in per.items() if len(names) > 1]


def packets_per_frame(drones: Iterable[str], uris: Mapping[str, str]) -> int:
    """Packed packets one frame needs for ``drones``: one per group."""
    wanted = set(drones)
    return sum(1 for g in packed_groups(uris) if wanted & set(g.names))
