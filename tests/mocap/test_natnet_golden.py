"""Golden tests: real Motive 2.1 / NatNet 3.0 captures must decode to exactly what OptiTrack's SampleClient
printed for the same session (every printed field, at its printed precision)."""

from __future__ import annotations

from decimal import ROUND_HALF_UP, Decimal

import pytest
from natnet_captures import DATA, parse_sample_client_output, read_udp_datagrams

from rpf_fly.mocap.natnet_protocol import (
    ConnectRequest,
    EchoResponse,
    FrameOfData,
    MessageId,
    ModelDefinitions,
    ServerInfo,
    decode_packet,
    timecode_string,
)

V30 = (3, 0)


def f2(value: float) -> str:
    """The SampleClient's "%3.2f" as printed by the 2017 Windows C runtime.

    That runtime first converts a double to 17 significant digits, then rounds half away from zero: frame
    162741's timestamp 1356.17499999999995... printed as 1356.18 and the exact tie 1356.125 as 1356.13, where
    Python and glibc print 1356.17 and 1356.12. Values that are not that close to a tie print the same everywhere.
    """
    return str(Decimal(f"{value:.17g}").quantize(Decimal("0.01"), rounding=ROUND_HALF_UP))


@pytest.fixture(scope="module")
def printout():
    return parse_sample_client_output(DATA / "SampleClient_output.txt")


@pytest.fixture(scope="module")
def datagrams():
    return read_udp_datagrams(DATA / "traffic.pcapng")


@pytest.fixture(scope="module")
def server_info(datagrams) -> ServerInfo:
    infos = [decode_packet(d.payload)[1] for d in datagrams if d.payload[:2] == b"\x01\x00"]
    assert len(infos) == 2  # one answers DISCOVERY, one answers CONNECT
    assert infos[0] == infos[1]
    return infos[0]


@pytest.fixture(scope="module")
def decoded_frames(datagrams, server_info) -> dict[int, FrameOfData]:
    frames: dict[int, FrameOfData] = {}
    for d in datagrams:
        message_id, body = decode_packet(d.payload, server_info.version)
        if message_id == MessageId.FRAMEOFDATA:
            assert d.src == ("192.168.0.106", 1511) and d.dst == ("239.255.42.99", 1511)
            assert body.frame_number not in frames
            frames[body.frame_number] = body
    return frames


def test_every_packet_in_the_live_session_decodes(datagrams, server_info):
    kinds: dict[int, int] = {}
    for d in datagrams:
        message_id, _ = decode_packet(d.payload, server_info.version)  # raises on any malformed packet
        kinds[message_id] = kinds.get(message_id, 0) + 1
    assert kinds == {
        MessageId.DISCOVERY: 1,
        MessageId.CONNECT: 1,
        MessageId.SERVERINFO: 2,
        MessageId.REQUEST: 4,
        MessageId.RESPONSE: 3,
        MessageId.UNRECOGNIZED_REQUEST: 1,
        MessageId.REQUEST_MODELDEF: 1,
        MessageId.MODELDEF: 1,
        MessageId.ECHOREQUEST: 9,
        MessageId.ECHORESPONSE: 9,
        MessageId.FRAMEOFDATA: 518,
    }


def test_server_info_matches_printout(server_info, printout):
    assert server_info.app_name == printout.application == "Motive"
    assert ".".join(map(str, server_info.app_version)) == printout.application_version == "2.1.0.0"
    assert ".".join(map(str, server_info.natnet_version)) == printout.natnet_version == "3.0.0.0"
    # Not printed directly, but every printed latency below is computed with it.
    assert server_info.clock_frequency_hz == 3312787
    assert (server_info.data_port, server_info.multicast, server_info.multicast_group) == (1511, True, "239.255.42.99")


def test_server_info_packet_file(server_info):
    _, info = decode_packet((DATA / "serverinfo_packet_v3.bin").read_bytes())
    assert info == server_info  # junk after the name's NUL ("Motive\0ib\0...") is ignored


