"""NatNet wire format: pure encode/decode of OptiTrack Motive's streaming packets (no sockets, no clocks).

Covers the bitstream versions 3.x, 4.0, 4.1 and 4.2 (4.3+ is decoded with the 4.2 layout, which the SDK samples
treat as current). Everything is little-endian. Facts are from ``shared/reference/natnet.md``; the layouts that
change between versions:

* 4.0 adds marker names to rigid-body descriptions (MODELDEF).
* 4.1 adds an int32 byte count after every FRAMEOFDATA section count and after every MODELDEF dataset type, the
  asset section in frames, and the precision timestamp (two uint32) in the frame suffix.
* 4.2 adds a rotation offset quaternion to rigid-body descriptions.

Every read is bounds-checked: a malformed or truncated packet raises :class:`NatNetDecodeError` (and nothing
else), carrying the message id and the byte offset into the payload. Where 4.1+ gives section sizes, the decoder
checks that the parsed bytes match them exactly, so a layout change in a future Motive makes frames fail loudly
instead of yielding wrong poses.

Units: positions in metres, quaternions (qx, qy, qz, qw), timestamps in seconds, hardware stamps in ticks of the
server's HighResClockFrequency. Axes are whatever Motive streams (Y-up by default); the client converts.

Speed: frame decoding uses precompiled :class:`struct.Struct` objects, ``unpack_from`` and ``iter_unpack`` over
whole record arrays, so the per-rigid-body cost is one tuple construction.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from enum import IntEnum
from typing import NamedTuple, Sequence, Union

__all__ = [
    "MessageId",
    "NatNetDecodeError",
    "Version",
    "SUPPORTED_VERSIONS",
    "parse_version",
    "RigidBodyData",
    "LabeledMarker",
    "MarkerSetData",
    "SkeletonData",
    "AssetData",
    "AnalogData",
    "FrameOfData",
    "ServerInfo",
    "ConnectRequest",
    "Response",
    "EchoResponse",
    "RigidBodyMarker",
    "RigidBodyDescription",
    "MarkerSetDescription",
    "SkeletonDescription",
    "OtherDescription",
    "ModelDefinitions",
    "decode_header",
    "decode_packet",
    "decode_frame",
    "decode_model_def",
    "decode_server_info",
    "decode_connect",
    "decode_request",
    "decode_response",
    "decode_message_string",
    "decode_echo_request",
    "decode_echo_response",
    "encode_packet",
    "encode_connect",
    "encode_discovery",
    "encode_server_info",
    "encode_request",
    "encode_response",
    "encode_request_model_def",
    "encode_model_def",
    "encode_frame",
    "encode_keepalive",
    "encode_disconnect",
    "encode_echo_request",
    "encode_echo_response",
    "encode_message_string",
    "encode_unrecognized_request",
    "timecode_string",
]


class MessageId(IntEnum):
    """NatNet message ids (header field 1)."""

    CONNECT = 0
    SERVERINFO = 1
    REQUEST = 2
    RESPONSE = 3
    REQUEST_MODELDEF = 4
    MODELDEF = 5
    REQUEST_FRAMEOFDATA = 6
    FRAMEOFDATA = 7
    MESSAGESTRING = 8
    DISCONNECT = 9
    KEEPALIVE = 10
    DISCONNECTBYTIMEOUT = 11
    ECHOREQUEST = 12
    ECHORESPONSE = 13
    DISCOVERY = 14
    UNRECOGNIZED_REQUEST = 100


#: One third-party source documents UNRECOGNIZED_REQUEST as 0x100; real Motive sends 100. Both are accepted.
UNRECOGNIZED_REQUEST_ALT = 0x100

#: Largest payload a NatNet packet may carry (the header's byte count is a uint16; Motive caps at this).
MAX_PAYLOAD = 65503

#: Frame suffix params bits.
FRAME_RECORDING = 0x01
FRAME_MODELS_CHANGED = 0x02
#: Rigid-body params bit.
RIGID_BODY_TRACKING_VALID = 0x01

#: MODELDEF dataset types.
DATASET_MARKER_SET = 0
DATASET_RIGID_BODY = 1
DATASET_SKELETON = 2
DATASET_FORCE_PLATE = 3
DATASET_DEVICE = 4
DATASET_CAMERA = 5
DATASET_ASSET = 6

Version = tuple[int, int]
"""A NatNet bitstream version as (major, minor)."""

SUPPORTED_VERSIONS: tuple[Version, ...] = ((3, 0), (4, 0), (4, 1), (4, 2))


class NatNetDecodeError(ValueError):
    """A NatNet packet is malformed, truncated or of an unsupported version.

    ``message_id`` is the packet's message id (or -1 when the header itself is bad); ``offset`` is the byte
    offset into the payload (after the 4-byte header) where decoding failed, or -1 when unknown.
    """

    def __init__(self, reason: str, message_id: int = -1, offset: int = -1) -> None:
        super().__init__(f"{reason} (message id {message_id}, payload offset {offset})")
        self.reason = reason
        self.message_id = message_id
        self.offset = offset


def parse_version(version: str | Sequence[int]) -> Version:
    """Normalise ``"4.1"``, ``(4, 1)`` or ``(4, 1, 0, 0)`` to ``(4, 1)``."""
    if isinstance(version, str):
        parts = version.strip().split(".")
        try:
            numbers = [int(p) for p in parts if p != ""]
        except ValueError as exc:
            raise ValueError(f"not a NatNet version: {version!r}") from exc
    else:
        numbers = [int(p) for p in version]
    if not numbers:
        raise ValueError(f"not a NatNet version: {version!r}")
    return (numbers[0], numbers[1] if len(numbers) > 1 else 0)


class _Layout(NamedTuple):
    """What a bitstream version puts on the wire."""

    section_sizes: bool  # 4.1+: int32 byte count after each frame section count / dataset type
    assets: bool  # 4.1+: asset section in frames
    precision_timestamp: bool  # 4.1+: two uint32 in the frame suffix
    rb_marker_names: bool  # 4.0+: marker names in rigid-body descriptions
    rb_rotation_offset: bool  # 4.2+: rotation offset quaternion in rigid-body descriptions


def _layout(version: Version, message_id: int) -> _Layout:
    """Return the wire layout of ``version``, or raise for versions this module cannot decode."""
    major, minor = version
    if major == 3:
        return _Layout(False, False, False, False, False)
    if major == 4:
        return _Layout(minor >= 1, minor >= 1, minor >= 1, True, minor >= 2)
    raise NatNetDecodeError(f"unsupported NatNet version {major}.{minor} (3.x and 4.x are supported)", message_id)


# ---------------------------------------------------------------------------------------------------------------
# Data objects
# ---------------------------------------------------------------------------------------------------------------


class RigidBodyData(NamedTuple):
    """One rigid body in a frame: position (m), orientation quaternion, mean marker error (m), params bits."""

    id: int
    x: float
    y: float
    z: float
    qx: float
    qy: float
    qz: float
    qw: float
    error: float
    params: int

    @property
    def valid(self) -> bool:
        """Motive tracked the body in this frame (params bit 0x01)."""
        return bool(self.params & RIGID_BODY_TRACKING_VALID)


class LabeledMarker(NamedTuple):
    """A labeled marker (26 bytes): id (model << 16 | marker), position (m), size (m), params, residual (m)."""

    id: int
    x: float
    y: float
    z: float
    size: float
    params: int
    residual: float

    @property
    def model_id(self) -> int:
        """Asset id (high 16 bits of the id)."""
        return (self.id >> 16) & 0xFFFF

    @property
    def marker_id(self) -> int:
        """Marker id within the asset (low 16 bits of the id)."""
        return self.id & 0xFFFF

    @property
    def occluded(self) -> bool:
        return bool(self.params & 0x01)

    @property
    def point_cloud_solved(self) -> bool:
        return bool(self.params & 0x02)

    @property
    def model_solved(self) -> bool:
        return bool(self.params & 0x04)


class MarkerSetData(NamedTuple):
    """A named marker set in a frame: marker positions (m)."""

    name: str
    markers: list[tuple[float, float, float]]


class SkeletonData(NamedTuple):
    """A skeleton in a frame: its bones as rigid-body records."""

    id: int
    rigid_bodies: list[RigidBodyData]


class AssetData(NamedTuple):
    """A 4.1+ asset in a frame: its rigid bodies and markers (markers use the labeled-marker record)."""

    id: int
    rigid_bodies: list[RigidBodyData]
    markers: list[LabeledMarker]


class AnalogData(NamedTuple):
    """A force plate or device in a frame: per channel, the analog samples of this mocap frame."""

    id: int
    channels: list[list[float]]


@dataclass(slots=True)
class FrameOfData:
    """One FRAMEOFDATA message, as streamed (server axes, server clock)."""

    frame_number: int
    marker_sets: list[MarkerSetData] = field(default_factory=list)
    other_markers: list[tuple[float, float, float]] = field(default_factory=list)
    rigid_bodies: list[RigidBodyData] = field(default_factory=list)
    skeletons: list[SkeletonData] = field(default_factory=list)
    assets: list[AssetData] = field(default_factory=list)
    labeled_markers: list[LabeledMarker] = field(default_factory=list)
    force_plates: list[AnalogData] = field(default_factory=list)
    devices: list[AnalogData] = field(default_factory=list)
    timecode: int = 0
    timecode_subframe: int = 0
    timestamp: float = 0.0
    """Seconds since Motive started streaming (server clock)."""
    camera_mid_exposure: int = 0
    """High-resolution clock ticks at the cameras' mid-exposure."""
    camera_data_received: int = 0
    """High-resolution clock ticks when Motive received the camera data."""
    transmit: int = 0
    """High-resolution clock ticks when Motive sent the frame."""
    precision_seconds: int = 0
    """4.1+: precision (e.g. PTP) timestamp, whole seconds; 0 when absent."""
    precision_fraction: int = 0
    """4.1+: precision timestamp, fractional part as Motive sends it; 0 when absent."""
    params: int = 0

    @property
    def models_changed(self) -> bool:
        """The tracked model list changed: re-request MODELDEF (params bit 0x02)."""
        return bool(self.params & FRAME_MODELS_CHANGED)

    @property
    def recording(self) -> bool:
        """Motive is recording (params bit 0x01)."""
        return bool(self.params & FRAME_RECORDING)


