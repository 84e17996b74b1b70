"""The fake Crazyflie's memory subsystem (CRTP port 4) and the memories of a Crazyflie 2.1 without decks.

Mirrors crazyflie-firmware 2026.08 `src/modules/src/crtp_mem.c` (the protocol) and `mem.c` (the handler table):

- channel 0 (info): ``[1]`` -> ``[1, count]``; ``[2, id]`` -> ``[2, id, type, size u32, serial (8 bytes)]``
  (`createInfoResponse`: at least 8 serial bytes, zeros for memories that have no serial number);
- channel 1 (read): ``[id, addr u32, len]`` -> ``[id, addr u32, status, data]``, status 0 with ``len`` bytes or
  ``EIO`` (5) and no data when the memory's handler refuses;
- channel 2 (write): ``[id, addr u32, data...]`` -> ``[id, addr u32, status]``, status 0 or ``EIO``.

The memories, in the order the firmware registers them at boot (`system.c`: `configblockInit` -> eeprom,
`commanderInit` -> high-level commander, `memInit` -> memory tester, `deckInit` -> deck memory and deck-controller
DFU memory; each deck found would add its own, a deckless drone has none):

| id | type | size | handler (firmware source) |
|---|---|---|---|
| 0 | 0x00 EEPROM (cflib: I2C) | 0x1FFF | `eeprom.c`: the config block v1 at address 0, then erased bytes |
| 1 | 0x12 TRAJ | 4096 | `crtp_commander_high_level.c`: `trajectories_memory`, the high-level commander's RAM |
| 2 | 0x15 TESTER | 0x1000 | `mem.c`: reads give ``addr & 0xFF``, writes are checked against that pattern |
| 3 | 0x19 DECK_MEM | 5 * 0x10000000 | `deck_memory.c` with no deck: the info section is version 3, then zeros |
| 4 | 0x20 DECKCTRL_DFU | 0x18000 | `deckctrl_dfu_memory.c` with no deck controller: version 1, count 0 |

Every handler refuses an access that does not fit in its memory (``offset + length > size``), which the protocol
answers with ``EIO``: that is how the firmware refuses a trajectory upload larger than its 4096 bytes (the chunk
that crosses the end is refused whole; the chunks before it are written).

Where the firmware has no defined answer the fake picks a safe one (docs/radio.md, "Memory"): an unknown memory
id (the firmware ASSERTs, i.e. halts) gets ``[2, id]`` on the info channel, as the protocol document specifies, and
``EIO`` on read and write; a read of more than 24 bytes (the firmware would overrun its 30-byte packet) gets
``EIO``.
"""

from __future__ import annotations

import errno
import struct
from collections.abc import Callable, Sequence
from typing import Protocol

Packet = tuple[int, int, bytes]

PORT_MEM = 4
CHANNEL_INFO, CHANNEL_READ, CHANNEL_WRITE = 0, 1, 2
CMD_GET_NUMBER, CMD_GET_INFO = 1, 2
STATUS_OK = 0
MAX_READ_LENGTH = 24
"""The most a read reply carries: 30 payload bytes minus the 6-byte header (cflib asks for 24 at most)."""
SERIAL_LENGTH = 8

MEM_TYPE_EEPROM = 0x00
MEM_TYPE_TRAJ = 0x12
MEM_TYPE_TESTER = 0x15
MEM_TYPE_DECK_MEM = 0x19
MEM_TYPE_DECKCTRL_DFU = 0x20

TRAJECTORY_MEMORY_SIZE = 4096
"""`TRAJECTORY_MEMORY_SIZE` of crtp_commander_high_level.c ("4k allows us to store 31 poly4d pieces")."""
EEPROM_SIZE = 0x1FFF
"""`EEPROM_SIZE` of eeprom.h (the 24AA64's 8 KiB less one byte, as the firmware declares it)."""
MEM_TESTER_SIZE = 0x1000
DECK_MEM_SECTION_SIZE = 0x10000000
DECK_MAX_COUNT = 4
DECK_MEM_SIZE = DECK_MEM_SECTION_SIZE * (DECK_MAX_COUNT + 1)
DECK_MEM_VERSION = 3
DECKCTRL_DFU_OFFSET = 0x10000
DECKCTRL_DFU_SIZE = DECKCTRL_DFU_OFFSET + 0x8000
DECKCTRL_DFU_VERSION = 1

