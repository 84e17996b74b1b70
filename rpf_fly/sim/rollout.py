"""Rollouts: run a scenario with a planner until every drone arrived or the time limit, recording every step.

Collided drones fly on (collisions are counted by the metrics, never hidden). Each drone ends with a named
outcome (CrowdNav style): it reached its goal; it stalled (not arrived, and over the last ``STALL_WINDOW_S`` its net
displacement was under a tenth of what it could have flown: stuck in a local minimum, oscillating or still); or it
timed out while still making progress.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

from rpf_fly.planning.factory import AnyPlanner
from rpf_fly.sim.scenario import Scenario
from rpf_fly.sim.world import World

STALL_WINDOW_S = 10.0


class DroneOutcome(str, enum.Enum):
    """Why a drone's rollout ended."""

    REACHED = "reached"
    STALLED = "stalled"
    TIMEOUT = "timeout"


@dataclass(frozen=True)
class SimParams:
    """Kinematics and limits: speed (m/s), planning step dt (s), goal tolerance (m), time limit (s)."""

    speed: float = 0.5
    dt: float = 0.1
    goal_tolerance: float = 0.1
    time_limit_s: float = 100.0

    @property
    def max_steps(self) -> int:
        return int(round(self.time_limit_s / self.dt))


@dataclass(frozen=True)
class Rollout:
    """A recorded run. ``positions`` ``(T+1, N)`` complex (metres, at every planning step including the start);
    per step ``(T, N)``: ``modes`` (0 apf, 1 wall, 2 soft, -1 arrived), gains ``eta`` and ``lam``, the planner's
    diagnostics ``f_a``, ``f_r``, ``f_in`` and ``direction`` (complex) and ``neighbours`` (lambda-neighbours used);
    ``outcomes`` per drone; ``geofence_clamps`` per drone."""

    scenario: Scenario
    params: SimParams
    positions: np.ndarray
    modes: np.ndarray
    eta: np.ndarray
    lam: np.ndarray
    outcomes: tuple[DroneOutcome, ...]
    geofence_clamps: np.ndarray
    f_a: np.ndarray
    f_r: np.ndarray
    f_in: np.ndarray
    direction: np.ndarray
    neighbours: np.ndarray

    @property
    def steps(self) -> int:
        return int(self.modes.shape[0])


def rollout(scenario: Scenario, planner: AnyPlanner, params: SimParams) -> Rollout:
    """Run one scenario to completion (all arrived) or to the time limit."""
    world = World(
        scenario.starts,
        scenario.goals,
        params.speed,
        params.dt,
        params.goal_tolerance,
        scenario.arena_x,
        scenario.arena_y,
    )
    n = scenario.n_drones
    positions = [world.position.copy()]
    modes: list[np.ndarray] = []
    etas: list[np.ndarray] = []
    lams: list[np.ndarray] = []
    diagnostics: dict[str, list[np.ndarray]] = {"f_a": [], "f_r": [], "f_in": [], "direction": [], "neighbours": []}
    sensing = planner.config.sensing_range
    for _ in range(params.max_steps):
        if world.all_arrived:
            break
        step = planner.step(world.views(sensing))
        active = ~world.arrived
        world.advance(step.direction)
        positions.append(world.position.copy())
        modes.append(np.where(active, np.broadcast_to(step.mode, (n,)), -1).astype(np.int8))
        etas.append(np.broadcast_to(np.asarray(step.eta, dtype=float), (n,)).copy())
        lams.append(np.broadcast_to(np.asarray(step.lam, dtype=float), (n,)).copy())
        for key, values in diagnostics.items():
            values.append(np.broadcast_to(getattr(step, key), (n,)).copy())
    track = np.array(positions)
    window = min(int(round(STALL_WINDOW_S / params.dt)), track.shape[0] - 1)
    progress = abs(track[-1] - track[-1 - window])
    stalled = progress < 0.1 * params.speed * window * params.dt
    outcomes = tuple(
        DroneOutcome.REACHED if world.arrived[i] else (DroneOutcome.STALLED if stalled[i] else DroneOutcome.TIMEOUT)
        for i in range(n)
    )
    empty = np.zeros((0, n))

    def stacked(key: str, dtype: type) -> np.ndarray:
        return np.array(diagnostics[key], dtype=dtype) if diagnostics[key] else empty.astype(dtype)

    return Rollout(
        scenario=scenario,
        params=params,
        positions=track,
        modes=np.array(modes, dtype=np.int8) if modes else empty.astype(np.int8),
        eta=np.array(etas) if etas else empty,
        lam=np.array(lams) if lams else empty,
        outcomes=outcomes,
        geofence_clamps=world.geofence_clamps.copy(),
        f_a=stacked("f_a", complex),
        f_r=stacked("f_r", complex),
        f_in=stacked("f_in", complex),
        direction=stacked("direction", complex),
        neighbours=stacked("neighbours", int),
    )
