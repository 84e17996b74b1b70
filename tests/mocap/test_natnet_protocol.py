"""Encode/decode of every NatNet message, the version-specific layouts and the error contract."""

from __future__ import annotations

import dataclasses
import struct

import pytest
from natnet_samples import VERSIONS, rich_frame, rich_model, server_info

from rpf_fly.mocap.natnet_protocol import (
    UNRECOGNIZED_REQUEST_ALT,
    ConnectRequest,
    EchoResponse,
    MessageId,
    ModelDefinitions,
    NatNetDecodeError,
    OtherDescription,
    decode_frame,
    decode_header,
    decode_model_def,
    decode_packet,
    encode_connect,
    encode_discovery,
    encode_echo_request,
    encode_echo_response,
    encode_frame,
    encode_keepalive,
    encode_message_string,
    encode_model_def,
    encode_packet,
    encode_request,
    encode_request_model_def,
    encode_response,
    encode_server_info,
    parse_version,
    timecode_string,
)


@pytest.mark.parametrize("version", VERSIONS)
def test_frame_round_trip(version):
    frame = rich_frame(version)
    message_id, decoded = decode_packet(encode_frame(frame, version), version)
    assert message_id == MessageId.FRAMEOFDATA
    assert decoded == frame
    assert decoded.models_changed and decoded.recording
    assert decoded.rigid_bodies[1].valid is False and decoded.rigid_bodies[0].valid is True


def test_assets_and_precision_timestamp_exist_only_from_4_1():
    frame = rich_frame((4, 1))
    assert decode_packet(encode_frame(frame, (4, 0)), (4, 0))[1] == dataclasses.replace(
        frame, assets=[], precision_seconds=0, precision_fraction=0
    )
    sizes = {v: len(encode_frame(rich_frame((4, 0)), v)) for v in VERSIONS}
    assert sizes[(3, 0)] == sizes[(4, 0)]
    # 4.1: a size field in each of the 7 older sections, an empty asset section (count + size), 8 precision bytes
    assert sizes[(4, 1)] == sizes[(4, 0)] + 7 * 4 + 8 + 8
    assert sizes[(4, 2)] == sizes[(4, 1)]


@pytest.mark.parametrize("encoded, decoded_as", [((4, 0), (4, 1)), ((4, 1), (4, 0)), ((3, 0), (4, 1))])
def test_decoding_with_the_wrong_version_fails_instead_of_misreading(encoded, decoded_as):
    packet = encode_frame(rich_frame(encoded), encoded)
    with pytest.raises(NatNetDecodeError):
        decode_packet(packet, decoded_as)


def test_4_1_section_size_must_match_content():
    version = (4, 1)
    frame = dataclasses.replace(rich_frame(version), marker_sets=[], other_markers=[])
    payload = bytearray(decode_header(encode_frame(frame, version))[1])
    # rigid-body section header sits after frame number and the two empty sections (count + size each)
    offset = 4 + 8 + 8
    count, size = struct.unpack_from("<ii", payload, offset)
    assert (count, size) == (3, 3 * 38)
    struct.pack_into("<i", payload, offset + 4, size - 2)
    with pytest.raises(NatNetDecodeError, match="rigid bodies"):
        decode_frame(bytes(payload), version)


def test_the_rigid_body_record_is_38_bytes_and_labeled_marker_26():
    version = (3, 0)
    base = dataclasses.replace(rich_frame(version), rigid_bodies=[], labeled_markers=[])
    n0 = len(encode_frame(base, version))
    with_bodies = dataclasses.replace(base, rigid_bodies=rich_frame(version).rigid_bodies)
    assert len(encode_frame(with_bodies, version)) == n0 + 3 * 38
    assert (
        len(encode_frame(dataclasses.replace(base, labeled_markers=rich_frame(version).labeled_markers), version))
        == n0 + 3 * 26
    )


@pytest.mark.parametrize("version", VERSIONS)
def test_model_def_round_trip(version):
    model = rich_model(version)
    message_id, decoded = decode_packet(encode_model_def(model, version), version)
    assert message_id == MessageId.MODELDEF
    assert decoded == model


def test_rigid_body_description_layout_by_version():
    names = {}
    for version in VERSIONS:
        model = ModelDefinitions(rigid_bodies=rich_model(version).rigid_bodies[:1])
        names[version] = len(encode_model_def(model, version))
    marker_names = len(b"Marker1\0Marker2\0Marker3\0")
    assert names[(4, 0)] == names[(3, 0)] + marker_names  # 4.0: marker names
    assert names[(4, 1)] == names[(4, 0)] + 4  # 4.1: dataset size
    assert names[(4, 2)] == names[(4, 1)] + 16  # 4.2: rotation offset quaternion


