"""The fake firmware's log service (CRTP port 5; rpf_fly/emulator/fake_firmware.py): the TOC, blocks created,
appended, started, stopped and deleted as the firmware does them, and the periodic data packets of the started
blocks. Why apart: the log is the firmware's telemetry, with rules of its own (block sizes, periods, errors).

:class:`FirmwareLog` is a part of :class:`~rpf_fly.emulator.fake_firmware.FakeFirmware`: it reads and sets the
firmware's attributes named in its body.
"""

from __future__ import annotations

import errno
import struct
from dataclasses import dataclass
from typing import TYPE_CHECKING, cast

from .crtp import PORT_LOG, Packet
from .fake_toc import LOG_TYPE_NAMES, Toc, pack_value, value_size
from .firmware_tables import LOG_GETTERS, LOG_TOC

if TYPE_CHECKING:
    from .fake_firmware import FakeFirmware

LOG_MAX_BLOCKS = 16
LOG_MAX_PAYLOAD = 26


@dataclass
class LogBlock:
    block_id: int
    variables: list[tuple[int, str]]
    """(log TOC id, fetch C type)."""
    period_s: float = 0.0
    started: bool = False
    next_due_s: float = 0.0


class FirmwareLog:
    """The log blocks and their data packets; the TOC requests of both TOCs (log and param)."""

    _blocks: dict[int, LogBlock]
    _boot_s: float
    _toc_item_requests: int

    def _log(self, channel: int, data: bytes, now_s: float) -> list[Packet]:
        if channel == 0:
            return self._toc(PORT_LOG, LOG_TOC, data)
        if channel != 1 or not data:
            return []
        cmd = data[0]
        if cmd == 5:  # reset
            self._blocks.clear()
            return [(PORT_LOG, 1, bytes([5, 0, 0]))]
        block_id = data[1]
        if cmd in (0, 6, 1, 7):  # create / append, v1 and v2
            result = self._log_add(cmd, block_id, data[2:])
        elif cmd == 3:  # start
            block = self._blocks.get(block_id)
            if block is None:
                result = errno.ENOENT
            else:
                block.period_s = max(data[2], 1) * 0.01
                block.started = True
                block.next_due_s = now_s + block.period_s
                result = 0
        elif cmd == 4:  # stop
            block = self._blocks.get(block_id)
            result = errno.ENOENT if block is None else 0
            if block is not None:
                block.started = False
        elif cmd == 2:  # delete
            result = 0 if self._blocks.pop(block_id, None) is not None else errno.ENOENT
        else:
            result = errno.ENOEXEC
        return [(PORT_LOG, 1, bytes([cmd, block_id, result]))]

    def _log_add(self, cmd: int, block_id: int, specs: bytes) -> int:
        create = cmd in (0, 6)
        step = 3 if cmd in (6, 7) else 2
        if create and block_id in self._blocks:
            return errno.EEXIST
        if not create and block_id not in self._blocks:
            return errno.ENOENT
        if create and len(self._blocks) >= LOG_MAX_BLOCKS:
            return errno.ENOMEM
        variables = [] if create else list(self._blocks[block_id].variables)
        for i in range(0, len(specs) - step + 1, step):
            type_byte = specs[i]
            ident = struct.unpack("<H", specs[i + 1 : i + 3])[0] if step == 3 else specs[i + 1]
            fetch = LOG_TYPE_NAMES.get(type_byte & 0x0F)
            if fetch is None or ident >= len(LOG_TOC):
                return errno.ENOENT
            variables.append((ident, fetch))
        if sum(value_size(ctype) for _, ctype in variables) > LOG_MAX_PAYLOAD:
            return errno.E2BIG
        if create:
            self._blocks[block_id] = LogBlock(block_id, variables)
        else:
            self._blocks[block_id].variables = variables
        return 0

    def _log_data_due(self, now_s: float) -> list[Packet]:
        packets = []
        stamp = round((now_s - self._boot_s) * 1000.0) & 0xFFFFFF
        for block in self._blocks.values():
            if not block.started or now_s + 1e-6 < block.next_due_s:
                continue
            block.next_due_s += block.period_s
            if block.next_due_s < now_s:
                block.next_due_s = now_s + block.period_s
            payload = bytearray([block.block_id]) + stamp.to_bytes(3, "little")
            for ident, ctype in block.variables:
                payload += pack_value(ctype, LOG_GETTERS[ident](cast("FakeFirmware", self)))  # the firmware itself
            packets.append((PORT_LOG, 2, bytes(payload)))
        return packets

    def _toc(self, port: int, toc: Toc, data: bytes) -> list[Packet]:
        if not data:
            return []
        if data[0] == 3:
            return [(port, 0, toc.info_reply())]
        if data[0] == 2 and len(data) >= 3:
            self._toc_item_requests += 1
            return [(port, 0, toc.item_reply(struct.unpack("<H", data[1:3])[0]))]
        return []
