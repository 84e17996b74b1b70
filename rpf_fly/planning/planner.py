"""One planning step: local view in, commanded direction and diagnostics out.

This is the only APF in the project: the simulator, the training environment and the flight loop all call
:meth:`Planner.step`. It is batched (``S`` drones, each from its own view) and pure: no clock, no I/O, no state.
The caller integrates the motion (constant speed along ``direction``) and keeps each drone's heading.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from rpf_fly.planning.arrival import capture
from rpf_fly.planning.config import PlannerConfig
from rpf_fly.planning.forces import attractive, inter_robot, perceived, repulsion_one, repulsive, repulsive_sum
from rpf_fly.planning.gains import FixedGains, GainsPolicy
from rpf_fly.planning.guidance import Guidance
from rpf_fly.planning.observation import Observation, build_observation
from rpf_fly.planning.obstacles import FAR, NearestObstacle, ObstacleSet, every_surface, nearest_obstacle
from rpf_fly.planning.speed import brake, yield_speed
from rpf_fly.planning.vectors import Planar, Scalar, norm
from rpf_fly.planning.view import LocalView
from rpf_fly.planning.visibility import Bounds
from rpf_fly.planning.wall_following import select_heading


@dataclass(frozen=True)
class PlanStep:
    """Result for drones of leading shape ``S``. ``direction`` (complex) is a unit vector, zero for a stalled
    drone (resultant 0), or shorter than unit for a drone that yields (``config.yield_gain``, :mod:`.speed`).

    Diagnostics for the log: forces ``f_a``, ``f_r``, ``f_in`` (complex); ``mode`` int8 (0 apf, 1 wall, 2 soft);
    gains ``eta``, ``lam``; ``neighbours``: lambda-neighbours used; ``obstacle_distance``: signed distance to the
    nearest visible obstacle surface (metres, FAR when none); ``goal_distance`` (metres).
    """

    direction: Planar
    mode: Scalar
    f_a: Planar
    f_r: Planar
    f_in: Planar
    eta: Scalar
    lam: Scalar
    neighbours: Scalar
    obstacle_distance: Scalar
    goal_distance: Scalar
    observation: Observation | None = None
    waypoint: Planar | None = None
    """With guidance: the point the attraction pulled toward (complex; the goal once it is in sight)."""


def plan_row(step: PlanStep, i: int) -> PlanStep:
    """Drone ``i`` of a batched step ``(P,)``, shaped as the one-drone call returns it (scalars, its observation)."""
    row = {}
    for f in dataclasses.fields(PlanStep):
        x = getattr(step, f.name)
        if isinstance(x, Observation):
            x = Observation(x.local[i], x.neighbours[i], x.mask[i])
        elif isinstance(x, np.ndarray) and x.ndim:
            x = x[i]
        row[f.name] = x
    return PlanStep(**row)


def static_mask(view: LocalView, config: PlannerConfig) -> np.ndarray:
    """The neighbours each drone sees slower than ``config.static_speed`` (hovering, arrived: parked)."""
    return view.neighbour_mask & (abs(view.neighbour_velocity) < config.static_speed)


def sense_obstacles(
    view: LocalView, obstacles: ObstacleSet, config: PlannerConfig
) -> tuple[NearestObstacle, np.ndarray]:
    """Nearest obstacle for each drone (static neighbours included as circles of radius r when the preset says so)
    and the mask of the neighbours that remain lambda-neighbours."""
    mask = view.neighbour_mask
    if config.static_neighbours_as_obstacles and mask.shape[-1]:
        static = static_mask(view, config)
        nearest = nearest_obstacle(
            view.position, obstacles, view.neighbour_position, config.safety_radius, static, view.neighbour_offsets()
        )
        return nearest, mask & ~static
    return nearest_obstacle(view.position, obstacles), mask


def apf_step(
    view: LocalView,
    nearest: NearestObstacle,
    lambda_mask: np.ndarray,
    eta: Scalar,
    lam: Scalar,
    config: PlannerConfig,
    observation: Observation | None = None,
    waypoint: Planar | None = None,
    goal_distance: Scalar | None = None,
    goal: Planar | None = None,
    repulsion: Planar | None = None,
    walls: NearestObstacle | None = None,
) -> PlanStep:
    """The APF with (soft) wall-following for given gains (``observation``, when the gains came from one, is kept
    in the result for the log). ``view.goal`` is what the attraction pulls toward: the goal, or with guidance the
    drone's ``waypoint`` (then ``goal_distance`` is the distance to the goal itself, for the log). ``nearest`` is
    the true nearest obstacle; the forces see it ``config.margin`` closer. ``goal``: the drone's goal itself
    (None: ``view.goal``), for the capture rule (:mod:`rpf_fly.planning.arrival`). ``repulsion``: with
    ``config.repulsion_sum``, the summed static repulsion at ``eta`` 1 (:meth:`Planner.unit_repulsion`); the
    repulsion is then ``eta`` times it (it is linear in ``eta``). ``walls``: the nearest of the mission's obstacles
    alone (static neighbours left out, the brake takes them as neighbours), for the brake; None: ``nearest``."""
    f_a, d_g = attractive(view.position, view.goal)
    seen = perceived(nearest, config)
    f_r = repulsive(seen, eta, config) if repulsion is None else eta * repulsion
    f_in, count = inter_robot(
        view.position, view.neighbour_position, lambda_mask, lam, config, view.neighbour_offsets()
    )
    direction, mode = select_heading(f_a, f_r, f_in, view.heading, seen.distance, config)
    direction, mode = capture(
        direction, mode, view.position, view.goal if goal is None else goal, f_in, nearest.distance, config
    )
    direction = yield_speed(direction, f_in, config)
    direction = brake(
        direction,
        view.position,
        view.neighbour_position,
        view.neighbour_mask,
        config,
        nearest if walls is None else walls,
        view.neighbour_offsets(),
    )
    return PlanStep(
        direction=direction,
        mode=mode,
        f_a=f_a,
        f_r=f_r,
        f_in=f_in,
        eta=eta,
        lam=lam,
        neighbours=count,
        obstacle_distance=nearest.distance,
        goal_distance=d_g if goal_distance is None else goal_distance,
        observation=observation,
        waypoint=waypoint,
    )


def make_guidance(obstacles: ObstacleSet, config: PlannerConfig, bounds: Bounds | None = None) -> Guidance | None:
    """The visibility graph of ``obstacles`` inflated by ``r + margin`` when ``config.guidance`` is ``path`` (None
    without guidance or without obstacles: the attraction then pulls at the goal)."""
    if config.guidance != "path" or obstacles.is_empty:
        return None
    parked = config.safety_radius + config.parked_clearance if config.guide_around_parked else 0.0
    return Guidance(
        obstacles,
        config.safety_radius + config.margin,
        bounds,
        parked,
        config.safety_radius if config.guide_around_parked else 0.0,
    )


def guided_view(
    view: LocalView,
    guidance: Guidance | None,
    reach: float = 0.0,
    parked_mask: np.ndarray | None = None,
) -> tuple[LocalView, Planar | None, Scalar | None]:
    """``view`` with its goal replaced by each drone's next visible waypoint, the waypoints and the remaining path
    lengths (the view itself and None without guidance). ``reach`` > 0: a drone nearer its waypoint corner than
    that has reached it and is pulled on to the corner's own next waypoint (:func:`past_reached`).
    ``parked_mask`` (``S + (K,)``): the neighbours each drone sees parked (:func:`static_mask`); a guidance with a
    ``parked_radius`` routes around those in a drone's way (``config.guide_around_parked``)."""
    if guidance is None:
        return view, None, None
    parked = None
    if parked_mask is not None and guidance.parked_radius and np.shape(parked_mask)[-1:] != (0,):
        parked = (view.neighbour_position, parked_mask)
    waypoint, remaining = guidance.waypoint(view.position, view.goal, parked)
    if reach:
        waypoint = past_reached(guidance, view.position, view.goal, waypoint, reach, parked)
    guided = view.with_goal(waypoint)
    return guided, waypoint, remaining


