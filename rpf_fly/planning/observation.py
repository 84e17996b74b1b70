"""The policy's observation of one drone, in its own heading frame (paper Section IV-A; docs/learning.md,
*Observation*).

``o_loc = [d_o, phi_o, d_g, phi_g]``: distance and bearing of the nearest visible obstacle surface point and of the
goal; ``w_j = [d_ji, phi_ji, psi_ji]`` per visible neighbour: distance, bearing, and the neighbour's motion heading
relative to ours. Bearings are signed angles in (-pi, pi] from the drone's current heading.

Neighbours are sorted nearest first and padded to a fixed ``max_neighbours`` with a mask (ONNX needs fixed
shapes and a graph that works with zero neighbours). With no obstacle in range ``d_o`` is the sensing range and
``phi_o`` 0; a static neighbour (slower than ``static_speed``) has ``psi`` 0. Scaling is the policy's business (it
stores its own observation normalisation).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rpf_fly.planning.config import PlannerConfig
from rpf_fly.planning.obstacles import NearestObstacle
from rpf_fly.planning.vectors import maximum, per_item, phase
from rpf_fly.planning.view import LocalView

LOCAL_SIZE = 4
NEIGHBOUR_SIZE = 3


@dataclass(frozen=True)
class Observation:
    """``local`` ``S + (4,)``, ``neighbours`` ``S + (K_max, 3)`` (float32) and ``mask`` ``S + (K_max,)`` (bool)."""

    local: np.ndarray
    neighbours: np.ndarray
    mask: np.ndarray


def _along_last_axis(order: np.ndarray) -> np.ndarray | tuple[np.ndarray, ...]:
    """An index that reorders arrays of shape ``S + (K,)`` along their last axis by ``order`` ``S + (k,)``: built
    once and used for every gathered array (``np.take_along_axis`` rebuilds it at each call)."""
    if order.ndim == 1:
        return order
    grids = np.ogrid[tuple(slice(n) for n in order.shape[:-1])]
    return (*(g[..., None] for g in grids), order)


def build_observation(
    view: LocalView,
    nearest: NearestObstacle,
    config: PlannerConfig,
    max_neighbours: int,
    goal_distance: np.ndarray | float | None = None,
) -> Observation:
    """Observation of every drone in ``view``, from the same nearest obstacle the APF uses.

    Bearings use ``phase(v * conj(h))``: the angle of ``v`` in the frame of the unit heading ``h``. With guidance
    ``view.goal`` is the drone's waypoint (``phi_g`` its bearing) and ``goal_distance`` the remaining path length
    (``d_g``); without, ``d_g = |goal - p|``. With ``config.margin`` ``m > 0`` the distances ``d_o`` and ``d_ji``
    are measured from surfaces grown by ``m`` (clamped at 0): the policy sees the world the forces see.
    """
    h_conj = np.conj(view.heading) if isinstance(view.heading, np.ndarray) else view.heading.conjugate()
    surface = nearest.distance - config.margin if config.margin else nearest.distance
    visible = surface <= config.sensing_range
    d_o = visible * maximum(surface, 0.0) + (1 - visible) * config.sensing_range
    phi_o = visible * phase(-nearest.normal * h_conj)
    to_goal = view.goal - view.position
    phi_g = phase(to_goal * h_conj)
    d_g = abs(to_goal) if goal_distance is None else goal_distance
    if isinstance(d_o, np.ndarray):
        local = np.empty(np.broadcast_shapes(np.shape(d_o), np.shape(to_goal)) + (LOCAL_SIZE,), np.float32)
        for j, value in enumerate((d_o, phi_o, d_g, phi_g)):
            local[..., j] = value
    else:
        local = np.array([d_o, phi_o, d_g, phi_g], dtype=np.float32)

    lead = local.shape[:-1]
    k = view.neighbour_position.shape[-1]
    if k == 0:
        return Observation(
            local,
            np.zeros(lead + (max_neighbours, NEIGHBOUR_SIZE), np.float32),
            np.zeros(lead + (max_neighbours,), bool),
        )
    delta, dist = view.neighbour_offsets()
    order = _along_last_axis(
        np.argsort(np.where(view.neighbour_mask, dist, np.inf), axis=-1, kind="stable")[..., :max_neighbours]
    )
    dist = dist[order]
    mask = view.neighbour_mask[order]
    h = per_item(h_conj)
    phi = phase(delta[order] * h)
    velocity = view.neighbour_velocity[order]
    psi = (abs(velocity) >= config.static_speed) * phase(velocity * h)
    # Fill preallocated slots (np.stack + np.pad cost 20 us a drone).
    used = dist.shape[-1]
    feats = np.zeros(lead + (max_neighbours, NEIGHBOUR_SIZE), np.float32)
    if config.margin:
        dist = np.maximum(dist - config.margin, 0.0)
    feats[..., :used, 0] = dist * mask
    feats[..., :used, 1] = phi * mask
    feats[..., :used, 2] = psi * mask
    slots = np.zeros(lead + (max_neighbours,), bool)
    slots[..., :used] = mask
    return Observation(local, feats, slots)