def test_requests_and_responses_match_printout(datagrams, printout):
    exchanges = []
    for d in datagrams:
        message_id, body = decode_packet(d.payload, V30)
        if message_id in (MessageId.REQUEST, MessageId.RESPONSE, MessageId.UNRECOGNIZED_REQUEST):
            exchanges.append((message_id, body))
    requests = [b for m, b in exchanges if m == MessageId.REQUEST]
    assert requests[1:] == ["FrameRate", "AnalogSamplesPerMocapFrame", "TestRequest"]
    responses = [b for m, b in exchanges if m == MessageId.RESPONSE]
    frame_rate, analog = responses[1], responses[2]
    assert f2(frame_rate.as_float()) == printout.frame_rate == "120.00"  # FrameRate answers a float32
    assert str(analog.as_int()) == printout.analog_samples == "0"
    assert exchanges[-1][0] == MessageId.UNRECOGNIZED_REQUEST  # TestRequest is not a Motive command


def test_model_definitions_match_printout(datagrams, printout):
    models = [decode_packet(d.payload, V30)[1] for d in datagrams if d.payload[:2] == b"\x05\x00"]
    assert len(models) == 1
    model: ModelDefinitions = models[0]
    assert model == decode_packet((DATA / "modeldef_packet_v3.bin").read_bytes(), V30)[1]
    assert len(model.rigid_bodies) == len(printout.rigid_body_descriptions) == 1
    rb, printed = model.rigid_bodies[0], printout.rigid_body_descriptions[0]
    assert (rb.name, rb.id, rb.parent_id) == (printed["name"], printed["id"], printed["parent_id"])
    assert (rb.name, rb.id, rb.parent_id) == ("RaceQuad", 2, -1)
    assert tuple(map(f2, rb.offset)) == printed["offset"]
    assert [tuple(map(f2, m.offset)) for m in rb.markers] == printed["markers"]
    assert {ms.name: list(ms.marker_names) for ms in model.marker_sets} == printout.marker_sets
    assert model.skeletons == () and model.others == ()


def test_printed_frames_are_consistent_with_the_capture(decoded_frames, printout):
    captured = sorted(decoded_frames)
    assert captured == list(range(captured[0], captured[-1] + 1))  # 518 consecutive frames, none lost
    printed = sorted(printout.frames)
    assert len(printed) == 251
    assert printed == list(range(printed[0], printed[-1] + 1))
    assert printed[0] == captured[0] == 162734 and set(printed) <= set(captured)


def test_every_printed_frame_matches_the_decoded_frame(decoded_frames, printout, server_info):
    clock = server_info.clock_frequency_hz
    for frame_id, printed in printout.frames.items():
        frame = decoded_frames[frame_id]
        assert frame.frame_number == frame_id
        assert f2(frame.timestamp) == printed.timestamp
        assert f2((frame.transmit - frame.camera_data_received) * 1000.0 / clock) == printed.software_latency_ms
        assert f2((frame.transmit - frame.camera_mid_exposure) * 1000.0 / clock) == printed.system_latency_ms
        assert timecode_string(frame.timecode, frame.timecode_subframe) == printed.timecode
        assert printed.counts == {
            "Other Markers": len(frame.other_markers),
            "Rigid Bodies": len(frame.rigid_bodies),
            "Skeletons": len(frame.skeletons),
            "Labeled Markers": len(frame.labeled_markers),
            "Force Plate": len(frame.force_plates),
            "Device": len(frame.devices),
        }
        assert [tuple(map(f2, m)) for m in frame.other_markers] == printed.other_markers
        assert len(frame.rigid_bodies) == len(printed.rigid_bodies)
        for rb, p in zip(frame.rigid_bodies, printed.rigid_bodies):
            assert rb.id == p["id"]
            assert f2(rb.error) == p["error"]
            assert str(int(rb.valid)) == p["valid"]
            assert tuple(map(f2, (rb.x, rb.y, rb.z, rb.qx, rb.qy, rb.qz, rb.qw))) == p["pose"]
        assert len(frame.labeled_markers) == len(printed.labeled_markers)
        for m, p in zip(frame.labeled_markers, printed.labeled_markers):
            assert (m.model_id, m.marker_id) == (p["model_id"], p["marker_id"])
            assert (int(m.occluded), int(m.point_cloud_solved), int(m.model_solved)) == (
                p["occluded"],
                p["pc_solved"],
                p["model_solved"],
            )
            assert f2(m.size) == p["size"]
            assert tuple(map(f2, (m.x, m.y, m.z))) == p["pos"]


