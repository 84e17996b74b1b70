"""The whole-mission checks, once every section has been read: starts and goals against the arena, the obstacles
and each other; the flight height and circles against the arena; the mocap rate against the pose timeout. Why
apart: they judge a complete `Mission`, the file's and one the CLI changed (`with_planner`) alike.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from . import model as m
from .checker import fmt, fmt_point
from .errors import MissionError
from .sections import FIRMWARE_MAIN_LOOP_HZ, period_slip, unit_slip

LayoutError = Callable[..., MissionError]
"""``(path, message, at=())`` -> the error to raise: ``path`` is the field at fault (``drones[2].start``),
``at`` other paths whose line to use when ``path`` has no line of its own (a defaulted value)."""


def _clearance(p: m.Vec2, obstacle: m.Obstacle) -> float:
    """Distance from ``p`` to the obstacle's surface, 0 (box) or negative (circle) inside."""
    if isinstance(obstacle, m.CircleObstacle):
        return math.hypot(p[0] - obstacle.center[0], p[1] - obstacle.center[1]) - obstacle.radius
    dx = max(obstacle.min[0] - p[0], 0.0, p[0] - obstacle.max[0])
    dy = max(obstacle.min[1] - p[1], 0.0, p[1] - obstacle.max[1])
    return math.hypot(dx, dy)


def _describe_obstacle(obstacle: m.Obstacle) -> str:
    if isinstance(obstacle, m.CircleObstacle):
        return f"circle at {fmt_point(obstacle.center)} radius {fmt(obstacle.radius)}"
    return f"box {fmt_point(obstacle.min)}-{fmt_point(obstacle.max)}"


def check_layout(mission: m.Mission, error: LayoutError) -> None:
    """The whole-mission checks: flight height in arena.z; a pose at least every safety.pose_timeout_s; circular
    obstacles no wider than the arena (and a formation radius written in cm or mm); every start and goal inside
    arena.x/y, clear of every obstacle by planner.safety_radius, start and goal at least flight.goal_tolerance apart,
    starts at least 2 safety_radius apart, goals at least 4 safety_radius apart. Raises ``error(path, message)``."""
    arena, r = mission.arena, mission.planner.safety_radius
    h = mission.flight.height
    if not arena.z[0] <= h <= arena.z[1]:
        hint = unit_slip(h, "m", lambda x: max(arena.z[0], 0.1) <= x <= arena.z[1])
        raise error(
            "flight.height",
            f"{fmt(h)} is outside arena.z [{fmt(arena.z[0])}, {fmt(arena.z[1])}]"
            f"{'; heights are in m' + hint if hint else ''}",
            at=("arena.z", "flight", "arena"),
        )
    _check_rates(mission, error)
    _check_radii(mission, error)
    tolerance = mission.flight.goal_tolerance
    for i, drone in enumerate(mission.drones):
        for what, p in (("start", drone.start), ("goal", drone.goal)):
            path = f"drones[{i}].{what}"
            for axis, span in (("x", arena.x), ("y", arena.y)):
                v = p[0] if axis == "x" else p[1]
                if not span[0] <= v <= span[1]:
                    raise error(
                        path,
                        f"{fmt_point(p)} is outside the arena: {axis} {fmt(v)} not in arena.{axis} "
                        f"[{fmt(span[0])}, {fmt(span[1])}]",
                    )
        d = math.dist(drone.start, drone.goal)
        if d < tolerance:
            raise error(
                f"drones[{i}].start",
                f"start {fmt_point(drone.start)} and goal {fmt_point(drone.goal)} are "
                f"{fmt(d)} m apart, less than flight.goal_tolerance {fmt(tolerance)} m (start equals goal)",
            )
        for what, p in (("start", drone.start), ("goal", drone.goal)):
            for k, obstacle in enumerate(mission.obstacles):
                c = _clearance(p, obstacle)
                if c <= 0:
                    raise error(
                        f"drones[{i}].{what}",
                        f"{fmt_point(p)} is inside obstacles[{k}] ({_describe_obstacle(obstacle)})",
                    )
                if c < r:
                    raise error(
                        f"drones[{i}].{what}",
                        f"{fmt_point(p)} is {fmt(c)} m from the surface of obstacles[{k}] "
                        f"({_describe_obstacle(obstacle)}), less than planner.safety_radius {fmt(r)} m",
                    )
    _check_spacing(mission, "start", 2 * r, "2 x planner.safety_radius", "they would start in collision", error)
    _check_spacing(
        mission,
        "goal",
        4 * r,
        "4 x planner.safety_radius",
        f"an arrived drone is held as an obstacle of radius {fmt(r)} m",
        error,
    )


