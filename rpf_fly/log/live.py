"""The live view: a flight served as it happens over Foxglove's WebSocket protocol (foxglove-sdk, the ``live`` extra).

One source of truth: :class:`LiveView` is the flight log's *sink* (:class:`rpf_fly.log.writer.FlightLog`, ``sink``).
The log's writer thread hands it each message right after writing it to the MCAP file: the same topic, schema,
log time and bytes. Nothing is encoded a second time, a message the log's queue dropped is missing live too, and a
live client sees exactly the topics, schemas and JSON that ``rpf-fly review`` and Foxglove read from the file
(docs/log-format.md).

The flight loop never waits on a client. The loop only queues to the log (as without a live view); the writer thread
calls :meth:`LiveView.publish`, which hands the bytes to the SDK's server without blocking (a few microseconds a
message with a client subscribed). The server (Rust, its own threads) keeps a bounded outbox per client
(``message_backlog_size``, :data:`BACKLOG` messages, about 0.3-1.5 s of a flight): a client that reads slower than
the flight writes loses the oldest messages of its outbox, and the other clients, the log and the loop are not
affected. The SDK does not say how many messages it dropped; it logs "outbox for client ... full" (at most once every
30 s per process, its own throttle), and :attr:`LiveView.slow_client_reports` counts those reports.

A client that connects late still sees the scene: ``/scene`` is written once at the start of a flight, so the last
``/scene`` message is sent again (the same bytes and log time) whenever a client subscribes to it: at the next
message after the subscription and again `RESEND_AFTER_S` later (the server tells of a subscription from its
own thread, and a message sent at once can reach the server before the subscription does: a live client once
missed the scene that way, under load). A subscription that comes before the topic's first message keeps those
sends apart too: they start from that message.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Any

from rpf_fly import install_hint
from rpf_fly.log import schemas as S

DEFAULT_PORT = 8765
"""Foxglove's usual port for a WebSocket data source (``ws://localhost:8765``)."""

DEFAULT_HOST = "127.0.0.1"
"""Only this machine can connect unless asked otherwise (docs/foxglove.md, "Who can connect")."""

BACKLOG = 1024
"""Messages the server buffers per client before it drops that client's oldest (the SDK's own default): at 10 drones
and 100 Hz (about 3 500 messages a second with ``/truth``) a third of a second. A live view wants fresh data: a client
further behind than that is better served by dropping than by showing the past."""

LATCHED = ("/scene",)
"""Topics written once (or rarely): the last message is sent again when a client subscribes."""
RESEND_AFTER_S = (0.5, 2.0)
"""When a latched topic's last message is sent again after the send that follows a subscription (module doc):
seconds after it. A duplicate costs a client nothing (the same message at the same log time); a scene missed
leaves it without the obstacles for the whole flight."""

INSTALL_HINT = install_hint("live")

SDK_DROP_LOGGER = "foxglove.websocket.connected_client.send_lossy"
"""Where foxglove-sdk (0.30) reports a client's full outbox, through Python logging."""

SDK_LOGGER = "foxglove"
"""The parent of foxglove-sdk's Python loggers: its Rust core logs through Python logging (pyo3-log; its level is
cached per logger at first use, so ``FOXGLOVE_LOG_LEVEL`` or :func:`foxglove.set_log_level` are not needed), e.g.
``foxglove.websocket.connected_client: Client ... attempted to subscribe to unknown channel: 7`` at ERROR when a
client subscribes to a channel id that is gone or not yet advertised. With no handler anywhere, Python's last
resort prints such a record on stderr; :func:`quiet_sdk` gives the SDK's loggers a handler that discards, so its
records reach only the handlers on the root logger: during ``rpf-fly fly`` the flight's text log, and stderr with
``--verbose`` (rpf_fly/log/text_log.py), as cflib's do."""