@dataclass(frozen=True, slots=True)
class ServerInfo:
    """SERVERINFO: who the server is and how it streams."""

    app_name: str
    app_version: tuple[int, int, int, int]
    natnet_version: tuple[int, int, int, int]
    clock_frequency_hz: int | None = None
    """HighResClockFrequency (ticks per second) of the frame hardware stamps; None before NatNet 3.0."""
    data_port: int | None = None
    multicast: bool | None = None
    multicast_group: str | None = None

    @property
    def version(self) -> Version:
        """The bitstream version as (major, minor)."""
        return (self.natnet_version[0], self.natnet_version[1])


@dataclass(frozen=True, slots=True)
class ConnectRequest:
    """CONNECT or DISCOVERY payload; every field is optional on the wire (any length is accepted)."""

    client_name: str = ""
    app_version: tuple[int, int, int, int] = (0, 0, 0, 0)
    natnet_version: tuple[int, int, int, int] = (0, 0, 0, 0)
    subscribed_only: bool | None = None
    requested_bitstream: tuple[int, int, int, int] | None = None


@dataclass(frozen=True, slots=True)
class Response:
    """RESPONSE to a REQUEST: either 4 raw bytes (an int32 or a float32, depending on the command) or a string."""

    raw: bytes
    text: str | None

    def as_int(self) -> int:
        """The 4-byte reply as int32 (e.g. the result code of most commands)."""
        if len(self.raw) != 4:
            raise ValueError("response is not a 4-byte value")
        return struct.unpack("<i", self.raw)[0]

    def as_float(self) -> float:
        """The 4-byte reply as float32 (e.g. ``FrameRate``)."""
        if len(self.raw) != 4:
            raise ValueError("response is not a 4-byte value")
        return struct.unpack("<f", self.raw)[0]


