"""Emulator -> client over real UDP sockets on 127.0.0.1, for every bitstream version and transport."""

from __future__ import annotations

import math
import time

import pytest
from natnet_samples import VERSIONS

from rpf_fly.emulator.natnet_server import NatNetServer
from rpf_fly.mocap.frame import MocapSource
from rpf_fly.mocap.natnet_client import NatNetClient
from rpf_fly.mocap.natnet_protocol import MessageId

TRANSPORTS = {"unicast": False, "multicast": True}
_C = math.cos(0.3)
_S = math.sin(0.3)
TRUTH = {
    "cf1": ((1.0, 2.0, 0.5), (0.0, 0.0, _S, _C), True),  # yawed 0.6 rad about world z
    "cf2": ((-0.5, 0.25, 1.25), (_S, 0.0, 0.0, _C), True),  # rolled about world x
    "cf3": ((0.0, -1.5, 0.75), (0.0, 0.0, 0.0, 1.0), False),  # not tracked
    "cf4": ((2.0, 2.0, 2.0), (0.0, 0.0, 0.0, 1.0), True),  # only streamed after set_bodies
}


def truth() -> dict:
    return TRUTH


def open_pair(version, multicast, up_axis="y", bodies=("cf1", "cf2", "cf3")):
    server = NatNetServer(truth, version=version, multicast=multicast, rate_hz=0, up_axis=up_axis, bodies=bodies)
    server.start()
    client = NatNetClient(
        "127.0.0.1",
        multicast=multicast,
        command_port=server.command_port,
        data_port=server.data_port,
        up_axis=up_axis,
        keepalive_s=0.2,
    )
    assert client.wait_for_server(3.0), "handshake did not complete"
    return server, client


def receive_after_send(server: NatNetServer, client: NatNetClient, timeout_s: float = 2.0):
    number = server.send_frame()
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        frame = client.receive(0.1)
        if frame is not None and frame.frame_number == number:
            return frame
    raise AssertionError(f"frame {number} did not arrive")


@pytest.mark.parametrize("transport", TRANSPORTS)
@pytest.mark.parametrize("version", VERSIONS, ids=lambda v: f"{v[0]}.{v[1]}")
@pytest.mark.parametrize("up_axis", ["y", "z"])
def test_names_and_poses_arrive_in_the_z_up_world_frame(version, transport, up_axis):
    server, client = open_pair(version, TRANSPORTS[transport], up_axis)
    with server, client:
        assert isinstance(client, MocapSource)
        assert client.version == version
        assert client.rigid_body_names == {1: "cf1", 2: "cf2", 3: "cf3"}
        frame = receive_after_send(server, client)
        assert sorted(frame.bodies) == ["cf1", "cf2", "cf3"]
        for name, pose in frame.bodies.items():
            position, quaternion, valid = TRUTH[name]
            assert pose.name == name and pose.id == server.body_ids[name]
            assert pose.valid is valid
            if valid:
                assert pose.position == pytest.approx(position, abs=1e-6)
                assert pose.quaternion == pytest.approx(quaternion, abs=1e-6)
        assert frame.latency_s == pytest.approx(0.004, abs=1e-6)
        assert 0.0 <= time.monotonic() - frame.receive_time_s < 2.0
        stats = client.stats
        assert stats.malformed == 0 and stats.dropped == 0
        assert stats.body_dropouts == 1
        assert stats.packets == stats.frames + stats.messages