def past_reached(
    guidance: Guidance,
    position: Planar,
    goal: Planar,
    waypoint: Planar,
    reach: float,
    parked: tuple[np.ndarray, np.ndarray] | None = None,
) -> Planar:
    """The waypoints with every corner nearer its drone than ``reach`` replaced by the corner's own next waypoint.

    Why (docs/algorithm.md, *RPF-3's tuning*): a drone rounding a corner within the repulsion's band is pushed off
    the corner before it stands on it; an inch short of it the goal is still hidden, so the pull points back at the
    corner, and an inch past it the pull points on: the drone can shuttle between the two for ever (one arena-a
    drone in 40 fresh runs). Pulling on from the corner once the drone is within ``reach`` of it removes the
    backward pull; the repulsion still keeps the clearance."""
    near = (norm(waypoint - position) < reach) & (waypoint != goal)
    if not isinstance(near, np.ndarray):
        return guidance.waypoint(complex(waypoint), complex(goal), parked)[0] if near else waypoint
    if not near.any():
        return waypoint
    rows = np.nonzero(near)
    if parked is not None:
        parked = (
            np.broadcast_to(parked[0], near.shape + parked[0].shape[-1:])[rows],
            np.broadcast_to(parked[1], near.shape + parked[1].shape[-1:])[rows],
        )
    waypoint = np.array(waypoint, dtype=complex)  # a copy: the caller's waypoints stay as they are
    onward, _ = guidance.waypoint(waypoint[rows], np.broadcast_to(goal, near.shape)[rows], parked)
    waypoint[rows] = onward
    return waypoint


