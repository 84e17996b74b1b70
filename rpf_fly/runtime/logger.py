"""A distributed flight's logger: one process writing the MCAP log from the flight's keys (docs/distributed.md).

It subscribes to ``rpf_fly/<flight>/**`` and writes each message a worker or the coordinator published, the bytes
and times they carry (rpf_fly/runtime/keys.py), into the same topics a single-process flight writes; the scene and
the mission come from its own copy of the mission, ``runtime.flight_id`` and ``runtime.workers`` from the
coordinator's ``runtime`` record. Nothing waits on it: if it dies, the workers fly on and the log written so far is
salvageable (``rpf-fly review --salvage``), as any log cut short by a kill. SIGTERM (the coordinator, at the end)
finishes the file; SIGINT is ignored (a Ctrl-C reaches the whole process group: the flight is still landing). With
the coordinator gone it writes on until no worker is alive, then finishes.

``python -m rpf_fly.runtime.logger MISSION --flight ID --log PATH --connect ENDPOINT [--source dry-run]``
"""

from __future__ import annotations

import argparse
import json
import logging
import signal
import sys
import threading
import time
from pathlib import Path
from typing import Any

import orjson

from rpf_fly.runtime.keys import COORDINATOR, LOGGER, STAMPS, suffix_topic

logger = logging.getLogger(__name__)


class FlightLogger:
    """Subscribes to a flight's keys and writes them into a :class:`~rpf_fly.flight.recording.McapRecorder`'s log."""

    def __init__(self, bus: Any, mission: Any, log_path: Path, source: str):
        from rpf_fly.flight.recording import McapRecorder

        self.bus = bus
        self.recorder = McapRecorder(log_path, mission, source=source)
        self.log = self.recorder.log
        self.received = 0
        self.dropped = 0
        self.alive: set[str] = set()
        self.coordinator_seen = False
        self.changed = threading.Event()
        self._runtime_written = False
        self.first_at: tuple[float, float] | None = None
        """(monotonic s, process CPU s) at the first message: its CPU share is measured from there."""
        keys = bus.keys
        bus.session.declare_subscriber(keys.all, self._sample)
        bus.watch_alive(keys.alive_all, self._alive)

    def _sample(self, sample: Any) -> None:
        try:
            suffix = self.bus.keys.suffix_of(str(sample.key_expr))
            if suffix == "runtime":
                if not self._runtime_written:
                    self._runtime_written = True
                    self.log.metadata("runtime", json.loads(sample.payload.to_bytes()))
                return
            topic = suffix_topic(suffix) if suffix is not None else None
            if topic is None:
                return  # command, workers, rig: not log messages
            attachment = sample.attachment
            if attachment is None:
                raise ValueError("no stamps")
            if self.first_at is None:
                self.first_at = (time.monotonic(), time.process_time())
            log_time, t_ns = STAMPS.unpack(attachment.to_bytes())
            data = sample.payload.to_bytes()
            if type(orjson.loads(data)) is not dict:  # the log holds JSON objects only (a foreign session's junk)
                raise ValueError("not a JSON object")
            self.log.message(topic, t_ns, log_time, data)
            self.received += 1
        except Exception as err:  # noqa: BLE001 - a malformed message is dropped and counted
            self.dropped += 1
            if self.dropped <= 3:
                logger.warning("logger: dropped a malformed sample on %s: %s", sample.key_expr, err)

    def _alive(self, name: str, alive: bool) -> None:
        if alive:
            self.alive.add(name)
            self.coordinator_seen |= name == COORDINATOR
        else:
            self.alive.discard(name)
        self.changed.set()

    def everyone_gone(self) -> bool:
        return self.coordinator_seen and not any(n == COORDINATOR or n.startswith("dongle-") for n in self.alive)

    def close(self) -> None:
        self.recorder.close()


def _share(since: tuple[float, float] | None) -> float | None:
    """Percent of a core used since ``(monotonic s, process CPU s)``."""
    if since is None or time.monotonic() <= since[0]:
        return None
    return round(100 * (time.process_time() - since[1]) / (time.monotonic() - since[0]), 1)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m rpf_fly.runtime.logger")
    parser.add_argument("mission")
    parser.add_argument("--flight", required=True)
    parser.add_argument("--log", required=True)
    parser.add_argument("--connect", action="append", default=[])
    parser.add_argument("--source", default="flight")
    args = parser.parse_args(argv)
    from rpf_fly.log.text_log import route_logging
    from rpf_fly.mission import load_mission
    from rpf_fly.runtime.bus import FlightBus
    from rpf_fly.runtime.session import ZenohUnavailable, open_session

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    log_path = Path(args.log)
    with route_logging(log_path.with_name(log_path.stem + ".logger.log"), False):
        mission = load_mission(args.mission)
        try:
            session = open_session(mission.runtime.zenoh, connect=args.connect)
        except ZenohUnavailable as err:
            print(err, file=sys.stderr)
            return 2
        bus = FlightBus(session, args.flight, LOGGER)
        try:
            flight_logger = FlightLogger(bus, mission, log_path, args.source)
        except OSError as err:  # the coordinator then stops in one line, nothing armed
            print(f"logger: cannot write {log_path}: {err.strerror or err}", file=sys.stderr)
            bus.close()
            return 2
        bus.token(LOGGER)
        try:
            while not stop.is_set():
                stop.wait(0.2)
                if flight_logger.everyone_gone():
                    time.sleep(0.3)  # the last samples in flight
                    break
        finally:
            flight_logger.close()
            bus.put_json(
                f"workers/{LOGGER}",
                json.dumps(
                    {
                        "name": LOGGER,
                        "state": "done",
                        "cpu_s": time.process_time(),
                        "written": flight_logger.received,
                        "cpu_pct": _share(flight_logger.first_at),
                        "dropped": flight_logger.dropped,
                    }
                ).encode(),
            )
            time.sleep(0.1)
            bus.close()
        logger.info("logger: %d messages written, %d malformed dropped", flight_logger.received, flight_logger.dropped)
    return 0


if __name__ == "__main__":
    sys.exit(main())
