"""The key expressions of a flight on Zenoh, and how they map to the flight log's topics (docs/distributed.md).

Every key is under ``rpf_fly/<flight>/`` where ``<flight>`` is the log's file stem. Values are the log's own JSON
messages (docs/log-format.md), byte for byte; each sample carries an attachment of 16 bytes, the message's log time
and publish time (two little-endian int64 nanoseconds since the Unix epoch), so the logger writes what a
single-process flight writes.
"""

from __future__ import annotations

import re
import struct

ROOT = "rpf_fly"
STAMPS = struct.Struct("<qq")
"""The attachment of a message sample: log time, publish time (ns since the Unix epoch)."""

_NAME = re.compile(r"^[A-Za-z0-9_.-]+$")


def check_flight_id(flight: str) -> str:
    """A flight id is one key chunk: letters, digits, ``_ . -`` (a log's stem); ValueError otherwise."""
    if not _NAME.match(flight):
        raise ValueError(f"flight id {flight!r}: expected letters, digits, '_', '.' or '-' only (the log's file stem)")
    return flight


class FlightKeys:
    """The keys of one flight."""

    def __init__(self, flight: str):
        self.flight = check_flight_id(flight)
        self.prefix = f"{ROOT}/{flight}"

    def key(self, suffix: str) -> str:
        return f"{self.prefix}/{suffix}"

    @property
    def all(self) -> str:
        return f"{self.prefix}/**"

    @property
    def command(self) -> str:
        return self.key("command")

    @property
    def events(self) -> str:
        return self.key("events")

    @property
    def mocap_frames(self) -> str:
        """The mocap relay's frames: one signed message per frame holding every body (rpf_fly/runtime/frames.py)."""
        return self.key("mocap_frames")

    @property
    def rig(self) -> str:
        """The dry run's rig (the coordinator's simulated drones: radio server and NatNet port), a queryable."""
        return self.key("rig")

    def alive(self, worker: str) -> str:
        return self.key(f"alive/{worker}")

    @property
    def alive_all(self) -> str:
        return self.key("alive/*")

    def worker_info(self, worker: str) -> str:
        return self.key(f"workers/{worker}")

    @property
    def workers_all(self) -> str:
        return self.key("workers/*")

    def suffix_of(self, key: str) -> str | None:
        """``rpf_fly/<flight>/setpoint/cf1`` -> ``setpoint/cf1``; None for another flight's key."""
        head = self.prefix + "/"
        return key[len(head) :] if key.startswith(head) else None


COORDINATOR = "coordinator"
"""The coordinator's liveliness token: ``alive/coordinator``."""
LOGGER = "logger"
RELAY = "relay"
"""The mocap relay's liveliness token (``alive/relay``) and ``workers/relay`` record."""


def worker_name(dongle: int) -> str:
    return f"dongle-{int(dongle)}"


def topic_suffix(topic: str, publisher: str) -> str | None:
    """The key suffix of a log topic (None: not published): ``/mocap/cf1`` -> ``mocap/cf1``, ``/cf1/setpoint`` ->
    ``setpoint/cf1``, ``/events`` -> ``events``, ``/tf`` -> ``tf/<publisher>``, ``/truth/cf1`` -> ``truth/cf1``,
    ``/radio/0`` -> ``radio/0`` (a dongle's measured load, from its worker).
    ``/scene`` is not published: the logger writes it from the mission."""
    parts = topic.strip("/").split("/")
    if len(parts) == 1:
        if parts[0] == "events":
            return "events"
        if parts[0] == "tf":
            return f"tf/{publisher}"
        return None
    if len(parts) == 2:
        if parts[0] in ("mocap", "truth", "radio"):
            return f"{parts[0]}/{parts[1]}"
        if parts[1] in ("setpoint", "planner", "status"):
            return f"{parts[1]}/{parts[0]}"
    return None


def suffix_topic(suffix: str) -> str | None:
    """The log topic of a key suffix (the inverse of :func:`topic_suffix`); None for keys that are not messages
    (command, alive, workers, rig) or are malformed."""
    parts = suffix.split("/")
    if parts == ["events"]:
        return "/events"
    if len(parts) != 2 or not _NAME.match(parts[1]):
        return None
    kind, name = parts
    if kind == "tf":
        return "/tf"
    if kind in ("mocap", "truth", "radio"):
        return f"/{kind}/{name}"
    if kind in ("setpoint", "planner", "status"):
        return f"/{name}/{kind}"
    return None
