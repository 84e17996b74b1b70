"""The policy's observation of one drone, in its own heading frame (paper Section IV-A, DESIGN.md 4.4).

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
from rpf_fly.planning.vectors import heading_angle, per_item, relative_angle, wrap_angle
from rpf_fly.planning.view import LocalView

LOCAL_SIZE = 4
NEIGHBOUR_SIZE = 3


@dataclass(frozen=True)
class Observation:
    """``local`` ``S + (4,)``, ``neighbours`` ``S + (K_max, 3)`` (float32) and ``mask`` ``S + (K_max,)`` (bool)."""

    local: np.ndarray
    neighbours: np.ndarray
    mask: np.ndarray


def build_observation(
    view: LocalView, nearest: NearestObstacle, config: PlannerConfig, max_neighbours: int
) -> Observation:
    """Observation of every drone in ``view``, from the same nearest obstacle the APF uses."""
    visible = nearest.distance <= config.sensing_range
    d_o = np.where(visible, np.maximum(nearest.distance, 0.0), config.sensing_range)
    phi_o = np.where(visible, relative_angle(view.heading, -nearest.normal), 0.0)
    to_goal = view.goal - view.position
    phi_g = relative_angle(view.heading, to_goal)
    local = np.stack(np.broadcast_arrays(d_o, phi_o, abs(to_goal), phi_g), axis=-1).astype(np.float32)

    delta = view.neighbour_position - per_item(view.position)
    dist = abs(delta)
    order = np.argsort(np.where(view.neighbour_mask, dist, np.inf), axis=-1, kind="stable")[..., :max_neighbours]
    dist = np.take_along_axis(dist, order, axis=-1)
    mask = np.take_along_axis(view.neighbour_mask, order, axis=-1)
    delta = np.take_along_axis(delta, order, axis=-1)
    vel = np.take_along_axis(view.neighbour_velocity, order, axis=-1)
    heading = per_item(view.heading)
    phi = relative_angle(heading, delta)
    moving = abs(vel) >= config.static_speed
    psi = np.where(moving, wrap_angle(heading_angle(vel) - heading_angle(heading)), 0.0)
    feats = np.where(mask[..., None], np.stack([dist, phi, psi], axis=-1), 0.0)

    k = feats.shape[-2]
    if k < max_neighbours:  # fewer robots than slots: pad
        pad = [(0, 0)] * (feats.ndim - 2) + [(0, max_neighbours - k), (0, 0)]
        feats = np.pad(feats, pad)
        mask = np.pad(mask, pad[:-1])
    return Observation(local, feats.astype(np.float32), mask)
