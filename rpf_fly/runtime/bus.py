"""A process's side of a flight on Zenoh: publishing the log's messages, the liveliness token, the coordinator's
signed commands (docs/distributed.md).

Publishing never blocks the caller: samples go out with congestion control ``DROP`` (a slow or dead logger loses
messages, never a worker's tick) from the log writer's thread, where :class:`~rpf_fly.log.writer.FlightLog` calls
:meth:`FlightBus.out`. A malformed or refused command is dropped, counted and logged as a warning; nothing a
subscriber callback receives can raise into Zenoh or the flight.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from typing import Any

from rpf_fly.runtime.auth import Command, CommandVerifier, sign
from rpf_fly.runtime.keys import STAMPS, FlightKeys, topic_suffix

logger = logging.getLogger(__name__)


class FlightBus:
    """One process's publishers and subscribers on a flight's keys. ``name``: the publisher's name (``dongle-0``,
    ``coordinator``): the key of its ``/tf``."""

    def __init__(self, session: Any, flight: str, name: str):
        self.session = session
        self.keys = FlightKeys(flight)
        self.name = name
        self._publishers: dict[str, Any] = {}
        self._routes: dict[str, Any] = {}
        """Log topic -> its publisher (None: the topic is not published), so a message costs one lookup."""
        self._lock = threading.Lock()
        self._handles: list[Any] = []
        self.published = 0
        self.refused = 0
        self.malformed = 0
        self._seq = 0

    # ------------------------------------------------------------------------------------------ publishing

    def _publisher(self, key: str) -> Any:
        publisher = self._publishers.get(key)
        if publisher is None:
            import zenoh

            with self._lock:
                publisher = self._publishers.get(key)
                if publisher is None:
                    publisher = self.session.declare_publisher(key, congestion_control=zenoh.CongestionControl.DROP)
                    self._publishers[key] = publisher
        return publisher

    def out(self, topic: str, log_time: int, t_ns: int, data: bytes) -> None:
        """A :class:`~rpf_fly.log.writer.FlightLog` ``out``: publish one log message under its key (the log writer's
        thread, every message of the flight: the topic's publisher is looked up once)."""
        try:
            publisher = self._routes.get(topic, self)
            if publisher is self:  # a topic's first message
                suffix = topic_suffix(topic, self.name)
                publisher = self._routes[topic] = None if suffix is None else self._publisher(self.keys.key(suffix))
            if publisher is None:
                return
            publisher.put(data, attachment=STAMPS.pack(log_time, t_ns))
            self.published += 1
        except Exception as err:  # noqa: BLE001 - a closed session at the end: the message is lost, not the flight
            logger.debug("zenoh: %s not published: %s", topic, err)

    def put_json(self, suffix: str, data: bytes) -> None:
        try:
            self.session.put(self.keys.key(suffix), data)
        except Exception as err:  # noqa: BLE001
            logger.warning("zenoh: %s not published: %s", suffix, err)

    def token(self, worker: str) -> Any:
        """Declare this process's liveliness token ``alive/<worker>``."""
        handle = self.session.liveliness().declare_token(self.keys.alive(worker))
        self._handles.append(handle)
        return handle

    # ------------------------------------------------------------------------------------------ commands

    def command(self, secret: str, command: str, reason: str = "", grounded: tuple[str, ...] = ()) -> None:
        """The coordinator: publish one signed command (a ``go``'s ``grounded`` drones signed with it)."""
        self._seq += 1
        payload, signature = sign(secret, self.keys.flight, command, self._seq, reason, grounded)
        self.session.put(self.keys.command, payload, attachment=signature)

    def on_commands(self, secret: str, obey: Callable[[Command], None], refuse: Callable[[str], None]) -> None:
        """A worker: ``obey`` each command of its coordinator; ``refuse(why)`` each other one (a warning)."""
        verifier = CommandVerifier(secret, self.keys.flight)

        def received(sample: Any) -> None:
            try:
                attachment = sample.attachment.to_bytes() if sample.attachment is not None else None
                command, why = verifier.verify(sample.payload.to_bytes(), attachment)
            except Exception as err:  # noqa: BLE001 - a malformed sample is dropped and counted
                command, why = None, f"malformed command ({err})"
            try:
                if command is None:
                    self.refused += 1
                    refuse(why)
                else:
                    obey(command)
            except Exception:  # noqa: BLE001 - never into Zenoh's thread
                logger.exception("zenoh: command handling failed")

        self._handles.append(self.session.declare_subscriber(self.keys.command, received))

    def subscribe(self, key: str, callback: Callable[[Any], None], remote_only: bool = False) -> Any:
        """A subscriber whose callback's exceptions are counted and logged, never raised into Zenoh."""

        def received(sample: Any) -> None:
            try:
                callback(sample)
            except Exception as err:  # noqa: BLE001
                self.malformed += 1
                if self.malformed <= 3:
                    logger.warning("zenoh: dropped a malformed sample on %s: %s", sample.key_expr, err)

        if remote_only:
            import zenoh

            handle = self.session.declare_subscriber(key, received, allowed_origin=zenoh.Locality.REMOTE)
        else:
            handle = self.session.declare_subscriber(key, received)
        self._handles.append(handle)
        return handle

    def watch_alive(self, key: str, changed: Callable[[str, bool], None]) -> Any:
        """``changed(worker, alive)`` for each liveliness token under ``key`` (those alive already, at once)."""
        import zenoh

        def received(sample: Any) -> None:
            try:
                worker = str(sample.key_expr).rsplit("/", 1)[-1]
                changed(worker, sample.kind == zenoh.SampleKind.PUT)
            except Exception:  # noqa: BLE001
                logger.exception("zenoh: liveliness handling failed")

        handle = self.session.liveliness().declare_subscriber(key, received, history=True)
        self._handles.append(handle)
        return handle

    def close(self) -> None:
        for handle in self._handles:
            try:
                handle.undeclare()
            except Exception:  # noqa: BLE001
                pass
        self._handles.clear()
        for publisher in self._publishers.values():
            try:
                publisher.undeclare()
            except Exception:  # noqa: BLE001
                pass
        self._publishers.clear()
        try:
            self.session.close()
        except Exception:  # noqa: BLE001
            pass