CONFIG_BLOCK_MAGIC = 0x43427830
CONFIG_BLOCK_VERSION = 1


class MemoryHandler(Protocol):
    """One memory of the firmware's table (`MemoryHandlerDef_t`): type, size, read and write."""

    mem_type: int
    size: int

    def read(self, address: int, length: int) -> bytes | None:
        """The bytes at `address`, or None to refuse (answered EIO)."""
        ...

    def write(self, address: int, data: bytes) -> bool:
        """Store `data` at `address`; False to refuse (answered EIO)."""
        ...


class BufferMemory:
    """A memory backed by a byte buffer, bounds-checked as the firmware's RAM and EEPROM handlers are
    (``offset + length <= size``, else refused). `buffer` is a callable so the buffer can belong to someone else
    (the trajectory memory is the high-level commander's, replaced when the drone reboots)."""

    def __init__(self, mem_type: int, buffer: Callable[[], bytearray]) -> None:
        self.mem_type = mem_type
        self._buffer = buffer
        self.size = len(buffer())

    def read(self, address: int, length: int) -> bytes | None:
        buffer = self._buffer()
        if address + length > len(buffer):
            return None
        return bytes(buffer[address : address + length])

    def write(self, address: int, data: bytes) -> bool:
        buffer = self._buffer()
        if address + len(data) > len(buffer):
            return False
        buffer[address : address + len(data)] = data
        return True


def config_block(channel: int, datarate: int, address: int) -> bytes:
    """The EEPROM config block v1 (`configblockeeprom.c`): magic, version, radio channel, radio speed (0 250K,
    1 1M, 2 2M), pitch and roll trim (0), radio address (upper byte, lower word), modulo-256 checksum."""
    body = struct.pack(
        "<IBBBffBI",
        CONFIG_BLOCK_MAGIC,
        CONFIG_BLOCK_VERSION,
        channel,
        datarate,
        0.0,
        0.0,
        (address >> 32) & 0xFF,
        address & 0xFFFFFFFF,
    )
    return body + bytes([sum(body) & 0xFF])


def eeprom_image(channel: int, datarate: int, address: int) -> bytearray:
    """A Crazyflie's EEPROM as shipped: the config block, then erased (0xFF) bytes."""
    image = bytearray(b"\xff" * EEPROM_SIZE)
    block = config_block(channel, datarate, address)
    image[: len(block)] = block
    return image


class MemoryTester:
    """`mem.c`'s memory tester: a read returns ``address & 0xFF`` for each byte; a write is accepted and checked
    against the same pattern, counting the writes with a wrong byte in `write_errors` (log ``memTst.errCntW``,
    reset by writing the parameter ``memTst.resetW``)."""

    mem_type = MEM_TYPE_TESTER
    size = MEM_TESTER_SIZE

    def __init__(self, on_reset: Callable[[], None] | None = None) -> None:
        """`on_reset` is called when a write consumes a reset request (the firmware clears ``memTst.resetW``)."""
        self.write_errors = 0
        self.reset_requested = False
        self._on_reset = on_reset

    def read(self, address: int, length: int) -> bytes | None:
        return bytes((address + i) & 0xFF for i in range(length))

    def write(self, address: int, data: bytes) -> bool:
        if self.reset_requested:
            self.reset_requested = False
            self.write_errors = 0
            if self._on_reset is not None:
                self._on_reset()
        if any(byte != (address + i) & 0xFF for i, byte in enumerate(data)):
            self.write_errors += 1
        return True


