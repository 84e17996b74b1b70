"""The kinematic world: first-order point-mass drones at constant speed (paper eq. 1), batched over arenas.

Each step every drone that has not arrived moves ``speed * |direction| * dt`` along its planned direction (a unit
vector for the APF planners; shorter for a planner that slows down, like ORCA); a stalled drone (zero direction)
stays put; an arrived drone (goal distance below the tolerance) stays where it arrived and remains visible to the
others as a static neighbour; a halted drone (the training environment halts a drone that collided) likewise. Positions
are clamped to the arena (the geofence) and every clamp is counted. Arrays have shape ``(..., N)`` complex: one leading
entry per arena.
"""

from __future__ import annotations

import numpy as np

from rpf_fly.planning.vectors import Planar, norm, unit
from rpf_fly.planning.view import LocalView, views_from_states


class World:
    """State of ``N`` drones in one or many arenas; :meth:`advance` applies planned directions."""

    def __init__(
        self,
        starts: np.ndarray,
        goals: np.ndarray,
        speed: float,
        dt: float,
        goal_tolerance: float,
        arena_x: tuple[float, float] | np.ndarray,
        arena_y: tuple[float, float] | np.ndarray,
    ):
        self.position = np.array(starts, dtype=complex)
        self.goal = np.array(goals, dtype=complex)
        self.speed = float(speed)
        self.dt = float(dt)
        self.goal_tolerance = float(goal_tolerance)
        ax = np.asarray(arena_x, dtype=float)
        ay = np.asarray(arena_y, dtype=float)
        self._lo_x, self._hi_x = ax[..., 0, None], ax[..., 1, None]
        self._lo_y, self._hi_y = ay[..., 0, None], ay[..., 1, None]
        # The initial heading points at the goal; drones start cruising along it, so at the first step neighbours
        # see each other moving rather than static.
        self.heading = unit(self.goal - self.position)
        self.velocity = self.speed * self.heading
        self.arrived = abs(self.goal - self.position) < self.goal_tolerance
        self.velocity = np.where(self.arrived, 0, self.velocity)
        self.halted = np.zeros(self.position.shape, dtype=bool)
        self.geofence_clamps = np.zeros(self.position.shape, dtype=int)
        self.steps = 0

    def views(self, sensing_range: float) -> LocalView:
        """Every drone's local view (neighbours of the same arena within range)."""
        return views_from_states(self.position, self.velocity, self.goal, self.heading, sensing_range)

    def advance(self, direction: Planar) -> None:
        """Move every active drone one step along ``direction`` (unit or zero)."""
        moving = ~(self.arrived | self.halted) & (norm(direction) > 0.0)
        self.velocity = moving * (self.speed * direction)
        new = self.position + self.velocity * self.dt
        x = np.clip(new.real, self._lo_x, self._hi_x)
        y = np.clip(new.imag, self._lo_y, self._hi_y)
        clamped = (x != new.real) | (y != new.imag)
        self.geofence_clamps += clamped
        self.position = x + 1j * y
        self.heading = np.where(moving, direction / np.where(moving, norm(direction), 1.0), self.heading)
        self.arrived = self.arrived | (abs(self.goal - self.position) < self.goal_tolerance)
        self.steps += 1

    @property
    def all_arrived(self) -> bool:
        return bool(self.arrived.all())