def quiet_sdk() -> None:
    """Keep foxglove-sdk's log records off the console unless the application routes them (:data:`SDK_LOGGER`):
    a :class:`logging.NullHandler` on its parent logger, once. Records still propagate to the root's handlers."""
    logger = logging.getLogger(SDK_LOGGER)
    if not any(isinstance(h, logging.NullHandler) for h in logger.handlers):
        logger.addHandler(logging.NullHandler())


class LiveUnavailable(RuntimeError):
    """The live view cannot run: foxglove-sdk is missing, or the server cannot listen. One line, for the CLI."""


def load_sdk() -> Any:
    """The ``foxglove`` module (foxglove-sdk), or :class:`LiveUnavailable` naming the extra that installs it."""
    try:
        import foxglove
        import foxglove.websocket  # noqa: F401 - the server's listener protocol
    except ImportError:
        raise LiveUnavailable(f"the live view needs foxglove-sdk, which is not installed: {INSTALL_HINT}") from None
    return foxglove


class _DropCounter(logging.Handler):
    """Counts the SDK's "outbox for client ... full" reports (the SDK exposes no drop count of its own)."""

    def __init__(self, view: LiveView):
        super().__init__(logging.INFO)
        self.view = view

    def emit(self, record: logging.LogRecord) -> None:
        if "full" in record.getMessage():
            self.view.slow_client_reports += 1


