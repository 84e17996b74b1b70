"""ORCA baseline: optimal reciprocal collision avoidance (van den Berg, Guy, Lin, Manocha, ISRR 2009 / 2011).

Written from the paper's description, in the project's conventions (planar vectors are complex numbers, metres,
metres per second). Each drone plans from its own :class:`~rpf_fly.planning.view.LocalView`:

1. Preferred velocity: full speed toward the goal (shortened only so that one step does not overshoot the goal).
2. One half-plane of permitted velocities per visible neighbour and per nearby static obstacle
   (:func:`orca_half_plane`): the velocity obstacle ``VO^tau`` (the truncated cone of relative velocities that
   collide within the time horizon ``tau``), the smallest change ``u`` that takes the relative velocity out of it,
   and the half-plane ``(v - (v_A + c u)) . n >= 0`` with ``n`` the outward normal of ``VO`` where ``u`` leaves it
   and ``c`` the responsibility: 0.5 for a moving neighbour (both sides share the avoidance), 1.0 for static ones.
3. The velocity closest to the preferred one inside every half-plane and within the speed disc: an incremental
   2D linear program (:func:`solve_velocity`); when the half-planes leave no room, the 3D program of the paper picks
   the velocity that minimises the largest violation of the neighbour half-planes while keeping the obstacle
   half-planes hard.

Static things, all with responsibility 1 and the obstacle horizon ``tau_obst``:

- circle obstacles are static discs of radius ``radius + r + margin``;
- boxes use the half-plane of the nearest surface point: the box lies behind the plane through that point
  normal to ``p - p_o`` (projection onto a convex set), so ``v . n >= (r + margin - d_o) / tau_obst`` is the exact
  ORCA of that infinite wall and a conservative one for the box; it lets a drone slide along faces and round corners;
- hovering neighbours (slower than ``config.static_speed``: arrived, or stopped) are static discs of radius
  ``2r + margin``.

The drone's own velocity ``v_A`` is not part of a LocalView. The planner remembers the velocity it commanded last
for each drone of a batch and uses it while the view agrees (same goal, heading along that velocity); otherwise it
assumes cruise speed along the view's heading (the world's initial state). ``remember_velocity=False`` makes the
planner stateless.

The output direction is ``v / speed`` (``|direction| <= 1``): the world flies ``speed * direction``, so ORCA slows
down and stops where it must. One drone at a time in Python (about 65 us per drone with 7 neighbours and 5
obstacles, 150 us with 30 neighbours); a batch loops over drones.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from rpf_fly.planning.config import PlannerConfig
from rpf_fly.planning.obstacles import ObstacleSet
from rpf_fly.planning.planner import PlanStep, guided_view, make_guidance, sense_obstacles
from rpf_fly.planning.vectors import Scalar, norm
from rpf_fly.planning.view import LocalView
from rpf_fly.planning.visibility import Bounds

HalfPlane = tuple[complex, complex]
"""``(point, unit normal)``: the velocities ``v`` with ``(v - point) . normal >= 0``."""

EPSILON = 1.0e-9


def _dot(a: complex, b: complex) -> float:
    return a.real * b.real + a.imag * b.imag


def _cross(a: complex, b: complex) -> float:
    return a.real * b.imag - a.imag * b.real


def orca_half_plane(
    relative_position: complex,
    relative_velocity: complex,
    radius: float,
    time_horizon: float,
    time_step: float,
    responsibility: float,
    velocity: complex,
) -> HalfPlane:
    """ORCA half-plane of permitted velocities for drone A against one other disc B.

    ``relative_position = p_B - p_A``, ``relative_velocity = v_A - v_B`` (metres, m/s); ``radius``: combined radius
    (metres); ``time_horizon`` tau (s); ``time_step`` (s) is the horizon used when the discs already overlap (leave
    the overlap within one step); ``responsibility``: share of the avoidance A takes (0.5 reciprocal, 1 static);
    ``velocity``: A's current velocity ``v_A``. Returns ``(point, normal)``.
    """
    p = complex(relative_position)
    v = complex(relative_velocity)
    dist_sq = p.real * p.real + p.imag * p.imag
    r_sq = radius * radius
    if dist_sq > r_sq:
        # VO^tau: the cone from the origin tangent to the disc D(p, R), cut off by the disc D(p/tau, R/tau).
        w = v - p / time_horizon  # relative velocity seen from the cut-off disc's centre
        w_sq = w.real * w.real + w.imag * w.imag
        w_dot_p = _dot(w, p)
        if w_dot_p < 0.0 and w_dot_p * w_dot_p > r_sq * w_sq:
            # w points back toward the apex within the tangent angle: the nearest boundary is the cut-off arc.
            w_len = math.sqrt(w_sq)
            normal = w / w_len
            u = (radius / time_horizon - w_len) * normal
        else:
            # The nearest boundary is a leg of the cone: the tangent from the origin on w's side of p.
            leg = math.sqrt(dist_sq - r_sq)
            if _cross(p, w) > 0.0:
                direction = p * complex(leg, radius) / dist_sq  # p turned counter-clockwise by asin(R/|p|)
                normal = 1j * direction
            else:
                direction = p * complex(leg, -radius) / dist_sq  # turned clockwise (ties take this, right leg)
                normal = -1j * direction
            u = _dot(v, direction) * direction - v
    else:
        # Already overlapping: leave the overlap within one time step.
        w = v - p / time_step
        w_len = abs(w)
        if w_len > EPSILON:
            normal = w / w_len
        elif dist_sq > 0.0:
            normal = -p / math.sqrt(dist_sq)
        else:
            normal = 1.0 + 0.0j
        u = (radius / time_step - w_len) * normal
    return complex(velocity) + responsibility * u, complex(normal)


def wall_half_plane(normal: complex, distance: float, radius: float, time_horizon: float) -> HalfPlane:
    """Half-plane of velocities that keep the centre ``radius`` away from a wall within ``time_horizon``.

    ``normal``: outward unit normal of the wall at the nearest surface point, ``distance``: centre to surface
    (metres). ``v . n >= (radius - distance) / time_horizon``: approaching at most as fast as the free gap closes.
    """
    return normal * ((radius - distance) / time_horizon), normal


def _satisfied(v: complex, plane: HalfPlane) -> bool:
    point, normal = plane
    return _dot(v - point, normal) >= -EPSILON


def _solve_on_line(
    planes: Sequence[HalfPlane], index: int, max_speed: float, target: complex, maximise: bool
) -> complex | None:
    """Best point on the boundary line of ``planes[index]`` within the speed disc and ``planes[:index]``.

    ``maximise``: the point furthest along the unit vector ``target``; otherwise the point closest to ``target``.
    None when the line misses the feasible region.
    """
    point, normal = planes[index]
    along = 1j * normal  # unit vector along the line
    # Speed disc: |point + t along|^2 <= max_speed^2.
    b = _dot(point, along)
    disc = b * b - (point.real * point.real + point.imag * point.imag) + max_speed * max_speed
    if disc < 0.0:
        return None
    root = math.sqrt(disc)
    lo, hi = -b - root, -b + root
    for j in range(index):
        q, n = planes[j]
        denom = _dot(along, n)  # (point + t along - q) . n >= 0  <=>  t denom >= (q - point) . n
        numer = _dot(q - point, n)
        if abs(denom) <= EPSILON:
            if numer > EPSILON:  # parallel and entirely outside plane j
                return None
            continue
        t = numer / denom
        if denom > 0.0:
            lo = max(lo, t)
        else:
            hi = min(hi, t)
        if lo > hi + EPSILON:
            return None
    if maximise:
        t = hi if _dot(target, along) > 0.0 else lo
    else:
        t = min(max(_dot(target - point, along), lo), hi)
    return point + t * along


def _solve_2d(
    planes: Sequence[HalfPlane], max_speed: float, target: complex, maximise: bool = False
) -> tuple[int, complex]:
    """Incremental 2D linear program: the velocity closest to ``target`` (or furthest along the unit ``target``
    when ``maximise``) within the speed disc and every half-plane. Returns ``(count, v)``: ``count ==
    len(planes)`` on success, else the index of the first half-plane that could not be met (``v`` then satisfies
    the ones before it)."""
    if maximise:
        result = target * max_speed
    else:
        speed = abs(target)
        result = target * (max_speed / speed) if speed > max_speed else target
    for i in range(len(planes)):
        if not _satisfied(result, planes[i]):
            found = _solve_on_line(planes, i, max_speed, target, maximise)
            if found is None:
                return i, result
            result = found
    return len(planes), result


def _solve_3d(planes: Sequence[HalfPlane], n_hard: int, start: int, max_speed: float, result: complex) -> complex:
    """The paper's fallback when the half-planes are infeasible: minimise the largest violation ``d`` of the soft
    half-planes (``planes[n_hard:]``) while meeting the hard ones (``planes[:n_hard]``) and the speed disc.

    Incremental over the soft half-planes from ``start``: when one is violated by more than the current ``d``, the
    new optimum lies where it is violated by exactly ``d``; projecting the earlier soft constraints onto that plane
    gives half-planes in ``v`` (``v . (n_j - n_i) >= q_j . n_j - q_i . n_i``), and maximising ``v . n_i`` over them
    is a 2D program.
    """
    worst = 0.0
    for i in range(start, len(planes)):
        q_i, n_i = planes[i]
        if _dot(q_i - result, n_i) <= worst + EPSILON:
            continue
        projected: list[HalfPlane] = list(planes[:n_hard])
        for j in range(n_hard, i):
            q_j, n_j = planes[j]
            m = n_j - n_i
            m_len = abs(m)
            if m_len <= EPSILON:  # parallel, same side: implied by plane i
                continue
            normal = m / m_len
            projected.append((normal * ((_dot(q_j, n_j) - _dot(q_i, n_i)) / m_len), normal))
        count, candidate = _solve_2d(projected, max_speed, n_i, maximise=True)
        if count == len(projected):  # else keep the previous result (can only happen by rounding)
            result = candidate
        worst = _dot(q_i - result, n_i)
    return result


def solve_velocity(planes: Sequence[HalfPlane], n_hard: int, max_speed: float, preferred: complex) -> complex:
    """The velocity closest to ``preferred`` within ``|v| <= max_speed`` and every half-plane; if there is none,
    the 3D fallback (soft ``planes[n_hard:]``; if even the hard ones conflict, all are soft)."""
    count, result = _solve_2d(planes, max_speed, preferred)
    if count < len(planes):
        hard = n_hard if count >= n_hard else 0
        result = _solve_3d(planes, hard, count, max_speed, result)
    speed = abs(result)
    if speed > max_speed:  # rounding only
        result *= max_speed / speed
    return result


class OrcaPlanner:
    """ORCA with the :class:`~rpf_fly.planning.Planner` interface: ``step(view) -> PlanStep``.

    ``config`` supplies the safety radius r, the sensing range and the hovering-speed threshold; ``speed`` is the
    cruise speed (m/s, the maximum ORCA may choose) and ``time_step`` the planning step (s, for the overlap case
    and to keep the last step from overshooting the goal). ``margin`` is added to every combined radius (metres).
    """

    def __init__(
        self,
        obstacles: ObstacleSet,
        config: PlannerConfig | None = None,
        time_horizon: float = 5.0,
        obstacle_time_horizon: float = 2.0,
        speed: float = 0.5,
        time_step: float = 0.1,
        margin: float = 0.05,
        responsibility: float = 0.5,
        remember_velocity: bool = True,
        bounds: Bounds | None = None,
    ):
        if time_horizon <= 0 or obstacle_time_horizon <= 0 or speed <= 0 or time_step <= 0:
            raise ValueError("time horizons, speed and time step must be positive")
        self.obstacles = obstacles
        self.config = config or PlannerConfig()
        self.time_horizon = float(time_horizon)
        self.obstacle_time_horizon = float(obstacle_time_horizon)
        self.speed = float(speed)
        self.time_step = float(time_step)
        self.margin = float(margin)
        self.responsibility = float(responsibility)
        self.remember_velocity = remember_velocity
        self._memory: dict[tuple[int, ...], tuple[np.ndarray, np.ndarray]] = {}
        # planner.guidance path: the preferred velocity points at the next visible waypoint (the obstacles
        # inflated by r + margin), not at the goal.
        self.guidance = make_guidance(obstacles, replace(self.config, margin=self.margin), bounds)
        r = self.config.safety_radius
        # Obstacles farther than this (surface distance) cannot constrain a velocity within the speed disc.
        self._obstacle_range = min(self.config.sensing_range, self.obstacle_time_horizon * self.speed + r + self.margin)

    # -- one drone ---------------------------------------------------------------------------------------------------

    def _obstacle_planes(self, position: complex, velocity: complex, index: tuple[int, ...]) -> list[HalfPlane]:
        obstacles = self.obstacles
        r = self.config.safety_radius + self.margin
        reach = self._obstacle_range
        planes: list[HalfPlane] = []
        if obstacles.n_circles:
            centers = _select(obstacles.centers, index)
            radii = _select(obstacles.radii, index)
            gap = np.abs(centers - position) - radii
            for k in np.flatnonzero(gap < reach):
                combined = float(radii[k]) + r
                planes.append(
                    orca_half_plane(
                        complex(centers[k]) - position,
                        velocity,
                        combined,
                        self.obstacle_time_horizon,
                        self.time_step,
                        1.0,
                        velocity,
                    )
                )
        if obstacles.n_boxes:
            center = _select(obstacles.box_center, index)
            half_x = _select(obstacles.box_half_x, index)
            half_y = _select(obstacles.box_half_y, index)
            a = position - center
            qx = np.abs(a.real) - half_x
            qy = np.abs(a.imag) - half_y
            outside = np.hypot(np.maximum(qx, 0.0), np.maximum(qy, 0.0))
            depth = np.minimum(np.maximum(qx, qy), 0.0)
            gap = outside + depth
            for k in np.flatnonzero(gap < reach):
                sx = 1.0 if a[k].real >= 0 else -1.0
                sy = 1.0 if a[k].imag >= 0 else -1.0
                if outside[k] > 0.0:
                    offset = complex(sx * max(qx[k], 0.0), sy * max(qy[k], 0.0))
                    normal = offset / abs(offset)
                else:  # inside: push out through the nearest face
                    normal = complex(sx, 0.0) if qx[k] > qy[k] else complex(0.0, sy)
                horizon = self.obstacle_time_horizon if gap[k] > r else self.time_step
                planes.append(wall_half_plane(normal, float(gap[k]), r, horizon))
        return planes

    def _neighbour_planes(
        self, position: complex, velocity: complex, others: np.ndarray, others_velocity: np.ndarray
    ) -> list[HalfPlane]:
        combined = 2.0 * self.config.safety_radius + self.margin
        hover = self.config.static_speed
        planes = []
        for q, u in zip(others.tolist(), others_velocity.tolist()):
            static = abs(u) < hover
            planes.append(
                orca_half_plane(
                    q - position,
                    velocity - u,
                    combined,
                    self.obstacle_time_horizon if static else self.time_horizon,
                    self.time_step,
                    1.0 if static else self.responsibility,
                    velocity,
                )
            )
        return planes

    def velocity(
        self,
        position: complex,
        goal: complex,
        velocity: complex,
        others: np.ndarray,
        others_velocity: np.ndarray,
        index: tuple[int, ...] = (),
    ) -> complex:
        """ORCA velocity (m/s, complex) of one drone at ``position`` with current ``velocity``, given the visible
        neighbours' positions and velocities (complex arrays). ``index``: the drone's index in a batch, to pick
        its row of per-arena obstacle arrays."""
        to_goal = goal - position
        d_g = abs(to_goal)
        preferred = to_goal * (min(self.speed, d_g / self.time_step) / d_g) if d_g > 0.0 else 0j
        hard = self._obstacle_planes(position, velocity, index)
        planes = hard + self._neighbour_planes(position, velocity, others, others_velocity)
        return solve_velocity(planes, len(hard), self.speed, preferred)

    # -- the planner interface -----------------------------------------------------------------------------------------

    def prepare(self, goals: np.ndarray) -> None:
        """Precompute the guidance of these goals (as :meth:`Planner.prepare`)."""
        if self.guidance is not None:
            self.guidance.prepare(goals)

    def step(self, view: LocalView) -> PlanStep:
        """Plan every drone of ``view`` (leading shape ``()`` or ``S``) from its own local view."""
        if self.guidance is None:
            return self._step(view)
        goal = view.goal
        guided, waypoint, _ = guided_view(view, self.guidance)
        step = self._step(guided)
        return dataclasses.replace(step, goal_distance=norm(goal - view.position), waypoint=waypoint)

    def _step(self, view: LocalView) -> PlanStep:
        nearest, _ = sense_obstacles(view, self.obstacles, self.config)
        if not isinstance(view.position, np.ndarray) or view.position.ndim == 0:
            return self._step_one(view, nearest.distance)
        shape = view.position.shape
        goals = np.asarray(view.goal)
        current = self._current_velocity(view)
        result = np.zeros(shape, dtype=complex)
        counts = np.zeros(shape, dtype=int)
        mask = np.broadcast_to(view.neighbour_mask, view.neighbour_position.shape)
        for idx in np.ndindex(*shape):
            m = mask[idx]
            others = view.neighbour_position[idx][m]
            result[idx] = self.velocity(
                view.position[idx].item(),
                goals[idx].item(),
                current[idx].item(),
                others,
                view.neighbour_velocity[idx][m],
                idx,
            )
            counts[idx] = others.shape[0]
        if self.remember_velocity:
            self._memory[shape] = (goals.copy(), result.copy())
        to_goal = view.goal - view.position
        d_g = np.abs(to_goal)
        zero = np.zeros(shape, dtype=complex)
        return PlanStep(
            direction=result / self.speed,
            mode=np.zeros(shape, dtype=np.int8),
            f_a=np.where(d_g > 0, to_goal / np.where(d_g > 0, d_g, 1.0), 0),
            f_r=zero,
            f_in=zero.copy(),
            eta=np.full(shape, np.nan),
            lam=np.full(shape, np.nan),
            neighbours=counts,
            obstacle_distance=nearest.distance,
            goal_distance=d_g,
        )

    def _step_one(self, view: LocalView, obstacle_distance: Scalar) -> PlanStep:
        position = complex(view.position)
        goal = complex(view.goal)
        current = self.speed * complex(view.heading)
        if self.remember_velocity and () in self._memory:
            last_goal, last_v = self._memory[()]
            if _consistent(complex(last_goal), goal, complex(last_v), complex(view.heading)):
                current = complex(last_v)
        mask = np.asarray(view.neighbour_mask, dtype=bool)
        others = np.asarray(view.neighbour_position)[mask]
        v = self.velocity(position, goal, current, others, np.asarray(view.neighbour_velocity)[mask])
        if self.remember_velocity:
            self._memory[()] = (np.asarray(goal), np.asarray(v))
        to_goal = goal - position
        d_g = abs(to_goal)
        return PlanStep(
            direction=v / self.speed,
            mode=0,
            f_a=to_goal / d_g if d_g > 0 else 0j,
            f_r=0j,
            f_in=0j,
            eta=math.nan,
            lam=math.nan,
            neighbours=int(others.shape[0]),
            obstacle_distance=float(obstacle_distance),
            goal_distance=d_g,
        )

    def _current_velocity(self, view: LocalView) -> np.ndarray:
        """Each drone's own velocity: the remembered command where the view agrees with it, else cruise speed
        along the view's heading."""
        cruise = self.speed * np.asarray(view.heading, dtype=complex)
        remembered = self._memory.get(np.shape(view.position)) if self.remember_velocity else None
        if remembered is None:
            return cruise
        last_goal, last_v = remembered
        ok = np.vectorize(_consistent, otypes=[bool])(last_goal, view.goal, last_v, view.heading)
        return np.where(ok, last_v, cruise)

    def reset(self) -> None:
        """Forget the remembered velocities (a new scenario with the same batch shape)."""
        self._memory.clear()


def _consistent(last_goal: complex, goal: complex, last_v: complex, heading: complex) -> bool:
    """Whether a remembered command still describes the drone: same goal, and the drone moves along it (the world
    keeps the heading of a drone that stopped)."""
    if last_goal != goal:
        return False
    speed = abs(last_v)
    return speed <= EPSILON or abs(last_v / speed - heading) <= 1.0e-6


def _select(values: np.ndarray, index: tuple[int, ...]) -> np.ndarray:
    """One drone's obstacle row: shared ``(M,)`` arrays pass through; per-arena or per-drone arrays ``S' + (M,)``
    (``S'`` broadcastable to the batch shape) are indexed with the drone's batch ``index``."""
    if values.ndim <= 1:
        return values
    lead = values.shape[:-1]
    tail = index[len(index) - len(lead) :] if len(lead) <= len(index) else (0,) * (len(lead) - len(index)) + index
    return values[tuple(i if n > 1 else 0 for i, n in zip(tail, lead))]
