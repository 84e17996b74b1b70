"""Fuzz: mutated and truncated packets of every version, fed to the decoder and to the client's packet handler.

Contract: the decoder raises only NatNetDecodeError; the client never raises, counts every packet as exactly one
of frame / message / drop (malformed ones also as malformed), agrees with the decoder, and decodes the next valid
frame correctly. Seeded, so a failure reproduces.
"""

from __future__ import annotations

import logging
import random
import socket
import struct
import time

import pytest
from natnet_captures import DATA
from natnet_samples import VERSIONS, rich_frame, rich_model, rigid_body, server_info

from rpf_fly.mocap.natnet_client import NatNetClient
from rpf_fly.mocap.natnet_protocol import (
    FrameOfData,
    MessageId,
    NatNetDecodeError,
    decode_packet,
    encode_echo_response,
    encode_frame,
    encode_model_def,
    encode_response,
    encode_server_info,
)

SEED = 1510
MUTANTS_PER_VERSION = 40_000  # x 4 versions = 160,000 mutated packets
SERVER = ("127.0.0.1", 1510)
#: Messages whose payload the client decodes (it drops the others unread, e.g. a REQUEST sent to a client).
CLIENT_DECODES = {
    MessageId.FRAMEOFDATA,
    MessageId.MODELDEF,
    MessageId.SERVERINFO,
    MessageId.RESPONSE,
    MessageId.MESSAGESTRING,
    MessageId.ECHORESPONSE,
}
_SPECIAL_INTS = (-1, -(2**31), 2**31 - 1, 0x10000, 0x7FFF, 1 << 24, 56_000_000, 2, 0)


def base_packets(version) -> list[bytes]:
    packets = [
        encode_frame(rich_frame(version), version),
        encode_frame(FrameOfData(5, rigid_bodies=[rigid_body(i) for i in range(1, 11)]), version),
        encode_model_def(rich_model(version), version),
        encode_server_info(server_info(version)),
        encode_response(120.0),
        encode_response("OK"),
        encode_echo_response(1, 2),
    ]
    if version == (3, 0):
        real = ("mocapframe_packet_v3.bin", "mocapframe_packet_occluded_v3.bin", "modeldef_packet_v3.bin")
        packets += [(DATA / name).read_bytes() for name in real]
    return packets


def count_offsets(packet: bytes) -> list[int]:
    """Offsets holding small non-negative int32 values: where counts and sizes live."""
    return [i for i in range(4, len(packet) - 3) if 0 <= struct.unpack_from("<i", packet, i)[0] <= 64] or [4]


def with_header(payload: bytes, message_id: int) -> bytes:
    return struct.pack("<HH", message_id, min(len(payload), 0xFFFF)) + payload


def mutate(packet: bytes, offsets: list[int], rng: random.Random) -> bytes:
    data = bytearray(packet)
    if not data:
        return b""
    kind = rng.randrange(7) if len(data) >= 8 else rng.randrange(2)  # tiny leftovers: flip or replace only
    if kind == 0:  # bit flips
        for _ in range(rng.randint(1, 4)):
            i = rng.randrange(len(data))
            data[i] ^= 1 << rng.randrange(8)
    elif kind == 1:  # byte replacements
        for _ in range(rng.randint(1, 4)):
            data[rng.randrange(len(data))] = rng.randrange(256)
    elif kind == 2:  # a count or size set huge, negative or off by a little
        i = rng.choice(offsets)
        if i > len(data) - 4:  # an earlier mutation shortened the packet
            i = rng.randrange(len(data) - 3)
        old = struct.unpack_from("<i", data, i)[0]
        value = rng.choice(_SPECIAL_INTS + (old + 1, old - 1, rng.randint(-(2**31), 2**31 - 1)))
        struct.pack_into("<i", data, i, (value + 2**31) % 2**32 - 2**31)
    elif kind == 3:  # truncated, with the header left as is or made consistent
        n = rng.randrange(len(data))
        data = data[:n]
        if n >= 4 and rng.random() < 0.5:
            data = bytearray(with_header(bytes(data[4:]), struct.unpack_from("<H", data)[0]))
    elif kind == 4:  # header byte count wrong
        struct.pack_into("<H", data, 2, rng.randrange(0x10000))
    elif kind == 5:  # bytes inserted or deleted, header made consistent
        i = rng.randrange(4, len(data) + 1)
        if rng.random() < 0.5 and len(data) > 4:
            del data[i : i + rng.randint(1, 8)]
        else:
            data[i:i] = bytes(rng.randrange(256) for _ in range(rng.randint(1, 8)))
        data = bytearray(with_header(bytes(data[4:]), struct.unpack_from("<H", data)[0]))
    else:  # two mutations
        return mutate(mutate(packet, offsets, rng), offsets, rng)
    return bytes(data)


