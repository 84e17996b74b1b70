"""A distributed flight's mocap relay: one process reads the mocap and publishes every frame: signed, to the
workers when they fly on it, and always each drone's pose for the log and the taps (docs/distributed.md, "Mocap
relay").

Multicast NatNet reaches every worker, so each opens its own client. A unicast NatNet server, or a ``motioncapture``
system that serves one client per host, cannot feed several workers: then the workers fly on this process's
frames: it opens the mission's mocap (:func:`rpf_fly.flight.session.mocap_source`; a dry run: the coordinator's
NatNet emulator, as a worker would) and publishes each frame on ``rpf_fly/<flight>/mocap_frames`` (rpf_fly/runtime/
frames.py: every body, signed with the flight's secret, numbered). Workers read them through
:class:`~rpf_fly.runtime.relayed_mocap.RelayedMocap`. :func:`uses_relay` says when (``runtime.mocap_relay``).

Every distributed flight runs it, relayed or not, as the flight's one mocap tap: it publishes each drone's valid
pose on ``mocap/<drone>`` (the log's ``foxglove.PoseInFrame``, stamped with its receipt), which the logger writes as
``/mocap/<drone>`` and any tap reads. So the workers, the flight's processes, publish only what they decide
(setpoints, planner steps, status, events, their ``tf``): the mocap's 100 messages a second a drone cost them
nothing (docs/performance.md), and a lost worker's drones stay in the log's mocap as they fall.

It holds ``alive/relay`` once its mocap answers: the coordinator starts the workers only then, and names it at
once if the token vanishes (relayed, the workers then see their mocap stop: their supervisors hold, then land the
drones; direct, they fly on and the log's mocap ends there).
Its records go to ``<log>.relay.log``; its events (mocap silent, back) to the flight's ``events``; ``workers/relay``
says what it relays and, at its end, how many frames and how much CPU. SIGTERM (the coordinator, once every worker
has ended) stops it; SIGINT is ignored (a Ctrl-C reaches the whole process group while the drones still land on its
frames); it also ends once neither the coordinator nor any worker is left.

``RPF_FLY_SECRET=... python -m rpf_fly.runtime.relay MISSION --flight ID --log PATH --connect ENDPOINT [--dry-run]``
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import signal
import socket
import sys
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

from rpf_fly.mission.model import Mission
from rpf_fly.runtime.keys import COORDINATOR, RELAY
from rpf_fly.runtime.session import StartError

logger = logging.getLogger(__name__)

SILENT_S = 1.0
"""The relay's mocap delivering no frame for this long is a warning event (and its return an info)."""


class RelayError(StartError):
    """The relay did not come up (its mocap did not answer, it exited, no token in time): one line, exit 2."""


def uses_relay(mission: Mission) -> bool:
    """Whether the flight's workers take their mocap from the relay: ``runtime.mocap_relay`` ``on``/``off``, or
    ``auto``: unicast NatNet (``mocap.multicast: false``) and ``motioncapture`` systems (one client per host) go
    through the relay; multicast NatNet reaches every worker directly (and ``sim``, a dry run's emulator, serves
    each client). A dry run follows the same rule, so it exercises the path its real flight takes."""
    setting = mission.runtime.mocap_relay
    if setting != "auto":
        return setting == "on"
    mocap = mission.mocap
    return mocap.kind == "motioncapture" or (mocap.kind == "natnet" and not mocap.multicast)


def describe_source(mission: Mission, dry_run: bool) -> str:
    """What the relay reads, for its record and the console."""
    m = mission.mocap
    if dry_run:
        return (
            "the dry run's NatNet emulator (multicast, through the motioncapture package's OptiTrack decoder)"
            if m.kind == "motioncapture"
            else "the dry run's NatNet emulator (unicast)"
        )
    if m.kind == "motioncapture":
        return f"motioncapture {m.system}" + (f" at {m.hostname}" if m.hostname else "")
    return f"NatNet {m.server} ({'multicast' if m.multicast else 'unicast'})"


