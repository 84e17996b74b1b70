"""A :class:`~rpf_fly.mocap.frame.MocapSource` over the ``motioncapture`` package (libmotioncapture), crash-isolated.

The library runs in a child process (:mod:`rpf_fly.mocap.motioncapture_worker`) that sends each frame over a pipe.
Why: it is C++ that parses network data without bounds checks (its OptiTrack decoder segfaults on a NatNet 4.2
MODELDEF with two rigid bodies, and on any frame whose counts lie), and ``waitForNextFrame()`` blocks without a
timeout. In the flight's process a segfault would kill every drone's setpoint stream; in a child it costs the
poses only. A child that dies (crash, kill, the library's exception) is logged once and then delivers nothing:
the flight's supervisor sees no fresh pose for any drone, which is its *mocap lost* path (every drone holds, then
lands). A child that hangs delivers nothing either, the same path. It is not restarted: a library that crashed on
the stream once is not flown on again in the same flight.

Same semantics as the NatNet client, as far as the library lets them be:

- **validity**: every backend of the library leaves an untracked body out of ``rigidBodies`` (OptiTrack: tracking
  bit clear; Vicon: occluded; Qualisys: NaN). A body seen before (or named in ``bodies``) and missing from a frame
  is reported ``valid=False`` with its last pose (the origin before any), as NatNet reports an untracked body;
  a pose with a non-finite number is invalid too.
- **up axis**: ``up_axis="y"`` converts exactly as the NatNet client does: (x, y, z) -> (x, -z, y), (qx, qy, qz)
  -> (qx, -qz, qy), qw unchanged. The library passes its system's axes through.
- **names**: the library keys bodies by name from its system's model definitions (OptiTrack: MODELDEF, read once at
  connect). It does not report ids, so a body it has no name for comes as ``""``: such bodies are left out (and
  counted in :attr:`MotioncaptureSource.unnamed_bodies`), since no drone can be flown on them.
  ``RigidBodyPose.id`` is -1.
- **frames**: the library reports neither frame numbers nor timestamps nor latency (in its Python API):
  ``frame_number`` is the child's frame counter, ``capture_time_s`` and ``receive_time_s`` are the child's
  ``time.monotonic()`` when ``waitForNextFrame()`` returned (so the pipe's delay counts in the flight's
  mocap-to-setpoint latency), ``latency_s`` is None.

Like the NatNet client it has no thread: ``receive()`` drains the pipe without blocking, keeps the newest frame and
only then waits in ``select()``. The child's stderr (the library prints there) goes to an anonymous temporary file,
whose last lines are quoted when the child fails.
"""

from __future__ import annotations

import dataclasses
import importlib.util
import ipaddress
import json
import logging
import math
import os
import select
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Mapping, Sequence
from types import TracebackType

if sys.platform != "win32":  # Windows has no fcntl
    import fcntl

from rpf_fly.mocap.frame import MocapFrame, MocapStats, RigidBodyPose
from rpf_fly.mocap.motioncapture_options import (
    MISSING_LIBRARY,
    WHEEL_TYPES,
    check_hostname,
    check_option,
    system_type,
)
from rpf_fly.mocap.motioncapture_worker import ERROR, FRAME, READY, STARTED, RecordReader, decode_frame

__all__ = ["MotioncaptureSource", "MotioncaptureUnavailable", "library_installed", "START_TIMEOUT_S"]

_log = logging.getLogger(__name__)

START_TIMEOUT_S = 20.0
"""How long the child may take to start Python and import the library (seconds; a loaded machine is slow), before
``connect()`` begins. Separate from the connect timeout, which is the system's answer only."""
_PIPE_SIZE = 1 << 20
"""The record pipe's size asked for on Linux (64 KiB by default: 0.3 s of 10-body frames at 100 Hz). Frames queue
there while the flight does not call ``receive()``; the child blocks when it is full (and then reads the newest
frame from the library when it goes on)."""
_READ_SIZE = 1 << 16
_STDERR_TAIL = 400
_ORIGIN = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))


class MotioncaptureUnavailable(ConnectionError):
    """The library's process could not start or connect: package missing, unknown type, no answer, a crash.
    A ConnectionError, as a Motive that does not answer is, so ``fly`` and ``check`` report it in one line."""


def library_installed() -> bool:
    """Whether the ``motioncapture`` package is importable, found without importing it (no C++ in this process)."""
    try:
        return importlib.util.find_spec("motioncapture") is not None
    except (ImportError, ValueError):
        return False


def _describe_exit(code: int | None) -> str:
    if code is None:
        return "its pipe closed"
    if code < 0:
        try:
            return f"killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"killed by signal {-code}"
    return f"exit status {code}"