class Planner:
    """APF planner whose gains come from a :class:`GainsPolicy` (fixed gains: vanilla APF; ONNX policy: RPF).

    With ``config.guidance == "path"`` it builds the visibility graph of its obstacles once (``bounds``: the arena,
    where corners may lie) and every step pulls each drone toward its next visible waypoint; :meth:`prepare` with
    the mission's goals computes their cost-to-go at load time, so a tick costs one visibility test per drone."""

    def __init__(
        self,
        obstacles: ObstacleSet,
        config: PlannerConfig | None = None,
        gains: GainsPolicy | None = None,
        bounds: Bounds | None = None,
    ):
        self.obstacles = obstacles
        self.config = config or PlannerConfig()
        self.gains = gains or FixedGains()
        self.guidance = make_guidance(obstacles, self.config, bounds)
        self._shapes: tuple[list, list] | None = None

    def prepare(self, goals: np.ndarray) -> None:
        """Precompute the guidance of these goals (nothing without guidance; other goals are computed on first use)."""
        if self.guidance is not None:
            self.guidance.prepare(goals)

    def step(self, view: LocalView) -> PlanStep:
        """Plan every drone of ``view`` from its own local view."""
        nearest, lambda_mask = sense_obstacles(view, self.obstacles, self.config)
        parked = None
        if self.guidance is not None and self.guidance.parked_radius:
            # the static neighbours sense_obstacles took out of the lambda-neighbours, not computed twice
            statics = self.config.static_neighbours_as_obstacles and view.neighbour_mask.shape[-1]
            parked = view.neighbour_mask & ~lambda_mask if statics else static_mask(view, self.config)
        guided, waypoint, remaining = guided_view(view, self.guidance, self.config.waypoint_reach, parked)
        observation = None
        if self.gains.needs_observation:
            observation = build_observation(guided, nearest, self.config, self.gains.max_neighbours, remaining)
        eta, lam = self.gains.gains(observation)
        repulsion = walls = None
        if self.config.repulsion_sum:
            repulsion, walls = self.unit_repulsion(view, lambda_mask)
        elif self.config.brake_distance and self.config.static_neighbours_as_obstacles:
            walls = nearest_obstacle(view.position, self.obstacles)
        if waypoint is None:
            return apf_step(
                view, nearest, lambda_mask, eta, lam, self.config, observation, repulsion=repulsion, walls=walls
            )
        return apf_step(
            guided,
            nearest,
            lambda_mask,
            eta,
            lam,
            self.config,
            observation,
            waypoint,
            norm(view.goal - view.position),
            view.goal,
            repulsion,
            walls,
        )

    def unit_repulsion(self, view: LocalView, lambda_mask: np.ndarray) -> tuple[Planar, NearestObstacle]:
        """The static repulsion summed over every surface (``config.repulsion_sum``) at ``eta`` 1: the mission's
        obstacles and the static neighbours as :func:`sense_obstacles` counts them; and the nearest of the mission's
        obstacles alone (for the brake's wall slide), from the same distances. One drone: plain Python."""
        config = self.config
        mask = view.neighbour_mask
        statics = config.static_neighbours_as_obstacles and mask.shape[-1]
        if not isinstance(view.position, np.ndarray):
            if self._shapes is None:
                o = self.obstacles
                self._shapes = (
                    [(c.real, c.imag, r) for c, r in zip(np.ravel(o.centers).tolist(), np.ravel(o.radii).tolist())],
                    [
                        (c.real, c.imag, hx, hy)
                        for c, hx, hy in zip(
                            np.ravel(o.box_center).tolist(),
                            np.ravel(o.box_half_x).tolist(),
                            np.ravel(o.box_half_y).tolist(),
                        )
                    ],
                )
            chosen = (mask & ~lambda_mask) if statics else ()
            others = [q for q, keep in zip(view.neighbour_position.tolist(), np.ravel(chosen).tolist()) if keep]
            one_force, one_wall, one_normal = repulsion_one(
                complex(view.position), *self._shapes, others, config.safety_radius, config
            )
            return one_force, NearestObstacle(one_wall, one_normal)
        if statics:
            surfaces = every_surface(
                view.position,
                self.obstacles,
                view.neighbour_position,
                config.safety_radius,
                mask & ~lambda_mask,
                view.neighbour_offsets(),
            )
        else:
            surfaces = every_surface(view.position, self.obstacles)
        force = repulsive_sum(surfaces, 1.0, config)
        mapped = surfaces.mapped
        if not mapped:
            shape = np.shape(view.position)
            return force, NearestObstacle(np.full(shape, FAR), np.zeros(shape, dtype=complex))
        k = surfaces.distance[..., :mapped].argmin(axis=-1)[..., None]
        wall = NearestObstacle(
            np.take_along_axis(surfaces.distance, k, -1)[..., 0], np.take_along_axis(surfaces.normal, k, -1)[..., 0]
        )
        return force, wall
