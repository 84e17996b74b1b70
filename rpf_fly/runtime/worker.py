"""A distributed flight's worker: the drones of one radio dongle, flown by the same :class:`FlightLoop` as a
single-process flight (docs/distributed.md).

The worker receives mocap itself (NatNet multicast reaches every worker), or, when the flight has a mocap relay
(unicast NatNet, a ``motioncapture`` system: rpf_fly/runtime/relay.py), the relay's frames, signed with the
flight's secret (:class:`~rpf_fly.runtime.relayed_mocap.RelayedMocap`). Either way its drones plan from what they
sense: every other drone of the mission is a mocap body in their views (:attr:`FlightLoop.others`), never a
message from another worker's planner. It publishes what its loop logs
(setpoints, planner steps, status, events, its drones' mocap) on the flight's keys, holds its liveliness token
``alive/dongle-K``, waits for the coordinator's signed ``go`` after its preflight and obeys only signed commands
(rpf_fly/runtime/auth.py). Its coordinator's token vanishing (the coordinator died, its host or the network went)
lands every drone it flies.
"""

from __future__ import annotations

import json
import logging
import os
import socket
import threading
import time
from collections.abc import Callable, Collection
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from rpf_fly.flight.events import ERROR, WARNING, FlightEvent
from rpf_fly.flight.loop import FlightLoop, FlightReport, PlannerFactory
from rpf_fly.flight.recorder import MeteredRecorder
from rpf_fly.mission.model import Mission
from rpf_fly.radio.budget import dongle_of
from rpf_fly.runtime.auth import Command
from rpf_fly.runtime.bus import FlightBus
from rpf_fly.runtime.cpu import ZENOH_SENDING, zenoh_threads_cpu_s
from rpf_fly.runtime.keys import COORDINATOR, worker_name
from rpf_fly.runtime.relayed_mocap import RelayedMocap

logger = logging.getLogger(__name__)

COORDINATOR_WAIT_S = 10.0
"""How long a worker waits for its coordinator's liveliness token at start."""
RIG_WAIT_S = 10.0
RELAY_FRAME_WAIT_S = 5.0
"""How long a worker of a relayed flight waits for the relay's first frame (the coordinator starts the workers once
the relay is alive, so the frames are flowing already)."""


class WorkerError(RuntimeError):
    """The worker cannot fly (no such dongle, no coordinator, no rig): one line, exit 2, nothing armed."""


def dongle_drones(mission: Mission, dongle: int) -> list[str]:
    return [d.name for d in mission.drones if dongle_of(d.uri) == dongle]


def tick_offset(mission: Mission, dongle: int) -> float:
    """Where in the planning period this dongle's worker ticks: the k-th of the mission's n dongles at k/n, so the
    workers on one host plan on different mocap frames instead of all queueing for the cores on the same one."""
    dongles = sorted({dongle_of(d.uri) for d in mission.drones})
    return dongles.index(dongle) / len(dongles)


def logging_cpu(since: tuple[float, float | None], metered: MeteredRecorder, recorder: Any) -> dict[str, Any]:
    """What logging cost this worker from its recorder's start to now, in percent of a core: the flight loop's
    hand-over (``loop_pct``), the log writer thread's encoding and publishing (``writer_pct``), Zenoh's sending
    threads (``zenoh_pct``: ``tx``, ``net``, ``app``; the receiving ``rx`` threads run the subscribers, the relayed
    mocap among them, which is the worker's input) and their ``total_pct``; the messages published and the span
    (docs/performance.md)."""
    wall0, zenoh0 = since
    span = time.monotonic() - wall0
    zenoh1 = zenoh_threads_cpu_s(ZENOH_SENDING)
    parts = {
        "loop_pct": metered.cpu_s,
        "writer_pct": recorder.log.writer_cpu_s,
        "zenoh_pct": None if zenoh0 is None or zenoh1 is None else zenoh1 - zenoh0,
    }
    out: dict[str, Any] = {k: None if v is None else round(100 * v / span, 3) for k, v in parts.items()}
    out["total_pct"] = round(100 * sum(v for v in parts.values() if v is not None) / span, 3)
    out["span_s"] = round(span, 1)
    out["messages"] = recorder.log.written
    return out