class MotioncaptureSource:
    """Rigid bodies from a system the ``motioncapture`` package supports, read in a child process.

    Args:
        system: the library's type (``optitrack``, ``vicon``, ``qualisys``, ``vrpn``, ``mock``, ...).
        hostname: the system's host (None: the library's default; ``mock`` has none). For ``optitrack`` a host
            name is resolved here, as the library takes only IPv4 literals.
        options: the library's other options, checked by :func:`~rpf_fly.mocap.motioncapture_options.check_option`
            (values as YAML gives them or as text). For ``optitrack`` on a loopback host without ``interface_ip``,
            ``interface_ip`` becomes 127.0.0.1 (the NatNet client's rule: multicast over loopback must be joined on
            the loopback interface).
        up_axis: ``"z"`` or ``"y"`` (converted to Z-up, as the NatNet client does).
        bodies: rigid bodies expected (the mission's): reported ``valid=False`` until first seen.
        connect_timeout_s: how long ``connect()`` may take once the library is imported; the child is then killed
            and :class:`MotioncaptureUnavailable` raised (the library's OptiTrack connect waits forever otherwise).
        start_timeout_s: how long starting the child and importing the library may take.

    Raises :class:`MotioncaptureUnavailable` (one line) when the package is missing, the type is not compiled in,
    the system does not answer, or the library fails or crashes while connecting.
    """

    def __init__(
        self,
        system: str,
        hostname: str | None = None,
        options: Mapping[str, object] | None = None,
        *,
        up_axis: str = "z",
        bodies: Sequence[str] = (),
        connect_timeout_s: float = 5.0,
        start_timeout_s: float = START_TIMEOUT_S,
    ) -> None:
        axis = up_axis.lower()
        if axis not in ("y", "z"):
            raise ValueError(f"up_axis must be 'y' or 'z', not {up_axis!r}")
        spec = system_type(system)
        config = {key: check_option(system, key, value) for key, value in (options or {}).items()}
        if hostname is None and spec.hostname == "ip":
            hostname = spec.hostname_default  # the library's own default, `localhost`, is no IPv4 literal
        if hostname is not None:
            hostname = check_hostname(system, hostname)
            if spec.hostname == "ip":
                hostname = _resolve_ipv4(hostname)
            config["hostname"] = hostname
        if system == "optitrack" and "interface_ip" not in config and hostname is not None:
            if ipaddress.IPv4Address(hostname).is_loopback:
                config["interface_ip"] = "127.0.0.1"
        self.system = system
        self.config: dict[str, str] = config
        """The ``{str: str}`` the library's ``connect()`` got."""
        self._y_up = axis == "y"
        self._where = f"motioncapture {system}" + (f" at {hostname}" if hostname else "")
        self._stats = MocapStats()
        self._known: dict[str, tuple[tuple[float, float, float], tuple[float, float, float, float]]] = {
            name: _ORIGIN for name in bodies
        }
        self._pending: tuple[int, float, list] | None = None
        self._reader = RecordReader()
        self._closed = False
        self._dead = False
        self._failure: str | None = None
        self._error_record: str | None = None
        self._warned_unnamed = False
        self._unnamed = 0
        self._seen: set[int] = set()  # kinds of the non-frame records received
        self.library_version: str | None = None
        self._process: subprocess.Popen[bytes] | None = None
        self._stderr = tempfile.TemporaryFile(prefix="rpf-fly-motioncapture-")
        if not library_installed():
            self._stderr.close()
            self._closed = True
            raise MotioncaptureUnavailable(MISSING_LIBRARY)
        try:
            self._start(start_timeout_s, connect_timeout_s)
        except BaseException:
            self.close()
            raise

    # ------------------------------------------------------------------------------------------- start

    def _start(self, start_timeout_s: float, connect_timeout_s: float) -> None:
        self._process = subprocess.Popen(
            [sys.executable, "-m", "rpf_fly.mocap.motioncapture_worker"],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=self._stderr,
            bufsize=0,
        )
        assert self._process.stdin is not None and self._process.stdout is not None
        self._fd = self._process.stdout.fileno()
        if sys.platform != "win32" and hasattr(fcntl, "F_SETPIPE_SZ"):  # Linux
            try:
                fcntl.fcntl(self._fd, fcntl.F_SETPIPE_SZ, _PIPE_SIZE)
            except OSError:
                pass  # capped by /proc/sys/fs/pipe-max-size: the default size works, with less slack
        os.set_blocking(self._fd, False)
        settings = {"type": self.system, "options": self.config}
        try:
            self._process.stdin.write((json.dumps(settings) + "\n").encode())
            self._process.stdin.flush()  # stdin stays open: the child's lifeline
        except BrokenPipeError:
            pass  # the child is already gone: its end of the record pipe says why, below
        if not self._await(STARTED, start_timeout_s):
            raise MotioncaptureUnavailable(
                self._why_not("did not start")
                or f"{self._where}: the library's process did not start within {start_timeout_s:g} s"
            )
        if not self._await(READY, connect_timeout_s):
            raise MotioncaptureUnavailable(
                self._why_not("died while connecting")
                or f"{self._where}: no answer within {connect_timeout_s:g} s "
                "(is the system streaming, and this host on its network?)"
            )
        _log.info("%s: connected (libmotioncapture %s, pid %d)", self._where, self.library_version, self.pid)

    def _await(self, kind: int, timeout_s: float) -> bool:
        """Read records until one of ``kind`` has come; False on timeout or if the child ended first. Frames that
        come in the same read are kept for ``receive()``."""
        deadline = time.monotonic() + timeout_s
        while kind not in self._seen:
            self._handle(self._read())
            if kind in self._seen:
                break
            if self._dead:
                return False
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                return False
            select.select([self._fd], [], [], remaining)
        return True

    def _why_not(self, what: str) -> str | None:
        """The one line for a child that ended during start-up, or None if it is still running."""
        if not self._dead:
            return None
        error = self._error_record
        if error is not None and "Unknown motion capture type" in error:
            return (
                f"{self._where}: this motioncapture build has no {self.system!r} (the PyPI wheel of "
                f"{self.library_version or 'the library'} has {', '.join(WHEEL_TYPES)}): {error}"
            )
        if error == MISSING_LIBRARY:
            return MISSING_LIBRARY
        if error is not None:
            return f"{self._where}: the library failed: {error}"
        return f"{self._where}: the library's process {what} ({self._failure}){self._stderr_tail()}"

    # ---------------------------------------------------------------------------------------- reading

    def _read(self) -> list[tuple[int, bytes]]:
        """Every complete record the pipe holds now (non-blocking); marks the child dead at end of file."""
        records: list[tuple[int, bytes]] = []
        if self._dead or self._closed:
            return records
        while True:
            try:
                data = os.read(self._fd, _READ_SIZE)
            except BlockingIOError:
                return records
            except OSError as exc:
                data = b""
                _log.debug("%s: reading the pipe failed: %s", self._where, exc)
            if not data:
                records += self._reader.feed(b"")
                self._on_exit(records)
                return records
            records += self._reader.feed(data)

    def _on_exit(self, records: list[tuple[int, bytes]]) -> None:
        self._dead = True
        for kind, payload in records:
            if kind == ERROR:
                self._error_record = payload.decode("utf-8", "replace")
        process = self._process
        code: int | None = None
        if process is not None:
            try:  # the pipe ends when the child exits: reaping it is immediate, never a stall of the flight loop
                code = process.wait(timeout=0.2)
            except subprocess.TimeoutExpired:
                code = None
        self._failure = _describe_exit(code) + (f": {self._error_record}" if self._error_record else "")

    def _stderr_tail(self) -> str:
        try:
            self._stderr.seek(0, os.SEEK_END)
            size = self._stderr.tell()
            self._stderr.seek(max(0, size - _STDERR_TAIL))
            tail = self._stderr.read().decode("utf-8", "replace").strip().splitlines()
        except (OSError, ValueError):
            return ""
        return f"; it printed: {tail[-1][:200]}" if tail else ""

    # ------------------------------------------------------------------------------------- properties

    @property
    def pid(self) -> int:
        """The child's process id (tests kill it to play a crash)."""
        assert self._process is not None
        return self._process.pid

    @property
    def alive(self) -> bool:
        """Whether the child still delivers (not ended, not closed)."""
        return not (self._dead or self._closed)

    @property
    def failure(self) -> str | None:
        """Why the child ended (``killed by SIGSEGV``, ``exit status 1: ...``), None while it runs."""
        return self._failure

    @property
    def stats(self) -> MocapStats:
        """A snapshot of the counters: ``packets`` are records from the child, ``messages`` its non-frame records,
        ``dropped`` (= ``malformed``) records that did not decode; ``packets == frames + messages + dropped``."""
        return dataclasses.replace(self._stats)

    @property
    def unnamed_bodies(self) -> int:
        """Bodies left out of delivered frames because the library gave them no name (no model definition)."""
        return self._unnamed

    # ------------------------------------------------------------------------------------- MocapSource

    def receive(self, timeout_s: float) -> MocapFrame | None:
        """The newest frame since the last call, waiting up to ``timeout_s``; None on timeout, and (after waiting
        the timeout, so a caller's loop keeps its pace) once the child has ended or the source is closed."""
        deadline = time.monotonic() + max(0.0, timeout_s)
        while True:
            if self._closed or self._dead:
                remaining = deadline - time.monotonic()
                if remaining > 0:
                    time.sleep(remaining)
                return None
            was_alive = not self._dead
            self._handle(self._read())
            if was_alive and self._dead:
                _log.error(
                    "%s: the library's process ended (%s)%s: no poses from it any more, the flight "
                    "handles this as mocap loss",
                    self._where,
                    self._failure,
                    self._stderr_tail(),
                )
            if self._pending is not None:
                return self._deliver()
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                return None
            if not self._dead:
                select.select([self._fd], [], [], remaining)

    def _handle(self, records: list[tuple[int, bytes]]) -> None:
        stats = self._stats
        for kind, payload in records:
            stats.packets += 1
            if kind != FRAME:
                stats.messages += 1
                self._seen.add(kind)
                if kind == STARTED:
                    self.library_version = payload.decode("utf-8", "replace")
                elif kind == ERROR:
                    self._error_record = payload.decode("utf-8", "replace")
                continue
            try:
                frame = decode_frame(payload)
            except Exception as exc:  # noqa: BLE001 - a bad record must never raise into the flight loop
                stats.dropped += 1
                stats.malformed += 1
                _log.debug("%s: malformed frame record: %s", self._where, exc)
                continue
            stats.frames += 1
            if self._pending is not None:
                stats.superseded += 1
            self._pending = frame

    def _deliver(self) -> MocapFrame:
        pending = self._pending
        assert pending is not None
        self._pending = None
        seq, stamp, raw = pending
        y_up = self._y_up
        seen: dict[str, RigidBodyPose] = {}
        for name, (x, y, z, qx, qy, qz, qw) in raw:
            if not name:
                self._unnamed += 1
                if not self._warned_unnamed:
                    self._warned_unnamed = True
                    _log.warning(
                        "%s: a rigid body without a name (the library has no model definition for it) is ignored",
                        self._where,
                    )
                continue
            if y_up:
                position, quaternion = (x, -z, y), (qx, -qz, qy, qw)
            else:
                position, quaternion = (x, y, z), (qx, qy, qz, qw)
            valid = all(map(math.isfinite, (x, y, z, qx, qy, qz, qw)))
            if valid:
                self._known[name] = (position, quaternion)
            seen[name] = RigidBodyPose(name, -1, position, quaternion, valid)
        bodies: dict[str, RigidBodyPose] = {}
        dropouts = 0
        for name in sorted(self._known.keys() | seen.keys()):
            pose = seen.get(name)
            if pose is None:
                position, quaternion = self._known[name]
                pose = RigidBodyPose(name, -1, position, quaternion, False)
            dropouts += not pose.valid
            bodies[name] = pose
        now = time.monotonic()
        received = min(stamp, now)
        self._stats.delivered += 1
        self._stats.body_dropouts += dropouts
        return MocapFrame(seq, received, received, None, bodies)

    def close(self) -> None:
        """Stop the child (its lifeline closes; it is killed if the library does not let it leave) and release
        the pipes; idempotent."""
        if self._closed:
            return
        self._closed = True
        process = self._process
        if process is not None:
            for pipe in (process.stdin, process.stdout):
                try:
                    if pipe is not None:
                        pipe.close()
                except OSError:
                    pass
            try:
                process.wait(timeout=0.5)
            except subprocess.TimeoutExpired:
                process.kill()
                try:
                    process.wait(timeout=5.0)
                except subprocess.TimeoutExpired:
                    _log.error("%s: the library's process %d does not die", self._where, process.pid)
        self._stderr.close()

    def __enter__(self) -> MotioncaptureSource:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def __del__(self) -> None:  # a child must not outlive a forgotten source
        try:
            self.close()
        except Exception:  # noqa: BLE001 - interpreter shutdown
            pass


def _resolve_ipv4(host: str) -> str:
    """``host`` as an IPv4 address (libmotioncapture's OptiTrack backend takes only literals)."""
    try:
        return str(socket.getaddrinfo(host, None, socket.AF_INET, socket.SOCK_DGRAM)[0][4][0])
    except (socket.gaierror, UnicodeError) as err:
        raise MotioncaptureUnavailable(f"motioncapture: cannot resolve {host!r}: {err}") from None