@pytest.mark.parametrize("transport", TRANSPORTS)
@pytest.mark.parametrize("version", VERSIONS, ids=lambda v: f"{v[0]}.{v[1]}")
def test_models_changed_triggers_modeldef_and_new_names_appear(version, transport):
    server, client = open_pair(version, TRANSPORTS[transport])
    with server, client:
        assert "cf4" not in receive_after_send(server, client).bodies
        requests_before = server.request_count(MessageId.REQUEST_MODELDEF)
        server.set_bodies(["cf1", "cf4"])
        first = receive_after_send(server, client)  # carries the models-changed bit
        assert set(first.bodies) <= {"cf1", "cf4", str(server.body_ids["cf4"])}
        deadline = time.monotonic() + 3.0
        frame = first
        while "cf4" not in frame.bodies and time.monotonic() < deadline:
            frame = receive_after_send(server, client)
        assert sorted(frame.bodies) == ["cf1", "cf4"]
        assert frame.bodies["cf4"].position == pytest.approx(TRUTH["cf4"][0], abs=1e-6)
        assert server.request_count(MessageId.REQUEST_MODELDEF) > requests_before
        assert client.rigid_body_names == {1: "cf1", 4: "cf4"}


@pytest.mark.parametrize("transport", TRANSPORTS)
@pytest.mark.parametrize("version", VERSIONS, ids=lambda v: f"{v[0]}.{v[1]}")
def test_newest_frame_wins_when_several_are_queued(version, transport):
    server, client = open_pair(version, TRANSPORTS[transport])
    with server, client:
        receive_after_send(server, client)
        before = client.stats
        numbers = [server.send_frame() for _ in range(6)]
        time.sleep(0.1)  # all six are queued in the socket buffer
        frame = client.receive(1.0)
        assert frame is not None and frame.frame_number == numbers[-1]
        after = client.stats
        assert after.frames - before.frames == 6
        assert after.superseded - before.superseded == 5
        assert after.delivered - before.delivered == 1
        assert client.receive(0.05) is None  # nothing newer


def test_streaming_server_keeps_clients_fed_and_keepalives_flow():
    with NatNetServer(truth, version="4.1", multicast=False, rate_hz=200, bodies=["cf1"]) as server:
        with NatNetClient(
            "127.0.0.1", multicast=False, command_port=server.command_port, up_axis="y", keepalive_s=0.05
        ) as client:
            frames = []
            deadline = time.monotonic() + 0.5
            while time.monotonic() < deadline:
                frame = client.receive(0.2)
                if frame is not None:
                    frames.append(frame.frame_number)
            assert len(frames) > 20
            assert frames == sorted(frames)
            assert server.request_count(MessageId.KEEPALIVE) >= 3
            assert client.stats.dropped == 0
        time.sleep(0.1)
        assert server.request_count(MessageId.DISCONNECT) == 1
        assert server.clients == []


def test_emulator_answers_requests_like_motive():
    import socket

    from rpf_fly.mocap.natnet_protocol import (
        ConnectRequest,
        decode_packet,
        encode_discovery,
        encode_echo_request,
        encode_request,
    )

    with NatNetServer(truth, version="4.2", rate_hz=60, bodies=["cf1"]) as server:
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.settimeout(2.0)
        with sock:
            address = ("127.0.0.1", server.command_port)
            replies = []
            for packet in (
                encode_discovery(ConnectRequest("probe")),
                encode_request("FrameRate"),
                encode_request("TestRequest"),
                encode_echo_request(42),
                encode_request("Bitstream,3.0"),
                encode_request("Bitstream,9.9"),
            ):
                sock.sendto(packet, address)
                replies.append(decode_packet(sock.recv(65536)))
        discovered = replies.pop(0)
        assert discovered[0] == MessageId.SERVERINFO and discovered[1].version == (4, 2)
        assert discovered[1].data_port == server.data_port and server.clients == []  # discovery is not a connect
        assert replies[0][0] == MessageId.RESPONSE and replies[0][1].as_float() == 60.0
        assert replies[1][0] == MessageId.UNRECOGNIZED_REQUEST
        assert replies[2][0] == MessageId.ECHORESPONSE and replies[2][1].request_stamp == 42
        assert replies[3][1].as_int() == 0 and replies[4][1].as_int() == -1
        assert server.version == (3, 0)