@pytest.fixture
def client():
    sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sink.bind(("127.0.0.1", 0))
    natnet = NatNetClient("127.0.0.1", multicast=False, command_port=sink.getsockname()[1], keepalive_s=3600)
    yield natnet
    natnet.close()
    sink.close()


@pytest.mark.parametrize("version", VERSIONS, ids=lambda v: f"{v[0]}.{v[1]}")
def test_mutated_packets_never_escape_and_every_drop_is_counted(version, client, caplog):
    caplog.set_level(logging.ERROR, logger="rpf_fly.mocap.natnet_client")
    rng = random.Random(SEED + version[0] * 10 + version[1])
    valid_info = encode_server_info(server_info(version))
    client.handle_packet(valid_info, SERVER, time.monotonic())
    client.handle_packet(encode_model_def(rich_model(version), version), SERVER, time.monotonic())
    bases = [(p, count_offsets(p)) for p in base_packets(version)]
    decoded_frames = decode_failures = 0
    last_delivered = 0
    for i in range(MUTANTS_PER_VERSION):
        packet, offsets = bases[i % len(bases)]
        mutant = mutate(packet, offsets, rng)

        try:
            message_id, body = decode_packet(mutant, version)
            decoder_ok = True
        except NatNetDecodeError:
            decoder_ok = False
            decode_failures += 1
        header_ok = len(mutant) >= 4 and struct.unpack_from("<H", mutant, 2)[0] <= len(mutant) - 4
        mutant_id = struct.unpack_from("<H", mutant)[0] if len(mutant) >= 2 else -1
        is_frame = header_ok and mutant_id == MessageId.FRAMEOFDATA

        before = client.stats
        client.handle_packet(mutant, SERVER, time.monotonic())  # must not raise
        after = client.stats
        assert after.packets == before.packets + 1
        steps = (after.frames - before.frames, after.messages - before.messages, after.dropped - before.dropped)
        assert sorted(steps) == [0, 0, 1], f"mutant {i} counted {steps}"
        if not decoder_ok:
            assert steps[2] == 1  # dropped; as malformed when the client had to decode it
            assert (after.malformed - before.malformed == 1) == (not header_ok or mutant_id in CLIENT_DECODES)
        if is_frame:
            assert (steps[0] == 1) == decoder_ok
            decoded_frames += decoder_ok

        if client.version != version:  # a mutated SERVERINFO changed the bitstream: restore it
            client.handle_packet(valid_info, SERVER, time.monotonic())
        if i % 500 == 499:  # the next valid frame still decodes correctly
            flushed = client.receive(0.0)
            if flushed is not None:
                last_delivered = flushed.frame_number
            number = last_delivered + 1000 if last_delivered < 2**31 - 2000 else last_delivered - 100_000
            good = FrameOfData(number, rigid_bodies=[rigid_body(1), rigid_body(2)])
            client.handle_packet(encode_frame(good, version), SERVER, time.monotonic())
            frame = client.receive(0.0)
            assert frame is not None and frame.frame_number == number
            assert {p.id: (p.position, p.quaternion, p.valid) for p in frame.bodies.values()} == {
                rb.id: ((rb.x, rb.y, rb.z), (rb.qx, rb.qy, rb.qz, rb.qw), rb.valid) for rb in good.rigid_bodies
            }
            last_delivered = number

    stats = client.stats
    assert stats.packets == stats.frames + stats.messages + stats.dropped
    assert stats.dropped >= decode_failures > MUTANTS_PER_VERSION // 4  # the mutations do bite
    assert stats.malformed > MUTANTS_PER_VERSION // 4
    assert decoded_frames > 100  # and some mutants are still valid frames (flipped float bits)
    assert not [r for r in caplog.records if r.levelno >= logging.ERROR], "a decoder bug reached the safety net"
