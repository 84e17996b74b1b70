"""Metrics of a trajectory, computed from positions sampled at the planning step (docs/metrics.md).

The same function scores a simulated rollout and a logged flight (the review resamples logged poses at ``dt``),
so ``review --json`` reproduces ``sim --json``. Definitions (docs/metrics.md):

- arrival: the first sample with goal distance below the tolerance; ``T_i`` is that sample's index;
- travel distance ``l_i = sum_{t < T_i} |p(t+1) - p(t)|`` (the whole track for a drone that never arrived); the
  swarm figure is the mean over the drones that arrived (null if none);
- smoothness ``xi_i = (1/T_i) sum_{1 <= t < T_i} |v(t) - v(t-1)| / |v(t)|`` with ``v(t) = (p(t+1) - p(t))/dt``
  (steps where the drone did not move are skipped); the swarm figure is the mean over the drones that arrived;
- a collision is an event, counted once each time a pair enters ``d_ji < 2r`` or a drone enters ``d_o < r``;
- success: every drone arrived and no collision; makespan: time of the last arrival (null unless all arrived);
- minimum separation (centre to centre) and minimum obstacle clearance (centre to surface; null without obstacles);
- the margin the planner keeps (``planner.margin`` m): events of a pair entering ``d_ji < 2r + m`` or a drone
  entering ``d_o < r + m`` (collisions included), counted as collisions are; ``held`` when there are none.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from rpf_fly.planning.obstacles import ObstacleSet
from rpf_fly.sim.collisions import collision_flags, pair_distances

_CHUNK = 256
"""Time samples processed at once (bounds memory for large swarms: N x N per sample)."""


@dataclass(frozen=True)
class DroneMetrics:
    """One drone's row of the metrics JSON."""

    name: str
    reached: bool
    collided: bool
    travel_distance_m: float
    time_to_goal_s: float | None
    smoothness: float


@dataclass(frozen=True)
class Metrics:
    """The metrics JSON of docs/metrics.md (``to_json_dict`` gives its exact shape)."""

    mission: str
    planner: str
    seed: int
    drones: int
    reached: int
    success: bool
    collisions_drone_drone: int
    collisions_drone_obstacle: int
    min_separation_m: float | None
    min_obstacle_clearance_m: float | None
    travel_distance_m: float | None
    smoothness: float | None
    makespan_s: float | None
    per_drone: tuple[DroneMetrics, ...]
    margin_m: float = 0.0
    margin_breaches_drone_drone: int = 0
    margin_breaches_drone_obstacle: int = 0

    @property
    def margin_held(self) -> bool:
        """No pair came within ``2r + margin`` and no drone within ``r + margin`` of an obstacle."""
        return self.margin_breaches_drone_drone == 0 and self.margin_breaches_drone_obstacle == 0

    def to_json_dict(self) -> dict[str, Any]:
        """The contract shape: ``collisions`` nested, ``per_drone`` a list of rows."""
        return {
            "mission": self.mission,
            "planner": self.planner,
            "seed": self.seed,
            "drones": self.drones,
            "reached": self.reached,
            "success": self.success,
            "collisions": {
                "drone_drone": self.collisions_drone_drone,
                "drone_obstacle": self.collisions_drone_obstacle,
            },
            "margin": {
                "m": self.margin_m,
                "held": self.margin_held,
                "drone_drone": self.margin_breaches_drone_drone,
                "drone_obstacle": self.margin_breaches_drone_obstacle,
            },
            "min_separation_m": self.min_separation_m,
            "min_obstacle_clearance_m": self.min_obstacle_clearance_m,
            "travel_distance_m": self.travel_distance_m,
            "smoothness": self.smoothness,
            "makespan_s": self.makespan_s,
            "per_drone": [asdict(row) for row in self.per_drone],
        }


def _entries(flags: np.ndarray, previous: np.ndarray) -> np.ndarray:
    """Count of false -> true transitions along axis 0, given the state before the first sample."""
    before = np.concatenate([previous[None], flags[:-1]], axis=0)
    return (flags & ~before).sum(axis=0)