def test_4_2_model_def_misread_as_4_1_fails():
    """The 4.2 rotation offset broke public parsers; here it is version-gated and size-checked."""
    packet = encode_model_def(rich_model((4, 2)), (4, 2))
    with pytest.raises(NatNetDecodeError):
        decode_packet(packet, (4, 1))


def test_pre_4_1_force_plate_device_and_camera_descriptions_are_skipped():
    version = (3, 0)
    force_plate = (
        struct.pack("<i", 1)
        + b"FP-01\0"
        + struct.pack("<2f3f", 0.5, 0.6, 0, 0, 0)
        + bytes(4 * 144)
        + bytes(4 * 12)
        + struct.pack("<iii", 1, 0, 2)
        + b"Fx\0Fy\0"
    )
    device = struct.pack("<i", 4) + b"NI-DAQ\0SN1\0" + struct.pack("<iii", 1, 0, 1) + b"ch0\0"
    camera = b"Prime13\0" + struct.pack("<3f4f", 1, 2, 3, 0, 0, 0, 1)
    tail = encode_model_def(rich_model(version), version)[4:]
    count = struct.unpack_from("<i", tail)[0]
    payload = (
        struct.pack("<i", count + 3)
        + struct.pack("<i", 3)
        + force_plate
        + struct.pack("<i", 4)
        + device
        + struct.pack("<i", 5)
        + camera
        + tail[4:]
    )
    model = decode_model_def(payload, version)
    assert [o.type for o in model.others] == [3, 4, 5]
    assert model.others[2] == OtherDescription(5, camera)
    assert [rb.name for rb in model.rigid_bodies] == ["cf1", "cf2"]
    with pytest.raises(NatNetDecodeError, match="unknown dataset type"):
        decode_model_def(struct.pack("<ii", 1, 42) + bytes(16), version)


def test_server_info_round_trip_and_short_forms():
    info = server_info((4, 2), data_port=40000)
    assert decode_packet(encode_server_info(info)) == (MessageId.SERVERINFO, info)
    pre3 = dataclasses.replace(info, clock_frequency_hz=None, data_port=None, multicast=None, multicast_group=None)
    assert decode_packet(encode_server_info(pre3))[1] == pre3
    with pytest.raises(NatNetDecodeError):
        decode_packet(encode_packet(MessageId.SERVERINFO, bytes(100)))


@pytest.mark.parametrize("length", [0, 5, 256, 264, 265, 269, 300])
def test_connect_accepts_any_length(length):
    full = encode_connect(ConnectRequest("client", (1, 2, 3, 4), (4, 1, 0, 0), True, (4, 1, 0, 0)))[4:]
    payload = (full + bytes(300))[:length]
    message_id, request = decode_packet(encode_packet(MessageId.CONNECT, payload))
    assert message_id == MessageId.CONNECT
    if length >= 6:
        assert request.client_name == "client"
    if length >= 264:
        assert request.natnet_version == (4, 1, 0, 0)
    assert (request.requested_bitstream is not None) == (length >= 269)
    assert decode_packet(encode_discovery(ConnectRequest("x")))[0] == MessageId.DISCOVERY


def test_request_response_echo_keepalive_messages():
    assert decode_packet(encode_request("FrameRate")) == (MessageId.REQUEST, "FrameRate")
    _, rate = decode_packet(encode_response(120.0))
    assert rate.as_float() == 120.0 and rate.text is None
    _, code = decode_packet(encode_response(-1))
    assert code.as_int() == -1
    _, text = decode_packet(encode_response("OK"))
    assert text.text == "OK"
    _, four = decode_packet(encode_response("abc"))  # 4 bytes with its NUL: padded so it stays a string
    assert four.text == "abc"
    assert decode_packet(encode_echo_request(7)) == (MessageId.ECHOREQUEST, 7)
    assert decode_packet(encode_echo_response(7, 99)) == (MessageId.ECHORESPONSE, EchoResponse(7, 99))
    assert decode_packet(encode_keepalive()) == (MessageId.KEEPALIVE, None)
    assert decode_packet(encode_request_model_def()) == (MessageId.REQUEST_MODELDEF, None)
    assert decode_packet(encode_message_string("hello")) == (MessageId.MESSAGESTRING, "hello")
    assert decode_packet(encode_packet(MessageId.UNRECOGNIZED_REQUEST, bytes(264)))[1] is None
    assert decode_packet(encode_packet(UNRECOGNIZED_REQUEST_ALT))[1] is None
    assert decode_packet(encode_packet(77, b"abc")) == (77, b"abc")


