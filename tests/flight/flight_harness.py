"""Dry-run flight harness for the flight tests: real cflib over the fake radio, NatNet over loopback, a real MCAP
log; faults are injected from a thread once the swarm flies."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import host_retry

from rpf_fly.flight.dry_run import DryRun
from rpf_fly.flight.fault_injection import FaultInjection
from rpf_fly.flight.loop import FlightLoop, FlightReport
from rpf_fly.flight.phases import SwarmPhase
from rpf_fly.flight.session import run_flight
from rpf_fly.log.reader import LogData, read_log
from rpf_fly.planning.factory import make_planner
from rpf_fly.sim.scenario import obstacle_set

# margin 0: with the capture rule (docs/algorithm.md, *Arrival*) a dry run at the product's 0.05 m
# (planner.margin) takes as long (without it the outer drones of this line of goals 0.6 m apart circle their
# goals, arrived drones repelling as if 5 cm closer, for 17.5 s or more); the tests keep margin 0, the setting they
# are timed with: the replay tests build their rpf missions from this planner line, and the separation-hold test's
# geometry holds at margin 0 only. 0.8 m/s, not the product's 0.5: the three drones reach their goals 4.6 s after
# take-off instead of 7.2 s, in each of the sixty-odd flights of the suite flown on this mission.
SHORT_MISSION = """\
name: short-3
arena: {x: [-2.0, 2.0], y: [-2.0, 2.0], z: [0.0, 1.5]}
flight: {height: 0.5, speed: 0.8, rate_hz: 10, goal_tolerance: 0.1, takeoff_s: 1.0, land_s: 1.0, timeout_s: 30}
planner: {kind: apf, margin: 0}
mocap: {kind: sim, rate_hz: 100}
obstacles:
  - {shape: circle, center: [0.0, 0.9], radius: 0.1}
drones:
  - {name: cf1, uri: radio://0/80/2M/E7E7E7E701, start: [-1.0, -0.6], goal: [1.0, -0.6]}
  - {name: cf2, uri: radio://0/80/2M/E7E7E7E702, start: [-1.0, 0.0], goal: [1.0, 0.0]}
  - {name: cf3, uri: radio://0/80/2M/E7E7E7E703, start: [-1.0, 0.6], goal: [1.0, 0.6]}
"""


@dataclass
class Flight:
    """A finished dry-run flight: the loop's report, each fake drone's final state, the log read back."""

    report: FlightReport
    snapshots: dict
    log: LogData
    log_path: Path

    def events(self, kind: str, drone: str | None = None) -> list:
        return [e for e in self.report.events if e.kind == kind and (drone is None or e.drone == drone)]

    def logged_events(self) -> list[str]:
        return [m.data["message"] for m in self.log.messages("/events")]


def default_factory(mission):
    obstacles = obstacle_set(mission.obstacles)
    return lambda drone: make_planner(mission.planner, obstacles)


def fly(
    mission,
    tmp_path: Path,
    *,
    configs=None,
    start_faults=None,
    factory=None,
    when_flying: Callable[[FlightLoop, DryRun], None] | None = None,
    mocap: str = "natnet",
    process: bool = True,
) -> Flight:
    """Fly ``mission`` on simulated drones; ``when_flying(loop, rig)`` runs on its own thread once the swarm flies.
    ``configs`` and ``start_faults`` go to `DryRun` (``drone_configs``, ``start_faults``)."""
    log_path = tmp_path / "flight.mcap"
    with DryRun(mission, mocap=mocap, drone_configs=configs, start_faults=start_faults, process=process) as rig:
        FaultInjection.wrap(rig)  # rig.mocap.stall(seconds) blocks the loop thread (the loop_stall fault)
        workers: list[threading.Thread] = []

        def on_loop(loop: FlightLoop) -> None:
            if when_flying is None:
                return

            def wait_then_act() -> None:
                deadline = time.monotonic() + 30
                while loop.phase != SwarmPhase.FLYING and time.monotonic() < deadline:
                    if loop.phase in (SwarmPhase.ABORTED, SwarmPhase.DONE):
                        return
                    time.sleep(0.01)
                when_flying(loop, rig)

            worker = threading.Thread(target=wait_then_act, daemon=True)
            workers.append(worker)
            worker.start()

        report = run_flight(mission, factory or default_factory(mission), log_path, rig=rig, on_loop=on_loop)
        for worker in workers:
            worker.join(timeout=10)
        time.sleep(0.2)
        snapshots = {d.name: rig.snapshot(d.name) for d in mission.drones}
    return Flight(report, snapshots, read_log(log_path), log_path)


def held_back(flight: Flight) -> bool:
    """The flight's own events say the host held it back (`host_retry.STARVED_KINDS`)."""
    return any(e.kind in host_retry.STARVED_KINDS for e in flight.report.events)


def fly_to_every_goal(mission, tmp_path: Path, **kwargs) -> Flight:
    """`fly` for a flight that must reach every goal (a fixture others read), flown again while it did not and its
    own events say the host held it back (`host_retry.fly_on_time`)."""
    return host_retry.fly_on_time(
        lambda at: fly(mission, at, **kwargs), tmp_path, lambda f: f.report.success, held_back
    )


def fly_on_time(mission, tmp_path: Path, **kwargs) -> Flight:
    """`fly` for a test that judges how closely the simulated drones followed (their estimates, their tracking):
    flown again while its own events say the host held it back (a starved world drifts its estimators unfed, and
    that flight is not evidence), up to `host_retry.fly_on_time`'s tries; the last is judged whatever it did."""
    return host_retry.fly_on_time(
        lambda at: fly(mission, at, **kwargs), tmp_path, lambda f: not held_back(f), held_back
    )
