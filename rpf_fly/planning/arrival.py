"""The capture rule: the last few centimetres to the goal, where the APF's own fields cannot settle a drone.

Why (docs/algorithm.md, *Arrival: the capture rule*): the attraction is a unit vector, and the repulsion of the
nearest obstacle or arrived neighbour exceeds it within about 0.36 m of the (margin-grown) surface. A goal inside
that band has no balance point at all: the drone's forces cancel only beyond the goal, and wall-following turns
that into an orbit of the obstacle that passes the goal at 0.10-0.19 m once a lap, never inside the 0.1 m
tolerance, until the time limit (11 of RPF-3's 13 failed runs on the scene families).

The rule: a drone closer to its goal than ``config.capture_radius`` **and** closer to its goal than to the
nearest obstacle surface (static neighbours included) heads straight at the goal, plus the inter-robot force of
the moving neighbours capped at :data:`MAX_INTER_ROBOT` (so it deflects but can never cancel the pull: two drones
near their goals pushing each other apart stalled the fixed-gain APF in 2 circles of 24 without the cap), in
mode ``apf``. Why it keeps every clearance: the disc of radius ``d_g`` around the drone
holds no obstacle, so the segment to the goal is free; and the distance to a convex shape (a circle, a box, a
hovering drone) is convex along a segment, so nowhere on it is the drone nearer any obstacle than it is now or
than its goal is. The static repulsion the rule drops can only add what the goal itself has. Pure function of the
drone's position, goal, nearest-obstacle distance and inter-robot force: batched and one-drone calls agree.
"""

from __future__ import annotations

import numpy as np

from rpf_fly.planning.config import PlannerConfig
from rpf_fly.planning.vectors import TINY, Planar, Scalar, any_true, minimum, norm, unit
from rpf_fly.planning.wall_following import MODE_APF

MAX_INTER_ROBOT = 0.5
"""The moving neighbours' force is capped at this magnitude inside the capture radius (0 drops it)."""


def captured(position: Planar, goal: Planar, obstacle_distance: Scalar, config: PlannerConfig) -> np.ndarray | bool:
    """Where the capture rule applies: the goal nearer than ``capture_radius`` and than the nearest surface
    (``obstacle_distance``: the true signed distance, FAR when none). All false when the radius is 0."""
    d_g = norm(goal - position)
    return (d_g < config.capture_radius) & (d_g < obstacle_distance)


def capture(
    direction: Planar,
    mode: Scalar,
    position: Planar,
    goal: Planar,
    f_in: Planar,
    obstacle_distance: Scalar,
    config: PlannerConfig,
) -> tuple[Planar, Scalar]:
    """``(direction, mode)`` with the captured drones heading at ``unit(unit(goal - position) + f_in)`` (``f_in``
    capped at :data:`MAX_INTER_ROBOT`) in mode ``apf``; the others unchanged (the same objects when no drone is
    captured or the radius is 0)."""
    if not config.capture_radius:
        return direction, mode
    near = captured(position, goal, obstacle_distance, config)
    if not any_true(near):
        return direction, mode
    f_in = f_in * minimum(MAX_INTER_ROBOT / (norm(f_in) + TINY), 1.0)
    straight = unit(unit(goal - position) + f_in)
    if isinstance(near, np.ndarray):
        direction = np.where(near, straight, direction)
        mode = np.where(near, np.int8(MODE_APF), mode).astype(np.int8)
        return direction, mode
    return straight, MODE_APF
