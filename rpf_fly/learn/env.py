"""Vectorized multi-robot training environment: many arenas stepped at once with the SAME planning functions.

Each of ``n_arenas`` arenas holds ``n_robots`` drones (the paper trains with 6). Every step each active drone
observes its local view (``build_observation``), the policy answers with gains ``(eta, lambda)`` (RPF) or a
heading change ``a`` (the vanilla-PPO baseline), the APF of :mod:`rpf_fly.planning` (``sense_obstacles`` and
``apf_step``, exactly what the simulator and the flight loop call) turns gains into a direction, and the kinematic
:class:`~rpf_fly.sim.World` moves the drones. No second APF exists.

Reward per robot (paper Section IV-B; docs/learning.md, *Environment*):

- ``R_m = 300 - 100 d_a/d_s`` on reaching the goal (``d_a`` path flown, ``d_s`` straight distance);
- ``R_s = -5`` when the heading turns more than 45 degrees in one step;
- ``R_o = -collision_penalty`` if ``d_o < r``, ``-20`` if ``r <= d_o < 2r`` (static obstacles);
- ``-collision_penalty`` for a drone-drone collision (``d_ji < 2r``). The paper uses 100; with it, the policy
  learns that a small collision rate pays (measured: lambda fell from 2.5 to 1.2 and 10 % of arena-B episodes had a
  collision after 1,100 episodes, because shorter paths for six drones outweigh one -100 and a lost arrival bonus).
  The default here is 500 (docs/learning.md);
- ``R_p``: the paper's ``1 - d_g/d_m`` (``progress_reward="paper"``) or, by default, potential-based shaping with
  that potential, ``gamma Phi(s') - Phi(s)`` (the per-step form pays a drone for lingering near its goal instead of
  arriving; docs/learning.md).

Guidance and margin (``EnvConfig.guidance``, ``EnvConfig.margin``; both off by default, the paper's environment):
with ``guidance="path"`` each arena's visibility graph is built at its reset (the obstacles are static), every
step pulls each drone toward its next visible waypoint exactly as :class:`~rpf_fly.planning.Planner` does, and
``d_g`` in ``R_p`` and ``d_s`` in ``R_m`` are path lengths around the inflated obstacles instead of straight
distances (a drone is not punished for leaving a U-trap). With ``margin > 0`` the planner and the observation see
every surface ``margin`` closer (``PlannerConfig.margin``) and the reward knows it: ``-margin_penalty`` each step a
drone is closer than ``r + margin`` to an obstacle or ``2r + margin`` to another drone without colliding.

Scenes: the paper's arenas A and B (``arena``), or, with ``curriculum`` set, the scene families of
:mod:`rpf_fly.sim.generators` drawn uniformly, each at a seed drawn from the environment's generator in the
*training* seed stream (``split="train"``): the bench's families suite draws from the ``bench`` stream, so no bench
scene is ever trained on. Family scenes have ``n_robots`` drones, and their boxes (walls) are padded into the
per-arena obstacle arrays like the circles.

A robot is done when it arrives or collides (a collided drone halts where it is and stays visible to the others).
An arena resets with a freshly generated scene when all its robots are done or after ``max_steps``; the robots
still flying then end as truncated (treated as terminal).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np

from rpf_fly.planning.arrival import capture
from rpf_fly.planning.config import PlannerConfig
from rpf_fly.planning.guidance import Guidance
from rpf_fly.planning.observation import Observation, build_observation
from rpf_fly.planning.obstacles import FAR, ObstacleSet, nearest_obstacle
from rpf_fly.planning.planner import apf_step, sense_obstacles
from rpf_fly.planning.vectors import Planar, Scalar, dot, unit
from rpf_fly.planning.visibility import CIRCLE_SIDES, Inflated
from rpf_fly.planning.waypoints import next_waypoint
from rpf_fly.sim.collisions import nearest_neighbour_distance
from rpf_fly.sim.scenario import Scenario, arena_a, arena_b
from rpf_fly.sim.world import World

ArenaKind = Literal["a", "b", "both"]
ActionKind = Literal["gains", "heading"]


@dataclass(frozen=True)
class EnvConfig:
    """Environment settings; defaults are the paper's (dt 0.1 s, v 0.5 m/s, r 0.1 m, d_r 6 m, d_m 10 m, rho 10 m)."""

    n_arenas: int = 64
    n_robots: int = 6
    arena: ArenaKind = "both"
    action: ActionKind = "gains"
    max_steps: int = 1000
    dt: float = 0.1
    speed: float = 0.5
    safety_radius: float = 0.1
    sensing_range: float = 6.0
    influence_range: float = 10.0
    d_m: float = 10.0
    gamma: float = 0.999
    max_neighbours: int = 10
    obstacle_radius: float = 0.5
    n_obstacles: int = 12
    arena_half_size: float = 5.0
    circle_radius: float = 2.0
    progress_reward: Literal["potential", "paper"] = "potential"
    preset: Literal["robust", "paper"] = "robust"
    collision_penalty: float = 500.0
    guidance: Literal["none", "path"] = "none"
    """``path``: the attraction pulls at each drone's next visible waypoint (graphs built per arena at reset)."""
    margin: float = 0.0
    """Clearance beyond contact the planner keeps and the reward asks for (metres; the product flies 0.05)."""
    margin_penalty: float = 20.0
    """Per step inside ``r + margin`` of an obstacle or ``2r + margin`` of a drone (with ``margin > 0``)."""
    capture_radius: float = 0.0
    """The planner's capture rule (docs/algorithm.md, *Arrival*); 0, the paper's environment, turns it off (the
    product's planners fly 0.3)."""
    curriculum: tuple[str, ...] = ()
    """Scene families (rpf_fly.sim.generators.FAMILIES) to draw from, uniformly, instead of ``arena``; empty: the
    paper's arenas A and B."""

    def planner_config(self) -> PlannerConfig:
        return PlannerConfig.preset(
            self.preset,
            safety_radius=self.safety_radius,
            sensing_range=self.sensing_range,
            influence_range=self.influence_range,
            guidance=self.guidance,
            margin=self.margin,
            capture_radius=self.capture_radius,
        )


