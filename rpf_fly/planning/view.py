"""What a drone senses: its own state and the neighbours within its sensing range.

Each drone plans from a :class:`LocalView` alone; planners never exchange anything. The simulator and the
training environment build the views of all drones at once with :func:`views_from_states` (each drone still
sees only the neighbours within its own range); the flight loop builds one drone's view from a mocap frame with
:func:`view_of_drone`. Both give the same arrays, so one planner serves both. Planar vectors are complex
(:mod:`rpf_fly.planning.vectors`); metres and metres per second.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from rpf_fly.planning.vectors import Planar, offsets


@dataclass(frozen=True)
class LocalView:
    """Arrays with leading shape ``S`` (one entry per drone being planned; ``()`` for a single drone).

    ``position``, ``goal``: ``S``; ``heading``: ``S``, unit vector of the current motion direction;
    ``neighbour_position``, ``neighbour_velocity``: ``S + (K,)``; ``neighbour_mask``: ``S + (K,)``, true for a
    real neighbour within sensing range (padding is false).
    """

    position: Planar
    goal: Planar
    heading: Planar
    neighbour_position: np.ndarray
    neighbour_velocity: np.ndarray
    neighbour_mask: np.ndarray

    def neighbour_offsets(self) -> tuple[np.ndarray, np.ndarray]:
        """``(delta, distance)`` ``S + (K,)``: each neighbour's offset ``p_j - p`` (complex) and its length, computed
        once per view (:func:`~rpf_fly.planning.vectors.offsets`). The observation, the inter-robot force, the brake
        and the static-neighbour circles each needed them (a 100-drone tick computed the same 100 x 99 offsets five
        times); a view is never changed, so one computation serves all."""
        cached = self.__dict__.get("_offsets")
        if cached is None:
            cached = offsets(self.position, self.neighbour_position)
            object.__setattr__(self, "_offsets", cached)
        return cached

    def with_goal(self, goal: Planar) -> LocalView:
        """The same view with another goal (guidance's waypoint), its neighbour offsets shared."""
        view = LocalView(
            self.position, goal, self.heading, self.neighbour_position, self.neighbour_velocity, self.neighbour_mask
        )
        if "_offsets" in self.__dict__:
            object.__setattr__(view, "_offsets", self.__dict__["_offsets"])
        return view


@lru_cache(maxsize=64)
def others_index(n: int) -> np.ndarray:
    """``(n, n-1)`` indices of every robot but ``i`` in row ``i``."""
    if n <= 1:
        return np.zeros((n, 0), dtype=int)
    full = np.broadcast_to(np.arange(n), (n, n))
    return full[~np.eye(n, dtype=bool)].reshape(n, n - 1)


def views_from_states(
    positions: np.ndarray,
    velocities: np.ndarray,
    goals: np.ndarray,
    headings: np.ndarray,
    sensing_range: float,
) -> LocalView:
    """Views of all ``N`` robots of one or many arenas (arrays ``(..., N)``): each robot's neighbours are the
    other robots of its arena strictly closer than ``sensing_range``."""
    idx = others_index(positions.shape[-1])
    nbr_pos = positions[..., idx]  # (..., N, N-1)
    mask = abs(nbr_pos - positions[..., None]) < sensing_range
    return LocalView(positions, goals, headings, nbr_pos, velocities[..., idx], mask)


def view_of_drone(
    position: complex,
    goal: complex,
    heading: complex,
    others_position: np.ndarray,
    others_velocity: np.ndarray,
    sensing_range: float,
) -> LocalView:
    """One drone's view (leading shape ``()``) from the others' positions and velocities ``(K,)``: keeps those in
    range, as its sensors would."""
    others_position = np.asarray(others_position, dtype=complex).reshape(-1)
    others_velocity = np.asarray(others_velocity, dtype=complex).reshape(-1)
    keep = abs(others_position - position) < sensing_range
    nbr = others_position[keep]
    return LocalView(
        complex(position),
        complex(goal),
        complex(heading),
        nbr,
        others_velocity[keep],
        np.ones(nbr.shape[0], dtype=bool),
    )


def views_of_drones(
    position: np.ndarray,
    goal: np.ndarray,
    heading: np.ndarray,
    others_position: np.ndarray,
    others_velocity: np.ndarray,
    others_present: np.ndarray,
    sensing_range: float,
) -> LocalView:
    """The views of ``P`` drones at once (leading shape ``(P,)``), each from its own row ``(P, K)`` of the others'
    positions and velocities; ``others_present`` is false for padding (and for the drone itself). Keeps those in
    range exactly as :func:`view_of_drone` does for one drone, so a planner gives row ``i`` what the one-drone call
    on drone ``i``'s view gives (up to float summation order)."""
    mask = others_present & (abs(others_position - position[..., None]) < sensing_range)
    return LocalView(position, goal, heading, others_position, others_velocity, mask)