class FrameRelay:
    """Reads a :class:`~rpf_fly.mocap.frame.MocapSource` and publishes each frame: signed on the relay key when
    ``signed`` (the workers fly on it), and each drone's valid pose on ``mocap/<drone>`` (``drones``: rigid body
    name -> drone name; ``offset_ns``: this process's Unix-epoch ns minus its monotonic ns)."""

    def __init__(
        self,
        bus: Any,
        source: Any,
        secret: str,
        event: Callable[[int, str], None],
        *,
        signed: bool = True,
        drones: dict[str, str] | None = None,
        offset_ns: int = 0,
    ):
        import zenoh

        from rpf_fly.runtime.frames import FrameSigner

        self.bus = bus
        self.source = source
        self.event = event
        self.signed = signed
        self.topics = {body: f"/mocap/{name}" for body, name in (drones or {}).items()}
        self.offset_ns = offset_ns
        self.signer = FrameSigner(secret, bus.keys.flight)
        # Mocap is the flight's most urgent data: sent at once (express, no batching), ahead of the other
        # priorities; a congested link drops a frame (the next one supersedes it) rather than delay the relay.
        self.publisher = bus.session.declare_publisher(
            bus.keys.mocap_frames,
            congestion_control=zenoh.CongestionControl.DROP,
            priority=zenoh.Priority.REAL_TIME,
            express=True,
        )
        self.published = 0
        self.failed = 0
        self.first_at: tuple[float, float] | None = None
        """(monotonic s, process CPU s) at the first frame: the relay's CPU share is measured from there."""

    def run(self, stop: threading.Event, gone: Callable[[], bool]) -> None:
        """Relay until ``stop`` is set or ``gone()`` (nobody left to relay to)."""
        last_frame_s = time.monotonic()
        silent = False
        while not stop.is_set() and not gone():
            frame = self.source.receive(0.1)
            now = time.monotonic()
            if frame is None:
                if not silent and now - last_frame_s > SILENT_S:
                    silent = True
                    self.event(3, f"no mocap frame for {now - last_frame_s:.1f} s: the workers see none either")
                continue
            if self.first_at is None:
                self.first_at = (now, time.process_time())
            last_frame_s = now
            if silent:
                silent = False
                self.event(2, "mocap frames are back")
            if self.signed:
                payload, signature = self.signer.sign(frame)
                try:
                    self.publisher.put(payload, attachment=signature)
                except Exception as err:  # noqa: BLE001 - a closing session: counted, the relay goes on
                    self.failed += 1
                    if self.failed <= 3:
                        logger.warning("relay: a frame was not published: %s", err)
                    continue
            self.published += 1
            self._poses(frame)

    def _poses(self, frame: Any) -> None:
        """Each drone's valid pose of ``frame`` on ``mocap/<drone>``, stamped with the frame's receipt (the log's
        ``/mocap/<drone>``; the bus drops what it cannot send)."""
        from rpf_fly.log.encoding import pose_json

        t_ns = round(frame.receive_time_s * 1e9) + self.offset_ns
        out, topics = self.bus.out, self.topics
        for body in frame.bodies.values():
            topic = topics.get(body.name)
            if topic is not None and body.valid:
                out(topic, t_ns, t_ns, pose_json(t_ns, body.position, body.quaternion))

    def cpu_pct(self) -> float | None:
        if self.first_at is None or time.monotonic() <= self.first_at[0]:
            return None
        return round(100 * (time.process_time() - self.first_at[1]) / (time.monotonic() - self.first_at[0]), 1)

    def close(self) -> None:
        try:
            self.publisher.undeclare()
        except Exception:  # noqa: BLE001
            pass


