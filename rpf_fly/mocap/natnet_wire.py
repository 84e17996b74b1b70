"""NatNet wire primitives: the 4-byte packet header, the shared precompiled structs, bounded readers, C strings.

Every reader here is bounds-checked: a read that does not fit raises :class:`NatNetDecodeError` carrying the
message id and the byte offset into the payload. Everything is little-endian.

Part of the NatNet codec; import it through :mod:`rpf_fly.mocap.natnet_protocol`.
"""

from __future__ import annotations

import struct

from rpf_fly.mocap.natnet_types import MAX_PAYLOAD, NatNetDecodeError

__all__ = ["decode_header", "encode_packet"]

# ---------------------------------------------------------------------------------------------------------------
# Precompiled structs (shared by the frame, model-definition and message codecs)
# ---------------------------------------------------------------------------------------------------------------

_HEADER = struct.Struct("<HH")
_I32 = struct.Struct("<i")
_I32X2 = struct.Struct("<ii")
_VEC3 = struct.Struct("<3f")
_QUAT = struct.Struct("<4f")

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
# String writer
# ---------------------------------------------------------------------------------------------------------------


def _cstr_bytes(text: str) -> bytes:
    raw = text.encode("utf-8")
    if b"\0" in raw:
        raise ValueError(f"name {text!r} contains a NUL character")
    return raw + b"\0"
