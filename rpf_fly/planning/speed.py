"""Speed rules: a drone slows down where its moving neighbours push against its motion, instead of only turning.

Why (docs/algorithm.md, *RPF-3's tuning*): the APF flies at one speed, so every conflict with a moving neighbour is
resolved by a detour; ORCA, which may slow down, lets one drone pass in front of the other and keeps both on their
paths. With ``config.yield_gain`` ``k > 0`` the commanded direction is scaled by

    ``s = clip(1 + k (d . F_in), min_speed_fraction, 1)``

(``d`` the unit direction, ``F_in`` the inter-robot force the heading already saw): full speed where the neighbours
push sideways or from behind, slower where they push back against the motion, never slower than
``min_speed_fraction`` so no drone stalls on this rule alone. The world and the flight loop move a drone
``speed * |direction| * dt`` a step, so a shorter direction is a slower drone; the heading is unchanged (a
slide also turns it, along the wall). :func:`brake` is the second rule: a drone heading toward a neighbour slows as
the gap to ``2r + margin`` closes, and one heading into the nearest wall loses the inward part of its step as the
gap to ``r + margin`` closes.
Pure functions of the step's own vectors and the view: batched and one-drone calls agree.
"""

from __future__ import annotations

import math

import numpy as np

from rpf_fly.planning.config import PlannerConfig
from rpf_fly.planning.obstacles import NearestObstacle
from rpf_fly.planning.vectors import Planar, dot, maximum, minimum, per_item
from rpf_fly.planning.vectors import offsets as offsets_of


def yield_speed(direction: Planar, f_in: Planar, config: PlannerConfig) -> Planar:
    """``direction`` scaled by the yield factor (the same object when ``yield_gain`` is 0)."""
    if not config.yield_gain:
        return direction
    factor = minimum(maximum(1.0 + config.yield_gain * dot(direction, f_in), config.min_speed_fraction), 1.0)
    return direction * factor


def brake(
    direction: Planar,
    position: Planar,
    neighbour_position: np.ndarray,
    neighbour_mask: np.ndarray,
    config: PlannerConfig,
    nearest: NearestObstacle | None = None,
    offsets: tuple[np.ndarray, np.ndarray] | None = None,
) -> Planar:
    """``direction`` scaled by ``min clip(gap / brake_distance, 0, 1)`` over what it heads toward: each neighbour
    ``j`` with ``d . (p_j - p) > 0``, ``gap = |p_j - p| - (2r + margin + brake_buffer)``; then, toward the
    ``nearest`` obstacle surface (``d . normal < 0``), only the inward part of the step is scaled by the same
    ``clip(gap / brake_distance, 0, 1)`` with ``gap = d_o - (r + margin + brake_buffer)``: the drone slides along
    the wall at full speed. The same object when ``brake_distance`` is 0.

    Why: the forces keep ``2r + margin`` and ``r + margin`` on average, but a drone squeezed between several
    neighbours (a 23-drone circle), or between an arrived drone and a pillar, can be pushed a few millimetres (or
    centimetres) inside (0.2467 m against 0.25 in 1 of 120 fresh circles; 0.131 m against 0.15 beside a pillar).
    Braking within ``brake_distance`` of the bar makes the drone's own steps toward it shrink geometrically as the
    gap closes, so it never steps across the bar toward a hovering neighbour or a wall; moving sideways or away
    stays at full speed, so the rule alone cannot stall a drone that may turn away. ``offsets``: the neighbours'
    ``(p_j - p, |p_j - p|)`` when the caller has them (:meth:`LocalView.neighbour_offsets`)."""
    if not config.brake_distance:
        return direction
    pair_buffer = config.brake_buffer if config.pair_brake_buffer is None else config.pair_brake_buffer
    pair_bar = 2.0 * config.safety_radius + config.margin + pair_buffer
    wall_bar = config.safety_radius + config.margin + config.brake_buffer
    k = neighbour_position.shape[-1]
    if not isinstance(position, np.ndarray):  # one drone: plain Python over its few neighbours
        slowest = 1.0
        if k:
            for q, keep in zip(neighbour_position.tolist(), neighbour_mask.tolist()):
                dx, dy = q.real - position.real, q.imag - position.imag
                if keep and direction.real * dx + direction.imag * dy > 0.0:
                    slowest = min(slowest, max((math.hypot(dx, dy) - pair_bar) / config.brake_distance, 0.0))
        if slowest < 1.0:
            direction = direction * slowest
        if nearest is not None:
            n = nearest.normal
            inward = direction.real * n.real + direction.imag * n.imag
            if inward < 0.0:
                share = min(max((nearest.distance - wall_bar) / config.brake_distance, 0.0), 1.0)
                if share < 1.0:
                    direction = direction - (1.0 - share) * inward * n
        return direction
    factor = np.ones(np.shape(position))
    if k:
        delta, distance = offsets if offsets is not None else offsets_of(position, neighbour_position)
        heading = per_item(direction)
        towards = heading.real * delta.real + heading.imag * delta.imag > 0.0
        gap = distance - pair_bar
        factor = np.where(neighbour_mask & towards, np.clip(gap / config.brake_distance, 0.0, 1.0), 1.0).min(axis=-1)
    direction = direction * factor
    if nearest is not None:
        n = nearest.normal
        inward = np.minimum(direction.real * n.real + direction.imag * n.imag, 0.0)
        keep = np.clip((nearest.distance - wall_bar) / config.brake_distance, 0.0, 1.0)
        direction = direction - (1.0 - keep) * inward * n
    return direction
