"""Assemble and run one flight: the dry-run rig or the real hardware, the cflib backend, the recorder, the loop.

The CLI adds the console and the signal handlers around :func:`run_flight`; tests call it with fault hooks.
"""

from __future__ import annotations

import functools
import socket
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, ParamSpec

from rpf_fly.flight.events import EventSink
from rpf_fly.flight.loop import FlightLoop, FlightReport, PlannerFactory
from rpf_fly.flight.phases import SwarmPhase
from rpf_fly.flight.recording import McapRecorder
from rpf_fly.flight.thread_deaths import reported_thread_deaths
from rpf_fly.mission.model import Mission
from rpf_fly.mocap.frame import MocapSource

if TYPE_CHECKING:  # the dry run's emulators stay out of a real flight's imports
    from rpf_fly.flight.dry_run import DryRun
    from rpf_fly.log.live import LiveView

DEFAULT_TOC_CACHE = Path.home() / ".cache" / "rpf_fly" / "toc"


class UnresolvableServer(ValueError):
    """``mocap.server`` (or ``mocap.hostname``) names no host this machine can resolve. ``field`` names the key."""

    field = "mocap.server"


WATCHED_PHASES = (SwarmPhase.PREFLIGHT, SwarmPhase.TAKEOFF, SwarmPhase.FLYING, SwarmPhase.LANDING)
"""The flight's phases in which a dry run's radio links held by the host count as time behind
(`rpf_fly.emulator.host_lag.SpanMeter.window`): from the preflight (the estimators judged, extpos needed from here
on) to the end of the landing; connecting and closing hold the links for the flight's own reasons."""


def watched_window(loop: FlightLoop) -> EventSink:
    """A sink for ``loop``'s events that keeps the process's link meter's window (`host_lag.LINKS.window`) on
    `WATCHED_PHASES`: from the event that says the preflight began to the one after the landing ends."""
    import time

    from rpf_fly.emulator.host_lag import LINKS

    LINKS.window = (float("inf"), float("inf"))

    def follow(_event: object) -> None:
        window = LINKS.window
        if window is None:
            return
        now = time.monotonic()
        if loop.phase in WATCHED_PHASES and window[0] == float("inf"):
            LINKS.window = (now, float("inf"))
        elif loop.phase not in WATCHED_PHASES and window[0] != float("inf") and window[1] == float("inf"):
            LINKS.window = (window[0], now)

    return follow


def resolve_mocap_server(mission: Mission) -> str:
    """The mission's NatNet server as an IP address; :class:`UnresolvableServer` with the reason if it has none.
    Called before anything connects, so a typo never reaches a drone. For kind ``motioncapture`` the types whose
    host the library takes as an IPv4 literal only (``optitrack``) are resolved the same way; the others' hosts
    are the library's to resolve (Vicon and VRPN take ``host:port``), and the host itself is returned."""
    m = mission.mocap
    port: int | None
    host, port, family, field, what = m.server, m.command_port, 0, "mocap.server", "the PC running Motive"
    if m.kind == "motioncapture":
        from rpf_fly.mocap.motioncapture_options import TYPES

        if m.system is None or TYPES[m.system].hostname != "ip":
            return m.hostname or ""
        host, port, family = m.hostname or "localhost", None, socket.AF_INET
        field, what = "mocap.hostname", f"the {m.system} server"
    try:
        infos = socket.getaddrinfo(host, port, family, type=socket.SOCK_DGRAM)
    except (socket.gaierror, UnicodeError) as err:
        reason = err.strerror if isinstance(err, socket.gaierror) and err.strerror else str(err)
        error = UnresolvableServer(
            f"cannot resolve {host!r} ({reason}): expected the IP address or host name of {what}"
        )
        error.field = field
        raise error from None
    return str(infos[0][4][0])


def real_flight_problem(mission: Mission) -> str | None:
    """Why the mission's mocap cannot fly real drones (``FIELD: problem``), or None. ``sim`` and the library's
    ``mock`` serve poses that are not the drones': real drones would take off on them and fly blind."""
    m = mission.mocap
    if m.kind == "sim":
        return "mocap.kind: 'sim' can only fly with --dry-run (real drones need motion capture)"
    if m.kind == "motioncapture" and m.system == "mock":
        return (
            "mocap.type: 'mock' serves fixed poses from its options, not the drones': it can only fly with "
            "--dry-run (which serves the simulated drones' poses, docs/mocap.md)"
        )
    return None


