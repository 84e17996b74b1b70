"""What the flight loop writes down, as a protocol: the MCAP flight log implements it
(:class:`rpf_fly.flight.recording.McapRecorder`), :class:`NullRecorder` records nothing. Kept apart from the loop so
the loop does not import the log (and its writer thread) to say what it needs."""

from __future__ import annotations

import time
from typing import Protocol

from rpf_fly.flight.agent import DroneAgent
from rpf_fly.flight.events import FlightEvent
from rpf_fly.flight.poses import TrackedPose
from rpf_fly.planning.planner import PlanStep
from rpf_fly.radio.backend import DroneState

PlannerRecord = tuple[DroneAgent, TrackedPose | None, PlanStep | None, str]
"""One drone's planner row of a tick: the agent, its pose, its step (None when it did not plan) and its mode."""


class Recorder(Protocol):
    """Where the loop writes what happened. Times are the loop's monotonic seconds."""

    def poses(self, t_s: float, poses: dict[str, TrackedPose]) -> None: ...
    def planner_steps(self, t_s: float, tick: int, records: list[PlannerRecord]) -> None: ...
    def setpoints(self, sent: list[tuple[str, tuple[float, float, float], float]]) -> None: ...
    def status(self, t_s: float, agent: DroneAgent, state: DroneState | None) -> None: ...
    def event(self, event: FlightEvent) -> None: ...
    def after_tick(self, t_s: float) -> None: ...
    def close(self) -> None: ...


class NullRecorder:
    """Records nothing."""

    def poses(self, *args: object) -> None: ...
    def planner_steps(self, *args: object) -> None: ...
    def setpoints(self, *args: object) -> None: ...
    def status(self, *args: object) -> None: ...
    def event(self, *args: object) -> None: ...
    def after_tick(self, *args: object) -> None: ...
    def close(self) -> None: ...


class MeteredRecorder:
    """A :class:`Recorder` that adds up the CPU time (``time.thread_time``, of whichever thread calls) its calls take
    before they return: what logging costs the flight loop's own thread (the hand-over to the log writer), for a
    worker's logging figure (docs/performance.md). The calls go on to ``inner`` unchanged."""

    def __init__(self, inner: Recorder):
        self.inner = inner
        self.cpu_s = 0.0

    def poses(self, t_s: float, poses: dict[str, TrackedPose]) -> None:
        c = time.thread_time()
        self.inner.poses(t_s, poses)
        self.cpu_s += time.thread_time() - c

    def planner_steps(self, t_s: float, tick: int, records: list[PlannerRecord]) -> None:
        c = time.thread_time()
        self.inner.planner_steps(t_s, tick, records)
        self.cpu_s += time.thread_time() - c

    def setpoints(self, sent: list[tuple[str, tuple[float, float, float], float]]) -> None:
        c = time.thread_time()
        self.inner.setpoints(sent)
        self.cpu_s += time.thread_time() - c

    def status(self, t_s: float, agent: DroneAgent, state: DroneState | None) -> None:
        c = time.thread_time()
        self.inner.status(t_s, agent, state)
        self.cpu_s += time.thread_time() - c

    def event(self, event: FlightEvent) -> None:
        c = time.thread_time()
        self.inner.event(event)
        self.cpu_s += time.thread_time() - c

    def after_tick(self, t_s: float) -> None:
        c = time.thread_time()
        self.inner.after_tick(t_s)
        self.cpu_s += time.thread_time() - c

    def close(self) -> None:
        self.inner.close()