def test_frame_packet_file_is_frame_162734_of_the_session(decoded_frames, printout):
    _, frame = decode_packet((DATA / "mocapframe_packet_v3.bin").read_bytes(), V30)
    assert frame == decoded_frames[162734]
    rb = frame.rigid_bodies[0]
    pose = (rb.x, rb.y, rb.z, rb.qx, rb.qy, rb.qz, rb.qw)
    assert tuple(map(f2, pose)) == printout.frames[162734].rigid_bodies[0]["pose"]


def test_occluded_frame_packet():
    _, frame = decode_packet((DATA / "mocapframe_packet_occluded_v3.bin").read_bytes(), V30)
    assert frame.frame_number == 269007
    assert [(ms.name, len(ms.markers)) for ms in frame.marker_sets] == [("FakeTree", 5), ("all", 5)]
    assert frame.other_markers == []
    assert [(rb.id, rb.valid) for rb in frame.rigid_bodies] == [(7, True)]
    # marker 1 of the tree is missing from the labeled markers; marker 2 is flagged occluded
    assert [(m.model_id, m.marker_id, m.occluded) for m in frame.labeled_markers] == [
        (7, 2, True),
        (7, 3, False),
        (7, 4, False),
        (7, 5, False),
    ]
    assert f2(frame.timestamp) == "8966.90"
    assert frame.params == 0 and not frame.models_changed


def test_small_packet_files():
    _, connect = decode_packet((DATA / "connect_packet_v3.bin").read_bytes())
    assert connect == ConnectRequest("NatNetLib", (3, 0, 0, 0), (3, 0, 0, 0))
    message_id, discovery = decode_packet((DATA / "discovery_packet_v3.bin").read_bytes())
    assert message_id == MessageId.DISCOVERY and discovery == connect
    _, stamp = decode_packet((DATA / "echorequest_packet_v3.bin").read_bytes())
    _, echo = decode_packet((DATA / "echoresponse_packet_v3.bin").read_bytes())
    assert echo == EchoResponse(stamp, 1416498545924)
    assert decode_packet((DATA / "requestmodeldef_packet_v3.bin").read_bytes()) == (MessageId.REQUEST_MODELDEF, None)


def test_echo_pairs_in_the_session(datagrams):
    sent = [decode_packet(d.payload)[1] for d in datagrams if d.payload[:2] == b"\x0c\x00"]
    answered = [decode_packet(d.payload)[1] for d in datagrams if d.payload[:2] == b"\x0d\x00"]
    assert [e.request_stamp for e in answered] == sent
    ticks = [e.server_ticks for e in answered]
    assert ticks == sorted(ticks)


def test_every_frame_of_the_live_session_decodes_the_same_without_markers(datagrams, server_info, decoded_frames):
    """What the flight's client decodes (markers stepped over) of real Motive 2.1 frames: the same rigid bodies and
    timing as the full decode."""
    import dataclasses

    from rpf_fly.mocap.natnet_protocol import decode_frame, decode_header

    seen = 0
    for d in datagrams:
        message_id, payload = decode_header(d.payload)
        if message_id != MessageId.FRAMEOFDATA:
            continue
        lean = decode_frame(payload, server_info.version, markers=False)
        full = decoded_frames[lean.frame_number]
        assert lean == dataclasses.replace(full, marker_sets=[], other_markers=[], labeled_markers=[])
        seen += 1
    assert seen == len(decoded_frames) == 518
