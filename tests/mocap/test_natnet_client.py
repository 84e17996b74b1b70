"""NatNetClient behaviour against a bare UDP socket playing the server (real sockets, no emulator)."""

from __future__ import annotations

import dataclasses
import socket
import time

import numpy as np
import pytest
from natnet_samples import rich_model, server_info

from rpf_fly.mocap.natnet_client import NatNetClient
from rpf_fly.mocap.natnet_protocol import (
    FrameOfData,
    MessageId,
    ModelDefinitions,
    RigidBodyData,
    RigidBodyDescription,
    decode_connect,
    decode_header,
    encode_frame,
    encode_model_def,
    encode_packet,
    encode_server_info,
)

V = (4, 1)
SERVER = ("127.0.0.1", 1510)


@pytest.fixture
def fake_server():
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(1.0)
    yield sock
    sock.close()


def make_client(fake_server, **kwargs) -> NatNetClient:
    options = {"multicast": False, "command_port": fake_server.getsockname()[1]}
    options.update(kwargs)
    return NatNetClient("127.0.0.1", **options)


def received_ids(sock: socket.socket, seconds: float) -> list[int]:
    """Message ids the fake server receives within ``seconds``."""
    ids = []
    deadline = time.monotonic() + seconds
    while (remaining := deadline - time.monotonic()) > 0:
        sock.settimeout(remaining)
        try:
            ids.append(decode_header(sock.recv(65536))[0])
        except TimeoutError:
            break
    return ids


def frame(number: int, bodies: list[RigidBodyData], params: int = 0) -> bytes:
    return encode_frame(
        FrameOfData(number, rigid_bodies=bodies, camera_mid_exposure=1000, camera_data_received=51000, params=params), V
    )


def rb(body_id: int, x: float = 0.0, valid: bool = True) -> RigidBodyData:
    return RigidBodyData(body_id, x, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, int(valid))


def feed(client: NatNetClient, *packets: bytes, source=SERVER) -> None:
    for packet in packets:
        client.handle_packet(packet, source, time.monotonic())


def test_connect_layout_and_retry_until_server_info(fake_server):
    with make_client(fake_server, connect_retry_s=0.05) as client:
        packet, _ = fake_server.recvfrom(65536)
        message_id, payload = decode_header(packet)
        assert message_id == MessageId.CONNECT and len(payload) == 264
        assert decode_connect(payload).client_name == "rpf_fly"
        assert not client.wait_for_server(0.3)
        assert received_ids(fake_server, 0.05).count(MessageId.CONNECT) + 1 >= 4  # retried every 50 ms
        assert client.receive(0.0) is None


def test_bodies_keyed_by_id_until_modeldef_names_them(fake_server):
    with make_client(fake_server) as client:
        feed(client, encode_server_info(server_info(V)), frame(10, [rb(1), rb(2)]))
        first = client.receive(0.0)
        assert sorted(first.bodies) == ["1", "2"]
        model = ModelDefinitions(rigid_bodies=(RigidBodyDescription("cf1", 1), RigidBodyDescription("cf2", 2)))
        feed(client, encode_model_def(model, V), frame(11, [rb(1), rb(2), rb(3)]))
        second = client.receive(0.0)
        assert sorted(second.bodies) == ["3", "cf1", "cf2"]
        assert second.bodies["cf1"].id == 1
        assert second.latency_s == pytest.approx(50000 / 10_000_000)


def test_server_info_and_unknown_ids_request_modeldef(fake_server):
    with make_client(fake_server, keepalive_s=10.0) as client:
        fake_server.recvfrom(65536)  # CONNECT
        feed(client, encode_server_info(server_info(V)))
        client.receive(0.0)
        assert received_ids(fake_server, 0.2) == [MessageId.REQUEST_MODELDEF, MessageId.KEEPALIVE]
        feed(client, encode_model_def(rich_model(V), V), frame(1, [rb(1)]))
        assert client.receive(0.0) is not None
        assert received_ids(fake_server, 0.15) == []  # everything is known
        feed(client, frame(2, [rb(1), rb(99)]))  # an id MODELDEF did not list: maybe a lost models-changed frame
        assert "99" in client.receive(0.0).bodies
        client.receive(0.2)
        assert received_ids(fake_server, 0.1) == [MessageId.REQUEST_MODELDEF]


def test_models_changed_bit_requests_again_after_an_outstanding_reply(fake_server):
    with make_client(fake_server, keepalive_s=10.0, model_retry_s=5.0) as client:
        fake_server.recvfrom(65536)
        feed(client, encode_server_info(server_info(V)))
        client.receive(0.0)
        assert received_ids(fake_server, 0.2)[0] == MessageId.REQUEST_MODELDEF
        feed(client, frame(1, [rb(1)], params=0x02))  # change flagged while the first request is unanswered
        client.receive(0.0)
        assert received_ids(fake_server, 0.15) == []  # no duplicate while outstanding
        feed(client, encode_model_def(rich_model(V), V))
        client.receive(0.2)
        assert received_ids(fake_server, 0.1) == [MessageId.REQUEST_MODELDEF]  # the reply may predate the change


