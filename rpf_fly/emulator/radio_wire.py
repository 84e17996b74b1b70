"""The fake radio's wire between a flight's process and the simulated drones in their own process
(rpf_fly/emulator/world_process.py): each transaction of a fake link is one UDP request and its reply, as the real
Crazyradio driver waits on its USB dongle.

Little-endian: request ``op u8, seq u32, address u64, channel u8, flags u8`` then, for a transaction with an uplink
packet (flags bit 0), the CRTP header byte and payload; reply ``seq u32, ok u8, retry u8, more u8, down u8`` then,
when ``down``, port u8, channel u8 and the payload. ``more``: the drone still has downlink packets queued (the link
polls again at once). An ``open`` reply carries ``latency_s f64, rssi i32``.
"""

from __future__ import annotations

import struct

OPEN, TRANSACT, CLOSE, BROADCAST = 1, 2, 3, 4
"""Requests of a fake link to the child; BROADCAST (a packed extpos: no acknowledgement) carries its copies in the
flags byte and reaches every drone (`FakeWorld.broadcast`)."""
REQUEST = struct.Struct("<BIQBB")
REPLY = struct.Struct("<IBBBB")
INFO = struct.Struct("<di")
REPLY_TIMEOUT_S = 0.5
"""A transaction whose reply has not come back by then is a lost ack. A loopback round trip takes well under 1 ms;
the margin is for a loaded machine, because a reply given up on is lost with the downlink packet it carried (the
real radio's safelink loses none). A child that died fails at once instead: the closed port answers the connected
socket with ECONNREFUSED."""
