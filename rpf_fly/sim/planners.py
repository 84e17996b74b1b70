"""From a mission's planner settings to a :class:`~rpf_fly.planning.Planner` (used by sim, bench and flight).

``apf`` is the vanilla APF with the robust preset, ``apf-paper`` the literal formulas (docs/algorithm.md, *Presets*); both use
fixed gains (eta, lambda from the mission; the paper's 0.05 and 2 by default). ``rpf`` and ``rpf-mean`` take their
gains from an ONNX policy every step; ``ppo`` is the vanilla-PPO baseline that turns the heading with no APF.
"""

from __future__ import annotations

from rpf_fly.mission.model import PlannerSettings
from rpf_fly.planning.config import PlannerConfig
from rpf_fly.planning.gains import FixedGains
from rpf_fly.planning.heading_policy import HeadingPolicyPlanner
from rpf_fly.planning.onnx_policy import OnnxGains, OnnxPolicy
from rpf_fly.planning.obstacles import ObstacleSet
from rpf_fly.planning.planner import Planner


class UnsupportedPlanner(ValueError):
    """The planner kind is valid in a mission but not available in this build."""


def planner_config(settings: PlannerSettings) -> PlannerConfig:
    """The APF parameters of a mission (``apf-paper`` forces the paper preset)."""
    preset = "paper" if settings.kind == "apf-paper" else settings.preset
    return PlannerConfig.preset(
        preset,
        safety_radius=settings.safety_radius,
        sensing_range=settings.sensing_range,
        influence_range=settings.influence_range,
        wall_following=settings.wall_following,
        wall_threshold=settings.wall_threshold,
        neighbour_aggregate=settings.neighbour_aggregate,
    )


def make_planner(settings: PlannerSettings, obstacles: ObstacleSet) -> Planner | HeadingPolicyPlanner:
    """The planner a mission asks for. Raises :class:`PolicyError` for an unusable policy file."""
    config = planner_config(settings)
    if settings.kind in ("apf", "apf-paper"):
        return Planner(obstacles, config, FixedGains(settings.eta, settings.lam))
    if settings.kind == "orca":
        from rpf_fly.planning.orca import OrcaPlanner

        return OrcaPlanner(obstacles, config)
    if settings.policy is None:
        raise UnsupportedPlanner(f"planner kind {settings.kind!r} needs an ONNX policy")
    policy = OnnxPolicy(settings.policy)
    if settings.kind in ("rpf", "rpf-mean"):
        return Planner(obstacles, config, OnnxGains(policy))
    if settings.kind == "ppo":
        return HeadingPolicyPlanner(obstacles, config, policy)
    raise UnsupportedPlanner(f"planner kind {settings.kind!r} is not available")
