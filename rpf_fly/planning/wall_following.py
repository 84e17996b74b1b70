"""Wall-following (mode A) and the soft rule (mode B): how the paper turns forces into a heading (Section IV-C).

With ``F_ar = F_a + F_r`` and the tangents ``n1 = rot90(F_r)/|F_r|`` (the push turned 90 degrees
counter-clockwise, so a drone heading straight at an obstacle turns right) and ``n2 = -n1``:

- mode A, ``F_ar . F_a < 0``: the drone follows the chosen tangent;
- mode B, ``F_r . F_a < 0`` and ``F_ar . F_a >= 0``: ``F_soft = (F_ar + 2|F_r| n) / |...|``, equal to ``F_ar``
  where ``|F_r| = 0`` (entering the influence range) and turning toward the tangent as the drone closes in;
- otherwise the vanilla APF direction ``F_a + F_r + F_in``.

``F_a`` is a unit vector (or zero at the goal), so ``F_ar . F_a = 1 + F_r . F_a`` and both tests read one number.

Side choice: if the inter-robot force is large (``|F_in| >= F_in_bar``, or its tangential part ``|n1 . F_in|``
for the robust preset) the tangent with positive dot product with ``F_in``, else the one closer to the current
heading; an exact tie (``|n1 . ref| <= 1e-9 |ref|``) takes ``n1``, so the choice never depends on rounding.
"""

from __future__ import annotations

import numpy as np

from rpf_fly.planning.config import PlannerConfig
from rpf_fly.planning.vectors import TINY, Planar, Scalar, any_true, dot, maximum, norm, unit

MODE_APF = 0
"""No wall-following active: vanilla APF direction."""
MODE_WALL = 1
"""Mode A: following the obstacle's tangent."""
MODE_SOFT = 2
"""Mode B: the soft rule, between ``F_ar`` and the tangent."""
MODE_NAMES = {MODE_APF: "apf", MODE_WALL: "wall", MODE_SOFT: "soft"}

TIE_TOLERANCE = 1e-9


def choose_tangent(f_r: Planar, f_in: Planar, heading: Planar, config: PlannerConfig) -> Planar:
    """The tangent chosen by the side rule (unit, complex); zero where ``F_r`` is zero."""
    n1 = unit(1j * f_r)
    if config.side_from_tangential_force:
        strength = norm(dot(n1, f_in))
    else:
        strength = norm(f_in)
    ref = (strength >= config.wall_threshold) * f_in + (strength < config.wall_threshold) * heading
    flip = dot(n1, ref) < -TIE_TOLERANCE * norm(ref)
    return n1 - 2.0 * flip * n1


def select_heading(
    f_a: Planar,
    f_r: Planar,
    f_in: Planar,
    heading: Planar,
    obstacle_distance: Scalar,
    config: PlannerConfig,
) -> tuple[Planar, Scalar]:
    """Commanded unit direction and mode (int8) for each robot.

    The direction is zero where the resultant vanishes: a stalled drone (the vanilla APF local minimum), which
    the caller keeps in place.
    """
    total = f_a + f_r + f_in
    free = unit(total)
    push = dot(f_r, f_a)  # F_ar . F_a = 1 + push
    if not config.wall_following or not any_true(push < 0.0):
        return free, _modes(push, 0)
    in_a = push < -1.0
    in_b = (push < 0.0) & (push >= -1.0)

    n = choose_tangent(f_r, f_in, heading, config)
    f_r_norm = norm(f_r)
    wall = n
    if config.bend_near_surface:
        r = config.safety_radius
        k = maximum((2.0 * r - obstacle_distance) / r, 0.0)
        wall = unit(n + k * f_r / (f_r_norm + TINY))
    soft_base = total if config.soft_keeps_inter_robot else f_a + f_r
    soft = unit(soft_base + 2.0 * f_r_norm * n)
    direction = in_a * wall + in_b * soft + (push >= 0.0) * free
    return direction, _modes(push, in_a * MODE_WALL + in_b * MODE_SOFT)


def _modes(like, value):
    """Mode codes as int8 arrays for batches, a Python int for one drone."""
    if isinstance(like, np.ndarray):
        return np.broadcast_to(np.asarray(value, dtype=np.int8), like.shape)
    return int(value)