def test_header_errors_and_trailing_bytes():
    with pytest.raises(NatNetDecodeError):
        decode_header(b"\x07\x00")
    with pytest.raises(NatNetDecodeError, match="truncated"):
        decode_header(encode_keepalive()[:2] + b"\x10\x00" + bytes(8))
    packet = encode_frame(rich_frame((4, 1)), (4, 1))
    assert decode_packet(packet + b"trailing junk", (4, 1))[1] == rich_frame((4, 1))  # datagram longer than header


def test_frame_and_model_need_a_supported_version():
    packet = encode_frame(rich_frame((3, 0)), (3, 0))
    with pytest.raises(NatNetDecodeError, match="version"):
        decode_packet(packet)
    for bad in ((2, 9), (5, 0)):
        with pytest.raises(NatNetDecodeError, match="unsupported"):
            decode_packet(packet, bad)


def test_4_3_is_decoded_with_the_4_2_layout():
    packet = encode_frame(rich_frame((4, 2)), (4, 2))
    assert decode_packet(packet, (4, 3))[1] == rich_frame((4, 2))


def test_truncation_at_every_length_raises_only_decode_errors():
    for version in VERSIONS:
        for packet in (encode_frame(rich_frame(version), version), encode_model_def(rich_model(version), version)):
            message_id, payload = decode_header(packet)
            decoder = decode_frame if message_id == MessageId.FRAMEOFDATA else decode_model_def
            for n in range(len(payload)):
                try:
                    decoder(payload[:n], version)
                except NatNetDecodeError as exc:
                    assert exc.message_id == message_id
                else:  # only the optional end-of-data int32 (frames) may be cut off
                    assert message_id == MessageId.FRAMEOFDATA and n >= len(payload) - 4


def test_parse_version_and_timecode():
    assert parse_version("4.1") == parse_version((4, 1, 0, 0)) == parse_version([4, 1]) == (4, 1)
    assert parse_version("3") == (3, 0)
    with pytest.raises(ValueError):
        parse_version("four")
    assert timecode_string((1 << 24) | (2 << 16) | (3 << 8) | 4, 5) == "01:02:03:04.5"


def test_encoder_rejects_oversized_payloads_and_nul_in_names():
    with pytest.raises(ValueError):
        encode_packet(MessageId.REQUEST, bytes(70000))
    frame = dataclasses.replace(rich_frame((3, 0)), marker_sets=[])
    frame.marker_sets.append(type(rich_frame((3, 0)).marker_sets[0])("bad\0name", []))
    with pytest.raises(ValueError):
        encode_frame(frame, (3, 0))


def _without_markers(frame):  # type: ignore[no-untyped-def]
    return dataclasses.replace(frame, marker_sets=[], other_markers=[], labeled_markers=[])


@pytest.mark.parametrize("version", VERSIONS, ids=lambda v: f"{v[0]}.{v[1]}")
def test_frame_without_markers_is_the_full_decode_minus_the_marker_lists(version):
    """The flight's NatNet client steps over the marker sections (it needs rigid bodies only)."""
    frame = rich_frame(version)
    assert frame.marker_sets and frame.other_markers and frame.labeled_markers  # something to step over
    payload = decode_header(encode_frame(frame, version))[1]
    full = decode_frame(payload, version)
    assert decode_frame(payload, version, markers=False) == _without_markers(full)


@pytest.mark.parametrize("version", VERSIONS, ids=lambda v: f"{v[0]}.{v[1]}")
def test_frame_without_markers_rejects_every_malformed_payload_the_full_decode_rejects(version):
    payload = decode_header(encode_frame(rich_frame(version), version))[1]
    variants = [payload[:cut] for cut in range(len(payload))]
    # every int32 count or size field of the marker sections, set far too large
    variants += [
        payload[:k] + struct.pack("<i", 10_000) + payload[k + 4 :] for k in range(4, min(len(payload), 600) - 4)
    ]
    for bad in variants:
        try:
            full = decode_frame(bad, version)
        except NatNetDecodeError:
            with pytest.raises(NatNetDecodeError):
                decode_frame(bad, version, markers=False)
        else:
            assert decode_frame(bad, version, markers=False) == _without_markers(full)