@dataclass(frozen=True, slots=True)
class EchoResponse:
    """ECHORESPONSE: the client's echoed stamp and the server's high-resolution clock ticks at reply."""

    request_stamp: int
    server_ticks: int


class RigidBodyMarker(NamedTuple):
    """A marker of a rigid-body description: offset from the body (m), active label, name (4.0+, else '')."""

    offset: tuple[float, float, float]
    active_label: int
    name: str


@dataclass(frozen=True, slots=True)
class RigidBodyDescription:
    """A rigid body in MODELDEF: the only place its NAME appears (frames carry only the id)."""

    name: str
    id: int
    parent_id: int = -1
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rotation_offset: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)
    """4.2+: pivot rotation offset (qx, qy, qz, qw); identity before 4.2."""
    markers: tuple[RigidBodyMarker, ...] = ()


@dataclass(frozen=True, slots=True)
class MarkerSetDescription:
    """A marker set in MODELDEF: its name and marker names."""

    name: str
    marker_names: tuple[str, ...] = ()


@dataclass(frozen=True, slots=True)
class SkeletonDescription:
    """A skeleton in MODELDEF: its bones as rigid-body descriptions."""

    name: str
    id: int
    rigid_bodies: tuple[RigidBodyDescription, ...] = ()


@dataclass(frozen=True, slots=True)
class OtherDescription:
    """A dataset this module does not interpret (force plate, device, camera, asset, unknown): type and raw bytes."""

    type: int
    raw: bytes


@dataclass(frozen=True, slots=True)
class ModelDefinitions:
    """MODELDEF: the data descriptions, in wire order within each kind."""

    marker_sets: tuple[MarkerSetDescription, ...] = ()
    rigid_bodies: tuple[RigidBodyDescription, ...] = ()
    skeletons: tuple[SkeletonDescription, ...] = ()
    others: tuple[OtherDescription, ...] = ()


Message = Union[
    FrameOfData, ModelDefinitions, ServerInfo, ConnectRequest, Response, EchoResponse, str, int, bytes, None
]

# ---------------------------------------------------------------------------------------------------------------
# Precompiled structs
# ---------------------------------------------------------------------------------------------------------------

_HEADER = struct.Struct("<HH")
_I32 = struct.Struct("<i")
_I32X2 = struct.Struct("<ii")
_U64 = struct.Struct("<Q")
_U64X2 = struct.Struct("<QQ")
_F32 = struct.Struct("<f")
_VEC3 = struct.Struct("<3f")
_QUAT = struct.Struct("<4f")
_RB = struct.Struct("<i8fh")  # id, x y z, qx qy qz qw, mean marker error, params: 38 bytes
_LABELED = struct.Struct("<i4fhf")  # id, x y z, size, params, residual: 26 bytes
_SUFFIX_30 = struct.Struct("<IIdQQQh")  # timecode, subframe, timestamp, 3 stamps, params: 42 bytes
_SUFFIX_41 = struct.Struct("<IIdQQQIIh")  # + precision seconds, fraction: 50 bytes
_RB_DESC_HEAD = struct.Struct("<ii3f")  # id, parent id, offset
_SERVERINFO_HEAD = struct.Struct("<4B4B")
_SERVERINFO_TAIL = struct.Struct("<QHB4B")
_CONNECT_TAIL = struct.Struct("<4B4B")
_VERSION4 = struct.Struct("<4B")

_RB_SIZE = _RB.size
_LABELED_SIZE = _LABELED.size
_rb_make = RigidBodyData._make
_lm_make = LabeledMarker._make

_NAME_FIELD = 256  # fixed-size name fields in CONNECT and SERVERINFO

