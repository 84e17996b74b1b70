"""Scenarios: who starts where, flies to which goal, among which obstacles, inside which arena.

A scenario comes from a mission file (:func:`scenario_from_mission`, with the seeded start jitter of the mission's
``sim`` section) or from the paper's random generators: training arena A (random starts and goals among many
0.5 m obstacles) and arena B (a circle swap with random angular jitter). Positions are complex ``x + iy``, metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rpf_fly.mission.model import CircleObstacle, Mission, Obstacle
from rpf_fly.planning.factory import obstacle_set
from rpf_fly.planning.obstacles import ObstacleSet


@dataclass(frozen=True)
class Scenario:
    """Starts and goals ``(N,)`` complex, the obstacles (as shapes for plots and as arrays for the planner),
    and the arena's x and y ranges (the geofence)."""

    name: str
    names: tuple[str, ...]
    starts: np.ndarray
    goals: np.ndarray
    shapes: tuple[Obstacle, ...]
    obstacles: ObstacleSet
    arena_x: tuple[float, float]
    arena_y: tuple[float, float]

    @property
    def n_drones(self) -> int:
        return int(self.starts.shape[0])


def make_scenario(
    name: str,
    starts: np.ndarray,
    goals: np.ndarray,
    shapes: tuple[Obstacle, ...] = (),
    arena_x: tuple[float, float] = (-10.0, 10.0),
    arena_y: tuple[float, float] = (-10.0, 10.0),
    names: tuple[str, ...] | None = None,
) -> Scenario:
    """A scenario from arrays (complex or ``(N, 2)``)."""
    starts = _as_complex(starts)
    goals = _as_complex(goals)
    names = names or tuple(f"cf{i + 1}" for i in range(starts.shape[0]))
    return Scenario(name, names, starts, goals, tuple(shapes), obstacle_set(shapes), arena_x, arena_y)


def _as_complex(a: np.ndarray) -> np.ndarray:
    a = np.asarray(a)
    if np.iscomplexobj(a):
        return a.astype(complex).reshape(-1)
    a = a.astype(float).reshape(-1, 2)
    return a[:, 0] + 1j * a[:, 1]


def scenario_from_mission(mission: Mission, seed: int = 0) -> Scenario:
    """The mission's layout, with the ``sim`` section's jitter drawn from ``seed`` (0 jitter: the nominal layout).

    A circle-swap formation is jittered in angle (each goal stays the antipode of its start); explicit drones
    have their starts moved uniformly within a disc of ``start_jitter_m``. Jittered starts that would collide
    (closer than 2r to another start or r to an obstacle) or leave the arena are redrawn.
    """
    rng = np.random.default_rng(seed)
    starts = np.array([complex(*d.start) for d in mission.drones])
    goals = np.array([complex(*d.goal) for d in mission.drones])
    shapes = mission.obstacles
    obstacles = obstacle_set(shapes)
    r = mission.planner.safety_radius
    form = mission.formation
    jitter = mission.sim
    if form is not None and jitter.angle_jitter_deg > 0:
        center = complex(*form.center)
        base = np.angle(starts - center)
        for _ in range(1000):
            angles = base + np.deg2rad(rng.uniform(-jitter.angle_jitter_deg, jitter.angle_jitter_deg, base.shape))
            cand = center + form.radius * np.exp(1j * angles)
            if _valid_starts(cand, obstacles, r):
                starts, goals = cand, 2 * center - cand
                break
    if jitter.start_jitter_m > 0:
        for _ in range(1000):
            radius = jitter.start_jitter_m * np.sqrt(rng.uniform(0, 1, starts.shape))
            cand = starts + radius * np.exp(1j * rng.uniform(-np.pi, np.pi, starts.shape))
            inside = _inside(cand, mission.arena.x, mission.arena.y)
            if inside and _valid_starts(cand, obstacles, r):
                if form is not None:  # a swap keeps its goals antipodal
                    goals = 2 * complex(*form.center) - cand
                starts = cand
                break
    return Scenario(
        mission.name,
        tuple(d.name for d in mission.drones),
        starts,
        goals,
        shapes,
        obstacles,
        mission.arena.x,
        mission.arena.y,
    )


