"""The child process that runs the ``motioncapture`` C++ library, and the records it sends to the flight's process.

Why a process of its own: libmotioncapture parses network data in C++ without bounds checks (its OptiTrack decoder
trusts every count in a packet, and segfaults on a NatNet 4.2 MODELDEF with two rigid bodies: docs/mocap.md); a
crash in a C extension would take the flight's process down with every drone's setpoints, and its
``waitForNextFrame()`` blocks without a timeout. Here a crash or a hang costs only the poses: the flight sees
mocap loss (every drone holds, then lands) and keeps commanding the drones.

``python -m rpf_fly.mocap.motioncapture_worker``: reads its settings as one JSON line on stdin (``type``,
``options``: the library's ``{str: str}`` config), then keeps reading stdin only to notice its parent go away (EOF,
also after a SIGKILL of the parent: it exits then). It ignores SIGINT: a Ctrl-C in a terminal reaches the whole
process group, and the drones must keep their poses while the flight lands them.

Records on stdout, each ``length u32, kind u8`` then ``length`` bytes, little-endian: ``STARTED`` (the library
imported; its version, UTF-8), ``READY`` (``connect()`` returned), ``FRAME`` (``seq u64, stamp f64, count u16``, then
per body ``name length u16, name UTF-8, x y z qx qy qz qw f64``: the library's float32 values, exact), ``ERROR`` (one
line, UTF-8; the child exits after it). ``stamp`` is ``time.monotonic()`` when ``waitForNextFrame()`` returned: on
Linux, macOS and Windows that clock is system-wide, so the parent compares it with its own clock. The library's
own writes to stdout (``std::cout``, ``printf``) go to stderr, off the record pipe.
"""

from __future__ import annotations

import json
import os
import signal
import struct
import sys
import threading
import time
from collections.abc import Iterator
from typing import Any

__all__ = ["STARTED", "READY", "FRAME", "ERROR", "RecordReader", "RawBody", "decode_frame", "encode_frame", "main"]

STARTED, READY, FRAME, ERROR = 1, 2, 3, 4
_RECORD = struct.Struct("<IB")
_FRAME_HEAD = struct.Struct("<QdH")
_NAME_LENGTH = struct.Struct("<H")
_POSE = struct.Struct("<7d")

RawBody = tuple[str, tuple[float, float, float, float, float, float, float]]
"""(name, (x, y, z, qx, qy, qz, qw)) as the library reported it: its axes, its float32 values."""


def encode_record(kind: int, payload: bytes = b"") -> bytes:
    return _RECORD.pack(len(payload), kind) + payload


def encode_frame(seq: int, stamp: float, bodies: list[RawBody]) -> bytes:
    """One FRAME record."""
    parts = [_FRAME_HEAD.pack(seq, stamp, len(bodies))]
    for name, pose in bodies:
        raw = name.encode("utf-8", "replace")[:65535]
        parts += (_NAME_LENGTH.pack(len(raw)), raw, _POSE.pack(*pose))
    return encode_record(FRAME, b"".join(parts))


def decode_frame(payload: bytes) -> tuple[int, float, list[RawBody]]:
    """(seq, stamp, bodies) of a FRAME record's payload; ``struct.error`` or ``ValueError`` if it is malformed."""
    seq, stamp, count = _FRAME_HEAD.unpack_from(payload, 0)
    off = _FRAME_HEAD.size
    bodies: list[RawBody] = []
    for _ in range(count):
        (n,) = _NAME_LENGTH.unpack_from(payload, off)
        off += 2
        name = payload[off : off + n].decode("utf-8", "replace")
        off += n
        bodies.append((name, _POSE.unpack_from(payload, off)))
        off += _POSE.size
    if off != len(payload):
        raise ValueError(f"frame record of {len(payload)} bytes holds {off}")
    return seq, stamp, bodies


class RecordReader:
    """Splits the child's byte stream into ``(kind, payload)`` records (a pipe read may end mid-record)."""

    def __init__(self) -> None:
        self._buffer = bytearray()

    def feed(self, data: bytes) -> Iterator[tuple[int, bytes]]:
        buffer = self._buffer
        buffer += data
        off = 0
        while len(buffer) - off >= _RECORD.size:
            length, kind = _RECORD.unpack_from(buffer, off)
            end = off + _RECORD.size + length
            if end > len(buffer):
                break
            yield kind, bytes(buffer[off + _RECORD.size : end])
            off = end
        del buffer[:off]


def _exit_when_orphaned() -> None:
    """Block on stdin until the parent closes it or dies, then leave at once (the library may be blocked)."""
    try:
        while sys.stdin.buffer.read(4096):
            pass
    except (OSError, ValueError):
        pass
    os._exit(0)


def _writer(fd: int) -> Any:
    def write(record: bytes) -> None:
        view = memoryview(record)
        while view:
            view = view[os.write(fd, view) :]

    return write


def _serve(settings: dict[str, Any], write: Any) -> int:
    """Import and connect the library, then stream its frames; the exit status once it cannot go on."""
    try:
        import motioncapture  # noqa: PLC0415 - only here, in the child: the flight's process never loads it
    except ImportError:
        from rpf_fly.mocap.motioncapture_options import MISSING_LIBRARY

        write(encode_record(ERROR, MISSING_LIBRARY.encode()))
        return 1
    write(encode_record(STARTED, str(getattr(motioncapture, "__version__", "?")).encode()))
    system = settings["type"]
    try:
        mocap = motioncapture.connect(system, dict(settings["options"]))
    except Exception as err:  # noqa: BLE001 - the library raises RuntimeError (and std:: exceptions as others)
        write(encode_record(ERROR, f"{type(err).__name__}: {err}".replace("\n", " ").encode()))
        return 1
    write(encode_record(READY))
    seq = 0
    wait, monotonic = mocap.waitForNextFrame, time.monotonic
    while True:
        try:
            wait()
            stamp = monotonic()
            bodies: list[RawBody] = []
            for name, body in mocap.rigidBodies.items():
                p, q = body.position, body.rotation
                bodies.append((name, (float(p[0]), float(p[1]), float(p[2]), q.x, q.y, q.z, q.w)))
        except Exception as err:  # noqa: BLE001 - e.g. std::bad_alloc on a huge count: MemoryError
            write(encode_record(ERROR, f"{type(err).__name__} in waitForNextFrame: {err}".replace("\n", " ").encode()))
            return 1
        seq += 1
        write(encode_frame(seq, stamp, bodies))


def main() -> None:
    """Entry point of the child (started by :class:`rpf_fly.mocap.motioncapture_source.MotioncaptureSource`)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    out = os.dup(1)
    os.dup2(2, 1)  # the library prints with std::cout/printf: keep the record pipe ours alone
    sys.stdout = sys.stderr
    write = _writer(out)
    status = 1
    try:
        settings = json.loads(sys.stdin.buffer.readline())
        threading.Thread(target=_exit_when_orphaned, name="orphan-watch", daemon=True).start()
        status = _serve(settings, write)
    except BrokenPipeError:
        status = 0  # the parent stopped reading: it is closing us
    except Exception as err:  # noqa: BLE001 - tell the parent in one line rather than die silently
        try:
            write(encode_record(ERROR, f"{type(err).__name__}: {err}".replace("\n", " ").encode()))
        except OSError:
            pass
    os._exit(status)


if __name__ == "__main__":
    main()