# ---------------------------------------------------------------------------------------------------------------
# Header
# ---------------------------------------------------------------------------------------------------------------


def decode_header(packet: bytes) -> tuple[int, bytes]:
    """Split a datagram into (message id, payload); bytes beyond the header's count are ignored.

    Raises :class:`NatNetDecodeError` if the datagram is shorter than the header says.
    """
    if len(packet) < 4:
        raise NatNetDecodeError(f"datagram of {len(packet)} bytes is shorter than the 4-byte header")
    message_id, n_bytes = _HEADER.unpack_from(packet, 0)
    if n_bytes > len(packet) - 4:
        raise NatNetDecodeError(
            f"truncated: header says {n_bytes} payload bytes, datagram has {len(packet) - 4}", message_id, 0
        )
    return message_id, bytes(packet[4 : 4 + n_bytes])


def encode_packet(message_id: int, payload: bytes = b"") -> bytes:
    """Prefix ``payload`` with the NatNet header."""
    if len(payload) > MAX_PAYLOAD:
        raise ValueError(f"NatNet payload of {len(payload)} bytes exceeds {MAX_PAYLOAD}")
    return _HEADER.pack(int(message_id), len(payload)) + payload


# ---------------------------------------------------------------------------------------------------------------
# Small bounded readers (used on the slower, string-heavy paths)
# ---------------------------------------------------------------------------------------------------------------


def _cstr(buf: bytes, off: int, end: int, what: str, message_id: int) -> tuple[str, int]:
    """Read a NUL-terminated string in ``buf[off:end]``; returns (text, offset after the NUL)."""
    nul = buf.find(b"\0", off, end)
    if nul < 0:
        raise NatNetDecodeError(f"{what}: missing NUL terminator", message_id, off)
    return buf[off:nul].decode("utf-8", "replace"), nul + 1


def _fixed_name(buf: bytes, off: int, width: int) -> str:
    """A NUL-padded fixed-width name; anything after the first NUL is junk (seen in real captures)."""
    raw = buf[off : off + width]
    nul = raw.find(b"\0")
    if nul >= 0:
        raw = raw[:nul]
    return raw.decode("utf-8", "replace")


def _read(st: struct.Struct, buf: bytes, off: int, end: int, what: str, message_id: int) -> tuple:
    """Unpack ``st`` at ``off`` if it fits before ``end``."""
    if end - off < st.size:
        raise NatNetDecodeError(f"{what}: truncated ({end - off} of {st.size} bytes)", message_id, off)
    return st.unpack_from(buf, off)


def _count(buf: bytes, off: int, end: int, item_min: int, what: str, message_id: int) -> int:
    """Read an int32 count and check that ``count * item_min`` bytes can still follow."""
    if end - off < 4:
        raise NatNetDecodeError(f"{what}: truncated count", message_id, off)
    (n,) = _I32.unpack_from(buf, off)
    if n < 0 or n * item_min > end - off - 4:
        raise NatNetDecodeError(
            f"{what}: count {n} does not fit in the remaining {end - off - 4} bytes", message_id, off
        )
    return n


# ---------------------------------------------------------------------------------------------------------------
# FRAMEOFDATA
# ---------------------------------------------------------------------------------------------------------------

_FRAME = int(MessageId.FRAMEOFDATA)


def _open_section(buf: bytes, off: int, end: int, sized: bool, item_min: int, what: str) -> tuple[int, int, int]:
    """Read a section's count (and 4.1+ byte size). Returns (count, offset of the first item, section end).

    The section end is the size-checked limit for 4.1+, else the payload end.
    """
    if end - off < (8 if sized else 4):
        raise NatNetDecodeError(f"{what}: truncated section header", _FRAME, off)
    if sized:
        n, size = _I32X2.unpack_from(buf, off)
        off += 8
        if size < 0 or size > end - off:
            raise NatNetDecodeError(
                f"{what}: byte size {size} exceeds the remaining {end - off} bytes", _FRAME, off - 4
            )
        limit = off + size
    else:
        (n,) = _I32.unpack_from(buf, off)
        off += 4
        limit = end
    if n < 0 or n * item_min > limit - off:
        raise NatNetDecodeError(f"{what}: count {n} does not fit in {limit - off} bytes", _FRAME, off)
    return n, off, limit


def _close_section(off: int, limit: int, sized: bool, what: str) -> None:
    """For 4.1+, the parsed bytes must equal the declared section size."""
    if sized and off != limit:
        raise NatNetDecodeError(f"{what}: declared size ends at {limit}, content ends at {off}", _FRAME, off)


def _rigid_body_array(buf: bytes, mv: memoryview, off: int, limit: int, what: str) -> tuple[list[RigidBodyData], int]:
    """Read an int32 count then that many 38-byte rigid-body records."""
    if limit - off < 4:
        raise NatNetDecodeError(f"{what}: truncated rigid-body count", _FRAME, off)
    (n,) = _I32.unpack_from(buf, off)
    off += 4
    if n < 0 or n * _RB_SIZE > limit - off:
        raise NatNetDecodeError(f"{what}: {n} rigid bodies do not fit in {limit - off} bytes", _FRAME, off)
    stop = off + n * _RB_SIZE
    return list(map(_rb_make, _RB.iter_unpack(mv[off:stop]))), stop