def worker_info(mission: Mission, dongle: int, state: str, **extra: Any) -> dict[str, Any]:
    return {
        "name": worker_name(dongle),
        "dongle": dongle,
        "host": socket.gethostname(),
        "pid": os.getpid(),
        "drones": dongle_drones(mission, dongle),
        "state": state,
        **extra,
    }


class CoordinatorLink:
    """The loop's :class:`~rpf_fly.flight.loop.SwarmLink` to its coordinator, fed by the bus's command callback."""

    def __init__(self, bus: FlightBus, info: Callable[..., None]):
        self._bus = bus
        self._info = info
        self._verdict: str | None = None
        self._grounded: tuple[str, ...] = ()
        self._takeoff: tuple[str, ...] | None = None
        self.loop: FlightLoop | None = None
        self._pending: list[Command] = []
        self._lock = threading.Lock()
        self.coordinator_seen = threading.Event()
        self.coordinator_lost = False
        self.go_at: tuple[float, float] | None = None
        """(monotonic s, process CPU s) at the coordinator's go: the CPU share of the flight is measured from it."""

    # SwarmLink
    def preflight_done(self, loop: FlightLoop) -> None:
        self._info("ready")

    def verdict(self) -> str | None:
        return self._verdict

    def grounded(self) -> tuple[str, ...]:
        return self._grounded

    def armed(self, loop: FlightLoop, refused: Collection[str]) -> None:
        # The refusals go with the report itself: the drones' "failed" status messages may come after it.
        self._info("armed", refused=sorted(refused))

    def takeoff(self) -> tuple[str, ...] | None:
        return self._takeoff

    # the bus
    def attach(self, loop: FlightLoop) -> None:
        with self._lock:
            self.loop = loop
            pending, self._pending = self._pending, []
        for command in pending:
            self.obey(command)
        if self.coordinator_lost:
            loop.request_stop("coordinator lost: landing every drone")

    def obey(self, command: Command) -> None:
        with self._lock:
            loop = self.loop
            if loop is None:
                self._pending.append(command)
                return
        why = f"coordinator: {command.reason}" if command.reason else f"coordinator: {command.command}"
        if command.command == "go":
            if self._verdict is None:
                self.go_at = (time.monotonic(), time.process_time())
                self._grounded = command.grounded  # signed with the go; set before the verdict the loop reads
            self._verdict = self._verdict or "go"
        elif command.command == "takeoff":
            if self._takeoff is None:
                self._takeoff = command.grounded  # signed with the take-off
        elif command.command == "abort":
            self._verdict = "abort"
            loop.request_stop(why)
        elif command.command == "finish":
            loop.end(command.reason or "every drone of the swarm is at its goal")
        elif command.command == "land":
            loop.request_stop(why)
        elif command.command == "emergency_stop":
            loop.emergency_stop(why)

    def refuse(self, why: str) -> None:
        logger.warning("ignored a command on %s: %s", self._bus.keys.command, why)
        loop = self.loop
        if loop is not None:
            loop.events.emit(WARNING, "command", f"ignored a command that is not this flight's coordinator's: {why}")

    def alive_changed(self, worker: str, alive: bool) -> None:
        if worker != COORDINATOR:
            return
        if alive:
            self.coordinator_seen.set()
            return
        self.coordinator_lost = True
        loop = self.loop
        if loop is not None:
            loop.events.emit(ERROR, "coordinator", "the coordinator's liveliness token is gone: landing every drone")
            loop.request_stop("coordinator lost: landing every drone")


def discover_flight(session: Any, timeout_s: float = COORDINATOR_WAIT_S) -> str:
    """The flight id of the one coordinator this session reaches (its ``alive/coordinator`` token);
    :class:`WorkerError` when there is none, or several (then ``--flight`` must say which)."""
    deadline = time.monotonic() + timeout_s
    while True:
        flights = set()
        for reply in session.liveliness().get(f"rpf_fly/*/alive/{COORDINATOR}", timeout=1.0):
            if reply.ok is not None:
                flights.add(str(reply.ok.key_expr).split("/")[1])
        if len(flights) == 1:
            return flights.pop()
        if len(flights) > 1:
            raise WorkerError(f"several flights reachable ({', '.join(sorted(flights))}): give --flight")
        if time.monotonic() > deadline:
            raise WorkerError(
                f"no coordinator reachable within {timeout_s:.0f} s (start `rpf-fly fly MISSION "
                "--distributed` first; is --connect right?)"
            )
        time.sleep(0.2)