def _inside(points: np.ndarray, x: tuple[float, float], y: tuple[float, float]) -> bool:
    return bool(np.all((points.real >= x[0]) & (points.real <= x[1]) & (points.imag >= y[0]) & (points.imag <= y[1])))


def _valid_starts(points: np.ndarray, obstacles: ObstacleSet, r: float) -> bool:
    """No two points closer than 2r, none closer than r to an obstacle surface."""
    if points.shape[0] > 1:
        d = abs(points[:, None] - points[None, :])
        np.fill_diagonal(d, np.inf)
        if d.min() < 2 * r:
            return False
    return obstacles.is_empty or bool(np.min(obstacles.signed_distance(points)) >= r)


def arena_a(
    rng: np.random.Generator,
    n_drones: int = 6,
    n_obstacles: int = 12,
    obstacle_radius: float = 0.5,
    half_size: float = 5.0,
    safety_radius: float = 0.1,
    min_travel: float = 4.0,
    goal_clearance: float | None = None,
) -> Scenario:
    """The paper's training arena A: random obstacles of radius 0.5 m in a square arena, random starts and goals.

    Obstacles keep a free corridor between them (centres at least ``2 * radius + 4 r`` apart) so that every pair of
    points is connected; starts keep ``2r`` clearance from obstacle surfaces, goals ``goal_clearance`` (default
    ``2r``), starts and goals ``4r`` from each other, and each start is at least ``min_travel`` from its goal.

    A goal closer to an obstacle than where the repulsion exceeds the unit attraction (about 0.37 m for eta 0.05)
    cannot be reached by the fixed-gain APF: it orbits (docs/algorithm.md). Training keeps such goals (the learned
    eta can solve them); ``missions/arena-a-6.yaml`` was generated with 0.5 m.
    """
    goal_clear = 2 * safety_radius if goal_clearance is None else goal_clearance
    margin = obstacle_radius + 0.5
    centers: list[complex] = []
    while len(centers) < n_obstacles:
        c = complex(*rng.uniform(-half_size + margin, half_size - margin, 2))
        if all(abs(c - o) >= 2 * obstacle_radius + 4 * safety_radius for o in centers):
            centers.append(c)
    shapes = tuple(CircleObstacle((c.real, c.imag), obstacle_radius) for c in centers)
    obstacles = obstacle_set(shapes)
    edge = half_size - 0.3

    def free_point(taken: list[complex], clearance: float) -> complex:
        while True:
            p = complex(*rng.uniform(-edge, edge, 2))
            if obstacles.signed_distance(np.array([p]))[0] < clearance:
                continue
            if all(abs(p - q) >= 4 * safety_radius for q in taken):
                return p

    starts: list[complex] = []
    goals: list[complex] = []
    for _ in range(n_drones):
        s = free_point(starts, 2 * safety_radius)
        for _ in range(1000):
            g = free_point(goals, goal_clear)
            if abs(g - s) >= min_travel:
                break
        starts.append(s)
        goals.append(g)
    return make_scenario(
        "arena-a", np.array(starts), np.array(goals), shapes, (-half_size, half_size), (-half_size, half_size)
    )


def arena_b(
    rng: np.random.Generator, n_drones: int = 6, radius: float = 2.0, jitter_deg: float | None = None
) -> Scenario:
    """The paper's training arena B: drones evenly on a circle with random angular jitter, swapping to antipodes.

    The default jitter is a quarter of the spacing, so neighbours never start closer than half the spacing.
    """
    spacing = 360.0 / n_drones
    jitter = spacing / 4 if jitter_deg is None else jitter_deg
    angles = np.deg2rad(np.arange(n_drones) * spacing + rng.uniform(-jitter, jitter, n_drones))
    starts = radius * np.exp(1j * angles)
    half = radius + 1.0
    return make_scenario("arena-b", starts, -starts, (), (-half, half), (-half, half))


def circle_swap(n_drones: int, radius: float, name: str = "circle") -> Scenario:
    """Drones evenly on a circle, each flying to its antipode (no jitter)."""
    starts = radius * np.exp(2j * np.pi * np.arange(n_drones) / n_drones)
    half = radius + 1.0
    return make_scenario(name, starts, -starts, (), (-half, half), (-half, half))
