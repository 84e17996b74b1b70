"""NatNet control messages (SERVERINFO, CONNECT / DISCOVERY, REQUEST / RESPONSE, MESSAGESTRING, keep-alive, echo,
DISCONNECT) and :func:`decode_packet`, the dispatch of any datagram to its decoder.

Part of the NatNet codec; import it through :mod:`rpf_fly.mocap.natnet_protocol`.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence

from rpf_fly.mocap import natnet_wire as _wire
from rpf_fly.mocap.natnet_frame import decode_frame
from rpf_fly.mocap.natnet_modeldef import decode_model_def
from rpf_fly.mocap.natnet_types import (
    UNRECOGNIZED_REQUEST_ALT,
    ConnectRequest,
    EchoResponse,
    Message,
    MessageId,
    NatNetDecodeError,
    Response,
    ServerInfo,
    Version,
)
from rpf_fly.mocap.natnet_wire import _cstr, _cstr_bytes, _fixed_name, _read, decode_header, encode_packet

__all__ = [
    "decode_packet",
    "decode_server_info",
    "decode_connect",
    "decode_request",
    "decode_response",
    "decode_message_string",
    "decode_echo_request",
    "decode_echo_response",
    "encode_connect",
    "encode_discovery",
    "encode_server_info",
    "encode_request",
    "encode_response",
    "encode_request_model_def",
    "encode_keepalive",
    "encode_disconnect",
    "encode_echo_request",
    "encode_echo_response",
    "encode_message_string",
    "encode_unrecognized_request",
]

# ---------------------------------------------------------------------------------------------------------------
# Precompiled structs
# ---------------------------------------------------------------------------------------------------------------

# Bound by assignment, not ``from ... import``: CPython compiles ``name.method(...)`` on an imported name to
# LOAD_ATTR instead of LOAD_METHOD, which would cost a bound-method object per call on the hot paths.
_I32 = _wire._I32
_U64 = struct.Struct("<Q")
_U64X2 = struct.Struct("<QQ")
_F32 = struct.Struct("<f")
_SERVERINFO_HEAD = struct.Struct("<4B4B")
_SERVERINFO_TAIL = struct.Struct("<QHB4B")
_CONNECT_TAIL = struct.Struct("<4B4B")
_VERSION4 = struct.Struct("<4B")

_NAME_FIELD = 256  # fixed-size name fields in CONNECT and SERVERINFO

# ---------------------------------------------------------------------------------------------------------------
# SERVERINFO, CONNECT / DISCOVERY
# ---------------------------------------------------------------------------------------------------------------

_SERVERINFO = int(MessageId.SERVERINFO)


def decode_server_info(payload: bytes) -> ServerInfo:
    """Decode SERVERINFO: name[256], app version u8[4], NatNet version u8[4], (3.0+) clock, port, multicast."""
    if len(payload) < _NAME_FIELD + 8:
        raise NatNetDecodeError(f"server info: {len(payload)} bytes, need at least {_NAME_FIELD + 8}", _SERVERINFO, 0)
    name = _fixed_name(payload, 0, _NAME_FIELD)
    head = _SERVERINFO_HEAD.unpack_from(payload, _NAME_FIELD)
    app_version = (head[0], head[1], head[2], head[3])
    natnet_version = (head[4], head[5], head[6], head[7])
    off = _NAME_FIELD + 8
    if len(payload) - off >= _SERVERINFO_TAIL.size:
        clock, port, multicast, g0, g1, g2, g3 = _SERVERINFO_TAIL.unpack_from(payload, off)
        return ServerInfo(name, app_version, natnet_version, clock, port, bool(multicast), f"{g0}.{g1}.{g2}.{g3}")
    return ServerInfo(name, app_version, natnet_version)


def _name_field(text: str) -> bytes:
    raw = text.encode("utf-8")[: _NAME_FIELD - 1]
    return raw + b"\0" * (_NAME_FIELD - len(raw))


def _quad(values: Sequence[int]) -> tuple[int, int, int, int]:
    v = tuple(int(x) for x in values) + (0, 0, 0, 0)
    return (v[0], v[1], v[2], v[3])


def encode_server_info(info: ServerInfo) -> bytes:
    """Encode a SERVERINFO packet (the 279-byte NatNet 3.0+ layout when the clock frequency is set)."""
    payload = _name_field(info.app_name) + _SERVERINFO_HEAD.pack(*_quad(info.app_version), *_quad(info.natnet_version))
    if info.clock_frequency_hz is not None:
        group = [int(p) for p in (info.multicast_group or "0.0.0.0").split(".")]
        payload += _SERVERINFO_TAIL.pack(
            info.clock_frequency_hz, info.data_port or 0, 1 if info.multicast else 0, *_quad(group)
        )
    return encode_packet(MessageId.SERVERINFO, payload)


def decode_connect(payload: bytes) -> ConnectRequest:
    """Decode a CONNECT or DISCOVERY payload. Any length is valid: missing fields keep their defaults."""
    name = _fixed_name(payload, 0, _NAME_FIELD)
    if len(payload) < _NAME_FIELD + 8:
        return ConnectRequest(name)
    v = _CONNECT_TAIL.unpack_from(payload, _NAME_FIELD)
    app_version = (v[0], v[1], v[2], v[3])
    natnet_version = (v[4], v[5], v[6], v[7])
    subscribed = bool(payload[264]) if len(payload) >= 265 else None
    bitstream = tuple(_VERSION4.unpack_from(payload, 265)) if len(payload) >= 269 else None
    return ConnectRequest(name, app_version, natnet_version, subscribed, bitstream)


def _connect_payload(request: ConnectRequest) -> bytes:
    payload = _name_field(request.client_name)
    payload += _CONNECT_TAIL.pack(*_quad(request.app_version), *_quad(request.natnet_version))
    if request.subscribed_only is not None or request.requested_bitstream is not None:
        payload += bytes([1 if request.subscribed_only else 0])
        payload += _VERSION4.pack(*_quad(request.requested_bitstream or (0, 0, 0, 0)))
    return payload


def encode_connect(request: ConnectRequest) -> bytes:
    """Encode a CONNECT packet in NatNetLib's layout (264 bytes, 269 with the SDK samples' extra fields)."""
    return encode_packet(MessageId.CONNECT, _connect_payload(request))


def encode_discovery(request: ConnectRequest) -> bytes:
    """Encode a DISCOVERY packet (same payload as CONNECT); servers answer with SERVERINFO."""
    return encode_packet(MessageId.DISCOVERY, _connect_payload(request))


# ---------------------------------------------------------------------------------------------------------------
# REQUEST / RESPONSE, MESSAGESTRING, keep-alive, echo
# ---------------------------------------------------------------------------------------------------------------


def decode_request(payload: bytes) -> str:
    """A REQUEST's NUL-terminated ASCII command (bytes after the NUL are junk in real captures)."""
    text, _ = _cstr(payload, 0, len(payload), "request", int(MessageId.REQUEST))
    return text


