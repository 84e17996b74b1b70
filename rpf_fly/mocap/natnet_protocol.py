"""NatNet wire format: pure encode/decode of OptiTrack Motive's streaming packets (no sockets, no clocks).

Covers the bitstream versions 3.x, 4.0, 4.1 and 4.2 (4.3+ is decoded with the 4.2 layout, which the SDK samples
treat as current). Everything is little-endian. Facts are from OptiTrack's NatNet SDK 4.3 samples (PythonClient,
PacketClient.cpp, NatNetTypes.h), checked against real Motive captures (``tests/data/natnet``) and libmotioncapture
(docs/mocap.md); the layouts that change between versions:

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

The codec is split by job; this module is its public face and re-exports their names, so import from here:

* :mod:`~rpf_fly.mocap.natnet_types`: message ids, versions, :class:`NatNetDecodeError`, decoded packet objects.
* :mod:`~rpf_fly.mocap.natnet_wire`: packet header, shared precompiled structs, bounded readers.
* :mod:`~rpf_fly.mocap.natnet_frame`: FRAMEOFDATA decode / encode.
* :mod:`~rpf_fly.mocap.natnet_modeldef`: MODELDEF decode / encode.
* :mod:`~rpf_fly.mocap.natnet_messages`: the control messages and the :func:`decode_packet` dispatch.
"""

from __future__ import annotations

from rpf_fly.mocap.natnet_frame import decode_frame, encode_frame, timecode_string
from rpf_fly.mocap.natnet_messages import (
    decode_connect,
    decode_echo_request,
    decode_echo_response,
    decode_message_string,
    decode_packet,
    decode_request,
    decode_response,
    decode_server_info,
    encode_connect,
    encode_disconnect,
    encode_discovery,
    encode_echo_request,
    encode_echo_response,
    encode_keepalive,
    encode_message_string,
    encode_request,
    encode_request_model_def,
    encode_response,
    encode_server_info,
    encode_unrecognized_request,
)
from rpf_fly.mocap.natnet_modeldef import decode_model_def, encode_model_def
from rpf_fly.mocap.natnet_types import (
    DATASET_ASSET,
    DATASET_CAMERA,
    DATASET_DEVICE,
    DATASET_FORCE_PLATE,
    DATASET_MARKER_SET,
    DATASET_RIGID_BODY,
    DATASET_SKELETON,
    FRAME_MODELS_CHANGED,
    FRAME_RECORDING,
    MAX_PAYLOAD,
    RIGID_BODY_TRACKING_VALID,
    SUPPORTED_VERSIONS,
    UNRECOGNIZED_REQUEST_ALT,
    AnalogData,
    AssetData,
    ConnectRequest,
    EchoResponse,
    FrameOfData,
    LabeledMarker,
    MarkerSetData,
    MarkerSetDescription,
    Message,
    MessageId,
    ModelDefinitions,
    NatNetDecodeError,
    OtherDescription,
    Response,
    RigidBodyData,
    RigidBodyDescription,
    RigidBodyMarker,
    ServerInfo,
    SkeletonData,
    SkeletonDescription,
    Version,
    parse_version,
)
from rpf_fly.mocap.natnet_wire import decode_header, encode_packet

__all__ = [
    "Message",
    "MessageId",
    "NatNetDecodeError",
    "Version",
    "SUPPORTED_VERSIONS",
    "DATASET_ASSET",
    "DATASET_CAMERA",
    "DATASET_DEVICE",
    "DATASET_FORCE_PLATE",
    "DATASET_MARKER_SET",
    "DATASET_RIGID_BODY",
    "DATASET_SKELETON",
    "FRAME_MODELS_CHANGED",
    "FRAME_RECORDING",
    "MAX_PAYLOAD",
    "RIGID_BODY_TRACKING_VALID",
    "UNRECOGNIZED_REQUEST_ALT",
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