def open_source(mission: Mission, bus: Any, dry_run: bool, connect: Sequence[str] = ()) -> Any:
    """The mission's mocap, connected; a dry run: the coordinator's NatNet emulator (its ``rig``, reached where
    ``connect`` reached the coordinator). Raises with one line when it does not answer."""
    if dry_run:
        from rpf_fly.runtime.session import rig_address
        from rpf_fly.runtime.worker import find_rig, rig_mocap

        rig = find_rig(bus)
        return rig_mocap(mission, rig, rig_address(str(rig["radio"][0]), connect))
    from rpf_fly.flight.session import mocap_source

    return mocap_source(mission)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m rpf_fly.runtime.relay")
    parser.add_argument("mission")
    parser.add_argument("--flight", required=True)
    parser.add_argument("--log", required=True, help="the flight's log (the relay's records: <log>.relay.log)")
    parser.add_argument("--connect", action="append", default=[])
    parser.add_argument("--dry-run", action="store_true")
    args = parser.parse_args(argv)
    from rpf_fly.log.encoding import encode
    from rpf_fly.log.messages import log_message
    from rpf_fly.log.text_log import route_logging
    from rpf_fly.mission import load_mission
    from rpf_fly.runtime.auth import SECRET_ENV
    from rpf_fly.runtime.bus import FlightBus
    from rpf_fly.runtime.session import ZenohUnavailable, open_session

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    secret = os.environ.get(SECRET_ENV, "")
    if len(secret) < 32:
        print(
            f"relay: {SECRET_ENV}: the flight's secret is missing (the coordinator starts the relay)", file=sys.stderr
        )
        return 2
    log_path = Path(args.log)
    with route_logging(log_path.with_name(log_path.stem + ".relay.log"), False):
        mission = load_mission(args.mission)
        try:
            session = open_session(mission.runtime.zenoh, connect=args.connect)
        except ZenohUnavailable as err:
            print(f"relay: {err}", file=sys.stderr)
            return 2
        bus = FlightBus(session, args.flight, RELAY)
        offset_ns = time.time_ns() - time.monotonic_ns()
        what = describe_source(mission, args.dry_run)

        def event(level: int, message: str) -> None:
            t_ns = time.monotonic_ns() + offset_ns
            logger.log(10 * level, "relay: %s", message)
            bus.out("/events", t_ns, t_ns, encode(log_message(t_ns, level, message, name=RELAY, file="mocap_relay")))

        def info(state: str, **extra: Any) -> None:
            bus.put_json(
                f"workers/{RELAY}",
                json.dumps(
                    {
                        "name": RELAY,
                        "host": socket.gethostname(),
                        "pid": os.getpid(),
                        "state": state,
                        "source": what,
                        "key": bus.keys.mocap_frames,
                        **extra,
                    }
                ).encode(),
            )

        alive: set[str] = set()
        seen = {"coordinator": False}

        def changed(name: str, up: bool) -> None:
            (alive.add if up else alive.discard)(name)
            seen["coordinator"] |= up and name == COORDINATOR

        def gone() -> bool:  # the coordinator went and no worker is left to relay to
            return seen["coordinator"] and not any(n == COORDINATOR or n.startswith("dongle-") for n in set(alive))

        try:
            source = open_source(mission, bus, args.dry_run, args.connect)
        except Exception as err:  # noqa: BLE001 - whatever the mocap says: one line, nothing armed
            print(f"relay: cannot open the mocap ({what}): {' '.join(str(err).split())}", file=sys.stderr)
            bus.close()
            return 2
        signed = uses_relay(mission)
        relay = FrameRelay(
            bus,
            source,
            secret,
            event,
            signed=signed,
            offset_ns=offset_ns,
            drones={d.rigid_body: d.name for d in mission.drones},
        )
        try:
            bus.watch_alive(bus.keys.alive_all, changed)
            info("relaying")
            bus.token(RELAY)
            event(
                2,
                f"relaying {what} to the workers on {bus.keys.mocap_frames}"
                if signed
                else f"publishing {what}'s poses for the log on mocap/<drone> (the workers read their own mocap)",
            )
            relay.run(stop, gone)
        finally:
            stats = source.stats
            source.close()
            relay.close()
            info(
                "done", frames=relay.published, cpu_s=time.process_time(), cpu_pct=relay.cpu_pct(), mocap=asdict(stats)
            )
            time.sleep(0.1)  # the last record leaves before the session closes
            bus.close()
        logger.info("relay: %d frames published", relay.published)
    return 0


if __name__ == "__main__":
    sys.exit(main())
