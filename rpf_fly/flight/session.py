"""Assemble and run one flight: the dry-run rig or the real hardware, the cflib backend, the recorder, the loop.

The CLI adds the console and the signal handlers around :func:`run_flight`; tests call it with fault hooks.
"""

from __future__ import annotations

import socket
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Optional

from rpf_fly.flight.events import EventSink
from rpf_fly.flight.loop import FlightLoop, FlightReport, PlannerFactory
from rpf_fly.flight.recording import McapRecorder
from rpf_fly.mission.model import Mission
from rpf_fly.mocap.frame import MocapSource

if TYPE_CHECKING:  # the dry run's emulators stay out of a real flight's imports
    from rpf_fly.flight.dry_run import DryRun
    from rpf_fly.log.live import LiveView

DEFAULT_TOC_CACHE = Path.home() / ".cache" / "rpf_fly" / "toc"


class UnresolvableServer(ValueError):
    """``mocap.server`` names no host this machine can resolve."""


def resolve_mocap_server(mission: Mission) -> str:
    """The mission's NatNet server as an IP address; :class:`UnresolvableServer` with the reason if it has none.
    Called before anything connects, so a typo never reaches a drone."""
    m = mission.mocap
    try:
        infos = socket.getaddrinfo(m.server, m.command_port, type=socket.SOCK_DGRAM)
    except (socket.gaierror, UnicodeError) as err:
        reason = err.strerror if isinstance(err, socket.gaierror) and err.strerror else str(err)
        raise UnresolvableServer(f"cannot resolve {m.server!r} ({reason}): expected the IP address or host name "
                                 "of the PC running Motive") from None
    return str(infos[0][4][0])


def natnet_source(mission: Mission, timeout_s: float = 5.0) -> MocapSource:
    """The mission's NatNet client, connected (raises ConnectionError if the server does not answer)."""
    from rpf_fly.mocap.natnet_client import NatNetClient

    resolve_mocap_server(mission)
    m = mission.mocap
    client = NatNetClient(
        m.server, multicast=m.multicast, local_ip=m.local_ip, multicast_group=m.multicast_group,
        command_port=m.command_port, data_port=m.data_port, up_axis=m.up_axis,
    )
    if not client.wait_for_server(timeout_s):
        client.close()
        raise ConnectionError(
            f"no answer from the NatNet server {m.server}:{m.command_port} within {timeout_s:.0f} s "
            "(is Motive streaming? try `rpf-fly mocap watch --natnet HOST`)"
        )
    return client


def run_flight(
    mission: Mission,
    planner_factory: PlannerFactory,
    log_path: Optional[Path],
    *,
    rig: Optional["DryRun"] = None,
    status_hook: Optional[Callable[[FlightLoop], None]] = None,
    event_sinks: tuple[EventSink, ...] = (),
    on_loop: Optional[Callable[[FlightLoop], None]] = None,
    seed: int = 0,
    live: Optional["LiveView"] = None,
) -> FlightReport:
    """Fly ``mission`` (on ``rig``'s simulated drones when given; the rig must be entered). ``on_loop`` receives the
    loop before it runs (signal handlers, fault injection). ``live``: a started live view, fed by the log's writer
    thread with every message the log writes (needs ``log_path``; the caller closes it after the flight)."""
    from rpf_fly.radio.cflib_backend import CflibBackend

    if live is not None and not log_path:
        raise ValueError("the live view serves what the flight log writes: give a log path")
    if rig is not None:
        backend, source, uris = CflibBackend(cache_dir=rig.cache_dir), rig.mocap, rig.uris
    else:
        backend, source, uris = CflibBackend(cache_dir=DEFAULT_TOC_CACHE), natnet_source(mission), None
    recorder = None
    if log_path:
        truth = rig.truth_samples if rig is not None and rig.truth else None  # only a dry run has a truth
        recorder = McapRecorder(log_path, mission, seed, source="dry-run" if rig else "flight", truth=truth,
                                sink=live.publish if live is not None else None)
    try:
        try:
            loop = FlightLoop(mission, backend, source, planner_factory, uris=uris, recorder=recorder,
                              status_hook=status_hook)
        except BaseException:
            if recorder is not None:  # the loop closes it once it exists; before that, nobody would
                recorder.close()
            raise
        for sink in event_sinks:
            loop.events.subscribe(sink)
        if on_loop is not None:
            on_loop(loop)
        report = loop.run()
        if recorder is not None:
            report.log_dropped, report.log_failed = recorder.log.dropped, recorder.log.failed
        return report
    finally:
        if rig is None:
            source.close()
