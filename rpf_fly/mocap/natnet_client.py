"""NatNet client: rigid-body poses from OptiTrack Motive (NatNet 3.x, 4.0, 4.1, 4.2), unicast or multicast.

Handshake: CONNECT to the server's command port -> SERVERINFO (bitstream version, clock frequency) ->
REQUEST_MODELDEF -> MODELDEF (rigid-body names) -> frames. MODELDEF is the only place names appear, so until it
has arrived (and for any id it does not list) bodies are keyed by ``str(id)``. MODELDEF is re-requested whenever a
frame has the models-changed bit set, and (rate-limited) when a frame carries an id the definitions do not list,
which also covers a lost models-changed frame. KEEPALIVE goes out on the command socket every ``keepalive_s``.

Transport: the command socket (bound to ``local_ip``, ephemeral port) sends all commands and receives replies and
unicast frames (Motive sends unicast frames to the address the CONNECT came from). In multicast mode a data socket
joins ``multicast_group`` on the chosen interface and binds ``data_port`` with SO_REUSEADDR, so several clients on
one host can listen. In unicast mode ``listen_data_port=True`` also binds the data port, for servers that send
unicast frames to the client's port 1511. Packets are accepted only from the server's address, so another Motive
on the same multicast group cannot inject bodies.

Why no background thread: ``receive()`` drains the sockets non-blocking, decodes every datagram and keeps the
newest frame, then (only if nothing new arrived) blocks in ``select()`` until a datagram or the timeout: no busy
spin, no locks, no GIL ping-pong with the flight loop, errors surface in the caller's thread and shutdown is just
closing sockets. The kernel's socket buffer (enlarged to 4 MiB) holds frames between calls. The cost: keep-alives
and handshake retries are sent from ``receive()``/``wait_for_server()``, so call ``receive()`` at least every
``keepalive_s`` (the flight loop runs at 20-100 Hz). Not thread-safe: one consumer.

Axes: with ``up_axis="y"`` (Motive's default streaming setting) positions (x, y, z) become (x, -z, y) and
quaternion vectors (qx, qy, qz) become (qx, -qz, qy), qw unchanged; with ``up_axis="z"`` data pass through.

Robustness: a malformed, truncated or unexpected packet is dropped and counted in :attr:`stats`; nothing raises
out of the receive path. After several consecutive undecodable frames the client re-sends CONNECT, so a bitstream
change made by another client (``Bitstream,x.y``) is picked up from the new SERVERINFO.
"""

from __future__ import annotations

import dataclasses
import ipaddress
import logging
import select
import socket
import time
from collections.abc import Mapping
from types import TracebackType

from rpf_fly.mocap.frame import NO_UNSEEN, MocapFrame, MocapStats
from rpf_fly.mocap.natnet_delivery import NewestFrame, camera_latency_s, rigid_body_poses
from rpf_fly.mocap.natnet_protocol import (
    UNRECOGNIZED_REQUEST_ALT,
    ConnectRequest,
    FrameOfData,
    MessageId,
    ModelDefinitions,
    NatNetDecodeError,
    ServerInfo,
    Version,
    decode_echo_response,
    decode_frame,
    decode_header,
    decode_message_string,
    decode_model_def,
    decode_response,
    decode_server_info,
    encode_connect,
    encode_disconnect,
    encode_keepalive,
    encode_request_model_def,
)
from rpf_fly.mocap.natnet_sockets import open_command_socket, open_data_socket, resolve_ipv4

__all__ = ["NatNetClient"]

_log = logging.getLogger(__name__)

#: Most datagrams handled per drain, so a flood cannot trap ``receive()``.
_MAX_DRAIN = 4096
#: Minimum seconds between MODELDEF requests, and between re-requests caused by unknown rigid-body ids.
_MODEL_REQUEST_GAP_S = 0.1
_UNKNOWN_ID_INTERVAL_S = 1.0
#: Consecutive undecodable frames after which CONNECT is re-sent to re-learn the bitstream version.
_BAD_FRAMES_RECONNECT = 10
#: Minimum seconds between repeated warnings of one kind.
_WARN_INTERVAL_S = 5.0
#: NatNet identification we send in CONNECT (NatNetLib's 264-byte layout); our newest decodable bitstream.
_CLIENT_NATNET_VERSION = (4, 2, 0, 0)


