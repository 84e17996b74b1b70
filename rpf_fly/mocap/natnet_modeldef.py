"""NatNet MODELDEF: decode and encode the data descriptions (marker sets, rigid bodies, skeletons, others).

4.0 adds marker names to rigid-body descriptions, 4.1 an int32 byte count after every dataset type (unknown
kinds are then skipped by size, known kinds must fill it exactly), 4.2 a rotation offset quaternion to rigid-body
descriptions.

Part of the NatNet codec; import it through :mod:`rpf_fly.mocap.natnet_protocol`.
"""

from __future__ import annotations

import struct

from rpf_fly.mocap import natnet_wire as _wire
from rpf_fly.mocap.natnet_types import (
    DATASET_CAMERA,
    DATASET_DEVICE,
    DATASET_FORCE_PLATE,
    DATASET_MARKER_SET,
    DATASET_RIGID_BODY,
    DATASET_SKELETON,
    MarkerSetDescription,
    MessageId,
    ModelDefinitions,
    NatNetDecodeError,
    OtherDescription,
    RigidBodyDescription,
    RigidBodyMarker,
    SkeletonDescription,
    Version,
    _Layout,
    _layout,
)
from rpf_fly.mocap.natnet_wire import _count, _cstr, _cstr_bytes, _read, encode_packet

__all__ = ["decode_model_def", "encode_model_def"]

# ---------------------------------------------------------------------------------------------------------------
# Precompiled structs
# ---------------------------------------------------------------------------------------------------------------

# Bound by assignment, not ``from ... import``: CPython compiles ``name.method(...)`` on an imported name to
# LOAD_ATTR instead of LOAD_METHOD, which would cost a bound-method object per call on the hot paths.
_I32 = _wire._I32
_I32X2 = _wire._I32X2
_VEC3 = _wire._VEC3
_QUAT = _wire._QUAT
_RB_DESC_HEAD = struct.Struct("<ii3f")  # id, parent id, offset

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
        qx, qy, qz, qw = _read(_QUAT, buf, off, end, "rigid body rotation offset", _MODELDEF)
        rotation = (qx, qy, qz, qw)
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
    return RigidBodyDescription(name, body_id, parent_id, (ox, oy, oz), rotation, markers), off


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