@dataclass
class EpisodeStats:
    """One finished arena episode: did every drone arrive without a collision, and the mean robot return."""

    arena_kind: str
    success: bool
    arrived: int
    collided: int
    robots: int
    mean_return: float
    steps: int


@dataclass
class StepResult:
    """What :meth:`SwarmEnv.step` returns. Arrays ``(n_arenas, n_robots)``.

    ``valid`` marks the transitions that belong to a drone that was flying when the action was taken; ``done``
    marks valid transitions that ended the drone's episode (arrived, collided or truncated)."""

    observation: Observation
    reward: np.ndarray
    done: np.ndarray
    valid: np.ndarray
    episodes: list[EpisodeStats] = field(default_factory=list)


class SwarmEnv:
    """Batched arenas of drones whose planners are the project's APF with gains set by a policy."""

    def __init__(self, config: EnvConfig, seed: int = 0):
        self.config = config
        self.rng = np.random.default_rng(seed)
        self.planner = config.planner_config()
        b, n = config.n_arenas, config.n_robots
        m, k = self._capacity()
        self.centers = np.full((b, 1, m), FAR + 0j)
        self.radii = np.full((b, 1, m), 0.1)
        if k:
            self.box_center = np.full((b, 1, k), FAR + 0j)
            self.box_half_x = np.full((b, 1, k), 0.1)
            self.box_half_y = np.full((b, 1, k), 0.1)
        else:
            self.box_center = np.zeros((0,), complex)
            self.box_half_x = self.box_half_y = np.zeros((0,))
        self.obstacles = ObstacleSet(self.centers, self.radii, self.box_center, self.box_half_x, self.box_half_y)
        self.kinds = ["a"] * b
        self.scene_seeds: list[tuple[str, int] | None] = [None] * b
        """Per arena, the (family, training seed) of its current scene (None for the paper's arenas)."""
        self.world = World(
            np.zeros((b, n), complex),
            np.ones((b, n), complex),
            config.speed,
            config.dt,
            0.0,
            np.tile([-1.0, 1.0], (b, 1)),
            np.tile([-1.0, 1.0], (b, 1)),
        )
        self.world.goal_tolerance = config.safety_radius  # the paper's arrival test d_g < r
        self.arena_x = np.zeros((b, 2))
        self.arena_y = np.zeros((b, 2))
        self.start = np.zeros((b, n), complex)
        self.path = np.zeros((b, n))
        self.done = np.zeros((b, n), dtype=bool)
        self.collided = np.zeros((b, n), dtype=bool)
        self.returns = np.zeros((b, n))
        self.t = np.zeros(b, dtype=int)
        self.guided = config.guidance == "path"
        if self.guided:  # per arena: corner nodes (padded far away, never chosen) and each drone's cost-to-go
            v = m * CIRCLE_SIDES + 4 * k
            self.node = np.full((b, 1, v), FAR * (1 + 1j))
            self.cost = np.full((b, n, v), np.inf)
            self.start_path = np.zeros((b, n))
        self.inflated: Inflated | None = None
        """Guided: the obstacles inflated by ``r + margin`` (None after a reset: rebuilt at the next observation);
        ``wide``: its :meth:`~rpf_fly.planning.visibility.Inflated.axis` form."""
        self.wide: Inflated | None = None
        self._scene_seed: tuple[str, int] | None = None
        for arena in range(b):
            self._reset_arena(arena)
        self._observe()

    # -------------------------------------------------------------------------------------------- scenes

    def _capacity(self) -> tuple[int, int]:
        """Circles and boxes an arena's padded obstacle arrays hold."""
        c = self.config
        if not c.curriculum:
            return c.n_obstacles, 0
        from rpf_fly.sim.generators import FAMILIES, GeneratorError

        unknown = [f for f in c.curriculum if f not in FAMILIES]
        if unknown:
            raise GeneratorError(f"unknown scene family {unknown[0]!r} (expected some of {', '.join(FAMILIES)})")
        return (max(FAMILIES[f].max_circles for f in c.curriculum), max(FAMILIES[f].max_boxes for f in c.curriculum))

    def _scene(self) -> tuple[str, Scenario]:
        c = self.config
        if c.curriculum:
            from rpf_fly.sim.generators import generate

            family = c.curriculum[int(self.rng.integers(len(c.curriculum)))]
            seed = int(self.rng.integers(2**31))
            self._scene_seed = (family, seed)
            return family, generate(family, seed, split="train", n_drones=c.n_robots, safety_radius=c.safety_radius)
        self._scene_seed = None
        kind = c.arena if c.arena != "both" else ("a" if self.rng.random() < 0.5 else "b")
        if kind == "a":
            scene = arena_a(self.rng, c.n_robots, c.n_obstacles, c.obstacle_radius, c.arena_half_size, c.safety_radius)
        else:
            scene = arena_b(self.rng, c.n_robots, c.circle_radius)
        return kind, scene

    def _reset_arena(self, b: int) -> None:
        kind, scene = self._scene()
        self.kinds[b] = kind
        self.scene_seeds[b] = self._scene_seed
        m = scene.obstacles.n_circles
        k = scene.obstacles.n_boxes
        if m > self.centers.shape[-1] or k > (self.box_center.shape[-1] if self.box_center.ndim == 3 else 0):
            raise ValueError(f"{kind} scene with {m} circles and {k} boxes exceeds the arena's obstacle arrays")
        self.centers[b, 0, :] = FAR + 0j
        self.centers[b, 0, :m] = scene.obstacles.centers
        self.radii[b, 0, :] = 0.1
        self.radii[b, 0, :m] = scene.obstacles.radii
        if self.box_center.ndim == 3:
            self.box_center[b, 0, :] = FAR + 0j
            self.box_center[b, 0, :k] = scene.obstacles.box_center
            self.box_half_x[b, 0, :] = 0.1
            self.box_half_x[b, 0, :k] = scene.obstacles.box_half_x
            self.box_half_y[b, 0, :] = 0.1
            self.box_half_y[b, 0, :k] = scene.obstacles.box_half_y
        w = self.world
        w.position[b] = scene.starts
        w.goal[b] = scene.goals
        w.heading[b] = unit(scene.goals - scene.starts)
        w.velocity[b] = w.speed * w.heading[b]
        w.arrived[b] = False
        w.halted[b] = False
        # The geofence of the world is the scene's arena (clamped per arena).
        w._lo_x[b], w._hi_x[b] = scene.arena_x
        w._lo_y[b], w._hi_y[b] = scene.arena_y
        self.start[b] = scene.starts
        if self.guided:
            self.inflated = None  # rebuilt from the new obstacles at the next observation
            guide = Guidance(
                scene.obstacles, self.planner.safety_radius + self.planner.margin, (scene.arena_x, scene.arena_y)
            )
            k = guide.nodes.shape[0]
            self.node[b, 0, :] = FAR * (1 + 1j)
            self.node[b, 0, :k] = guide.nodes
            self.cost[b] = np.inf
            self.cost[b, :, :k] = guide.rows(scene.goals)
            self.start_path[b] = guide.waypoint(scene.starts, scene.goals)[1]
        self.path[b] = 0.0
        self.done[b] = False
        self.collided[b] = False
        self.returns[b] = 0.0
        self.t[b] = 0

    # ------------------------------------------------------------------------------------------ stepping

    def _waypoints(self, position: np.ndarray) -> tuple[Planar, Scalar]:
        """Each drone's next visible waypoint and remaining path length (guidance on)."""
        if self.inflated is None:
            self.inflated = Inflated.of(self.obstacles, self.planner.safety_radius + self.planner.margin)
            self.wide = self.inflated.axis()
        return next_waypoint(position, self.world.goal, self.node, self.cost, self.inflated, self.wide)

    def _observe(self, guided: tuple[Planar, Scalar] | None = None) -> None:
        """The views and observations of the current state (``guided``: its waypoints, already computed)."""
        self.view = self.world.views(self.config.sensing_range)
        self.nearest, self.lambda_mask = sense_obstacles(self.view, self.obstacles, self.planner)
        remaining = None
        if self.guided:
            waypoint, remaining = guided if guided is not None else self._waypoints(self.world.position)
            self.view = replace(self.view, goal=waypoint)
            self.remaining = remaining
        self.observation = build_observation(
            self.view, self.nearest, self.planner, self.config.max_neighbours, remaining
        )

    def _potential(self, position: np.ndarray, d_g: Scalar | None = None) -> np.ndarray:
        d_g = abs(self.world.goal - position) if d_g is None else d_g
        return np.maximum(1.0 - d_g / self.config.d_m, 0.0)

    def directions(self, action: np.ndarray) -> Planar:
        """Planned directions for actions ``(arenas, robots, size)``: gains (eta, lambda) or a heading change ``a``
        (the vanilla-PPO baseline: ``F = (v + a v_perp)/|...|``, paper Section V)."""
        if self.config.action == "gains":
            step = apf_step(
                self.view,
                self.nearest,
                self.lambda_mask,
                action[..., 0],
                action[..., 1],
                self.planner,
                goal=self.world.goal,
            )
            return step.direction
        h = self.world.heading
        direction = unit(h + action[..., 0] * (1j * h))
        return capture(
            direction,
            0 * h.real.astype(np.int8),
            self.world.position,
            self.world.goal,
            0 * h,
            self.nearest.distance,
            self.planner,
        )[0]

    def step(self, action: np.ndarray) -> StepResult:
        """Apply one action per robot (ignored for robots that are done) and advance every arena by ``dt``."""
        c = self.config
        w = self.world
        valid = ~self.done
        before = w.position.copy()
        heading_before = w.heading.copy()
        potential_before = self._potential(before, self.remaining if self.guided else None)
        w.advance(self.directions(action))
        moved = w.position - before
        self.path += abs(moved)

        r = c.safety_radius
        arrived_now = valid & w.arrived
        straight = np.maximum(self.start_path if self.guided else abs(w.goal - self.start), 1e-6)
        reward = np.where(arrived_now, 300.0 - 100.0 * self.path / straight, 0.0)
        turned = (abs(moved) > 0) & (dot(heading_before, w.heading) < np.cos(np.pi / 4))
        reward -= 5.0 * turned
        clearance = nearest_obstacle(w.position, self.obstacles).distance
        reward -= np.where(clearance < r, c.collision_penalty, np.where(clearance < 2 * r, 20.0, 0.0))
        separation = nearest_neighbour_distance(w.position)
        hit_robot = separation < 2 * r
        reward -= c.collision_penalty * hit_robot
        if c.margin > 0:  # the margin the planner keeps, asked of the gains too
            near = ((clearance >= r) & (clearance < r + c.margin)) | (~hit_robot & (separation < 2 * r + c.margin))
            reward -= c.margin_penalty * near
        after = self._waypoints(w.position) if self.guided else None
        d_after = None if after is None else after[1]
        if c.progress_reward == "potential":
            reward += c.gamma * self._potential(w.position, d_after) - potential_before
        else:
            d_g = abs(w.goal - w.position) if d_after is None else d_after
            reward += np.where(d_g < c.d_m, 1.0 - d_g / c.d_m, 0.0)
        reward = reward * valid

        collided_now = valid & ((clearance < r) | hit_robot) & ~arrived_now
        self.collided |= collided_now
        w.halted |= collided_now
        self.returns += reward
        ended = arrived_now | collided_now
        self.t += 1
        truncated = (self.t >= c.max_steps)[:, None] & valid & ~ended
        done = ended | truncated
        self.done |= done

        episodes = []
        finished = np.flatnonzero(self.done.all(axis=1))
        for b in finished.tolist():
            arrived = int(w.arrived[b].sum())
            collided = int(self.collided[b].sum())
            episodes.append(
                EpisodeStats(
                    self.kinds[b],
                    arrived == c.n_robots and collided == 0,
                    arrived,
                    collided,
                    c.n_robots,
                    float(self.returns[b].mean()),
                    int(self.t[b]),
                )
            )
            self._reset_arena(b)
        self._observe(after if len(finished) == 0 else None)
        return StepResult(self.observation, reward, done, valid, episodes)
