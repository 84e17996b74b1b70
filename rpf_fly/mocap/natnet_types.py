"""NatNet message ids, bitstream versions, the decode error and the decoded packet objects (no wire code).

Units: positions in metres, quaternions (qx, qy, qz, qw), timestamps in seconds, hardware stamps in ticks of the
server's HighResClockFrequency. Axes are whatever Motive streams (Y-up by default); the client converts.

Part of the NatNet codec; import it through :mod:`rpf_fly.mocap.natnet_protocol`.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from dataclasses import dataclass, field
from enum import IntEnum
from typing import NamedTuple, TypeAlias

__all__ = [
    "MessageId",
    "UNRECOGNIZED_REQUEST_ALT",
    "MAX_PAYLOAD",
    "FRAME_RECORDING",
    "FRAME_MODELS_CHANGED",
    "RIGID_BODY_TRACKING_VALID",
    "DATASET_MARKER_SET",
    "DATASET_RIGID_BODY",
    "DATASET_SKELETON",
    "DATASET_FORCE_PLATE",
    "DATASET_DEVICE",
    "DATASET_CAMERA",
    "DATASET_ASSET",
    "Version",
    "SUPPORTED_VERSIONS",
    "NatNetDecodeError",
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
    "Message",
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


Message: TypeAlias = (
    FrameOfData | ModelDefinitions | ServerInfo | ConnectRequest | Response | EchoResponse | str | int | bytes | None
)