def motioncapture_missing(mission: Mission, dry_run: bool, dry_run_mocap: str | None = None) -> str | None:
    """The one line naming the extra when this flight needs the ``motioncapture`` package and it is missing (a real
    flight of kind ``motioncapture``, or a dry run whose mocap is ``motioncapture``: ``dry_run_mocap`` or, if None,
    the mission's kind); None otherwise. Checked before anything starts, without importing the C++ library."""
    if dry_run:
        needed = (
            dry_run_mocap or ("motioncapture" if mission.mocap.kind == "motioncapture" else "natnet")
        ) == "motioncapture"
    else:
        needed = mission.mocap.kind == "motioncapture"
    if not needed:
        return None
    from rpf_fly.mocap.motioncapture_options import MISSING_LIBRARY
    from rpf_fly.mocap.motioncapture_source import library_installed

    return None if library_installed() else MISSING_LIBRARY


def motioncapture_source(mission: Mission, timeout_s: float = 5.0) -> MocapSource:
    """The mission's ``motioncapture`` system, its library running in a child process, connected (raises
    :class:`~rpf_fly.mocap.motioncapture_source.MotioncaptureUnavailable`, a ConnectionError, otherwise)."""
    from rpf_fly.mocap.motioncapture_source import MotioncaptureSource

    m = mission.mocap
    assert m.system is not None
    return MotioncaptureSource(
        m.system,
        m.hostname,
        dict(m.options),
        up_axis=m.up_axis,
        bodies=[d.rigid_body for d in mission.drones],
        connect_timeout_s=timeout_s,
    )


def mocap_source(mission: Mission, timeout_s: float = 5.0) -> MocapSource:
    """The mission's real mocap, connected: the NatNet client, or a ``motioncapture`` system."""
    if mission.mocap.kind == "motioncapture":
        return motioncapture_source(mission, timeout_s)
    return natnet_source(mission, timeout_s)


def natnet_source(mission: Mission, timeout_s: float = 5.0) -> MocapSource:
    """The mission's NatNet client, connected (raises ConnectionError if the server does not answer)."""
    from rpf_fly.mocap.natnet_client import NatNetClient

    resolve_mocap_server(mission)
    m = mission.mocap
    client = NatNetClient(
        m.server,
        multicast=m.multicast,
        local_ip=m.local_ip,
        multicast_group=m.multicast_group,
        command_port=m.command_port,
        data_port=m.data_port,
        up_axis=m.up_axis,
    )
    if not client.wait_for_server(timeout_s):
        client.close()
        raise ConnectionError(
            f"no answer from the NatNet server {m.server}:{m.command_port} within {timeout_s:.0f} s "
            "(is Motive streaming? try `rpf-fly mocap watch --natnet HOST`)"
        )
    return client


def live_topics(mission: Mission, truth: bool) -> list[str]:
    """The topics a flight's log writes (docs/log-format.md), for the live view to advertise before the flight."""
    from rpf_fly.radio.budget import dongle_of

    topics = ["/scene", "/tf", "/events", *(f"/radio/{k}" for k in sorted({dongle_of(d.uri) for d in mission.drones}))]
    for drone in mission.drones:
        n = drone.name
        topics += [f"/mocap/{n}", f"/{n}/setpoint", f"/{n}/planner", f"/{n}/status"]
        if truth:
            topics.append(f"/truth/{n}")
    return topics


P = ParamSpec("P")

FLIGHT_SWITCH_INTERVAL_S = 0.5e-3
"""The flight's process's GIL switch interval while it flies (Python's default is 5 ms): cflib's radio threads
wake from each USB transfer and wait for the GIL while the flight loop, the planners and the log's writer hold it,
up to a whole interval each time, three times a transaction. Eight drones on one emulated Crazyradio PA
(`missions/circle-8-r3.yaml` with ``dry_run.radio: crazyradio``, 2 cores): at 5 ms the dongle carried 130-170
transactions a second in flight, up to 45 of the 80 setpoints a second were replaced before their links took them
and seven of eight drones landed early; at 0.5 ms it carried 180-290, at most 13 a second were replaced (mostly
none) and all eight reached their goals (one run each; docs/radio.md, "A full dongle through it")."""