def compute_metrics(
    positions: np.ndarray,
    goals: np.ndarray,
    dt: float,
    goal_tolerance: float,
    safety_radius: float,
    obstacles: ObstacleSet,
    names: Sequence[str],
    mission: str = "",
    planner: str = "",
    seed: int = 0,
    margin: float = 0.0,
) -> Metrics:
    """Metrics of a trajectory ``positions`` ``(T+1, N)`` complex sampled every ``dt`` seconds; ``margin`` (m) the
    clearance beyond contact the planner was asked to keep."""
    positions = np.asarray(positions, dtype=complex)
    samples, n = positions.shape
    goals = np.asarray(goals, dtype=complex)

    near_goal = abs(positions - goals) < goal_tolerance  # (T+1, N)
    reached = near_goal.any(axis=0)
    arrival = np.where(reached, near_goal.argmax(axis=0), samples - 1)  # index T_i

    steps = positions[1:] - positions[:-1]  # (T, N): v(t) * dt
    step_len = abs(steps)
    t_index = np.arange(samples - 1)[:, None]
    before_arrival = t_index < arrival[None, :]
    travel = (step_len * before_arrival).sum(axis=0)

    change = abs(steps[1:] - steps[:-1])  # |v(t) - v(t-1)| dt, t = 1..T-1
    moving = step_len[1:] > 0
    ratio = np.where(moving, change / np.where(moving, step_len[1:], 1.0), 0.0)
    counted = (t_index[1:] < arrival[None, :]) & moving
    smooth = np.where(arrival > 0, (ratio * counted).sum(axis=0) / np.maximum(arrival, 1), 0.0)

    pair_events = np.zeros((n, n), dtype=int)
    obstacle_events = np.zeros(n, dtype=int)
    prev_pairs = np.zeros((n, n), dtype=bool)
    prev_obst = np.zeros(n, dtype=bool)
    margin_pairs = np.zeros((n, n), dtype=int)
    margin_obstacle = np.zeros(n, dtype=int)
    prev_margin_pairs = np.zeros((n, n), dtype=bool)
    prev_margin_obst = np.zeros(n, dtype=bool)
    min_sep = np.inf
    min_clear = np.inf
    for start in range(0, samples, _CHUNK):
        chunk = positions[start : start + _CHUNK]
        pairs, obst = collision_flags(chunk, obstacles, safety_radius)
        pair_events += _entries(pairs, prev_pairs)
        obstacle_events += _entries(obst, prev_obst)
        prev_pairs, prev_obst = pairs[-1], obst[-1]
        if margin > 0:  # the same geometry with every surface margin/2 (pairs) and margin (obstacles) farther
            near_pairs, near_obst = collision_flags(chunk, obstacles, safety_radius + margin / 2)
            near_obst = near_obst if obstacles.is_empty else obstacles.signed_distance(chunk) < safety_radius + margin
            margin_pairs += _entries(near_pairs, prev_margin_pairs)
            margin_obstacle += _entries(near_obst, prev_margin_obst)
            prev_margin_pairs, prev_margin_obst = near_pairs[-1], near_obst[-1]
        else:
            margin_pairs += _entries(pairs, prev_margin_pairs)
            margin_obstacle += _entries(obst, prev_margin_obst)
            prev_margin_pairs, prev_margin_obst = pairs[-1], obst[-1]
        if n > 1:
            min_sep = min(min_sep, float(pair_distances(chunk).min()))
        if not obstacles.is_empty:
            min_clear = min(min_clear, float(obstacles.signed_distance(chunk).min()))
    drone_drone = int(np.triu(pair_events, 1).sum())
    collided = (pair_events.sum(axis=1) > 0) | (obstacle_events > 0)

    rows = tuple(
        DroneMetrics(
            name=names[i],
            reached=bool(reached[i]),
            collided=bool(collided[i]),
            travel_distance_m=float(travel[i]),
            time_to_goal_s=float(arrival[i] * dt) if reached[i] else None,
            smoothness=float(smooth[i]),
        )
        for i in range(n)
    )
    n_reached = int(reached.sum())
    collisions = drone_drone + int(obstacle_events.sum())
    return Metrics(
        mission=mission,
        planner=planner,
        seed=int(seed),
        drones=n,
        reached=n_reached,
        success=bool(n_reached == n and collisions == 0),
        collisions_drone_drone=drone_drone,
        collisions_drone_obstacle=int(obstacle_events.sum()),
        min_separation_m=float(min_sep) if np.isfinite(min_sep) else None,
        min_obstacle_clearance_m=float(min_clear) if np.isfinite(min_clear) else None,
        travel_distance_m=float(travel[reached].mean()) if n_reached else None,
        smoothness=float(smooth[reached].mean()) if n_reached else None,
        makespan_s=float(arrival.max() * dt) if n_reached == n else None,
        per_drone=rows,
        margin_m=float(margin),
        margin_breaches_drone_drone=int(np.triu(margin_pairs, 1).sum()),
        margin_breaches_drone_obstacle=int(margin_obstacle.sum()),
    )
