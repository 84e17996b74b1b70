"""Tables of contents (TOC) of the fake Crazyflie: log and parameter variables, their CRTP encoding and CRC.

The wire format is cflib's TOC protocol version 2 (CRTP protocol >= 4):
- info request ``[3]`` -> ``[3, count u16, crc u32]``;
- item request ``[2, id u16]`` -> ``[2, id u16, type, group\\0, name\\0]``.

Log type codes (`LOG_TYPES`) and parameter type codes (`PARAM_TYPES`) are the firmware's. Parameter type bytes also
carry flags: 0x10 "extended type follows" (used for persistent parameters) and 0x40 read-only.

The CRC is a CRC-32 of every item reply, so it changes exactly when a name, type or order changes: cflib's TOC
cache (one JSON file per CRC) stays valid across runs and is invalidated when this table changes.
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType

LOG_TYPES: Mapping[str, int] = MappingProxyType(
    {
        "uint8_t": 0x01,
        "uint16_t": 0x02,
        "uint32_t": 0x03,
        "int8_t": 0x04,
        "int16_t": 0x05,
        "int32_t": 0x06,
        "float": 0x07,
        "FP16": 0x08,
    }
)
"""Log variable C type -> firmware type code."""

LOG_TYPE_NAMES: Mapping[int, str] = MappingProxyType({code: name for name, code in LOG_TYPES.items()})

PARAM_TYPES: Mapping[str, int] = MappingProxyType(
    {
        "int8_t": 0x00,
        "int16_t": 0x01,
        "int32_t": 0x02,
        "int64_t": 0x03,
        "FP16": 0x05,
        "float": 0x06,
        "double": 0x07,
        "uint8_t": 0x08,
        "uint16_t": 0x09,
        "uint32_t": 0x0A,
        "uint64_t": 0x0B,
    }
)
"""Parameter C type -> firmware type code (low nibble of the type byte)."""

PARAM_FLAG_EXTENDED = 0x10
PARAM_FLAG_READ_ONLY = 0x40

STRUCT_FORMATS: Mapping[str, str] = MappingProxyType(
    {
        "uint8_t": "<B",
        "uint16_t": "<H",
        "uint32_t": "<I",
        "uint64_t": "<Q",
        "int8_t": "<b",
        "int16_t": "<h",
        "int32_t": "<i",
        "int64_t": "<q",
        "float": "<f",
        "double": "<d",
        "FP16": "<e",
    }
)
"""C type -> little-endian struct format."""

CMD_TOC_ITEM_V2 = 2
CMD_TOC_INFO_V2 = 3
EXTENDED_TYPE_PERSISTENT = 1


def pack_value(ctype: str, value: float) -> bytes:
    """Encode `value` as the C type `ctype`, saturating integers to the type's range."""
    fmt = STRUCT_FORMATS[ctype]
    if ctype in ("float", "double", "FP16"):
        return struct.pack(fmt, float(value))
    size = struct.calcsize(fmt)
    signed = fmt[1].islower()
    low, high = (-(1 << (8 * size - 1)), (1 << (8 * size - 1)) - 1) if signed else (0, (1 << (8 * size)) - 1)
    return struct.pack(fmt, min(max(int(value), low), high))


def unpack_value(ctype: str, data: bytes) -> float | int:
    """Decode one value of C type `ctype` from the start of `data`."""
    fmt = STRUCT_FORMATS[ctype]
    return struct.unpack(fmt, data[: struct.calcsize(fmt)])[0]


def value_size(ctype: str) -> int:
    """Size in bytes of C type `ctype`."""
    return struct.calcsize(STRUCT_FORMATS[ctype])


@dataclass(frozen=True)
class TocEntry:
    """One TOC variable."""

    ident: int
    group: str
    name: str
    ctype: str
    read_only: bool = False
    persistent: bool = False

    @property
    def full_name(self) -> str:
        """``group.name``."""
        return f"{self.group}.{self.name}"


class Toc:
    """An immutable TOC for one port (log or param), answering info and item requests."""

    def __init__(self, entries: Sequence[TocEntry], *, is_param: bool) -> None:
        self.entries: tuple[TocEntry, ...] = tuple(entries)
        self.by_name: Mapping[str, TocEntry] = MappingProxyType({entry.full_name: entry for entry in entries})
        self._is_param = is_param
        if len(self.by_name) != len(entries):
            raise ValueError("duplicate TOC names")
        for index, entry in enumerate(entries):
            if entry.ident != index:
                raise ValueError(f"TOC ids must be 0..n-1 in order, got {entry.ident} at {index}")
        self._items = tuple(self._item_payload(entry) for entry in entries)
        self.crc: int = zlib.crc32(b"".join(self._items)) & 0xFFFFFFFF

    def _type_byte(self, entry: TocEntry) -> int:
        if not self._is_param:
            return LOG_TYPES[entry.ctype]
        byte = PARAM_TYPES[entry.ctype]
        if entry.persistent:
            byte |= PARAM_FLAG_EXTENDED
        if entry.read_only:
            byte |= PARAM_FLAG_READ_ONLY
        return byte

    def _item_payload(self, entry: TocEntry) -> bytes:
        payload = struct.pack("<BHB", CMD_TOC_ITEM_V2, entry.ident, self._type_byte(entry))
        payload += entry.group.encode("ascii") + b"\0" + entry.name.encode("ascii") + b"\0"
        if len(payload) > 30:
            raise ValueError(f"TOC item {entry.full_name} does not fit a CRTP packet")
        return payload

    def info_reply(self) -> bytes:
        """Reply to ``[3]``: count and CRC."""
        return struct.pack("<BHI", CMD_TOC_INFO_V2, len(self.entries), self.crc)

    def item_reply(self, ident: int) -> bytes:
        """Reply to ``[2, ident]``; an out-of-range id gets the bare command byte, as the firmware does."""
        if 0 <= ident < len(self._items):
            return self._items[ident]
        return bytes([CMD_TOC_ITEM_V2])

    def __len__(self) -> int:
        return len(self.entries)


def make_toc(variables: Sequence[tuple], *, is_param: bool) -> Toc:
    """Build a `Toc` from ``(full_name, ctype[, read_only, persistent])`` tuples, numbering them in order."""
    entries = []
    for ident, spec in enumerate(variables):
        full_name, ctype = spec[0], spec[1]
        read_only = bool(spec[2]) if len(spec) > 2 else False
        persistent = bool(spec[3]) if len(spec) > 3 else False
        group, name = full_name.split(".")
        entries.append(TocEntry(ident, group, name, ctype, read_only, persistent))
    return Toc(entries, is_param=is_param)