def _check_rates(mission: m.Mission, error: LayoutError) -> None:
    """A pose at least once every ``safety.pose_timeout_s``: a slower mocap would hold every drone between frames."""
    rate, timeout = mission.mocap.rate_hz, mission.safety.pose_timeout_s
    if 1.0 / rate >= timeout:
        hint = period_slip(rate, lambda x: 1.0 / x < timeout and x <= FIRMWARE_MAIN_LOOP_HZ)
        raise error(
            "mocap.rate_hz",
            f"{fmt(rate)} Hz: a pose every {fmt(1.0 / rate)} s, not within "
            f"safety.pose_timeout_s ({fmt(timeout)} s), so every drone would hold between frames; rates are "
            f"in Hz{hint}",
            at=("safety.pose_timeout_s", "mocap", "safety"),
        )


def _check_radii(mission: m.Mission, error: LayoutError) -> None:
    """Circles that fit the arena: an obstacle no wider than the arena's larger side, a formation whose circle lies
    in the arena (only when the radius reads as centimetres or millimetres; otherwise its drones' starts say it)."""
    arena = mission.arena
    width = max(arena.x[1] - arena.x[0], arena.y[1] - arena.y[0])
    size = f"arena.x [{fmt(arena.x[0])}, {fmt(arena.x[1])}], arena.y [{fmt(arena.y[0])}, {fmt(arena.y[1])}]"
    for k, obstacle in enumerate(mission.obstacles):
        if isinstance(obstacle, m.CircleObstacle) and 2 * obstacle.radius > width:
            hint = unit_slip(obstacle.radius, "m", lambda x: 0.01 <= x <= width / 2)
            raise error(
                f"obstacles[{k}].radius",
                f"{fmt(obstacle.radius)} m: a circle {fmt(2 * obstacle.radius)} m "
                f"across, wider than the arena ({size}); lengths are in m{hint}",
            )
    formation = mission.formation
    if formation is not None:
        cx, cy = formation.center

        def fits(radius: float) -> bool:
            return (
                arena.x[0] <= cx - radius
                and cx + radius <= arena.x[1]
                and arena.y[0] <= cy - radius
                and cy + radius <= arena.y[1]
            )

        hint = unit_slip(formation.radius, "m", lambda x: x >= 0.1 and fits(x))
        if hint and not fits(formation.radius):
            raise error(
                "formation.radius",
                f"{fmt(formation.radius)} m: the circle around "
                f"{fmt_point(formation.center)} leaves the arena ({size}); lengths are in m{hint}",
            )


def _check_spacing(mission: m.Mission, what: str, minimum: float, label: str, why: str, error: LayoutError) -> None:
    points = np.array([getattr(d, what) for d in mission.drones], dtype=float).reshape(-1, 2)
    for i in range(1, len(points)):
        dist = np.hypot(*(points[:i] - points[i]).T)
        j = int(np.argmin(dist))
        if dist[j] < minimum:
            other = mission.drones[j]
            raise error(
                f"drones[{i}].{what}",
                f"{what} {fmt_point(points[i])} is {fmt(dist[j])} m from the {what} of drones[{j}] "
                f"({other.name}), less than {label} = {fmt(minimum)} m ({why})",
            )
