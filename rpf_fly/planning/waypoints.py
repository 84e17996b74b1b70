"""Each drone's next visible waypoint on the visibility graph (rpf_fly/planning/visibility.py), batched in numpy,
and the segment tests of one drone in plain Python (the flight loop's one-drone call, rpf_fly/planning/guidance.py).

Per tick a drone at ``p`` with goal ``g`` needs only its **next visible waypoint**: ``g`` itself when the segment
``p -> g`` is free, else the node ``v`` visible from ``p`` that minimises ``|p - v| + c_g(v)``: the first corner of
the shortest path from where the drone is now. Without a free path (every node hidden, or the goal cut off) the
waypoint is the goal: plain APF. Metres; points complex.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from rpf_fly.planning.vectors import Planar, Scalar
from rpf_fly.planning.visibility import UNREACHABLE, Inflated, blocked

CANDIDATES = 6
"""Nodes tested per drone and tick: those of smallest ``|p - v| + c_g(v)`` (a lower bound of the path through ``v``
that ignores whether ``v`` is in sight). The first of them in sight is the answer; a drone that sees none of them
(rare: deep in a cluttered corner) is tested against every node."""


def _visible(position: np.ndarray, goal: np.ndarray, targets: np.ndarray, inf: Inflated, wide: Inflated) -> np.ndarray:
    """``S + (T,)``: which targets (the goal first) each drone sees. Obstacles holding the drone are ignored for
    every target, those holding the goal for the goal only."""
    p_in = inf.inside(position.real, position.imag)
    g_in = inf.inside(goal.real, goal.imag)
    n = targets.shape[-1] - 1
    c_in, b_in = (
        np.concatenate([gi[..., None, :], np.zeros(gi.shape[:-1] + (n, gi.shape[-1]), bool)], axis=-2) for gi in g_in
    )
    return ~blocked(position[..., None], targets, wide, (p_in[0][..., None, :], p_in[1][..., None, :]), (c_in, b_in))


def next_waypoint(
    position: Planar,
    goal: Planar,
    nodes: np.ndarray,
    cost: np.ndarray,
    inf: Inflated,
    wide: Inflated | None = None,
    candidates: int | None = CANDIDATES,
) -> tuple[Planar, Scalar]:
    """The waypoint each drone should fly to (complex ``S``) and its remaining path length (metres, ``S``).

    ``nodes`` ``(V,)`` or ``S + (V,)`` (per arena, padded with FAR nodes whose cost is inf), ``cost`` ``S + (V,)``
    each drone's cost-to-go row for its goal; ``inf`` broadcasts as ``S + (M,)`` (``wide``: ``inf.axis()``, when the
    caller keeps it). The goal when it is in sight, or when no node leads there. Each drone tests the goal and its
    ``candidates`` best nodes (:data:`CANDIDATES`; None: every node) against every obstacle."""
    position = np.asarray(position, dtype=complex)
    goal = np.asarray(goal, dtype=complex)
    direct = abs(goal - position)
    if nodes.shape[-1] == 0:
        return (complex(goal), float(direct)) if goal.ndim == 0 else (goal, direct)
    wide = inf.axis() if wide is None else wide
    lead = np.broadcast_shapes(position.shape, goal.shape)
    position = np.broadcast_to(position, lead)
    goal = np.broadcast_to(goal, lead)
    all_nodes = np.broadcast_to(nodes, lead + nodes.shape[-1:])
    to_node = abs(all_nodes - position[..., None])
    bound = np.where(to_node > 1e-9, to_node + cost, UNREACHABLE)  # S + (V,)
    if candidates is not None and candidates < bound.shape[-1]:
        pick = np.argpartition(bound, candidates - 1, axis=-1)[..., :candidates]
    else:
        pick = np.broadcast_to(np.arange(bound.shape[-1]), bound.shape)
    waypoint, remaining, unresolved = _choose(position, goal, direct, all_nodes, bound, pick, inf, wide)
    if unresolved.any() and pick.shape[-1] < bound.shape[-1]:
        rows = np.nonzero(unresolved)
        full = np.broadcast_to(np.arange(bound.shape[-1]), (rows[0].shape[0], bound.shape[-1]))
        sub = Inflated(*(np.broadcast_to(a, lead + a.shape[-1:])[rows] for a in dataclasses.astuple(inf)))
        w2, r2, _ = _choose(
            position[rows], goal[rows], direct[rows], all_nodes[rows], bound[rows], full, sub, sub.axis()
        )
        waypoint = waypoint.copy()
        remaining = remaining.copy()
        waypoint[rows] = w2
        remaining[rows] = r2
    if waypoint.ndim == 0:
        return complex(waypoint), float(remaining)
    return waypoint, remaining


def _choose(position, goal, direct, nodes, bound, pick, inf, wide):
    """Waypoint and remaining length among the goal and the ``pick``ed nodes; ``unresolved``: the goal is hidden
    and no picked node with a finite bound is in sight."""
    chosen = np.take_along_axis(nodes, pick, -1)
    keys = np.take_along_axis(bound, pick, -1)
    targets = np.concatenate([goal[..., None], chosen], axis=-1)
    seen = _visible(position, goal, targets, inf, wide)
    goal_seen = seen[..., 0]
    key = np.where(seen[..., 1:], keys, UNREACHABLE)
    best = key.argmin(axis=-1)[..., None]
    best_key = np.take_along_axis(key, best, -1)[..., 0]
    node = np.take_along_axis(chosen, best, -1)[..., 0]
    use_node = ~goal_seen & np.isfinite(best_key)
    unresolved = ~goal_seen & ~np.isfinite(best_key) & np.isfinite(keys).any(axis=-1)
    return np.where(use_node, node, goal), np.where(use_node, best_key, direct), unresolved


def inside_one(x: float, y: float, circles: list, boxes: list) -> tuple[set, set]:
    ic = {k for k, (cx, cy, r2) in enumerate(circles) if (x - cx) ** 2 + (y - cy) ** 2 < r2}
    ib = {k for k, (x0, x1, y0, y1) in enumerate(boxes) if x0 < x < x1 and y0 < y < y1}
    return ic, ib


def free_one(ax: float, ay: float, bx: float, by: float, circles: list, boxes: list, skip: tuple[set, set]) -> bool:
    """:func:`blocked` for one segment, in plain Python (the flight's one-drone call: a few obstacles, early exit)."""
    dx, dy = bx - ax, by - ay
    length2 = dx * dx + dy * dy
    for k, (cx, cy, r2) in enumerate(circles):
        wx, wy = cx - ax, cy - ay
        t = (wx * dx + wy * dy) / length2 if length2 > 0.0 else 0.0
        t = 0.0 if t < 0.0 else (1.0 if t > 1.0 else t)
        ex, ey = wx - t * dx, wy - t * dy
        if ex * ex + ey * ey < r2 and k not in skip[0]:
            return False
    if not boxes:
        return True
    lo_x, hi_x = (ax, bx) if ax < bx else (bx, ax)
    lo_y, hi_y = (ay, by) if ay < by else (by, ay)
    q = dx * ay - dy * ax
    for k, (x0, x1, y0, y1) in enumerate(boxes):
        if hi_x > x0 and lo_x < x1 and hi_y > y0 and lo_y < y1:
            u0, u1, v0, v1 = dx * y0, dx * y1, dy * x0, dy * x1
            if u0 > u1:
                u0, u1 = u1, u0
            if v0 > v1:
                v0, v1 = v1, v0
            if u0 - v1 - q < 0.0 < u1 - v0 - q and k not in skip[1]:
                return False
    return True