def encode_request(command: str) -> bytes:
    """Encode a REQUEST packet carrying ``command`` (e.g. ``"FrameRate"``)."""
    return encode_packet(MessageId.REQUEST, _cstr_bytes(command))


def decode_response(payload: bytes) -> Response:
    """A RESPONSE: 4 raw bytes (int32 or float32 by command), else a NUL-terminated string."""
    if len(payload) == 4:
        return Response(bytes(payload), None)
    text, _ = _cstr(payload, 0, len(payload), "response", int(MessageId.RESPONSE))
    return Response(bytes(payload), text)


def encode_response(value: int | float | str) -> bytes:
    """Encode a RESPONSE: an int as int32, a float as float32, a str as a NUL-terminated string."""
    if isinstance(value, bool) or isinstance(value, int):
        payload = _I32.pack(int(value))
    elif isinstance(value, float):
        payload = _F32.pack(value)
    else:
        payload = _cstr_bytes(value)
        if len(payload) == 4:  # a 4-byte payload would read as a number: pad the string
            payload += b"\0"
    return encode_packet(MessageId.RESPONSE, payload)


def decode_message_string(payload: bytes) -> str:
    """A MESSAGESTRING's NUL-terminated text."""
    text, _ = _cstr(payload, 0, len(payload), "message string", int(MessageId.MESSAGESTRING))
    return text


