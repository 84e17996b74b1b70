"""An emulator of Motive's NatNet server, for tests, ``rpf-fly mocap emulate`` demos and ``fly --dry-run``.

It speaks bitstream 3.0, 4.0, 4.1 or 4.2 and answers like Motive: CONNECT and DISCOVERY with SERVERINFO,
REQUEST_MODELDEF with MODELDEF, REQUEST with RESPONSE (``FrameRate``, ``AnalogSamplesPerMocapFrame``,
``Bitstream,x.y``; anything else gets UNRECOGNIZED_REQUEST, as in the real capture), ECHOREQUEST with
ECHORESPONSE, REQUEST_FRAMEOFDATA with the current frame; KEEPALIVE and DISCONNECT are accepted.

Frames are built from a callable ``poses() -> {name: (position_xyz, quaternion_xyzw, valid)}`` given in the Z-up
world frame (metres), converted to the server's ``up_axis`` (Motive's default is Y-up: (x, y, z) -> (x, z, -y),
(qx, qy, qz) -> (qx, qz, -qy)). Each body also gets ``markers_per_body`` markers (marker set + labeled markers)
so every frame section is exercised. ``set_bodies()`` changes the streamed set and raises the models-changed bit
on the next ``models_changed_frames`` frames.

Transport: unicast frames go FROM the data port to every address a CONNECT came from (NatNetLib 4.1 drops unicast
frames that do not come from the server's data port); multicast frames go to ``(multicast_group, data_port)``
with IP_MULTICAST_IF set to ``local_ip`` (use 127.0.0.1 over loopback). Ports default to 0 (ephemeral, so tests
run in parallel); the bound ports are :attr:`command_port` and :attr:`data_port`.

One background thread serves commands and paces frames at ``rate_hz`` (0 = only when :meth:`send_frame` is
called, for deterministic tests); it blocks in ``select()`` between events.
"""

from __future__ import annotations

import logging
import math
import select
import socket
import threading
import time
from collections.abc import Callable, Sequence
from types import TracebackType

from rpf_fly.emulator.host_lag import LagMeter
from rpf_fly.mocap.frame import PoseCallable
from rpf_fly.mocap.natnet_protocol import (
    FRAME_MODELS_CHANGED,
    SUPPORTED_VERSIONS,
    FrameOfData,
    LabeledMarker,
    MarkerSetData,
    MarkerSetDescription,
    MessageId,
    ModelDefinitions,
    NatNetDecodeError,
    RigidBodyData,
    RigidBodyDescription,
    RigidBodyMarker,
    ServerInfo,
    Version,
    decode_echo_request,
    decode_header,
    decode_request,
    encode_echo_response,
    encode_frame,
    encode_model_def,
    encode_packet,
    encode_response,
    encode_server_info,
    parse_version,
)

__all__ = ["NatNetServer"]

_log = logging.getLogger(__name__)

#: Marker layout around a body (metres): a flat asymmetric pattern, as on a Crazyflie marker deck.
_MARKER_OFFSETS = ((0.03, 0.0, 0.01), (-0.02, 0.025, 0.01), (-0.02, -0.025, 0.01), (0.0, 0.0, 0.03))


def _to_server_axes(
    position: Sequence[float], quaternion: Sequence[float], y_up: bool
) -> tuple[tuple[float, float, float], tuple[float, float, float, float]]:
    """Z-up world pose -> the axes the server streams."""
    x, y, z = (float(v) for v in position)
    qx, qy, qz, qw = (float(v) for v in quaternion)
    if y_up:
        return (x, z, -y), (qx, qz, -qy, qw)
    return (x, y, z), (qx, qy, qz, qw)


