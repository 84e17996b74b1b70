"""NatNet FRAMEOFDATA: decode and encode a frame of bitstream 3.x / 4.0 / 4.1 / 4.2, and SMPTE timecode text.

4.1+ adds an int32 byte count after every section count, the asset section and the precision timestamp (two
uint32) in the suffix; where 4.1+ gives section sizes, the decoder checks that the parsed bytes match them
exactly, so a layout change in a future Motive makes frames fail loudly instead of yielding wrong poses.

Speed: frame decoding uses precompiled :class:`struct.Struct` objects, ``unpack_from`` and ``iter_unpack`` over
whole record arrays, so the per-rigid-body cost is one tuple construction.

Part of the NatNet codec; import it through :mod:`rpf_fly.mocap.natnet_protocol`.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from typing import Any

from rpf_fly.mocap import natnet_wire as _wire
from rpf_fly.mocap.natnet_types import (
    AnalogData,
    AssetData,
    FrameOfData,
    LabeledMarker,
    MarkerSetData,
    MessageId,
    NatNetDecodeError,
    RigidBodyData,
    SkeletonData,
    Version,
    _Layout,
    _layout,
)
from rpf_fly.mocap.natnet_wire import _cstr, _cstr_bytes, encode_packet

__all__ = ["decode_frame", "encode_frame", "timecode_string"]

# ---------------------------------------------------------------------------------------------------------------
# Precompiled structs
# ---------------------------------------------------------------------------------------------------------------

# Bound by assignment, not ``from ... import``: CPython compiles ``name.method(...)`` on an imported name to
# LOAD_ATTR instead of LOAD_METHOD, which would cost a bound-method object per call on the hot paths.
_I32 = _wire._I32
_I32X2 = _wire._I32X2
_VEC3 = _wire._VEC3
_RB = struct.Struct("<i8fh")  # id, x y z, qx qy qz qw, mean marker error, params: 38 bytes
_LABELED = struct.Struct("<i4fhf")  # id, x y z, size, params, residual: 26 bytes
_SUFFIX_30 = struct.Struct("<IIdQQQh")  # timecode, subframe, timestamp, 3 stamps, params: 42 bytes
_SUFFIX_41 = struct.Struct("<IIdQQQIIh")  # + precision seconds, fraction: 50 bytes

_RB_SIZE = _RB.size
_LABELED_SIZE = _LABELED.size
_rb_make = RigidBodyData._make
_lm_make = LabeledMarker._make

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


_SKIP = object()
"""``make`` of :func:`_record_section` for a section that is checked and stepped over, not decoded."""


def _record_section(
    buf: bytes, mv: memoryview, off: int, end: int, sized: bool, record: struct.Struct, make: Any, what: str
) -> tuple[list[Any], int]:
    """A section of fixed-size records (count, 4.1+ byte size, records), each decoded by ``make`` (None: the raw
    tuples; ``_SKIP``: none, an empty list). Returns the items and the offset after the section."""
    n, off, limit = _open_section(buf, off, end, sized, record.size, what)
    stop = off + record.size * n
    if make is _SKIP:
        items: list[Any] = []
    else:
        raw = record.iter_unpack(mv[off:stop])
        items = list(raw) if make is None else list(map(make, raw))
    _close_section(stop, limit, sized, what)
    return items, stop


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


def decode_frame(payload: bytes, version: Version, *, markers: bool = True) -> FrameOfData:
    """Decode a FRAMEOFDATA payload (after the header) of bitstream ``version``.

    ``markers=False`` checks the marker sections (marker sets, other markers, labeled markers) exactly as a full
    decode does but steps over their contents, leaving those lists empty: a flight needs the rigid bodies only, and
    Motive streams its markers by default (10 bodies with 3 markers each: 8 us against 35 us a frame).

    Raises :class:`NatNetDecodeError` on any malformed, truncated or inconsistent payload.
    """
    layout = _layout(version, _FRAME)
    try:
        return _decode_frame(payload, layout, markers)
    except NatNetDecodeError:
        raise
    except (struct.error, ValueError, IndexError, OverflowError, MemoryError) as exc:  # defence in depth
        raise NatNetDecodeError(f"frame: {exc}", _FRAME) from exc


def _decode_frame(buf: bytes, layout: _Layout, markers: bool = True) -> FrameOfData:
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
        if markers:
            marker_sets.append(MarkerSetData(name, list(_VEC3.iter_unpack(mv[off:stop]))))
        off = stop
    _close_section(off, limit, sized, "marker sets")

    # 2. other (unlabeled, legacy) markers
    other_markers, off = _record_section(buf, mv, off, end, sized, _VEC3, None if markers else _SKIP, "other markers")

    # 3. rigid bodies: fixed 38-byte records
    rigid_bodies, off = _record_section(buf, mv, off, end, sized, _RB, _rb_make, "rigid bodies")

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
    labeled_markers, off = _record_section(
        buf, mv, off, end, sized, _LABELED, _lm_make if markers else _SKIP, "labeled markers"
    )

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