def _analog_section(buf: bytes, off: int, limit: int, n: int, what: str) -> tuple[list[AnalogData], int]:
    """Force plates or devices: per item id, channel count, per channel frame count and float32 samples."""
    items: list[AnalogData] = []
    for _ in range(n):
        if limit - off < 8:
            raise NatNetDecodeError(f"{what}: truncated item header", _FRAME, off)
        item_id, n_channels = _I32X2.unpack_from(buf, off)
        off += 8
        if n_channels < 0 or n_channels * 4 > limit - off:
            raise NatNetDecodeError(f"{what}: channel count {n_channels} does not fit", _FRAME, off - 4)
        channels: list[list[float]] = []
        for _ in range(n_channels):
            if limit - off < 4:
                raise NatNetDecodeError(f"{what}: truncated channel", _FRAME, off)
            (n_frames,) = _I32.unpack_from(buf, off)
            off += 4
            if n_frames < 0 or n_frames * 4 > limit - off:
                raise NatNetDecodeError(f"{what}: sample count {n_frames} does not fit", _FRAME, off - 4)
            channels.append(list(struct.unpack_from(f"<{n_frames}f", buf, off)))
            off += 4 * n_frames
        items.append(AnalogData(item_id, channels))
    return items, off


def decode_frame(payload: bytes, version: Version) -> FrameOfData:
    """Decode a FRAMEOFDATA payload (after the header) of bitstream ``version``.

    Raises :class:`NatNetDecodeError` on any malformed, truncated or inconsistent payload.
    """
    layout = _layout(version, _FRAME)
    try:
        return _decode_frame(payload, layout)
    except NatNetDecodeError:
        raise
    except (struct.error, ValueError, IndexError, OverflowError, MemoryError) as exc:  # defence in depth
        raise NatNetDecodeError(f"frame: {exc}", _FRAME) from exc


def _decode_frame(buf: bytes, layout: _Layout) -> FrameOfData:
    sized = layout.section_sizes
    end = len(buf)
    mv = memoryview(buf)
    if end < 4:
        raise NatNetDecodeError("truncated frame number", _FRAME, 0)
    (frame_number,) = _I32.unpack_from(buf, 0)
    off = 4

    # 1. marker sets: name, count, positions
    n, off, limit = _open_section(buf, off, end, sized, 5, "marker sets")
    marker_sets: list[MarkerSetData] = []
    for _ in range(n):
        name, off = _cstr(buf, off, limit, "marker set name", _FRAME)
        if limit - off < 4:
            raise NatNetDecodeError("marker set: truncated marker count", _FRAME, off)
        (k,) = _I32.unpack_from(buf, off)
        off += 4
        if k < 0 or k * 12 > limit - off:
            raise NatNetDecodeError(f"marker set {name!r}: {k} markers do not fit", _FRAME, off - 4)
        stop = off + 12 * k
        marker_sets.append(MarkerSetData(name, list(_VEC3.iter_unpack(mv[off:stop]))))
        off = stop
    _close_section(off, limit, sized, "marker sets")

    # 2. other (unlabeled, legacy) markers
    n, off, limit = _open_section(buf, off, end, sized, 12, "other markers")
    stop = off + 12 * n
    other_markers = list(_VEC3.iter_unpack(mv[off:stop]))
    off = stop
    _close_section(off, limit, sized, "other markers")

    # 3. rigid bodies: fixed 38-byte records
    n, off, limit = _open_section(buf, off, end, sized, _RB_SIZE, "rigid bodies")
    stop = off + _RB_SIZE * n
    rigid_bodies = list(map(_rb_make, _RB.iter_unpack(mv[off:stop])))
    off = stop
    _close_section(off, limit, sized, "rigid bodies")

    # 4. skeletons: id, then rigid-body records
    n, off, limit = _open_section(buf, off, end, sized, 8, "skeletons")
    skeletons: list[SkeletonData] = []
    for _ in range(n):
        if limit - off < 4:
            raise NatNetDecodeError("skeleton: truncated id", _FRAME, off)
        (skeleton_id,) = _I32.unpack_from(buf, off)
        bones, off = _rigid_body_array(buf, mv, off + 4, limit, "skeleton")
        skeletons.append(SkeletonData(skeleton_id, bones))
    _close_section(off, limit, sized, "skeletons")

    # 5. assets (4.1+): id, rigid-body records, 26-byte markers
    assets: list[AssetData] = []
    if layout.assets:
        n, off, limit = _open_section(buf, off, end, sized, 12, "assets")
        for _ in range(n):
            if limit - off < 4:
                raise NatNetDecodeError("asset: truncated id", _FRAME, off)
            (asset_id,) = _I32.unpack_from(buf, off)
            bodies, off = _rigid_body_array(buf, mv, off + 4, limit, "asset")
            if limit - off < 4:
                raise NatNetDecodeError("asset: truncated marker count", _FRAME, off)
            (k,) = _I32.unpack_from(buf, off)
            off += 4
            if k < 0 or k * _LABELED_SIZE > limit - off:
                raise NatNetDecodeError(f"asset: {k} markers do not fit", _FRAME, off - 4)
            stop = off + _LABELED_SIZE * k
            assets.append(AssetData(asset_id, bodies, list(map(_lm_make, _LABELED.iter_unpack(mv[off:stop])))))
            off = stop
        _close_section(off, limit, sized, "assets")

    # 6. labeled markers: fixed 26-byte records
    n, off, limit = _open_section(buf, off, end, sized, _LABELED_SIZE, "labeled markers")
    stop = off + _LABELED_SIZE * n
    labeled_markers = list(map(_lm_make, _LABELED.iter_unpack(mv[off:stop])))
    off = stop
    _close_section(off, limit, sized, "labeled markers")

    # 7./8. force plates and devices
    n, off, limit = _open_section(buf, off, end, sized, 8, "force plates")
    force_plates, off = _analog_section(buf, off, limit, n, "force plates") if n else ([], off)
    _close_section(off, limit, sized, "force plates")
    n, off, limit = _open_section(buf, off, end, sized, 8, "devices")
    devices, off = _analog_section(buf, off, limit, n, "devices") if n else ([], off)
    _close_section(off, limit, sized, "devices")

    # 9. suffix (the end-of-data int32 after it is not required: the SDK parsers never read it)
    if layout.precision_timestamp:
        if end - off < _SUFFIX_41.size:
            raise NatNetDecodeError(f"suffix: truncated ({end - off} of {_SUFFIX_41.size} bytes)", _FRAME, off)
        (timecode, subframe, timestamp, mid, received, transmit, p_sec, p_frac, params) = _SUFFIX_41.unpack_from(
            buf, off
        )
    else:
        if end - off < _SUFFIX_30.size:
            raise NatNetDecodeError(f"suffix: truncated ({end - off} of {_SUFFIX_30.size} bytes)", _FRAME, off)
        (timecode, subframe, timestamp, mid, received, transmit, params) = _SUFFIX_30.unpack_from(buf, off)
        p_sec = p_frac = 0
    return FrameOfData(
        frame_number,
        marker_sets,
        other_markers,
        rigid_bodies,
        skeletons,
        assets,
        labeled_markers,
        force_plates,
        devices,
        timecode,
        subframe,
        timestamp,
        mid,
        received,
        transmit,
        p_sec,
        p_frac,
        params,
    )


