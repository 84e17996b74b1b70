"""The preflight rules: what must hold for a drone before anything takes off (docs/flight.md, "Stages").

Pure checks over what the loop knows of one drone (its radio state, its newest mocap pose and that pose's age);
each returns the first problem as a sentence a user can act on, or "" when the drone may fly. The loop runs them
until every drone passes or the preflight times out.
"""

from __future__ import annotations

import math

from rpf_fly.flight.agent import DroneAgent
from rpf_fly.flight.poses import PoseTracker, TrackedPose
from rpf_fly.mission.model import Mission
from rpf_fly.radio.backend import DroneState

ON_GROUND_MAX_Z_M = 0.3
"""A drone standing higher than this above the floor (mocap z = 0) is not on the ground (on a box, held in a hand)."""

NO_LINK = "no radio link"
NO_BATTERY = "no battery telemetry yet"
NOT_TRACKED = "not tracked by the mocap"
"""The problems that are an absence (of a link, of telemetry, of a pose), not a finding: data that may still come
(a link that is reconnecting, telemetry that starts, a rigid body someone steps out of the cameras' view of), so the
preflight waits its whole timeout for them (:func:`awaits_data`)."""


def awaits_data(problem: str) -> bool:
    """Whether ``problem`` (of :func:`preflight_problem`) says something has not arrived yet, rather than what the
    telemetry or the mocap shows (tumbled, low battery, off its start...): a finding the same data would only
    repeat, so the preflight need not wait its whole timeout for it to change."""
    return problem in (NO_LINK, NO_BATTERY) or problem.endswith(NOT_TRACKED)


def preflight_problem(
    mission: Mission, agent: DroneAgent, state: DroneState | None, pose: TrackedPose | None, pose_age_s: float
) -> str:
    """The first reason ``agent``'s drone must not take off, or ""."""
    s, arena = mission.safety, mission.arena
    if state is None or not state.link.up:
        return NO_LINK
    if state.supervisor is not None and (state.supervisor.locked or state.supervisor.crashed):
        return "the drone's supervisor is locked or crashed: reboot it"
    if state.supervisor is not None and state.supervisor.tumbled:
        return "the drone's supervisor reports it tumbled (on its back or tilted): set it upright"
    if state.battery is None:
        return NO_BATTERY
    if state.battery.low or state.battery.voltage_v < mission.radio.min_battery_v:
        return f"battery {state.battery.voltage_v:.2f} V below {mission.radio.min_battery_v:.2f} V"
    if pose is None or not pose.valid or pose_age_s > s.pose_timeout_s:
        return f"rigid body {agent.drone.rigid_body!r} {NOT_TRACKED}"
    x, y, z = pose.position
    if not (arena.x[0] <= x <= arena.x[1] and arena.y[0] <= y <= arena.y[1]):
        return f"outside the arena at ({x:.2f}, {y:.2f})"
    if abs(pose.xy - agent.start) > s.start_tolerance_m:
        return (
            f"at ({x:.2f}, {y:.2f}), {abs(pose.xy - agent.start):.2f} m from its start "
            f"({agent.start.real:.2f}, {agent.start.imag:.2f}); allowed {s.start_tolerance_m:.2f} m"
        )
    if z > ON_GROUND_MAX_Z_M:
        return f"not on the ground (z = {z:.2f} m)"
    return ""


def orientation_problem(tracker: PoseTracker, name: str) -> str:
    """Why a drone whose mocap orientation is refused as a jump (`PoseTracker.orientation_glitching`) must not take
    off: one of the two fits is wrong and nothing says which, and its estimator would start from that yaw."""
    degrees, seconds = tracker.last_turn.get(name, (math.nan, math.nan))
    return (
        f"mocap's orientation of its rigid body turned {degrees:.0f} deg in {seconds * 1e3:.0f} ms and has not "
        "turned back: a wrong fit of its markers (a nearly symmetric marker set?); which fit is right is "
        "unknown, so its estimator is not started from it: check the rigid body in Motive"
    )


ESTIMATE_POSITION_TOLERANCE_M = 0.1
"""How far the on-board position estimate may be from mocap before take-off: extpos at tens of hertz holds it
within a centimetre, so a decimetre means the estimator did not take the mocap (wrong rigid body, no extpos)."""

ESTIMATE_YAW_TOLERANCE_DEG = 10.0
"""How far the on-board yaw estimate may be from mocap's yaw before take-off. With position-only extpos nothing
corrects yaw in flight, and the position controller acts in the estimated frame: 10 degrees bends the path by a
sixth of each move; 90 or more and the drone flies away from its setpoint."""


def yaw_of(quaternion: tuple[float, float, float, float]) -> float:
    """Yaw (radians, about world z) of a unit quaternion (qx, qy, qz, qw), world from body."""
    qx, qy, qz, qw = quaternion
    return math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))


def estimate_problem(state: DroneState | None, pose: TrackedPose, since_s: float) -> str:
    """Whether the drone's on-board estimate agrees with mocap (position and yaw), from telemetry newer than
    ``since_s`` (the estimator reset); "" when it does."""
    if state is None or state.telemetry_stamp_s is None or state.telemetry_stamp_s <= since_s:
        return "no estimator telemetry since its reset"
    if state.position_m is None or state.yaw_deg is None:
        return "no position or yaw estimate in its telemetry"
    off = math.dist(state.position_m, pose.position)
    if off > ESTIMATE_POSITION_TOLERANCE_M:
        ex, ey, ez = state.position_m
        return (
            f"its on-board position estimate ({ex:.2f}, {ey:.2f}, {ez:.2f}) is {off:.2f} m from mocap's: is "
            "the rigid body the right drone, and does extpos reach it?"
        )
    return yaw_problem(state, pose)


def yaw_problem(state: DroneState | None, pose: TrackedPose) -> str:
    """Whether the drone's yaw estimate is off mocap's yaw by more than ``ESTIMATE_YAW_TOLERANCE_DEG``; "" if
    not (or if there is no yaw estimate yet)."""
    if state is None or state.yaw_deg is None:
        return ""
    mocap_yaw = math.degrees(yaw_of(pose.quaternion))
    yaw_error = (state.yaw_deg - mocap_yaw + 180.0) % 360.0 - 180.0
    if abs(yaw_error) > ESTIMATE_YAW_TOLERANCE_DEG:
        return (
            f"its on-board yaw estimate {state.yaw_deg:.0f} deg is {abs(yaw_error):.0f} deg from mocap's "
            f"{mocap_yaw:.0f} deg: under position control it would fly off"
        )
    return ""