class NatNetServer:
    """Motive's NatNet server, emulated. Use as a context manager (starts on enter, closes on exit).

    Args:
        poses: returns the current poses (Z-up world frame), called once per frame from the server thread.
        version: bitstream version ("3.0", "4.0", "4.1", "4.2" or a tuple).
        multicast: multicast frames (Motive's default) instead of unicast to connected clients.
        local_ip: interface to bind and to multicast from.
        multicast_group: multicast group for frames.
        command_port: command port to bind (0 = ephemeral).
        data_port: data port to bind and to multicast to (0 = ephemeral).
        rate_hz: frames per second streamed by the server thread; 0 streams only on :meth:`send_frame`.
        up_axis: "y" (Motive's default) or "z": the axes frames are streamed in.
        bodies: names of the streamed rigid bodies (ids 1, 2, ... in this order); None = the keys of the first
            ``poses()`` result.
        app_name, app_version: announced in SERVERINFO.
        clock_frequency_hz: HighResClockFrequency of the frame hardware stamps.
        camera_latency_s: camera mid-exposure to data-received latency encoded in every frame.
        extra_latency_s: called for every frame, seconds added to that latency (the poses served are that much
            older: a delayed mocap pipeline, which Motive's own timestamps show).
        markers_per_body: markers streamed per body (0-4).
        models_changed_frames: how many frames carry the models-changed bit after :meth:`set_bodies`.
    """

    def __init__(
        self,
        poses: PoseCallable,
        *,
        version: str | Sequence[int] = "4.1",
        multicast: bool = False,
        local_ip: str = "127.0.0.1",
        multicast_group: str = "239.255.42.99",
        command_port: int = 0,
        data_port: int = 0,
        rate_hz: float = 120.0,
        up_axis: str = "y",
        bodies: Sequence[str] | None = None,
        app_name: str = "Motive",
        app_version: Sequence[int] = (3, 1, 0, 0),
        clock_frequency_hz: int = 10_000_000,
        camera_latency_s: float = 0.004,
        extra_latency_s: Callable[[], float] | None = None,
        markers_per_body: int = 3,
        models_changed_frames: int = 3,
    ) -> None:
        self._version = self._checked_version(version)
        axis = up_axis.lower()
        if axis not in ("y", "z"):
            raise ValueError(f"up_axis must be 'y' or 'z', not {up_axis!r}")
        if not 0 <= markers_per_body <= len(_MARKER_OFFSETS):
            raise ValueError(f"markers_per_body must be 0..{len(_MARKER_OFFSETS)}")
        self._poses = poses
        self._multicast = multicast
        self._local_ip = local_ip
        self._group = multicast_group
        self._rate_hz = float(rate_hz)
        self._y_up = axis == "y"
        self._app_name = app_name
        major, minor, build, revision = app_version
        self._app_version = (major, minor, build, revision)
        self._clock_hz = int(clock_frequency_hz)
        self._camera_latency_s = float(camera_latency_s)
        self._extra_latency_s = extra_latency_s
        self._markers_per_body = markers_per_body
        self._models_changed_frames = models_changed_frames

        self._lock = threading.Lock()
        self._ids: dict[str, int] = {}
        self._bodies: list[str] | None = None
        if bodies is not None:
            self._assign(list(bodies))
        self._models_changed_left = 0
        self._frame_number = 0
        self._clients: list[tuple[str, int]] = []
        self.lag = LagMeter()
        """How late the paced frames go out (`rpf_fly.emulator.host_lag`)."""
        self._request_counts: dict[int, int] = {}
        self._frames_sent = 0
        self._t0 = time.monotonic()

        self._command = socket.socket(socket.AF_INET, socket.SOCK_DGRAM, socket.IPPROTO_UDP)
        self._data = socket.socket(socket.AF_INET, socket.SOCK_DGRAM, socket.IPPROTO_UDP)
        self._wake_r, self._wake_w = socket.socketpair()
        try:
            self._command.bind((local_ip, command_port))
            self._data.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            self._data.bind((local_ip, data_port))
            if multicast:
                self._data.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 1)
                self._data.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP, 1)
                if local_ip not in ("0.0.0.0", ""):
                    self._data.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton(local_ip))
            self._command.setblocking(False)
        except OSError:
            self._close_sockets()
            raise
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    @staticmethod
    def _checked_version(version: str | Sequence[int]) -> Version:
        parsed = parse_version(version)
        if parsed not in SUPPORTED_VERSIONS:
            raise ValueError(f"NatNet version {parsed[0]}.{parsed[1]} not emulated; choose one of {SUPPORTED_VERSIONS}")
        return parsed

    # --------------------------------------------------------------------------------------- public API

    @property
    def command_port(self) -> int:
        """The bound command port."""
        return self._command.getsockname()[1]

    @property
    def data_port(self) -> int:
        """The bound data port (frames are sent from it, and multicast to it)."""
        return self._data.getsockname()[1]

    @property
    def version(self) -> Version:
        """The bitstream version being streamed."""
        return self._version

    @property
    def frame_number(self) -> int:
        """Number of the last frame built (0 before the first)."""
        return self._frame_number

    @property
    def frames_sent(self) -> int:
        return self._frames_sent

    @property
    def clients(self) -> list[tuple[str, int]]:
        """Addresses that sent CONNECT (unicast destinations)."""
        with self._lock:
            return list(self._clients)

    def request_count(self, message_id: int) -> int:
        """How many messages of ``message_id`` the server received."""
        with self._lock:
            return self._request_counts.get(int(message_id), 0)

    @property
    def body_ids(self) -> dict[str, int]:
        """Streamed body name -> rigid-body id."""
        with self._lock:
            self._ensure_bodies()
            return {name: self._ids[name] for name in self._bodies or ()}

    def set_bodies(self, names: Sequence[str]) -> None:
        """Stream exactly ``names`` from now on (known names keep their ids) and flag the model change."""
        with self._lock:
            self._assign(list(names))
            self._models_changed_left = self._models_changed_frames

    def start(self) -> NatNetServer:
        """Start the server thread (idempotent)."""
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="natnet-emulator", daemon=True)
            self._thread.start()
        return self

    def close(self) -> None:
        """Stop the thread and close the sockets (idempotent)."""
        self._stop.set()
        try:
            self._wake_w.send(b"x")
        except OSError:
            pass
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=5.0)
        self._close_sockets()

    def __enter__(self) -> NatNetServer:
        return self.start()

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def send_frame(self) -> int:
        """Build and send one frame now (to the group, or to every connected client); returns its number."""
        with self._lock:
            packet = self._frame_packet()
            destinations = [(self._group, self.data_port)] if self._multicast else list(self._clients)
            number = self._frame_number
            self._frames_sent += 1
        for address in destinations:
            try:
                self._data.sendto(packet, address)
            except OSError as exc:
                _log.warning("NatNet emulator: sending a frame to %s failed: %s", address, exc)
        return number

    # ---------------------------------------------------------------------------------------- internals

    def _close_sockets(self) -> None:
        for sock in (self._command, self._data, self._wake_r, self._wake_w):
            try:
                sock.close()
            except OSError:
                pass

    def _assign(self, names: list[str]) -> None:
        """Set the body list, giving new names the next free id."""
        for name in names:
            if name not in self._ids:
                self._ids[name] = max(self._ids.values(), default=0) + 1
        self._bodies = names

    def _ensure_bodies(self) -> None:
        if self._bodies is None:
            self._assign(sorted(self._poses()))

    def _ticks(self, t: float) -> int:
        return int(t * self._clock_hz)

    def _frame_packet(self) -> bytes:
        """Encode the next frame (call with the lock held)."""
        self._ensure_bodies()
        try:
            samples = self._poses()
        except Exception:  # noqa: BLE001 - a faulty pose source must not kill the server thread
            _log.exception("NatNet emulator: poses() failed; streaming the bodies as not tracked")
            samples = {}
        self._frame_number += 1
        rigid_bodies: list[RigidBodyData] = []
        marker_sets: list[MarkerSetData] = []
        labeled: list[LabeledMarker] = []
        all_markers: list[tuple[float, float, float]] = []
        for name in self._bodies or ():
            body_id = self._ids[name]
            sample = samples.get(name)
            position: Sequence[float]
            quaternion: Sequence[float]
            if sample is None:
                position, quaternion, valid = (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0), False
            else:
                position, quaternion, valid = sample
            (x, y, z), (qx, qy, qz, qw) = _to_server_axes(position, quaternion, self._y_up)
            if not all(map(math.isfinite, (x, y, z, qx, qy, qz, qw))):
                (x, y, z), (qx, qy, qz, qw), valid = (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0), False
            rigid_bodies.append(RigidBodyData(body_id, x, y, z, qx, qy, qz, qw, 0.0002 if valid else 0.0, int(valid)))
            markers = []
            for k in range(self._markers_per_body):
                (mx, my, mz), _ = _to_server_axes(
                    [p + o for p, o in zip(position, _MARKER_OFFSETS[k])], (0.0, 0.0, 0.0, 1.0), self._y_up
                )
                markers.append((mx, my, mz))
                labeled.append(LabeledMarker((body_id << 16) | (k + 1), mx, my, mz, 0.014, 0x04, 0.0002))
            if self._markers_per_body:
                marker_sets.append(MarkerSetData(name, markers))
                all_markers.extend(markers)
        if self._markers_per_body:
            marker_sets.append(MarkerSetData("all", all_markers))
        params = 0
        if self._models_changed_left > 0:
            self._models_changed_left -= 1
            params |= FRAME_MODELS_CHANGED
        now = time.monotonic()
        received = self._ticks(now)
        wall = time.time()
        frame = FrameOfData(
            frame_number=self._frame_number,
            marker_sets=marker_sets,
            rigid_bodies=rigid_bodies,
            labeled_markers=labeled,
            timestamp=now - self._t0,
            camera_mid_exposure=received
            - self._ticks(
                self._camera_latency_s + (self._extra_latency_s() if self._extra_latency_s is not None else 0.0)
            ),
            camera_data_received=received,
            transmit=received + self._ticks(0.0003),
            precision_seconds=int(wall),
            precision_fraction=int((wall % 1.0) * 4294967296.0) & 0xFFFFFFFF,
            params=params,
        )
        return encode_frame(frame, self._version)

    def _model_packet(self) -> bytes:
        """Encode MODELDEF for the current bodies (call with the lock held)."""
        self._ensure_bodies()
        names = list(self._bodies or ())
        offsets = _MARKER_OFFSETS[: self._markers_per_body]
        rigid_bodies = tuple(
            RigidBodyDescription(
                name,
                self._ids[name],
                -1,
                markers=tuple(RigidBodyMarker(o, 0, f"Marker{k + 1}") for k, o in enumerate(offsets)),
            )
            for name in names
        )
        marker_sets: tuple[MarkerSetDescription, ...] = ()
        if self._markers_per_body:
            marker_sets = tuple(
                MarkerSetDescription(name, tuple(f"Marker{k + 1}" for k in range(len(offsets)))) for name in names
            )
            marker_sets += (
                MarkerSetDescription("all", tuple(f"{n}_{k + 1}" for n in names for k in range(len(offsets)))),
            )
        return encode_model_def(ModelDefinitions(marker_sets, rigid_bodies), self._version)

    def _server_info_packet(self) -> bytes:
        info = ServerInfo(
            self._app_name,
            self._app_version,
            (self._version[0], self._version[1], 0, 0),
            self._clock_hz,
            self.data_port,
            self._multicast,
            self._group,
        )
        return encode_server_info(info)

    def _response(self, command: str) -> bytes:
        """Answer a REQUEST like Motive does for the commands a client typically sends."""
        name, _, argument = command.partition(",")
        key = name.strip().lower()
        if key == "framerate":
            return encode_response(float(self._rate_hz))
        if key == "analogsamplespermocapframe":
            return encode_response(0)
        if key == "bitstream":
            try:
                self._version = self._checked_version(argument)
            except ValueError:
                return encode_response(-1)
            _log.info("NatNet emulator: bitstream switched to %d.%d", *self._version)
            return encode_response(0)
        return encode_packet(MessageId.UNRECOGNIZED_REQUEST)

    def _handle(self, packet: bytes, source: tuple[str, int]) -> None:
        """Answer one command datagram."""
        try:
            self._answer(packet, source)
        except ValueError as exc:  # a reply too large to encode: log it, keep serving
            _log.error("NatNet emulator: cannot answer %s: %s", source, exc)

    def _answer(self, packet: bytes, source: tuple[str, int]) -> None:
        try:
            message_id, payload = decode_header(packet)
        except NatNetDecodeError as exc:
            _log.debug("NatNet emulator: bad datagram from %s: %s", source, exc)
            return
        with self._lock:
            self._request_counts[message_id] = self._request_counts.get(message_id, 0) + 1
            if message_id == MessageId.CONNECT:
                if source not in self._clients:
                    self._clients.append(source)
                reply: bytes | None = self._server_info_packet()
            elif message_id == MessageId.DISCOVERY:
                reply = self._server_info_packet()
            elif message_id == MessageId.REQUEST_MODELDEF:
                reply = self._model_packet()
            elif message_id == MessageId.REQUEST_FRAMEOFDATA:
                reply = self._frame_packet()
            elif message_id == MessageId.REQUEST:
                try:
                    reply = self._response(decode_request(payload))
                except NatNetDecodeError:
                    reply = encode_packet(MessageId.UNRECOGNIZED_REQUEST)
            elif message_id == MessageId.ECHOREQUEST:
                try:
                    reply = encode_echo_response(decode_echo_request(payload), self._ticks(time.monotonic()))
                except NatNetDecodeError:
                    reply = None
            elif message_id == MessageId.DISCONNECT:
                if source in self._clients:
                    self._clients.remove(source)
                reply = None
            else:  # KEEPALIVE and anything else: nothing to say
                reply = None
        if reply is not None:
            try:
                self._command.sendto(reply, source)
            except OSError as exc:
                _log.warning("NatNet emulator: reply to %s failed: %s", source, exc)

    def _run(self) -> None:
        period = 1.0 / self._rate_hz if self._rate_hz > 0 else None
        next_frame = time.monotonic()
        readers = [self._command, self._wake_r]
        while not self._stop.is_set():
            now = time.monotonic()
            timeout = None if period is None else max(0.0, next_frame - now)
            try:
                ready, _, _ = select.select(readers, [], [], timeout)
            except (OSError, ValueError):  # sockets closed under us
                return
            if self._stop.is_set():
                return
            if self._command in ready:
                for _ in range(1024):
                    try:
                        packet, source = self._command.recvfrom(65536)
                    except (BlockingIOError, InterruptedError):
                        break
                    except (ConnectionResetError, ConnectionRefusedError):
                        continue
                    except OSError:
                        return
                    self._handle(packet, source)
            if period is not None and time.monotonic() >= next_frame:
                sent_at = time.monotonic()
                self.lag.record(sent_at - next_frame, sent_at, period)
                try:
                    self.send_frame()
                except ValueError as exc:  # e.g. too many bodies for one 64 KiB datagram: keep serving commands
                    _log.error("NatNet emulator: cannot encode a frame: %s", exc)
                next_frame += period
                if time.monotonic() - next_frame > period:  # fell behind: do not burst to catch up
                    next_frame = time.monotonic() + period