def _section_bytes(count: int, body: bytes, sized: bool) -> bytes:
    """A frame section: count, (4.1+) byte size, body."""
    if sized:
        return _I32X2.pack(count, len(body)) + body
    return _I32.pack(count) + body


def _rb_bytes(rb: RigidBodyData) -> bytes:
    return _RB.pack(*rb)


def _labeled_bytes(m: LabeledMarker) -> bytes:
    return _LABELED.pack(*m)


def _analog_bytes(items: Sequence[AnalogData]) -> bytes:
    out = bytearray()
    for item in items:
        out += _I32X2.pack(item.id, len(item.channels))
        for channel in item.channels:
            out += _I32.pack(len(channel)) + struct.pack(f"<{len(channel)}f", *channel)
    return bytes(out)


def _cstr_bytes(text: str) -> bytes:
    raw = text.encode("utf-8")
    if b"\0" in raw:
        raise ValueError(f"name {text!r} contains a NUL character")
    return raw + b"\0"


def encode_frame(frame: FrameOfData, version: Version) -> bytes:
    """Encode ``frame`` as a complete FRAMEOFDATA packet (header included) of bitstream ``version``.

    Assets are written only for 4.1+, the precision timestamp only for 4.1+.
    """
    layout = _layout(version, _FRAME)
    sized = layout.section_sizes
    parts = [_I32.pack(frame.frame_number)]

    body = bytearray()
    for ms in frame.marker_sets:
        body += _cstr_bytes(ms.name) + _I32.pack(len(ms.markers))
        for m in ms.markers:
            body += _VEC3.pack(*m)
    parts.append(_section_bytes(len(frame.marker_sets), bytes(body), sized))
    parts.append(_section_bytes(len(frame.other_markers), b"".join(_VEC3.pack(*m) for m in frame.other_markers), sized))
    parts.append(_section_bytes(len(frame.rigid_bodies), b"".join(map(_rb_bytes, frame.rigid_bodies)), sized))
    body = bytearray()
    for sk in frame.skeletons:
        body += _I32X2.pack(sk.id, len(sk.rigid_bodies)) + b"".join(map(_rb_bytes, sk.rigid_bodies))
    parts.append(_section_bytes(len(frame.skeletons), bytes(body), sized))
    if layout.assets:
        body = bytearray()
        for asset in frame.assets:
            body += _I32X2.pack(asset.id, len(asset.rigid_bodies)) + b"".join(map(_rb_bytes, asset.rigid_bodies))
            body += _I32.pack(len(asset.markers)) + b"".join(map(_labeled_bytes, asset.markers))
        parts.append(_section_bytes(len(frame.assets), bytes(body), sized))
    labeled = b"".join(map(_labeled_bytes, frame.labeled_markers))
    parts.append(_section_bytes(len(frame.labeled_markers), labeled, sized))
    parts.append(_section_bytes(len(frame.force_plates), _analog_bytes(frame.force_plates), sized))
    parts.append(_section_bytes(len(frame.devices), _analog_bytes(frame.devices), sized))
    if layout.precision_timestamp:
        parts.append(
            _SUFFIX_41.pack(
                frame.timecode,
                frame.timecode_subframe,
                frame.timestamp,
                frame.camera_mid_exposure,
                frame.camera_data_received,
                frame.transmit,
                frame.precision_seconds,
                frame.precision_fraction,
                frame.params,
            )
        )
    else:
        parts.append(
            _SUFFIX_30.pack(
                frame.timecode,
                frame.timecode_subframe,
                frame.timestamp,
                frame.camera_mid_exposure,
                frame.camera_data_received,
                frame.transmit,
                frame.params,
            )
        )
    parts.append(_I32.pack(0))  # end of data
    return encode_packet(MessageId.FRAMEOFDATA, b"".join(parts))