def encode_message_string(text: str) -> bytes:
    return encode_packet(MessageId.MESSAGESTRING, _cstr_bytes(text))


def decode_echo_request(payload: bytes) -> int:
    """ECHOREQUEST: the client's uint64 stamp."""
    return _read(_U64, payload, 0, len(payload), "echo request", int(MessageId.ECHOREQUEST))[0]


def encode_echo_request(stamp: int) -> bytes:
    return encode_packet(MessageId.ECHOREQUEST, _U64.pack(stamp))


def decode_echo_response(payload: bytes) -> EchoResponse:
    """ECHORESPONSE: the echoed uint64 stamp and the server's uint64 clock ticks."""
    stamp, ticks = _read(_U64X2, payload, 0, len(payload), "echo response", int(MessageId.ECHORESPONSE))
    return EchoResponse(stamp, ticks)


def encode_echo_response(stamp: int, server_ticks: int) -> bytes:
    return encode_packet(MessageId.ECHORESPONSE, _U64X2.pack(stamp, server_ticks))


def encode_request_model_def() -> bytes:
    return encode_packet(MessageId.REQUEST_MODELDEF)


def encode_keepalive() -> bytes:
    return encode_packet(MessageId.KEEPALIVE)


def encode_disconnect() -> bytes:
    return encode_packet(MessageId.DISCONNECT)


def encode_unrecognized_request() -> bytes:
    return encode_packet(MessageId.UNRECOGNIZED_REQUEST)


# ---------------------------------------------------------------------------------------------------------------
# Dispatch
# ---------------------------------------------------------------------------------------------------------------


def decode_packet(packet: bytes, version: Version | None = None) -> tuple[int, Message]:
    """Decode any NatNet datagram into (message id, decoded body).

    Bodies: FRAMEOFDATA -> :class:`FrameOfData`, MODELDEF -> :class:`ModelDefinitions` (both need ``version``),
    SERVERINFO -> :class:`ServerInfo`, CONNECT/DISCOVERY -> :class:`ConnectRequest`, REQUEST/MESSAGESTRING -> str,
    RESPONSE -> :class:`Response`, ECHOREQUEST -> int, ECHORESPONSE -> :class:`EchoResponse`, messages without
    payload -> None, unknown ids -> the raw payload bytes.
    """
    message_id, payload = decode_header(packet)
    try:
        if message_id == MessageId.FRAMEOFDATA or message_id == MessageId.MODELDEF:
            if version is None:
                raise NatNetDecodeError("the bitstream version is not known yet", message_id, 0)
            if message_id == MessageId.FRAMEOFDATA:
                return message_id, decode_frame(payload, version)
            return message_id, decode_model_def(payload, version)
        if message_id == MessageId.SERVERINFO:
            return message_id, decode_server_info(payload)
        if message_id == MessageId.CONNECT or message_id == MessageId.DISCOVERY:
            return message_id, decode_connect(payload)
        if message_id == MessageId.REQUEST:
            return message_id, decode_request(payload)
        if message_id == MessageId.RESPONSE:
            return message_id, decode_response(payload)
        if message_id == MessageId.MESSAGESTRING:
            return message_id, decode_message_string(payload)
        if message_id == MessageId.ECHOREQUEST:
            return message_id, decode_echo_request(payload)
        if message_id == MessageId.ECHORESPONSE:
            return message_id, decode_echo_response(payload)
        if message_id in (
            MessageId.REQUEST_MODELDEF,
            MessageId.REQUEST_FRAMEOFDATA,
            MessageId.DISCONNECT,
            MessageId.KEEPALIVE,
            MessageId.DISCONNECTBYTIMEOUT,
            MessageId.UNRECOGNIZED_REQUEST,
            UNRECOGNIZED_REQUEST_ALT,
        ):
            return message_id, None
        return message_id, payload
    except NatNetDecodeError:
        raise
    except (struct.error, ValueError, IndexError, OverflowError, MemoryError) as exc:
        raise NatNetDecodeError(f"message {message_id}: {exc}", message_id) from exc