def test_keepalives_are_periodic(fake_server):
    with make_client(fake_server, keepalive_s=0.05) as client:
        feed(client, encode_server_info(server_info(V)), encode_model_def(rich_model(V), V))
        start = time.monotonic()
        while time.monotonic() - start < 0.4:
            client.receive(0.05)
        ids = received_ids(fake_server, 0.05)
        assert 4 <= ids.count(MessageId.KEEPALIVE) <= 10
    assert received_ids(fake_server, 0.1) == [MessageId.DISCONNECT]  # close() says goodbye


def test_y_up_data_is_rotated_into_the_z_up_world(fake_server):
    """For any pose, converting then rotating equals rotating then converting (C R_y C^T = R_z)."""
    rng = np.random.default_rng(7)
    c = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])  # Y-up coordinates -> Z-up coordinates

    def matrix(q):
        x, y, z, w = q
        return np.array(
            [
                [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
            ]
        )

    with make_client(fake_server, up_axis="y") as client:
        feed(client, encode_server_info(server_info(V)))
        for number in range(1, 51):
            q = rng.normal(size=4)
            q /= np.linalg.norm(q)
            p = rng.uniform(-3, 3, size=3)
            body = RigidBodyData(5, *p.astype(np.float32), *q.astype(np.float32), 0.0, 1)
            feed(client, frame(number, [body]))
            pose = client.receive(0.0).bodies["5"]
            p32 = np.array([body.x, body.y, body.z])
            q32 = np.array([body.qx, body.qy, body.qz, body.qw])
            assert np.allclose(pose.position, c @ p32, atol=1e-9)
            assert np.allclose(matrix(pose.quaternion), c @ matrix(q32) @ c.T, atol=1e-6)
        # the textbook case: a yaw about Motive's +y is a yaw about the world's +z
        s, w = np.sin(0.4), np.cos(0.4)
        feed(client, frame(100, [RigidBodyData(5, 1.0, 2.0, 3.0, 0.0, s, 0.0, w, 0.0, 1)]))
        pose = client.receive(0.0).bodies["5"]
        assert pose.position == (1.0, -3.0, 2.0)
        assert pose.quaternion == pytest.approx((0.0, 0.0, s, w))


def test_packets_from_other_hosts_and_premature_frames_are_dropped(fake_server):
    with make_client(fake_server) as client:
        feed(client, frame(1, [rb(1)]))  # before SERVERINFO: version unknown
        feed(client, encode_server_info(server_info(V)), source=("10.9.9.9", 1510))  # not our server
        assert client.server_info is None
        feed(client, encode_server_info(server_info(V)))
        feed(client, frame(2, [rb(1)]), source=("10.9.9.9", 1511))
        feed(client, encode_packet(MessageId.CONNECT, b""))  # not something a server sends
        stats = client.stats
        assert (stats.packets, stats.frames, stats.messages, stats.dropped, stats.malformed) == (5, 0, 1, 4, 0)
        assert client.receive(0.0) is None


def test_stale_duplicate_and_restarted_frame_numbers(fake_server):
    with make_client(fake_server) as client:
        feed(client, encode_server_info(server_info(V)), frame(100, [rb(1)]))
        assert client.receive(0.0).frame_number == 100
        feed(client, frame(100, [rb(1)]), frame(95, [rb(1)]))  # duplicate, reordered
        assert client.receive(0.0) is None
        feed(client, frame(7, [rb(1)]))  # far back: Motive restarted or a take looped
        assert client.receive(0.0).frame_number == 7
        feed(client, frame(9, [rb(1)]), frame(8, [rb(1)]))  # reordered within one drain
        assert client.receive(0.0).frame_number == 9
        assert client.stats.superseded == 3


def test_unsupported_server_version_is_reported_not_misread(fake_server):
    with make_client(fake_server) as client:
        info = dataclasses.replace(server_info(V), natnet_version=(2, 10, 0, 0))
        feed(client, encode_server_info(info), frame(1, [rb(1)]))
        assert client.server_info == info and client.version is None
        assert not client.wait_for_server(0.1)
        assert client.stats.dropped == 1 and client.receive(0.0) is None


def test_duplicate_names_in_modeldef_fall_back_to_ids(fake_server):
    with make_client(fake_server) as client:
        model = ModelDefinitions(rigid_bodies=(RigidBodyDescription("cf", 1), RigidBodyDescription("cf", 2)))
        feed(client, encode_server_info(server_info(V)), encode_model_def(model, V), frame(1, [rb(1, 1.0), rb(2, 2.0)]))
        bodies = client.receive(0.0).bodies
        assert bodies["cf"].position[0] == 1.0 and bodies["2"].position[0] == 2.0


def test_invalid_bodies_are_reported_and_counted(fake_server):
    with make_client(fake_server) as client:
        feed(client, encode_server_info(server_info(V)), frame(1, [rb(1), rb(2, valid=False)]))
        bodies = client.receive(0.0).bodies
        assert bodies["1"].valid and not bodies["2"].valid
        assert client.stats.body_dropouts == 1


def test_receive_waits_without_spinning_and_returns_none_on_timeout(fake_server):
    with make_client(fake_server, keepalive_s=10.0) as client:
        feed(client, encode_server_info(server_info(V)), encode_model_def(rich_model(V), V))
        start_cpu, start = time.process_time(), time.monotonic()
        assert client.receive(0.3) is None
        assert time.monotonic() - start >= 0.29
        assert time.process_time() - start_cpu < 0.1


def test_closed_client_returns_none(fake_server):
    client = make_client(fake_server)
    client.close()
    client.close()
    assert client.receive(0.1) is None


def test_a_bitstream_change_by_another_client_is_relearned(fake_server):
    with make_client(fake_server, keepalive_s=10.0, connect_retry_s=0.0) as client:
        fake_server.recvfrom(65536)  # the first CONNECT
        feed(client, encode_server_info(server_info(V)))
        client.receive(0.0)
        received_ids(fake_server, 0.1)
        old = [encode_frame(FrameOfData(n, rigid_bodies=[rb(1)]), (3, 0)) for n in range(1, 11)]
        feed(client, *old[:9])
        assert MessageId.CONNECT not in received_ids(fake_server, 0.1)
        feed(client, old[9])  # the tenth undecodable frame in a row
        assert received_ids(fake_server, 0.1) == [MessageId.CONNECT]
        feed(client, encode_server_info(server_info((3, 0))), old[0])
        assert client.version == (3, 0)
        assert client.receive(0.0).frame_number == 1
        assert client.stats.malformed == 10


def test_unicast_frames_on_the_data_port_are_received_when_asked(fake_server):
    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    probe.bind(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()
    with make_client(fake_server, local_ip="127.0.0.1", listen_data_port=True, data_port=port) as client:
        _, client_address = fake_server.recvfrom(65536)  # CONNECT, from the client's command socket
        fake_server.sendto(encode_server_info(server_info(V)), client_address)
        assert client.wait_for_server(1.0, with_models=False)
        fake_server.sendto(frame(5, [rb(1, 0.5)]), ("127.0.0.1", port))  # to the data port, not the command socket
        received = client.receive(1.0)
        assert received is not None and received.bodies["1"].position[0] == 0.5


def test_a_gap_the_caller_never_saw_is_reported_with_the_frame_after_it(fake_server):
    """A caller that does not read for a while (a stalled flight loop) gets only the newest of the frames the
    socket queued. A body that went untracked and came back within those frames is reported with the delivered
    frame (`MocapFrame.unseen_untracked_s`, server time, to a frame), once: here body 1 is lost for 0.5 s and body 2 for
    0.05 s (one frame at 100 Hz would not count either). A gap whose start the caller saw (a frame it was given
    showed the body untracked) is not: the caller saw it live."""

    def at(n: int, *bodies: RigidBodyData) -> bytes:
        return encode_frame(FrameOfData(n, rigid_bodies=list(bodies), timestamp=n / 100.0), V)

    with make_client(fake_server) as client:
        feed(client, encode_server_info(server_info(V)), at(100, rb(1), rb(2)))
        assert client.receive(0.0).unseen_untracked_s == {}
        queued = [at(n, rb(1, valid=not 110 <= n < 160), rb(2, valid=not 120 <= n < 125)) for n in range(101, 200)]
        feed(client, *queued)  # the caller was stalled: all of them wait in the socket
        delivered = client.receive(0.0)
        assert delivered.frame_number == 199
        assert delivered.unseen_untracked_s == {"1": pytest.approx(0.50, abs=0.011)}  # 50 frames, within one
        feed(client, at(200, rb(1), rb(2)))
        assert client.receive(0.0).unseen_untracked_s == {}  # said once
        feed(client, at(201, rb(1, valid=False), rb(2)))
        assert not client.receive(0.0).bodies["1"].valid  # the caller sees the gap begin ...
        feed(client, *[at(n, rb(1, valid=n >= 260), rb(2)) for n in range(202, 262)])
        assert client.receive(0.0).unseen_untracked_s == {}  # ... so its end is not news