def timecode_string(timecode: int, subframe: int) -> str:
    """SMPTE timecode as Motive's sample client prints it: ``hh:mm:ss:ff.sub``."""
    hours = (timecode >> 24) & 255
    minutes = (timecode >> 16) & 255
    seconds = (timecode >> 8) & 255
    frames = timecode & 255
    return f"{hours:02d}:{minutes:02d}:{seconds:02d}:{frames:02d}.{subframe}"


# ---------------------------------------------------------------------------------------------------------------
# MODELDEF
# ---------------------------------------------------------------------------------------------------------------

_MODELDEF = int(MessageId.MODELDEF)


def _decode_rb_description(buf: bytes, off: int, end: int, layout: _Layout) -> tuple[RigidBodyDescription, int]:
    name, off = _cstr(buf, off, end, "rigid body name", _MODELDEF)
    body_id, parent_id, ox, oy, oz = _read(_RB_DESC_HEAD, buf, off, end, "rigid body description", _MODELDEF)
    off += _RB_DESC_HEAD.size
    rotation = (0.0, 0.0, 0.0, 1.0)
    if layout.rb_rotation_offset:
        rotation = _read(_QUAT, buf, off, end, "rigid body rotation offset", _MODELDEF)
        off += 16
    n = _count(buf, off, end, 16, f"rigid body {name!r} markers", _MODELDEF)
    off += 4
    offsets = list(_VEC3.iter_unpack(buf[off : off + 12 * n]))
    off += 12 * n
    labels = [v for (v,) in _I32.iter_unpack(buf[off : off + 4 * n])]
    off += 4 * n
    names = [""] * n
    if layout.rb_marker_names:
        for i in range(n):
            names[i], off = _cstr(buf, off, end, "rigid body marker name", _MODELDEF)
    markers = tuple(RigidBodyMarker(o, lab, nm) for o, lab, nm in zip(offsets, labels, names))
    return RigidBodyDescription(name, body_id, parent_id, (ox, oy, oz), tuple(rotation), markers), off


def _decode_marker_set_description(buf: bytes, off: int, end: int) -> tuple[MarkerSetDescription, int]:
    name, off = _cstr(buf, off, end, "marker set name", _MODELDEF)
    n = _count(buf, off, end, 1, f"marker set {name!r} names", _MODELDEF)
    off += 4
    names = []
    for _ in range(n):
        marker_name, off = _cstr(buf, off, end, "marker name", _MODELDEF)
        names.append(marker_name)
    return MarkerSetDescription(name, tuple(names)), off


def _decode_skeleton_description(buf: bytes, off: int, end: int, layout: _Layout) -> tuple[SkeletonDescription, int]:
    name, off = _cstr(buf, off, end, "skeleton name", _MODELDEF)
    (skeleton_id,) = _read(_I32, buf, off, end, "skeleton id", _MODELDEF)
    off += 4
    n = _count(buf, off, end, 25, f"skeleton {name!r} bones", _MODELDEF)  # smallest bone: NUL, ids, offset, 0 markers
    off += 4
    bones = []
    for _ in range(n):
        bone, off = _decode_rb_description(buf, off, end, layout)
        bones.append(bone)
    return SkeletonDescription(name, skeleton_id, tuple(bones)), off


def _skip_force_plate_description(buf: bytes, off: int, end: int) -> int:
    """Pre-4.1 only (no dataset sizes): parse just enough to find the end of a force plate description."""
    off += 4  # id
    _, off = _cstr(buf, off, end, "force plate serial", _MODELDEF)
    off += 4 * (2 + 3 + 144 + 12) + 4 + 4  # width, length, origin, calibration 12x12, corners 4x3, type, data type
    n = _count(buf, off, end, 1, "force plate channels", _MODELDEF)
    off += 4
    for _ in range(n):
        _, off = _cstr(buf, off, end, "force plate channel name", _MODELDEF)
    return off


def _skip_device_description(buf: bytes, off: int, end: int) -> int:
    """Pre-4.1 only: find the end of a device description."""
    off += 4  # id
    _, off = _cstr(buf, off, end, "device name", _MODELDEF)
    _, off = _cstr(buf, off, end, "device serial", _MODELDEF)
    off += 8  # device type, channel data type
    n = _count(buf, off, end, 1, "device channels", _MODELDEF)
    off += 4
    for _ in range(n):
        _, off = _cstr(buf, off, end, "device channel name", _MODELDEF)
    return off


def _skip_camera_description(buf: bytes, off: int, end: int) -> int:
    """Pre-4.1 only: a camera description is a name, a position and a quaternion."""
    _, off = _cstr(buf, off, end, "camera name", _MODELDEF)
    return off + 28