class NatNetClient:
    """A :class:`~rpf_fly.mocap.frame.MocapSource` for OptiTrack Motive over NatNet.

    Args:
        server: Motive host name or IPv4 address.
        multicast: receive frames on the multicast group (Motive's default) instead of unicast.
        local_ip: local interface address: the command socket binds to it and multicast is joined on it. With
            the default 0.0.0.0 the OS picks the interface (the loopback one when ``server`` is on loopback);
            on hosts with several network cards give the address of the card that faces Motive.
        multicast_group: the group Motive streams to (Motive: Streaming > Multicast Interface).
        command_port: the server's command port (1510).
        data_port: the port frames are multicast to (1511); None = the port the server announces in SERVERINFO.
        up_axis: ``"z"`` if Motive streams Z-up, ``"y"`` if it streams Y-up (Motive's default): converted to Z-up.
        keepalive_s: seconds between KEEPALIVE messages.
        listen_data_port: unicast only: also receive on ``data_port`` (for servers that send unicast frames there).
        connect_retry_s: seconds between CONNECT attempts until SERVERINFO arrives.
        model_retry_s: seconds between REQUEST_MODELDEF attempts until MODELDEF arrives.
        client_name: name sent in CONNECT.
    """

    def __init__(
        self,
        server: str,
        *,
        multicast: bool = True,
        local_ip: str = "0.0.0.0",
        multicast_group: str = "239.255.42.99",
        command_port: int = 1510,
        data_port: int | None = 1511,
        up_axis: str = "z",
        keepalive_s: float = 1.0,
        listen_data_port: bool = False,
        connect_retry_s: float = 0.5,
        model_retry_s: float = 1.0,
        client_name: str = "rpf_fly",
    ) -> None:
        axis = up_axis.lower()
        if axis not in ("y", "z"):
            raise ValueError(f"up_axis must be 'y' or 'z', not {up_axis!r}")
        if not ipaddress.IPv4Address(multicast_group).is_multicast:
            raise ValueError(f"{multicast_group} is not an IPv4 multicast address")
        self._y_up = axis == "y"
        self._multicast = multicast
        self._local_ip = local_ip
        self._group = multicast_group
        self._data_port = data_port
        self._keepalive_s = keepalive_s
        self._listen_data_port = listen_data_port
        self._connect_retry_s = connect_retry_s
        self._model_retry_s = model_retry_s
        self._client_name = client_name
        server_ip = resolve_ipv4(server)
        self._server_addr = (server_ip, command_port)
        self._server_ip = server_ip
        if local_ip in ("0.0.0.0", "") and ipaddress.IPv4Address(server_ip).is_loopback:
            self._membership_ip = "127.0.0.1"
        else:
            self._membership_ip = local_ip or "0.0.0.0"

        self._stats = MocapStats()
        self._server_info: ServerInfo | None = None
        self._version: Version | None = None
        self._models: ModelDefinitions | None = None
        self._names: dict[int, str] = {}
        self._frames = NewestFrame()
        self._last_connect = -1e9
        self._last_keepalive = -1e9
        self._last_model_request = -1e9
        self._model_request_at: float | None = None  # an unanswered REQUEST_MODELDEF was sent then
        self._model_stale = True  # the definitions need (re)requesting
        self._last_unknown_id = -1e9
        self._bad_frames = 0
        self._last_warning: dict[str, float] = {}
        self._closed = False

        self._sockets: list[socket.socket] = []
        self._data: socket.socket | None = None
        try:
            self._command = self._open_command_socket()
            if (multicast and data_port is not None) or (not multicast and listen_data_port):
                self._data = self._open_data_socket(data_port if data_port is not None else 1511)
        except OSError:
            for sock in self._sockets:
                sock.close()
            self._closed = True
            raise
        self._send_connect(time.monotonic())

    # ----------------------------------------------------------------------------------------------- sockets

    def _open_command_socket(self) -> socket.socket:
        sock = open_command_socket(self._local_ip)
        self._sockets.append(sock)
        return sock

    def _open_data_socket(self, port: int) -> socket.socket:
        sock = open_data_socket(
            port,
            multicast=self._multicast,
            group=self._group,
            membership_ip=self._membership_ip,
            local_ip=self._local_ip,
        )
        self._sockets.append(sock)
        _log.info(
            "NatNet data socket on port %d (%s)",
            port,
            f"multicast {self._group} via {self._membership_ip}" if self._multicast else "unicast",
        )
        return sock

    def _send(self, packet: bytes, what: str) -> None:
        try:
            self._command.sendto(packet, self._server_addr)
        except OSError as exc:  # network down, no route: keep trying on the next service tick
            self._warn("send", f"NatNet: sending {what} to {self._server_addr} failed: {exc}")

    def _send_connect(self, now: float) -> None:
        self._last_connect = now
        request = ConnectRequest(self._client_name, (0, 1, 0, 0), _CLIENT_NATNET_VERSION)
        self._send(encode_connect(request), "CONNECT")

    def _model_due(self) -> float | None:
        """When the next REQUEST_MODELDEF should go out, or None if none is needed.

        A request goes out when the definitions are missing or stale (models-changed bit, unknown id) and no
        request is outstanding (at most every _MODEL_REQUEST_GAP_S); an unanswered one is repeated after
        ``model_retry_s``. A change flagged while a request is outstanding is requested again after the reply,
        since that reply may predate the change.
        """
        if self._version is None or not (self._model_stale or self._models is None):
            return None
        if self._model_request_at is not None:
            return self._model_request_at + self._model_retry_s
        return self._last_model_request + _MODEL_REQUEST_GAP_S

    def _warn(self, key: str, message: str) -> None:
        """Log ``message`` as a warning at most every _WARN_INTERVAL_S per ``key`` (debug otherwise)."""
        now = time.monotonic()
        if now - self._last_warning.get(key, -1e9) >= _WARN_INTERVAL_S:
            self._last_warning[key] = now
            _log.warning(message)
        else:
            _log.debug(message)

    # ------------------------------------------------------------------------------------------- properties

    @property
    def stats(self) -> MocapStats:
        """A snapshot of the counters (see :class:`~rpf_fly.mocap.frame.MocapStats`)."""
        return dataclasses.replace(self._stats)

    @property
    def server_info(self) -> ServerInfo | None:
        """The server's SERVERINFO, once received."""
        return self._server_info

    @property
    def version(self) -> Version | None:
        """The bitstream version frames are decoded with, once known."""
        return self._version

    @property
    def model_definitions(self) -> ModelDefinitions | None:
        """The latest MODELDEF, once received."""
        return self._models

    @property
    def rigid_body_names(self) -> dict[int, str]:
        """Rigid-body id -> name from the latest MODELDEF."""
        return dict(self._names)

    @property
    def local_command_address(self) -> tuple[str, int]:
        """Address of the command socket (where unicast frames arrive)."""
        return self._command.getsockname()

    # ---------------------------------------------------------------------------------------- MocapSource

    def receive(self, timeout_s: float) -> MocapFrame | None:
        """The newest frame since the last call, waiting up to ``timeout_s`` seconds; None on timeout or closed."""
        if self._closed:
            return None
        deadline = time.monotonic() + max(0.0, timeout_s)
        while True:
            self._drain()
            now = time.monotonic()
            self._service(now)
            if self._frames.pending is not None:
                return self._deliver()
            if not self._wait(deadline, now):
                return None

    def wait_for_server(self, timeout_s: float, *, with_models: bool = True) -> bool:
        """Run the handshake until SERVERINFO (and, if ``with_models``, MODELDEF) arrived; False on timeout.

        Frames that arrive meanwhile are kept: the next ``receive()`` returns the newest.
        """
        deadline = time.monotonic() + max(0.0, timeout_s)
        while not self._closed:
            self._drain()
            now = time.monotonic()
            self._service(now)
            if self._server_info is not None and self._version is not None:
                if not with_models or self._models is not None:
                    return True
            if not self._wait(deadline, now):
                return False
        return False

    def close(self) -> None:
        """Send DISCONNECT (best effort) and close the sockets; idempotent."""
        if self._closed:
            return
        self._closed = True
        if self._server_info is not None:
            try:
                self._command.sendto(encode_disconnect(), self._server_addr)
            except OSError:
                pass
        for sock in self._sockets:
            sock.close()
        self._sockets.clear()

    def __enter__(self) -> NatNetClient:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def __del__(self) -> None:  # sockets must not leak when a caller forgets close()
        try:
            self.close()
        except Exception:  # noqa: BLE001 - interpreter shutdown
            pass

    # ------------------------------------------------------------------------------------------ event loop

    def _next_service(self, now: float) -> float:
        """When ``_service`` next has something to send."""
        if self._server_info is None:
            return self._last_connect + self._connect_retry_s
        due = self._last_keepalive + self._keepalive_s
        model_due = self._model_due()
        return due if model_due is None else min(due, model_due)

    def _wait(self, deadline: float, now: float) -> bool:
        """Block in select() until a datagram, the next service time or ``deadline``; False once past deadline."""
        remaining = deadline - now
        if remaining <= 0.0:
            return False
        wait = max(0.0, min(remaining, self._next_service(now) - now))
        if self._sockets:
            select.select(self._sockets, [], [], wait)
        else:
            time.sleep(wait)
        return True

    def _service(self, now: float) -> None:
        """Handshake retries and keep-alives."""
        if self._server_info is None:
            if now - self._last_connect >= self._connect_retry_s:
                self._send_connect(now)
            return
        model_due = self._model_due()
        if model_due is not None and now >= model_due:
            self._model_request_at = self._last_model_request = now
            self._model_stale = False
            self._send(encode_request_model_def(), "REQUEST_MODELDEF")
        if now - self._last_keepalive >= self._keepalive_s:
            self._last_keepalive = now
            self._send(encode_keepalive(), "KEEPALIVE")

    def _drain(self) -> None:
        """Read every queued datagram from every socket without blocking."""
        for sock in list(self._sockets):
            for _ in range(_MAX_DRAIN):
                try:
                    packet, source = sock.recvfrom(65536)
                except (BlockingIOError, InterruptedError):
                    break
                except (ConnectionResetError, ConnectionRefusedError):
                    continue  # Windows reports ICMP port-unreachable of an earlier send here
                except OSError as exc:
                    self._warn("recv", f"NatNet: receive failed: {exc}")
                    break
                self.handle_packet(packet, source, time.monotonic())

    def _deliver(self) -> MocapFrame:
        data, received, unseen = self._frames.take(self._names)
        frame = self._to_mocap_frame(data, received, unseen)
        self._stats.delivered += 1
        return frame

    # ------------------------------------------------------------------------------------- packet handling

    def handle_packet(self, packet: bytes, source: tuple[str, int], receive_time_s: float) -> None:
        """Process one datagram from ``source`` received at ``receive_time_s`` (``time.monotonic()``).

        Used by ``receive()``; public so tests can feed packets directly. Never raises: every packet ends up
        counted as a frame, a handled message or a drop.
        """
        stats = self._stats
        stats.packets += 1
        if source[0] != self._server_ip:
            stats.dropped += 1
            self._warn("foreign", f"NatNet: ignoring packets from {source[0]} (server is {self._server_addr[0]})")
            return
        try:
            message_id, payload = decode_header(packet)
            if message_id == MessageId.FRAMEOFDATA:
                if self._version is None:
                    stats.dropped += 1  # before SERVERINFO (or unsupported version): cannot decode yet
                    return
                try:
                    data = decode_frame(payload, self._version, markers=False)  # poses need rigid bodies only
                except NatNetDecodeError:
                    self._bad_frames += 1
                    if self._bad_frames >= _BAD_FRAMES_RECONNECT and (
                        receive_time_s - self._last_connect >= self._connect_retry_s
                    ):
                        self._warn("reconnect", "NatNet: frames keep failing to decode; asking the server again")
                        self._send_connect(receive_time_s)
                    raise
                self._bad_frames = 0
                self._on_frame(data, receive_time_s)
                return
            if message_id == MessageId.SERVERINFO:
                self._on_server_info(decode_server_info(payload))
            elif message_id == MessageId.MODELDEF:
                if self._version is None:
                    stats.dropped += 1
                    return
                self._on_models(decode_model_def(payload, self._version))
            elif message_id == MessageId.RESPONSE:
                _log.debug("NatNet response: %s", decode_response(payload))
            elif message_id == MessageId.MESSAGESTRING:
                _log.info("NatNet server message: %s", decode_message_string(payload))
            elif message_id == MessageId.ECHORESPONSE:
                _log.debug("NatNet echo: %s", decode_echo_response(payload))
            elif message_id == MessageId.DISCONNECTBYTIMEOUT:
                _log.warning("NatNet server dropped this client for inactivity; reconnecting")
                self._send_connect(receive_time_s)
            elif message_id in (MessageId.KEEPALIVE, MessageId.UNRECOGNIZED_REQUEST, UNRECOGNIZED_REQUEST_ALT):
                pass
            else:
                stats.dropped += 1  # not something a server sends to a client
                return
            stats.messages += 1
        except NatNetDecodeError as exc:
            stats.malformed += 1
            stats.dropped += 1
            self._warn("malformed", f"NatNet: dropped malformed packet: {exc}")
        except Exception:  # noqa: BLE001 - a decoder bug must not take the flight loop down
            stats.malformed += 1
            stats.dropped += 1
            _log.exception("NatNet: unexpected error decoding a packet; dropped")

    def _on_server_info(self, info: ServerInfo) -> None:
        version = info.version
        first = self._server_info is None
        self._server_info = info
        if version[0] not in (3, 4):
            self._version = None
            self._warn("version", f"NatNet: server streams unsupported bitstream {version[0]}.{version[1]} (3.x, 4.x)")
            return
        if version[0] == 4 and version[1] > 2:
            self._warn("version", f"NatNet: bitstream {version[0]}.{version[1]} is newer than 4.2; decoding as 4.2")
        if version != self._version:
            self._version = version
            self._models = None
            self._names = {}
            self._model_stale = True
            self._model_request_at = None
            self._last_model_request = -1e9
        if first:
            _log.info(
                "NatNet server %s %s, bitstream %d.%d, clock %s Hz, %s",
                info.app_name,
                ".".join(map(str, info.app_version)),
                version[0],
                version[1],
                info.clock_frequency_hz,
                "multicast" if info.multicast else "unicast",
            )
            self._check_transport(info)

    def _check_transport(self, info: ServerInfo) -> None:
        """Compare the server's announced transport with ours; open a data socket that waited for its port."""
        if info.multicast is None:
            return
        if info.multicast and not self._multicast:
            _log.warning("NatNet: Motive streams multicast but this client is unicast: frames will not arrive")
        if not info.multicast and self._multicast:
            _log.warning("NatNet: Motive streams unicast; frames will arrive on the command socket")
        if self._multicast and info.multicast:
            if info.multicast_group and info.multicast_group != self._group:
                _log.warning("NatNet: Motive announces group %s, client joined %s", info.multicast_group, self._group)
            if self._data is None:
                try:
                    self._data = self._open_data_socket(info.data_port or 1511)
                except OSError as exc:
                    _log.error("NatNet: cannot listen on data port %s: %s", info.data_port, exc)
            elif info.data_port and self._data_port is not None and info.data_port != self._data_port:
                _log.warning(
                    "NatNet: Motive announces data port %d, client listens on %d", info.data_port, self._data_port
                )

    def _on_models(self, models: ModelDefinitions) -> None:
        names: dict[int, str] = {}
        used: set[str] = set()
        for rb in models.rigid_bodies:
            name = rb.name
            if not name or name in used:
                _log.warning("NatNet: rigid body id %d has an empty or duplicate name %r; keyed by id", rb.id, name)
                name = str(rb.id)
            used.add(name)
            names[rb.id] = name
        self._models = models
        self._names = names
        self._model_request_at = None
        _log.info("NatNet rigid bodies: %s", ", ".join(f"{n} (id {i})" for i, n in sorted(names.items())) or "none")

    def _on_frame(self, data: FrameOfData, receive_time_s: float) -> None:
        stats = self._stats
        stats.frames += 1
        if data.models_changed:
            self._model_stale = True
        if self._frames.offer(data, receive_time_s):
            stats.superseded += 1  # the waiting frame, or a duplicate or reordered one older than the caller's

    def _to_mocap_frame(
        self, data: FrameOfData, received: float, unseen: Mapping[str, float] = NO_UNSEEN
    ) -> MocapFrame:
        bodies, unknown, dropouts = rigid_body_poses(data, self._names, self._y_up)
        self._stats.body_dropouts += dropouts
        if unknown and self._models is not None and received - self._last_unknown_id >= _UNKNOWN_ID_INTERVAL_S:
            self._last_unknown_id = received
            self._model_stale = True
        info = self._server_info
        latency = camera_latency_s(data, info.clock_frequency_hz if info is not None else None)
        return MocapFrame(data.frame_number, data.timestamp, received, latency, bodies, unseen)