class DeckMemory:
    """`deck_memory.c` on a drone without decks: section 0 (info) reads the format version, then zeros (no deck
    infos); the deck sections are refused; writes to section 0 (the command area) are accepted and do nothing."""

    mem_type = MEM_TYPE_DECK_MEM
    size = DECK_MEM_SIZE

    def read(self, address: int, length: int) -> bytes | None:
        if address // DECK_MEM_SECTION_SIZE != 0:
            return None
        return bytes(DECK_MEM_VERSION if address + i == 0 else 0 for i in range(length))

    def write(self, address: int, data: bytes) -> bool:
        return address // DECK_MEM_SECTION_SIZE == 0


class DeckCtrlDfuMemory:
    """`deckctrl_dfu_memory.c` without a deck controller: byte 0 the version (1), byte 1 the number of deck
    controllers (0), byte 2 the status (``STATUS_CAN_ENABLE_DFU``, 2: at most one controller, none in DFU mode),
    zeros up to 0x10000; the DFU window above needs the controller's I2C and is refused. A command byte (address 3)
    with both mode bits is refused; anything else in the first window is accepted (a real drone would then ask its
    nRF to power-cycle a deck it does not have)."""

    mem_type = MEM_TYPE_DECKCTRL_DFU
    size = DECKCTRL_DFU_SIZE

    def read(self, address: int, length: int) -> bytes | None:
        if address >= DECKCTRL_DFU_OFFSET:
            return None
        fixed = {0: DECKCTRL_DFU_VERSION, 1: 0, 2: 0x02}
        return bytes(fixed.get(address + i, 0) for i in range(length))

    def write(self, address: int, data: bytes) -> bool:
        if address >= DECKCTRL_DFU_OFFSET:
            return False
        command = 3 - address
        return not (0 <= command < len(data) and (data[command] & 0x03) == 0x03)


class MemorySubsystem:
    """The CRTP memory port in front of a table of memories (see the module docstring for the protocol)."""

    def __init__(self, memories: Sequence[MemoryHandler]) -> None:
        self.memories: tuple[MemoryHandler, ...] = tuple(memories)

    def handle(self, channel: int, data: bytes) -> list[Packet]:
        """Answer one port-4 packet (malformed ones raise struct.error/IndexError for the caller to log)."""
        if channel == CHANNEL_INFO:
            return self._info(data)
        if channel == CHANNEL_READ:
            mem_id, address, length = struct.unpack("<BIB", data[:6])
            head = data[:5]
            memory = self._memory(mem_id)
            content = memory.read(address, length) if memory is not None and length <= MAX_READ_LENGTH else None
            if content is None:
                return [(PORT_MEM, CHANNEL_READ, head + bytes([errno.EIO]))]
            return [(PORT_MEM, CHANNEL_READ, head + bytes([STATUS_OK]) + content)]
        if channel == CHANNEL_WRITE:
            mem_id, address = struct.unpack("<BI", data[:5])
            memory = self._memory(mem_id)
            ok = memory is not None and memory.write(address, bytes(data[5:]))
            return [(PORT_MEM, CHANNEL_WRITE, data[:5] + bytes([STATUS_OK if ok else errno.EIO]))]
        return []

    def _memory(self, mem_id: int) -> MemoryHandler | None:
        return self.memories[mem_id] if mem_id < len(self.memories) else None

    def _info(self, data: bytes) -> list[Packet]:
        if not data:
            return []
        if data[0] == CMD_GET_NUMBER:
            return [(PORT_MEM, CHANNEL_INFO, bytes([CMD_GET_NUMBER, len(self.memories)]))]
        if data[0] == CMD_GET_INFO:
            mem_id = data[1]
            memory = self._memory(mem_id)
            if memory is None:
                return [(PORT_MEM, CHANNEL_INFO, bytes([CMD_GET_INFO, mem_id]))]
            body = struct.pack("<BBBI", CMD_GET_INFO, mem_id, memory.mem_type, memory.size)
            return [(PORT_MEM, CHANNEL_INFO, body + bytes(SERIAL_LENGTH))]
        return []
