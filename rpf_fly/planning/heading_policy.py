"""The vanilla-PPO baseline planner: a policy turns the heading directly, with no APF (paper Section V).

``F = (v + a v_perp) / |v + a v_perp|`` with ``v`` the current heading, ``v_perp`` it turned 90 degrees
counter-clockwise and ``a`` in [-2.5, 2.5] from the policy. The observation is the same as RPF's.
"""

from __future__ import annotations

import numpy as np

from rpf_fly.planning.arrival import capture
from rpf_fly.planning.config import PlannerConfig
from rpf_fly.planning.forces import attractive
from rpf_fly.planning.observation import build_observation
from rpf_fly.planning.obstacles import ObstacleSet
from rpf_fly.planning.onnx_policy import OnnxPolicy, PolicyError
from rpf_fly.planning.planner import PlanStep, guided_view, make_guidance, sense_obstacles
from rpf_fly.planning.vectors import Planar, Scalar, norm, unit
from rpf_fly.planning.view import LocalView
from rpf_fly.planning.visibility import Bounds


class HeadingPolicyPlanner:
    """Same interface as :class:`~rpf_fly.planning.Planner`; forces in the diagnostics are the attraction only.
    The capture rule (:mod:`rpf_fly.planning.arrival`) applies as for the APF planners (no inter-robot force)."""

    def __init__(self, obstacles: ObstacleSet, config: PlannerConfig, policy: OnnxPolicy, bounds: Bounds | None = None):
        if policy.action != "heading":
            raise PolicyError(f"{policy.path}: a {policy.action!r} policy cannot steer the heading")
        self.obstacles = obstacles
        self.config = config
        self.policy = policy
        self.guidance = make_guidance(obstacles, config, bounds)

    def prepare(self, goals: np.ndarray) -> None:
        """Precompute the guidance of these goals (as :meth:`Planner.prepare`)."""
        if self.guidance is not None:
            self.guidance.prepare(goals)

    def step(self, view: LocalView) -> PlanStep:
        nearest, lambda_mask = sense_obstacles(view, self.obstacles, self.config)
        goal = view.goal
        view, waypoint, remaining = guided_view(view, self.guidance)
        observation = build_observation(view, nearest, self.config, self.policy.max_neighbours, remaining)
        action = self.policy.act(observation)[..., 0].astype(float)
        a: Scalar = float(action) if action.ndim == 0 else action
        direction: Planar = unit(view.heading + a * (1j * view.heading))
        f_a, d_g = attractive(view.position, view.goal)
        zero = f_a * 0
        mode: Scalar = zero.real.astype(np.int8) if isinstance(zero, np.ndarray) else 0
        direction, mode = capture(direction, mode, view.position, goal, zero, nearest.distance, self.config)
        count = lambda_mask.sum(axis=-1) if isinstance(lambda_mask, np.ndarray) else 0
        return PlanStep(
            direction=direction,
            mode=mode,
            f_a=f_a,
            f_r=zero,
            f_in=zero,
            eta=np.nan,
            lam=np.nan,
            neighbours=count,
            obstacle_distance=nearest.distance,
            goal_distance=d_g if waypoint is None else norm(goal - view.position),
            observation=observation,
            waypoint=waypoint,
        )
