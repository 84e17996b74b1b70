"""Kinematic simulation: scenarios, the point-mass world, collisions, metrics and rollouts (docs/metrics.md)."""

from rpf_fly.sim.metrics import DroneMetrics, Metrics, compute_metrics
from rpf_fly.sim.rollout import DroneOutcome, Rollout, SimParams, rollout
from rpf_fly.sim.scenario import Scenario, arena_a, arena_b, circle_swap, make_scenario, scenario_from_mission
from rpf_fly.sim.world import World

__all__ = [
    "DroneMetrics",
    "DroneOutcome",
    "Metrics",
    "Rollout",
    "Scenario",
    "SimParams",
    "World",
    "arena_a",
    "arena_b",
    "circle_swap",
    "compute_metrics",
    "make_scenario",
    "rollout",
    "scenario_from_mission",
]