def _radio_threads_first(fly: Callable[P, FlightReport]) -> Callable[P, FlightReport]:
    """``fly`` with the process's GIL switch interval at most `FLIGHT_SWITCH_INTERVAL_S`, restored after."""

    @functools.wraps(fly)
    def flying(*args: P.args, **kwargs: P.kwargs) -> FlightReport:
        previous = sys.getswitchinterval()
        sys.setswitchinterval(min(previous, FLIGHT_SWITCH_INTERVAL_S))
        try:
            return fly(*args, **kwargs)
        finally:
            sys.setswitchinterval(previous)

    return flying


@_radio_threads_first
def run_flight(
    mission: Mission,
    planner_factory: PlannerFactory,
    log_path: Path | None,
    *,
    rig: DryRun | None = None,
    status_hook: Callable[[FlightLoop], None] | None = None,
    event_sinks: tuple[EventSink, ...] = (),
    on_loop: Callable[[FlightLoop], None] | None = None,
    seed: int = 0,
    live: LiveView | None = None,
) -> FlightReport:
    """Fly ``mission`` (on ``rig``'s simulated drones when given; the rig must be entered). ``on_loop`` receives the
    loop before it runs (signal handlers, fault injection). ``live``: a started live view, fed by the log's writer
    thread with every message the log writes (needs ``log_path``; the caller closes it after the flight). The
    process's GIL switch interval is `FLIGHT_SWITCH_INTERVAL_S` meanwhile."""
    from rpf_fly.radio.cflib_backend import CflibBackend

    if live is not None and not log_path:
        raise ValueError("the live view serves what the flight log writes: give a log path")
    if rig is not None:
        backend, source, uris = CflibBackend.for_mission(mission, rig.cache_dir), rig.entered_mocap(), rig.uris
    else:
        backend, source, uris = CflibBackend.for_mission(mission, DEFAULT_TOC_CACHE), mocap_source(mission), None
    recorder = None
    if log_path:
        truth = rig.truth_samples if rig is not None and rig.truth else None  # only a dry run has a truth
        if live is not None:
            live.prepare(live_topics(mission, truth is not None))
        recorder = McapRecorder(
            log_path,
            mission,
            seed,
            source="dry-run" if rig else "flight",
            truth=truth,
            sink=live.publish if live is not None else None,
            radio=backend.radio_counts,
            dynamics=rig.dynamics if rig is not None else None,
        )
    try:
        try:
            first_order = (
                {
                    name
                    for name, address in rig.addresses.items()
                    if rig.drone_configs[address].vehicle.dynamics == "first_order"
                }
                if rig is not None
                else set()
            )
            loop = FlightLoop(
                mission,
                backend,
                source,
                planner_factory,
                uris=uris,
                recorder=recorder,
                status_hook=status_hook,
                first_order=first_order,
            )
        except BaseException:
            if recorder is not None:  # the loop closes it once it exists; before that, nobody would
                recorder.close()
            raise
        for sink in event_sinks:
            loop.events.subscribe(sink)
        if on_loop is not None:
            on_loop(loop)
        watch = None
        if rig is not None:
            from rpf_fly.emulator.host_lag import LINKS
            from rpf_fly.flight.host_watch import HostWatch

            loop.events.subscribe(watched_window(loop))
            watch = HostWatch(rig.host_lag, loop.events).start()
        try:
            with reported_thread_deaths(loop.events):
                report = loop.run()
        finally:
            if watch is not None:
                watch.stop()
                LINKS.window = None
        if watch is not None:
            report.host_behind_s = watch.behind_s
        if recorder is not None:
            report.log_dropped, report.log_failed = recorder.log.dropped, recorder.log.failed
        return report
    finally:
        if rig is None:
            source.close()