def find_rig(bus: FlightBus) -> dict[str, Any]:
    """The coordinator's dry-run rig (its simulated drones' radio server and NatNet emulator port), asked on the
    ``rig`` key; :class:`WorkerError` when no coordinator serves one within :data:`RIG_WAIT_S`."""
    rig = None
    deadline = time.monotonic() + RIG_WAIT_S
    while rig is None and time.monotonic() < deadline:
        for reply in bus.session.get(bus.keys.rig, timeout=2.0):
            if reply.ok is not None:
                rig = json.loads(reply.ok.payload.to_bytes())
        if rig is None:
            time.sleep(0.2)
    if rig is None:
        raise WorkerError(
            f"flight {bus.keys.flight!r}: the coordinator serves no dry-run rig (is it a dry run? "
            "start the worker with --dry-run only for one)"
        )
    return rig


def relay_transit(source: Any, since_s: float) -> dict[str, Any]:
    """A relayed source's hop from the relay's receipt to this worker's, for the frames received from ``since_s``
    (monotonic: the coordinator's go, as the loop's latencies) on (the report's ``relay_transit_*``); {} for a
    source of its own."""
    transit = source.transits(since_s) if isinstance(source, RelayedMocap) else []
    if not transit:
        return {}
    ordered = sorted(transit)
    return {
        "relay_transit_p50_s": ordered[len(ordered) // 2],
        "relay_transit_p99_s": ordered[min(len(ordered) - 1, round(0.99 * (len(ordered) - 1)))],
        "relay_transit_us": [round(v * 1e6) for v in transit],
    }


def rig_mocap(mission: Mission, rig: dict[str, Any], host: str) -> Any:
    """The dry-run rig's mocap as this process reads it, at ``host`` (where it reaches the rig:
    :func:`~rpf_fly.runtime.session.rig_address`): a unicast NatNet client to the emulator, its handshake done, or
    for a ``motioncapture`` mission the package's OptiTrack decoder on the emulator's multicast, as the
    single-process dry run reads it (:class:`WorkerError` when the emulator does not answer within 5 s)."""
    from rpf_fly.flight.dry_run import client_ip, emulator_motioncapture_source
    from rpf_fly.mocap.natnet_client import NatNetClient

    if mission.mocap.kind == "motioncapture":
        try:
            return emulator_motioncapture_source(
                host, int(rig["natnet_command_port"]), mission.mocap.up_axis, [d.rigid_body for d in mission.drones]
            )
        except Exception as err:  # noqa: BLE001 - the library's own words, in one line
            raise WorkerError(f"dry run: the motioncapture package could not read the emulator: {err}") from err
    client = NatNetClient(
        host,
        multicast=False,
        local_ip=client_ip(host),
        command_port=int(rig["natnet_command_port"]),
        data_port=None,
        up_axis=mission.mocap.up_axis,
    )
    if not client.wait_for_server(5.0):
        client.close()
        raise WorkerError("dry run: the coordinator's NatNet emulator did not answer within 5 s")
    return client


@dataclass
class WorkerRun:
    """What a worker needs besides its mission: built by ``rpf-fly worker`` (and by tests)."""

    mission: Mission
    dongle: int
    flight: str | None
    """None: the one flight whose coordinator the session reaches (:func:`discover_flight`)."""
    secret: str
    planner_factory: PlannerFactory
    dry_run: bool = False
    connect: tuple[str, ...] = ()
    event_sinks: tuple[Callable[[FlightEvent], None], ...] = ()
    on_loop: Callable[[FlightLoop], None] | None = None
    session: Any = None
    """An open Zenoh session to use (tests); None: open one from the mission and ``connect``."""
    _closers: list[Callable[[], None]] = field(default_factory=list)
    _plugged: Any = None

    def run(self) -> FlightReport:
        """Fly this dongle's drones in the coordinator's flight; raises :class:`WorkerError` or
        :class:`~rpf_fly.runtime.session.ZenohUnavailable` before anything is armed."""
        from rpf_fly.flight.recording import McapRecorder
        from rpf_fly.runtime.session import open_session

        names = dongle_drones(self.mission, self.dongle)
        if not names:
            dongles = sorted({dongle_of(d.uri) for d in self.mission.drones})
            raise WorkerError(
                f"--dongle {self.dongle}: no drone of the mission is on it (its dongles: "
                f"{', '.join(map(str, dongles))})"
            )
        session = self.session or open_session(self.mission.runtime.zenoh, connect=self.connect)
        if not self.flight:
            try:
                self.flight = discover_flight(session)
            except WorkerError:
                if self.session is None:
                    session.close()
                raise
        name = worker_name(self.dongle)
        bus = FlightBus(session, self.flight, name)
        try:

            def info(state: str, **extra: Any) -> None:
                bus.put_json(
                    f"workers/{name}", json.dumps(worker_info(self.mission, self.dongle, state, **extra)).encode()
                )

            link = CoordinatorLink(bus, info)
            bus.watch_alive(bus.keys.alive(COORDINATOR), link.alive_changed)
            if not link.coordinator_seen.wait(COORDINATOR_WAIT_S):
                raise WorkerError(
                    f"no coordinator of flight {self.flight!r} within {COORDINATOR_WAIT_S:.0f} s "
                    f"(start `rpf-fly fly MISSION --distributed` first; is --connect right?)"
                )
            bus.on_commands(self.secret, link.obey, link.refuse)
            backend, source, uris = self._rig(bus)
            logging_since = (time.monotonic(), zenoh_threads_cpu_s(ZENOH_SENDING))
            recorder = McapRecorder(
                Path(f"zenoh-{self.flight}-{name}"),
                self.mission,
                source="dry-run" if self.dry_run else "flight",
                out=bus.out,
                radio=backend.radio_counts,
                radio_dongles=(self.dongle,),
                mocap=False,
            )
            metered = MeteredRecorder(recorder)
            try:
                loop = FlightLoop(
                    self.mission,
                    backend,
                    source,
                    self.planner_factory,
                    uris=uris,
                    recorder=metered,
                    drones=names,
                    swarm=link,
                    tick_offset=tick_offset(self.mission, self.dongle),
                    # a dry run's simulated drones fly the mission's model: the first-order ones are followed with it
                    first_order=names if self.dry_run and self.mission.dry_run.dynamics == "first-order" else (),
                )
            except BaseException:
                recorder.close()
                raise
            for sink in self.event_sinks:
                loop.events.subscribe(sink)
            if isinstance(source, RelayedMocap):  # refused frames are warnings in the flight log

                def warn(message: str) -> None:
                    loop.events.emit(WARNING, "mocap_relay", message)

                source.warn = warn
            info("connecting")
            bus.token(name)
            link.attach(loop)
            if self.on_loop is not None:
                self.on_loop(loop)
            report = loop.run()
            wall0, cpu0 = link.go_at or (time.monotonic(), time.process_time())
            flown_s = time.monotonic() - wall0
            info(
                "done",
                outcomes={n: o.value for n, o in report.outcomes.items()},
                reasons={n: r for n, r in report.reasons.items() if r},
                latency=report.stats.summary(),
                cpu_s=time.process_time(),
                cpu_pct=round(100 * (time.process_time() - cpu0) / flown_s, 1) if flown_s > 0 else None,
                publish_cpu_pct=round(100 * recorder.log.writer_cpu_s / flown_s, 2) if flown_s > 0 else None,
                logging_cpu=logging_cpu(logging_since, metered, recorder),
                latencies_us=[round(v * 1e6) for v in report.stats.latencies],
                mocap=asdict(source.stats),
                **relay_transit(source, wall0),
                radio=self._radio_report() if self.dry_run else None,
            )
            time.sleep(0.2)  # the last messages leave before the session closes
            return report
        finally:
            for close in reversed(self._closers):
                try:
                    close()
                except Exception:  # noqa: BLE001
                    logger.exception("worker: closing failed")
            bus.close()

    def _relayed(self, bus: FlightBus) -> Any:
        """The relay's frames (the flight has a mocap relay: rpf_fly/runtime/relay.py), once the first arrived."""
        source = RelayedMocap(bus.session, bus.keys.mocap_frames, self.secret, bus.keys.flight)
        self._closers.append(source.close)
        if not source.wait_first(RELAY_FRAME_WAIT_S):
            raise WorkerError(
                f"no mocap frame from the flight's relay within {RELAY_FRAME_WAIT_S:.0f} s (on "
                f"{bus.keys.mocap_frames}; is alive/relay up, is RPF_FLY_SECRET this flight's?)"
            )
        return source

    def _rig(self, bus: FlightBus) -> tuple[Any, Any, dict[str, str] | None]:
        """The backend, the mocap source and the URIs: the coordinator's simulated drones (a dry run: their radio
        server and NatNet emulator, found on the ``rig`` key) or the real radios and mocap; the mocap is the relay's
        frames when the flight has a relay (:func:`~rpf_fly.runtime.relay.uses_relay`, dry runs alike)."""
        from rpf_fly.radio.cflib_backend import CflibBackend
        from rpf_fly.runtime.relay import uses_relay

        relayed = uses_relay(self.mission)
        if not self.dry_run:
            from rpf_fly.flight.session import DEFAULT_TOC_CACHE, mocap_source

            if relayed:
                return CflibBackend.for_mission(self.mission, DEFAULT_TOC_CACHE), self._relayed(bus), None
            source = mocap_source(self.mission)
            self._closers.append(source.close)
            return CflibBackend.for_mission(self.mission, DEFAULT_TOC_CACHE), source, None
        from rpf_fly.emulator import fake_radio
        from rpf_fly.emulator.dongle_air import RadioTiming
        from rpf_fly.emulator.remote_world import RemoteWorld
        from rpf_fly.flight.dry_run import AIR_TIME_S, DRY_RUN_TOC_CACHE, fake_uri, radio_uri, uri_address
        from rpf_fly.runtime.session import rig_address

        rig = find_rig(bus)
        addresses = tuple(uri_address(d.uri) for d in self.mission.drones)
        host = rig_address(str(rig["radio"][0]), self.connect or self.mission.runtime.zenoh.connect)
        world = RemoteWorld(
            (host, int(rig["radio"][1])), addresses, RadioTiming(transaction_s=float(rig.get("air_time_s", AIR_TIME_S)))
        )
        if self.mission.dry_run.radio == "crazyradio":
            uris = {d.name: radio_uri(d.uri) for d in self.mission.drones}
            self._plug_crazyradio(world)
        else:
            fake_radio.register(world)
            self._closers.append(fake_radio.unregister)
            uris = {d.name: fake_uri(d.uri) for d in self.mission.drones}
        if relayed:
            client = self._relayed(bus)
        else:
            client = rig_mocap(self.mission, rig, host)
            self._closers.append(client.close)
        return CflibBackend.for_mission(self.mission, DRY_RUN_TOC_CACHE), client, uris

    def _plug_crazyradio(self, world: Any) -> None:
        """A dry run with ``dry_run.radio: crazyradio``: this worker's dongle as an emulated Crazyradio of the
        mission's type plugged into this process (dongle numbers up to this one, the others unused), so cflib's
        own ``radio://`` driver carries this worker's packets to the coordinator's simulated drones, at the
        dongle's figures (docs/radio.md, "Dry runs through cflib's radio driver"). Its packets counted go in the
        worker's last report (``radio``)."""
        from rpf_fly.emulator import crazyradio
        from rpf_fly.flight.dry_run import dongle_type, release_dongles

        plugged = self._plugged = crazyradio.plug(world, dongles=self.dongle + 1, radio=dongle_type(self.mission))
        self._closers.append(lambda: release_dongles(plugged))

    def _radio_report(self) -> dict[str, Any]:
        """What carried this worker's packets: ``{"radio": "fake"}``, or the emulated dongle's type and the
        packets it carried to each drone (``{"radio": "crazyradio", "type": ..., "packets": {name: N}}``)."""
        from rpf_fly.flight.dry_run import uri_address

        if self._plugged is None:
            return {"radio": "fake"}
        counted = self._plugged.dongles[self.dongle].counters.packets
        names = dongle_drones(self.mission, self.dongle)
        packets = {d.name: counted[uri_address(d.uri)] for d in self.mission.drones if d.name in names}
        return {"radio": "crazyradio", "type": self._plugged.radio.name, "packets": packets}