class LiveView:
    """A Foxglove WebSocket server (foxglove-sdk) serving the flight log's messages as they are written.

    Started at construction, before the flight, so a port already taken fails before anything connects
    (:class:`LiveUnavailable`). Pass :meth:`publish` as the log's ``sink``; :meth:`close` stops the server (clients
    see the connection close). ``port=0`` picks a free port (:attr:`port` says which). Clients may only read: the
    server advertises no capability (no publishing, services or parameters), so nothing reaches the drones from it.

    Counters: :attr:`published` messages handed to the server, :attr:`failed` ones it refused (an exception, counted
    by the log as ``sink_failed`` too), :attr:`slow_client_reports` the SDK's reports of a client's full outbox,
    :attr:`subscriptions` clients' subscriptions so far."""

    def __init__(
        self, port: int = DEFAULT_PORT, host: str = DEFAULT_HOST, *, name: str = "rpf_fly", backlog: int = BACKLOG
    ):
        fg = load_sdk()
        self._fg = fg
        self.host = host
        self.published = 0
        self.failed = 0
        self.slow_client_reports = 0
        self.subscriptions = 0
        self._context = fg.Context()
        self._channels: dict[str, Any] = {}
        self._latched: dict[str, tuple[int, bytes]] = {}
        self._resend: dict[str, list[float]] = {}  # latched topic -> when to send it again (monotonic s)
        self._lock = threading.Lock()  # _latched and _resend: the writer thread and the SDK's threads
        self._closed = False
        quiet_sdk()
        # Before the server exists, so the SDK's first report of a full outbox finds the level set.
        self._drop_logger = logging.getLogger(SDK_DROP_LOGGER)
        self._drop_counter = _DropCounter(self)
        self._drop_logger.addHandler(self._drop_counter)
        if self._drop_logger.getEffectiveLevel() > logging.INFO:
            self._drop_logger.setLevel(logging.INFO)
        try:
            self._server = fg.start_server(
                name=name,
                host=host,
                port=port,
                context=self._context,
                server_listener=_listener(self),
                message_backlog_size=backlog,
            )
        except Exception as err:  # noqa: BLE001 - the SDK raises its own error type (address in use, bad host)
            self._drop_logger.removeHandler(self._drop_counter)
            raise LiveUnavailable(f"cannot serve the live view on {host}:{port}: {err}") from None
        self.port: int = int(self._server.port)

    @property
    def url(self) -> str:
        """What to type into Foxglove's "Open connection" (``ws://HOST:PORT``; ``localhost`` for 127.0.0.1)."""
        host = "localhost" if self.host in ("127.0.0.1", "localhost") else self.host
        return f"ws://{host}:{self.port}"

    def publish(self, topic: str, log_time: int, data: bytes) -> None:
        """The log's sink (writer thread): serve one written message, its channel opened on first use with the
        log's schema. Never blocks: the server queues the bytes for each subscribed client and returns."""
        channel = self._channels.get(topic)
        if channel is None:
            channel = self._open(topic)
        if topic in LATCHED:
            with self._lock:
                self._latched[topic] = (log_time, data)
        if self._resend:
            self._send_latched()
        try:
            channel.log(data, log_time=log_time)
        except Exception:
            self.failed += 1
            raise
        self.published += 1

    def prepare(self, topics: list[str]) -> None:
        """Open the flight's channels before its first message (call before the log's writer runs): a client
        that connects then is told of every channel at once and subscribes once, instead of each channel being
        advertised on its topic's first message while clients are subscribing to others (a live client once
        missed every message of one channel advertised mid-flight, under load)."""
        for topic in topics:
            if topic not in self._channels:
                self._open(topic)

    def _open(self, topic: str) -> Any:
        """A channel with the log's schema (name, ``jsonschema`` document) and message encoding (``json``)."""
        fg = self._fg
        name = S.topic_schema(topic)
        schema = fg.Schema(name=name, encoding=S.SCHEMA_ENCODING, data=S.schema_bytes(name))
        channel = fg.Channel(topic, schema=schema, message_encoding=S.MESSAGE_ENCODING, context=self._context)
        self._channels[topic] = channel
        return channel

    def _subscribed(self, topic: str) -> None:
        """SDK thread: a client subscribed to ``topic``; a latched topic's last message goes out at the next
        publish and again `RESEND_AFTER_S` later (on the writer thread, not from the SDK's callback)."""
        self.subscriptions += 1
        if topic in LATCHED:
            now = time.monotonic()
            with self._lock:
                times = self._resend.setdefault(topic, [])
                times.extend((now, *(now + after for after in RESEND_AFTER_S)))
                times.sort()

    def _send_latched(self) -> None:
        now = time.monotonic()
        with self._lock:
            # a topic not latched yet keeps its times: its first message may beat the subscription to the server
            due = [t for t, times in self._resend.items() if times and times[0] <= now and t in self._latched]
            for t in due:
                times = self._resend[t]
                fell_due = []
                while times and times[0] <= now:
                    fell_due.append(times.pop(0))
                # sends due together (subscribed before the topic's first message) still go out apart: one now,
                # the others as far after it as they were after the first of them
                times.extend(now + (d - fell_due[0]) for d in fell_due[1:])
                times.sort()
                if not times:
                    del self._resend[t]
            pending = [(t, self._latched[t]) for t in due]
        for topic, (log_time, data) in pending:
            self._channels[topic].log(data, log_time=log_time)
            self.published += 1

    def summary(self) -> str:
        """One line for the end of a flight."""
        line = f"live: {self.published} messages served at {self.url}, {self.subscriptions} subscriptions"
        if self.slow_client_reports:
            line += (
                f"; a client read too slowly and lost messages ({self.slow_client_reports} report"
                f"{'s' if self.slow_client_reports > 1 else ''} from the server)"
            )
        if self.failed:
            line += f"; {self.failed} messages failed"
        return line

    def close(self) -> None:
        """Stop the server (idempotent). Call after the log is closed: its last messages are served first."""
        if self._closed:
            return
        self._closed = True
        try:
            self._server.stop()
        finally:
            self._drop_logger.removeHandler(self._drop_counter)

    def __enter__(self) -> LiveView:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _listener(view: LiveView) -> Any:
    """The server's callbacks, on the SDK's threads: only subscriptions matter here (latched topics). A subclass of
    the SDK's ``ServerListener``, whose other callbacks do nothing (they need capabilities this server lacks)."""
    base: Any = load_sdk().websocket.ServerListener  # the SDK's class, loaded when the live view starts

    class Listener(base):
        def on_subscribe(self, client: Any, channel: Any) -> None:
            view._subscribed(channel.topic)  # noqa: SLF001

    return Listener()
