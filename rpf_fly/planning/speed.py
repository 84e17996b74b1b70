"""Yielding: a drone slows down where its moving neighbours push against its motion, instead of only turning.

Why (docs/algorithm.md, *RPF-3's tuning*): the APF flies at one speed, so every conflict with a moving neighbour is
resolved by a detour; ORCA, which may slow down, lets one drone pass in front of the other and keeps both on their
paths. With ``config.yield_gain`` ``k > 0`` the commanded direction is scaled by

    ``s = clip(1 + k (d . F_in), min_speed_fraction, 1)``

(``d`` the unit direction, ``F_in`` the inter-robot force the heading already saw): full speed where the neighbours
push sideways or from behind, slower where they push back against the motion, never slower than
``min_speed_fraction`` so no drone stalls on this rule alone. The world and the flight loop move a drone
``speed * |direction| * dt`` a step, so a shorter direction is a slower drone; the heading is unchanged. The
static obstacles do not slow anyone (the guidance path and the repulsion already keep their clearance).
Pure function of the step's own vectors: batched and one-drone calls agree.
"""

from __future__ import annotations

import numpy as np

from rpf_fly.planning.config import PlannerConfig
from rpf_fly.planning.vectors import dot, maximum, minimum


def yield_speed(direction: np.ndarray, f_in: np.ndarray, config: PlannerConfig) -> np.ndarray:
    """``direction`` scaled by the yield factor (the same object when ``yield_gain`` is 0)."""
    if not config.yield_gain:
        return direction
    factor = minimum(maximum(1.0 + config.yield_gain * dot(direction, f_in), config.min_speed_fraction), 1.0)
    return direction * factor
