"""Evaluate a planner on missions and on freshly generated scenes: many seeded rollouts, their metrics.

Used by ``rpf-fly train`` (the model card's evaluation) and ``rpf-fly bench`` (the paper's comparison). Pure
simulation: no torch, so it runs with only the runtime dependencies.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from rpf_fly.mission.load import with_planner
from rpf_fly.mission.model import Mission, PlannerSettings
from rpf_fly.planning.factory import make_planner
from rpf_fly.sim.metrics import Metrics, compute_metrics
from rpf_fly.sim.rollout import Rollout, SimParams, rollout
from rpf_fly.sim.scenario import Scenario, arena_a, scenario_from_mission


@dataclass(frozen=True)
class Run:
    """One seeded rollout and its metrics."""

    scenario: str
    planner: str
    seed: int
    metrics: Metrics
    rollout: Rollout | None = None


def sim_params(mission: Mission) -> SimParams:
    return SimParams(mission.flight.speed, mission.flight.dt, mission.flight.goal_tolerance, mission.sim.time_limit_s)


def run_scenario(
    scenario: Scenario, settings: PlannerSettings, params: SimParams, seed: int, label: str, keep: bool = False
) -> Run:
    """Roll out one scenario with the planner the settings describe."""
    planner = make_planner(settings, scenario.obstacles, (scenario.arena_x, scenario.arena_y), scenario.goals)
    result = rollout(scenario, planner, params)
    metrics = compute_metrics(
        result.positions,
        scenario.goals,
        params.dt,
        params.goal_tolerance,
        settings.safety_radius,
        scenario.obstacles,
        scenario.names,
        mission=label,
        planner=settings.kind,
        seed=seed,
        margin=settings.margin_m,
    )
    return Run(label, settings.kind, seed, metrics, result if keep else None)


def evaluate_mission(
    mission: Mission,
    kind: str,
    policy: str | Path | None,
    seeds: Iterable[int],
    on_run: Callable[[Run], None] | None = None,
) -> list[Run]:
    """Rollouts of ``mission`` with planner ``kind`` for each seed of its start jitter."""
    chosen = with_planner(mission, kind, policy)
    runs = []
    for seed in seeds:
        run = run_scenario(scenario_from_mission(chosen, seed), chosen.planner, sim_params(chosen), seed, mission.name)
        runs.append(run)
        if on_run:
            on_run(run)
    return runs


def evaluate_arena_a(
    settings: PlannerSettings,
    seeds: Iterable[int],
    goal_clearance: float | None = None,
    params: SimParams = SimParams(),
    on_run: Callable[[Run], None] | None = None,
) -> list[Run]:
    """Rollouts on freshly generated training-arena-A scenes (``arena_a`` with each seed)."""
    runs = []
    label = "arena-a-fresh" if goal_clearance is None else f"arena-a-fresh-clear{goal_clearance:g}"
    for seed in seeds:
        scenario = arena_a(np.random.default_rng(seed), goal_clearance=goal_clearance)
        run = run_scenario(scenario, settings, params, seed, label)
        runs.append(run)
        if on_run:
            on_run(run)
    return runs


def planner_settings(kind: str, policy: str | Path | None = None, **overrides: Any) -> PlannerSettings:
    """Planner settings with the paper's defaults for ``kind`` (``policy`` for the learned kinds)."""
    return replace(PlannerSettings(), kind=kind, policy=Path(policy) if policy else None, **overrides)


def summarise(runs: list[Run]) -> dict[str, object]:
    """Success rate, collision count and mean +- std of the path metrics over runs."""

    def stat(values: list[float | None]) -> dict[str, float] | None:
        present = [v for v in values if v is not None]
        if not present:
            return None
        return {"mean": float(np.mean(present)), "std": float(np.std(present))}

    ms = [r.metrics for r in runs]
    return {
        "runs": len(ms),
        "success_rate": float(np.mean([m.success for m in ms])) if ms else None,
        "collisions": int(sum(m.collisions_drone_drone + m.collisions_drone_obstacle for m in ms)),
        "reached_rate": float(np.mean([m.reached / m.drones for m in ms])) if ms else None,
        "travel_distance_m": stat([m.travel_distance_m for m in ms]),
        "smoothness": stat([m.smoothness for m in ms]),
        "makespan_s": stat([m.makespan_s for m in ms]),
    }