def decode_model_def(payload: bytes, version: Version) -> ModelDefinitions:
    """Decode a MODELDEF payload of bitstream ``version``.

    4.1+ datasets carry their byte size: unknown kinds are skipped by size and known kinds must fill it exactly.
    Before 4.1 every kind must be parsed to find the next one, so an unknown type is an error.
    """
    layout = _layout(version, _MODELDEF)
    try:
        return _decode_model_def(payload, layout)
    except NatNetDecodeError:
        raise
    except (struct.error, ValueError, IndexError, OverflowError, MemoryError) as exc:
        raise NatNetDecodeError(f"model definitions: {exc}", _MODELDEF) from exc


def _decode_model_def(buf: bytes, layout: _Layout) -> ModelDefinitions:
    end = len(buf)
    sized = layout.section_sizes
    n = _count(buf, 0, end, 8 if sized else 4, "datasets", _MODELDEF)
    off = 4
    marker_sets: list[MarkerSetDescription] = []
    rigid_bodies: list[RigidBodyDescription] = []
    skeletons: list[SkeletonDescription] = []
    others: list[OtherDescription] = []
    for _ in range(n):
        if sized:
            kind, size = _read(_I32X2, buf, off, end, "dataset header", _MODELDEF)
            off += 8
            if size < 0 or size > end - off:
                raise NatNetDecodeError(
                    f"dataset size {size} exceeds the remaining {end - off} bytes", _MODELDEF, off - 4
                )
            limit = off + size
        else:
            (kind,) = _read(_I32, buf, off, end, "dataset type", _MODELDEF)
            off += 4
            limit = end
        start = off
        if kind == DATASET_MARKER_SET:
            desc_ms, off = _decode_marker_set_description(buf, off, limit)
            marker_sets.append(desc_ms)
        elif kind == DATASET_RIGID_BODY:
            desc_rb, off = _decode_rb_description(buf, off, limit, layout)
            rigid_bodies.append(desc_rb)
        elif kind == DATASET_SKELETON:
            desc_sk, off = _decode_skeleton_description(buf, off, limit, layout)
            skeletons.append(desc_sk)
        elif sized:
            off = limit
            others.append(OtherDescription(kind, bytes(buf[start:off])))
        elif kind == DATASET_FORCE_PLATE:
            off = _skip_force_plate_description(buf, off, limit)
        elif kind == DATASET_DEVICE:
            off = _skip_device_description(buf, off, limit)
        elif kind == DATASET_CAMERA:
            off = _skip_camera_description(buf, off, limit)
        else:
            raise NatNetDecodeError(f"unknown dataset type {kind} (cannot be skipped before 4.1)", _MODELDEF, start - 4)
        if off > limit:
            raise NatNetDecodeError(f"dataset type {kind} runs past the end of its data", _MODELDEF, start)
        if not sized and kind not in (DATASET_MARKER_SET, DATASET_RIGID_BODY, DATASET_SKELETON):
            others.append(OtherDescription(kind, bytes(buf[start:off])))
        if sized and off != limit:
            raise NatNetDecodeError(
                f"dataset type {kind}: declared size ends at {limit}, content at {off}", _MODELDEF, off
            )
    return ModelDefinitions(tuple(marker_sets), tuple(rigid_bodies), tuple(skeletons), tuple(others))


def _rb_description_bytes(rb: RigidBodyDescription, layout: _Layout) -> bytes:
    out = bytearray(_cstr_bytes(rb.name))
    out += _RB_DESC_HEAD.pack(rb.id, rb.parent_id, *rb.offset)
    if layout.rb_rotation_offset:
        out += _QUAT.pack(*rb.rotation_offset)
    out += _I32.pack(len(rb.markers))
    for m in rb.markers:
        out += _VEC3.pack(*m.offset)
    for m in rb.markers:
        out += _I32.pack(m.active_label)
    if layout.rb_marker_names:
        for m in rb.markers:
            out += _cstr_bytes(m.name)
    return bytes(out)


def encode_model_def(model: ModelDefinitions, version: Version) -> bytes:
    """Encode ``model`` as a complete MODELDEF packet of bitstream ``version``.

    Datasets go out as marker sets, rigid bodies, skeletons, then the raw ``others`` (which must already be in
    the layout of ``version``).
    """
    layout = _layout(version, _MODELDEF)
    datasets: list[tuple[int, bytes]] = []
    for ms in model.marker_sets:
        body = _cstr_bytes(ms.name) + _I32.pack(len(ms.marker_names)) + b"".join(map(_cstr_bytes, ms.marker_names))
        datasets.append((DATASET_MARKER_SET, body))
    for rb in model.rigid_bodies:
        datasets.append((DATASET_RIGID_BODY, _rb_description_bytes(rb, layout)))
    for sk in model.skeletons:
        body = _cstr_bytes(sk.name) + _I32X2.pack(sk.id, len(sk.rigid_bodies))
        body += b"".join(_rb_description_bytes(b, layout) for b in sk.rigid_bodies)
        datasets.append((DATASET_SKELETON, body))
    for other in model.others:
        datasets.append((other.type, other.raw))
    out = bytearray(_I32.pack(len(datasets)))
    for kind, body in datasets:
        out += _I32X2.pack(kind, len(body)) if layout.section_sizes else _I32.pack(kind)
        out += body
    return encode_packet(MessageId.MODELDEF, bytes(out))


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
    return ConnectRequest(name, app_version, natnet_version, subscribed, bitstream)  # type: ignore[arg-type]


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
