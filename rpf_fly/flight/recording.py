"""The flight loop's recorder writing the MCAP flight log (docs/log-format.md).

Converts the loop's monotonic seconds to nanoseconds since the Unix epoch (one offset taken at the start), and
the loop's objects to the log's topics: poses and /tf at the mocap rate, planner steps and setpoints at the
planning rate, status at 10 Hz, events as they happen, the scene once.
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Optional

from rpf_fly.flight.agent import DroneAgent
from rpf_fly.flight.events import FlightEvent
from rpf_fly.flight.poses import TrackedPose
from rpf_fly.log import schemas as S
from rpf_fly.log.writer import FlightLog
from rpf_fly.mission.model import Mission
from rpf_fly.planning.obstacles import FAR
from rpf_fly.planning.planner import PlanStep
from rpf_fly.radio.backend import DroneState


TF_PERIOD_S = 0.05
"""/tf at 20 Hz: it repeats the mocap poses (logged at the full rate) for Foxglove's 3D panel, which needs no more."""

DRAIN_PERIOD_S = 0.05
"""The writer drains right after a planning tick at most this often (:meth:`McapRecorder.after_tick`)."""

POLL_FALLBACK_S = 0.25
"""The writer's own drain period in a flight: only a fallback when no tick asks (take-off, landing)."""


class McapRecorder:
    """Implements :class:`rpf_fly.flight.loop.Recorder` on a :class:`~rpf_fly.log.writer.FlightLog`."""

    def __init__(self, path: str | Path, mission: Mission, seed: int = 0, source: str = "flight"):
        self.mission = mission
        self.log = FlightLog(path, S.mission_metadata(mission, seed, source=source), S.scenario_metadata(mission),
                             poll_interval_s=POLL_FALLBACK_S)
        self._last_drain_s = -math.inf
        self._offset_s = time.time() - time.monotonic()
        self._sensing = mission.planner.sensing_range
        self._last_tf_s = -math.inf
        now = self._ns(time.monotonic())
        arena = {"x": list(mission.arena.x), "y": list(mission.arena.y), "z": list(mission.arena.z)}
        goals = {d.name: complex(*d.goal) for d in mission.drones}
        self.log.scene(now, [S._obstacle_dict(o) for o in mission.obstacles], goals, arena, mission.flight.height)  # noqa: SLF001

    @property
    def path(self) -> Path:
        return self.log.path

    def _ns(self, t_s: float) -> int:
        return int(round((t_s + self._offset_s) * 1e9))

    def poses(self, t_s: float, poses: dict[str, TrackedPose]) -> None:
        t = self._ns(t_s)
        for name, pose in poses.items():
            self.log.pose(name, t, pose.position, pose.quaternion)
        if poses and t_s - self._last_tf_s >= TF_PERIOD_S:
            self._last_tf_s = t_s
            self.log.tf(t, {name: (pose.position, pose.quaternion) for name, pose in poses.items()})

    def planner(self, t_s: float, tick: int, agent: DroneAgent, pose: Optional[TrackedPose], step: Optional[PlanStep],
                mode: str) -> None:
        if pose is None:
            return
        common = dict(tick=tick, position=pose.position, goal=agent.goal, heading=math.atan2(agent.heading.imag, agent.heading.real),
                      goal_distance=abs(agent.goal - pose.xy))
        if step is None:
            self.log.planner_step(agent.name, self._ns(t_s), mode=mode, eta=None, lam=None, **common)
            return
        d_o = float(step.obstacle_distance)
        self.log.planner_step(
            agent.name, self._ns(t_s), mode=mode, eta=float(step.eta), lam=float(step.lam), f_a=complex(step.f_a),
            f_r=complex(step.f_r), f_in=complex(step.f_in), direction=complex(step.direction),
            neighbours=int(step.neighbours), obstacle_distance=d_o if d_o < min(FAR, self._sensing + 1e-9) else None,
            **common,
        )

    def after_tick(self, t_s: float) -> None:
        """The loop finished a planning tick and waits for the next frame: let the writer drain now (its GIL-holding
        burst then falls in that idle gap instead of delaying the next frame's setpoints)."""
        if t_s - self._last_drain_s >= DRAIN_PERIOD_S:
            self._last_drain_s = t_s
            self.log.drain_soon()

    def setpoint(self, t_s: float, name: str, position: tuple[float, float, float]) -> None:
        self.log.setpoint(name, self._ns(t_s), position, 0.0)

    def status(self, t_s: float, agent: DroneAgent, state: Optional[DroneState]) -> None:
        battery = state.battery.voltage_v if state is not None and state.battery is not None else None
        quality = state.link.quality_pct / 100.0 if state is not None and state.link.quality_pct is not None else None
        latency = state.link.latency_ms if state is not None else None
        outcome = agent.outcome.value if agent.outcome is not None and agent.phase.terminal else None
        self.log.status(agent.name, self._ns(t_s), state=agent.phase.value, battery_v=battery, link_quality=quality,
                        latency_ms=latency, outcome=outcome)

    def event(self, event: FlightEvent) -> None:
        self.log.event(self._ns(event.time_s), event.level, event.message, name=event.drone or "flight",
                       file=event.kind)

    def close(self) -> None:
        self.log.close()
