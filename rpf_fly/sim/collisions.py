"""Collision geometry over positions: pairwise separation and obstacle clearance, per step or over a trajectory.

A drone-drone collision is ``d_ji < 2r`` (centre to centre), a drone-obstacle collision ``d_o < r`` (centre to
surface). These functions only measure; counting events is :mod:`rpf_fly.sim.metrics`' job and acting on them is
the flight supervisor's. Positions complex, metres.
"""

from __future__ import annotations

import numpy as np

from rpf_fly.planning.obstacles import ObstacleSet


def pair_distances(positions: np.ndarray) -> np.ndarray:
    """``(..., N, N)`` centre distances with ``inf`` on the diagonal."""
    d = abs(positions[..., :, None] - positions[..., None, :])
    n = positions.shape[-1]
    d[..., np.arange(n), np.arange(n)] = np.inf
    return d


def nearest_neighbour_distance(positions: np.ndarray) -> np.ndarray:
    """``(..., N)`` distance from each drone to its nearest other drone (``inf`` when alone)."""
    return pair_distances(positions).min(axis=-1)


def obstacle_clearance(positions: np.ndarray, obstacles: ObstacleSet) -> np.ndarray:
    """``(..., N)`` signed distance from each drone centre to the nearest obstacle surface (FAR without any)."""
    return obstacles.signed_distance(positions)


def collision_flags(
    positions: np.ndarray, obstacles: ObstacleSet, safety_radius: float
) -> tuple[np.ndarray, np.ndarray]:
    """``(..., N, N)`` pairs in collision (symmetric, diagonal false) and ``(..., N)`` drones inside ``r`` of an
    obstacle surface."""
    pairs = pair_distances(positions) < 2.0 * safety_radius
    if obstacles.is_empty:
        return pairs, np.zeros(positions.shape, dtype=bool)
    return pairs, obstacle_clearance(positions, obstacles) < safety_radius
