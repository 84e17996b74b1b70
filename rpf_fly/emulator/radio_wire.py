"""The fake radio's wire between a flight's process and the simulated drones in their own process
(rpf_fly/emulator/world_process.py): each transaction of a fake link is one UDP request and its reply, as the real
Crazyradio driver waits on its USB dongle; a piped link (rpf_fly/emulator/remote_world.py, "Piped links") instead
decides each transaction in its own process, records it with one unanswered request, and is pushed its drone's
downlink packets and link state.

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
RECORD, BROADCAST_QUIET = 5, 6
"""A piped link's requests, never answered: RECORD, a transaction the link decided itself (`RECORDED` after the
request, then the uplink packet when flags bit 0); BROADCAST_QUIET, a BROADCAST without its reply."""
DOWN, STATE = 7, 8
"""What the child pushes to a piped link, unasked (`PUSH` first): DOWN, one downlink packet (port u8, channel u8,
payload) as the drone's firmware queues it; STATE (`LINK_STATE` after `PUSH`), the drone's link state when it
changes and every `STATE_EVERY_S`."""
PIPED = 0x02
"""OPEN's flags bit: the link decides its transactions itself (a piped link); the reply adds `PIPE_INFO`."""
REQUEST = struct.Struct("<BIQBB")
REPLY = struct.Struct("<IBBBB")
INFO = struct.Struct("<di")
PIPE_INFO = struct.Struct("<ddqBddddBB")
"""world time (s) when the reply was made, configured attempt loss, the drone's seed, bursty loss on (u8) and its
good loss, bad loss, mean good and bad times, the channel it listens on (255: any), the world's ARC retries."""
RECORDED = struct.Struct("<BB")
"""acknowledged (u8), retries used (u8)."""
PUSH = struct.Struct("<IBQ")
"""`PUSH_MARK` where a reply has its sequence number, op (DOWN or STATE), the drone's address."""
PUSH_MARK = 0xFFFFFFFF
"""No request's sequence number (a link skips it): a datagram that starts with it is a push, not a reply."""
LINK_STATE = struct.Struct("<Bddi")
"""answering the radio (u8), the runtime loss fault's rate and until (world s; until < 0: none), the drone's
downlink flushes (a reboot: the link forgets what it queued)."""
STATE_EVERY_S = 0.1
"""A piped link hears its drone's state at least this often; its changes are pushed after the world step that made
them (10 ms)."""
PIPE_SILENT_S = 2.0
"""A piped link that heard nothing from the child for this long takes every transaction as unanswered (the
child is gone or stopped)."""
REPLY_TIMEOUT_S = 0.5
"""A transaction whose reply has not come back by then is a lost ack. A loopback round trip takes well under 1 ms;
the margin is for a loaded machine, because a reply given up on is lost with the downlink packet it carried (the
real radio's safelink loses none). A child that died fails at once instead: the closed port answers the connected
socket with ECONNREFUSED."""
