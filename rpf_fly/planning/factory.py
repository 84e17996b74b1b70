"""From a mission's planner settings to a :class:`~rpf_fly.planning.Planner`: the one factory the simulator, the
bench, the trainer's evaluation, the flight, its dry run and its replay build their planners with.

Beside the planners so that every layer above (sim, bench, flight, the application layer) reaches it without
importing one another. It reads the mission's dataclasses (``rpf_fly.mission.model``: data only) and stays pure
like the rest of planning/: no sockets, threads, clocks or torch; onnxruntime only through
:mod:`rpf_fly.planning.onnx_policy`, for the learned kinds.

``apf`` is the vanilla APF with the robust preset, ``apf-paper`` the literal formulas (docs/algorithm.md, *Presets*);
both use fixed gains (eta, lambda from the mission; the paper's 0.05 and 2 by default). ``rpf``, ``rpf-mean`` and
``rpf3`` (RPF-3) take their gains from an ONNX policy every step; ``ppo`` is the vanilla-PPO baseline that turns the
heading with no APF; ``orca`` the ORCA baseline.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, TypeAlias

import numpy as np

from rpf_fly.mission.model import BoxObstacle, CircleObstacle, Mission, Obstacle, PlannerSettings
from rpf_fly.planning.config import RPF3_TUNING, PlannerConfig
from rpf_fly.planning.gains import FixedGains
from rpf_fly.planning.guidance import Bounds
from rpf_fly.planning.heading_policy import HeadingPolicyPlanner
from rpf_fly.planning.obstacles import ObstacleSet
from rpf_fly.planning.onnx_policy import OnnxGains, OnnxPolicy
from rpf_fly.planning.planner import Planner

if TYPE_CHECKING:
    from rpf_fly.planning.orca import OrcaPlanner

AnyPlanner: TypeAlias = "Planner | HeadingPolicyPlanner | OrcaPlanner"
"""What :func:`make_planner` builds for a mission's planner kind."""


class UnsupportedPlanner(ValueError):
    """The planner kind is valid in a mission but not available in this build."""


def obstacle_set(shapes: Sequence[Obstacle]) -> ObstacleSet:
    """Planner arrays from mission obstacle shapes."""
    circles = [(o.center, o.radius) for o in shapes if isinstance(o, CircleObstacle)]
    boxes = [(o.min, o.max) for o in shapes if isinstance(o, BoxObstacle)]
    return ObstacleSet.from_shapes(circles, boxes)


def planner_config(settings: PlannerSettings) -> PlannerConfig:
    """The APF parameters of a mission (``apf-paper`` forces the paper preset; ``rpf3`` with the robust preset adds
    :data:`~rpf_fly.planning.config.RPF3_TUNING`)."""
    preset = "paper" if settings.kind == "apf-paper" else settings.preset
    tuning = RPF3_TUNING if settings.kind == "rpf3" and preset == "robust" else {}
    return PlannerConfig.preset(
        preset,
        capture_radius=settings.capture_radius_m,
        safety_radius=settings.safety_radius,
        sensing_range=settings.sensing_range,
        influence_range=settings.influence_range,
        wall_following=settings.wall_following,
        wall_threshold=settings.wall_threshold,
        neighbour_aggregate=settings.neighbour_aggregate,
        guidance=settings.guidance_mode,
        margin=settings.margin_m,
        **tuning,
    )


def make_planner(
    settings: PlannerSettings,
    obstacles: ObstacleSet,
    bounds: Bounds | None = None,
    goals: np.ndarray | None = None,
) -> AnyPlanner:
    """The planner a mission asks for. Raises :class:`PolicyError` for an unusable policy file.

    With guidance, ``bounds`` (the arena's ((x_lo, x_hi), (y_lo, y_hi))) keeps the path's corners inside the
    geofence and ``goals`` (the mission's) are prepared now rather than at the first tick."""
    planner = _make(settings, obstacles, planner_config(settings), bounds)
    if goals is not None and hasattr(planner, "prepare"):
        planner.prepare(np.asarray(goals, dtype=complex))
    return planner


def mission_planner(mission: Mission, settings: PlannerSettings | None = None, obstacles: ObstacleSet | None = None):
    """The planner of a mission as the flight, its dry run and its replay build it: the mission's obstacles, its arena
    as the guidance bounds and every drone's goal prepared at load time (the flight's tick then only looks up the
    next visible waypoint)."""
    return make_planner(
        settings or mission.planner,
        obstacles if obstacles is not None else obstacle_set(mission.obstacles),
        (mission.arena.x, mission.arena.y),
        np.array([complex(*d.goal) for d in mission.drones]),
    )


def _make(
    settings: PlannerSettings, obstacles: ObstacleSet, config: PlannerConfig, bounds: Bounds | None
) -> AnyPlanner:
    if settings.kind in ("apf", "apf-paper"):
        return Planner(obstacles, config, FixedGains(settings.eta, settings.lam), bounds)
    if settings.kind == "orca":
        from rpf_fly.planning.orca import OrcaPlanner

        return OrcaPlanner(obstacles, config, margin=settings.margin_m, bounds=bounds)
    if settings.policy is None:
        raise UnsupportedPlanner(f"planner kind {settings.kind!r} needs an ONNX policy")
    policy = OnnxPolicy(settings.policy)
    if settings.kind in ("rpf", "rpf-mean", "rpf3"):
        return Planner(obstacles, config, OnnxGains(policy), bounds)
    if settings.kind == "ppo":
        return HeadingPolicyPlanner(obstacles, config, policy, bounds)
    raise UnsupportedPlanner(f"planner kind {settings.kind!r} is not available")
