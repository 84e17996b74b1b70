"""The preflight rules: what must hold for a drone before anything takes off (docs/flight.md, "Stages").

Pure checks over what the loop knows of one drone (its radio state, its newest mocap pose and that pose's age);
each returns the first problem as a sentence a user can act on, or "" when the drone may fly. The loop runs them
until every drone passes or the preflight times out.
"""

from __future__ import annotations

from typing import Optional

from rpf_fly.flight.agent import DroneAgent
from rpf_fly.flight.poses import TrackedPose
from rpf_fly.mission.model import Mission
from rpf_fly.radio.backend import DroneState

ON_GROUND_MAX_Z_M = 0.3
"""A drone standing higher than this above the floor (mocap z = 0) is not on the ground (on a box, held in a hand)."""


def preflight_problem(mission: Mission, agent: DroneAgent, state: Optional[DroneState], pose: Optional[TrackedPose],
                      pose_age_s: float) -> str:
    """The first reason ``agent``'s drone must not take off, or ""."""
    s, arena = mission.safety, mission.arena
    if state is None or not state.link.up:
        return "no radio link"
    if state.supervisor is not None and (state.supervisor.locked or state.supervisor.crashed):
        return "the drone's supervisor is locked or crashed: reboot it"
    if state.battery is None:
        return "no battery telemetry yet"
    if state.battery.low or state.battery.voltage_v < mission.radio.min_battery_v:
        return f"battery {state.battery.voltage_v:.2f} V below {mission.radio.min_battery_v:.2f} V"
    if pose is None or not pose.valid or pose_age_s > s.pose_timeout_s:
        return f"rigid body {agent.drone.rigid_body!r} not tracked by the mocap"
    x, y, z = pose.position
    if not (arena.x[0] <= x <= arena.x[1] and arena.y[0] <= y <= arena.y[1]):
        return f"outside the arena at ({x:.2f}, {y:.2f})"
    if abs(pose.xy - agent.start) > s.start_tolerance_m:
        return (f"at ({x:.2f}, {y:.2f}), {abs(pose.xy - agent.start):.2f} m from its start "
                f"({agent.start.real:.2f}, {agent.start.imag:.2f}); allowed {s.start_tolerance_m:.2f} m")
    if z > ON_GROUND_MAX_Z_M:
        return f"not on the ground (z = {z:.2f} m)"
    return ""
