"""The visibility graph round a mission's static obstacles: inflated obstacles, segment tests, corner nodes, edges
and shortest distances (rpf_fly/planning/guidance.py builds its guidance on them).

Each obstacle is inflated by ``delta = r + margin`` (the clearance the planner keeps) and replaced by the corners of
a polygon that contains the inflated shape (a box: the box grown by ``delta``; a circle: the circumscribed
``CIRCLE_SIDES``-gon of radius ``rho + delta``). Those corners are the nodes of a *visibility graph*: two nodes are
joined when the straight segment between them crosses no inflated obstacle, and the shortest path between any two
points of the plane that stays out of the inflated obstacles runs along such segments. The all-pairs node distances
are computed once per obstacle set (Floyd-Warshall); a goal adds one row, its cost-to-go ``c_g(v)`` for every node
(docs/algorithm.md, *Global guidance*).

Inflated obstacles that contain an end point of a segment are ignored for that segment: a drone that is already
inside the inflated band of an obstacle (closer than ``delta``) still sees its way out, the repulsion is what
pushes it back. Everything is numpy over leading shapes; metres; points complex.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from rpf_fly.planning.obstacles import FAR, ObstacleSet

CIRCLE_SIDES = 8
"""Corners of the polygon that replaces an inflated circle (its circumscribed regular polygon)."""

NODE_PUSH = 1e-6
"""Relative outward push of every node off its polygon, so that segments along a polygon's edge are not blocked by
rounding (metres per metre of the node's offset)."""

UNREACHABLE = np.inf


@dataclass(frozen=True)
class Inflated:
    """Inflated obstacles as float arrays with a trailing obstacle axis (leading shapes broadcast against the
    points, as :class:`ObstacleSet`'s): circles ``cx``, ``cy``, ``cr`` (radius grown by delta); boxes ``x0``, ``x1``,
    ``y0``, ``y1`` (grown by delta on every side)."""

    cx: np.ndarray
    cy: np.ndarray
    cr: np.ndarray
    x0: np.ndarray
    x1: np.ndarray
    y0: np.ndarray
    y1: np.ndarray

    @staticmethod
    def of(obstacles: ObstacleSet, delta: float) -> Inflated:
        c = np.asarray(obstacles.centers)
        b = np.asarray(obstacles.box_center)
        hx, hy = np.asarray(obstacles.box_half_x) + delta, np.asarray(obstacles.box_half_y) + delta
        return Inflated(
            c.real, c.imag, np.asarray(obstacles.radii) + delta, b.real - hx, b.real + hx, b.imag - hy, b.imag + hy
        )

    @property
    def n_circles(self) -> int:
        return int(self.cr.shape[-1])

    @property
    def n_boxes(self) -> int:
        return int(self.x0.shape[-1])

    def inside(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Points ``(x, y)`` (float arrays ``S``) strictly inside each inflated circle ``S + (Mc,)`` / box
        ``S + (Mb,)``."""
        x, y = x[..., None], y[..., None]
        in_c = (x - self.cx) ** 2 + (y - self.cy) ** 2 < self.cr**2
        in_b = (x > self.x0) & (x < self.x1) & (y > self.y0) & (y < self.y1)
        return in_c, in_b

    def axis(self) -> Inflated:
        """The same obstacles with an axis inserted before the obstacle axis (for ``S + (T, M)`` tests)."""
        return Inflated(*(getattr(self, f.name)[..., None, :] for f in dataclasses.fields(Inflated)))


def blocked(
    a: np.ndarray,
    b: np.ndarray,
    inf: Inflated,
    a_inside: tuple[np.ndarray, np.ndarray] | None = None,
    b_inside: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """Whether each segment ``a -> b`` (complex, broadcasting shapes ``S``) crosses the interior of an inflated
    obstacle that contains neither end point; ``inf``'s arrays broadcast as ``S + (M,)``. ``a_inside``,
    ``b_inside``: which obstacles contain the end points, when the caller knows (``S + (M,)`` each kind).

    Circle: the segment's closest approach to the centre is below the radius. Box: the segment's bounding box
    overlaps the box and the box's corners lie strictly on both sides of the segment's line (grazing is free)."""
    a = np.asarray(a, dtype=complex)
    b = np.asarray(b, dtype=complex)
    ax, ay = a.real[..., None], a.imag[..., None]
    bx, by = b.real[..., None], b.imag[..., None]
    dx, dy = bx - ax, by - ay
    out = None
    if inf.n_circles:
        length2 = dx * dx + dy * dy
        wx, wy = inf.cx - ax, inf.cy - ay
        t = np.clip((wx * dx + wy * dy) / np.maximum(length2, 1e-300), 0.0, 1.0)
        ex, ey = wx - t * dx, wy - t * dy
        hit = ex * ex + ey * ey < inf.cr * inf.cr
        ins_a = a_inside[0] if a_inside is not None else wx * wx + wy * wy < inf.cr * inf.cr
        ins_b = b_inside[0] if b_inside is not None else (inf.cx - bx) ** 2 + (inf.cy - by) ** 2 < inf.cr * inf.cr
        out = (hit & ~(ins_a | ins_b)).any(axis=-1)
    if inf.n_boxes:
        overlap = (np.maximum(ax, bx) > inf.x0) & (np.minimum(ax, bx) < inf.x1)
        overlap &= (np.maximum(ay, by) > inf.y0) & (np.minimum(ay, by) < inf.y1)
        q = dx * ay - dy * ax
        u0, u1 = dx * inf.y0, dx * inf.y1
        v0, v1 = dy * inf.x0, dy * inf.x1
        low = np.minimum(u0, u1) - np.maximum(v0, v1) - q
        high = np.maximum(u0, u1) - np.minimum(v0, v1) - q
        hit = overlap & (low < 0.0) & (high > 0.0)
        if a_inside is not None:
            hit &= ~a_inside[1]
        else:
            hit &= ~((ax > inf.x0) & (ax < inf.x1) & (ay > inf.y0) & (ay < inf.y1))
        if b_inside is not None:
            hit &= ~b_inside[1]
        else:
            hit &= ~((bx > inf.x0) & (bx < inf.x1) & (by > inf.y0) & (by < inf.y1))
        boxes = hit.any(axis=-1)
        out = boxes if out is None else out | boxes
    if out is None:
        return np.zeros(np.broadcast_shapes(a.shape, b.shape), dtype=bool)
    return out


Bounds = tuple[tuple[float, float], tuple[float, float]]


def graph_nodes(obstacles: ObstacleSet, delta: float, bounds: Bounds | None = None) -> np.ndarray:
    """Corner nodes ``(V,)`` of one obstacle set (shared arrays ``(M,)``; FAR padding skipped): polygon corners
    outside every other inflated obstacle and, with ``bounds`` ((x_lo, x_hi), (y_lo, y_hi)), inside the arena."""
    inf = Inflated.of(obstacles, delta)
    nodes = []
    k = np.arange(CIRCLE_SIDES)
    spoke = np.exp(1j * (2 * np.pi * (k + 0.5) / CIRCLE_SIDES))
    scale = (1.0 + NODE_PUSH) / math.cos(math.pi / CIRCLE_SIDES)
    for c, radius in zip(np.asarray(obstacles.centers).reshape(-1), inf.cr.reshape(-1)):
        if abs(c) < FAR / 2:
            nodes.append(c + radius * scale * spoke)
    for x0, x1, y0, y1 in zip(inf.x0.reshape(-1), inf.x1.reshape(-1), inf.y0.reshape(-1), inf.y1.reshape(-1)):
        corners = np.array([complex(x0, y0), complex(x1, y0), complex(x1, y1), complex(x0, y1)])
        centre = complex((x0 + x1) / 2, (y0 + y1) / 2)
        nodes.append(corners + NODE_PUSH * (corners - centre))
    if not nodes:
        return np.zeros(0, dtype=complex)
    v = np.concatenate(nodes)
    in_c, in_b = inf.inside(v.real, v.imag)
    keep = ~(in_c.any(axis=-1) | in_b.any(axis=-1))
    if bounds is not None:
        (x0, x1), (y0, y1) = bounds
        keep &= (v.real >= x0) & (v.real <= x1) & (v.imag >= y0) & (v.imag <= y1)
    return v[keep]


def adjacency(nodes: np.ndarray, inf: Inflated) -> np.ndarray:
    """``(V, V)`` visibility graph: the straight distance between two nodes that see each other, inf otherwise."""
    direct = abs(nodes[:, None] - nodes[None, :])
    free = ~blocked(nodes[:, None], nodes[None, :], inf)
    dist = np.where(free, direct, UNREACHABLE)
    np.fill_diagonal(dist, 0.0)
    return dist


def all_pairs(nodes: np.ndarray, inf: Inflated, direct: np.ndarray | None = None) -> np.ndarray:
    """``(V, V)`` shortest distances between nodes over the visibility graph (Floyd-Warshall; inf: no path).
    ``direct``: the graph's :func:`adjacency`, when the caller has it."""
    n = nodes.shape[0]
    if n == 0:
        return np.zeros((0, 0))
    dist = (adjacency(nodes, inf) if direct is None else direct).copy()
    for k in range(n):
        np.minimum(dist, dist[:, k, None] + dist[None, k, :], out=dist)
    return dist


def shortest_from(start: np.ndarray, direct: np.ndarray) -> np.ndarray:
    """Shortest distances ``(V,)`` over the graph ``direct`` (:func:`adjacency`) from a source whose distance to each
    node is ``start`` (Dijkstra on the dense graph: one goal's cost-to-go without the all-pairs table)."""
    dist = np.array(start, dtype=float, copy=True)
    done = np.zeros(dist.shape[0], dtype=bool)
    for _ in range(dist.shape[0]):
        u = int(np.where(done, UNREACHABLE, dist).argmin())
        if done[u] or not math.isfinite(dist[u]):
            break
        done[u] = True
        np.minimum(dist, dist[u] + direct[u], out=dist)
    return dist


def cost_to_go(goals: np.ndarray, nodes: np.ndarray, pairs: np.ndarray, inf: Inflated) -> np.ndarray:
    """``goals.shape + (V,)``: path length from each node to each goal (inf where cut off)."""
    goals = np.asarray(goals, dtype=complex)
    if nodes.shape[0] == 0:
        return np.zeros(goals.shape + (0,))
    seen = ~blocked(goals[..., None], nodes, inf)  # goals.shape + (V,)
    leg = np.where(seen, abs(goals[..., None] - nodes), UNREACHABLE)
    return (leg[..., :, None] + pairs).min(axis=-2)


def adjacency_between(a: np.ndarray, b: np.ndarray, inf: Inflated) -> np.ndarray:
    """``(A, B)``: the straight distance from each node of ``a`` to each of ``b`` it sees, inf otherwise."""
    return np.where(~blocked(a[:, None], b[None, :], inf), abs(a[:, None] - b[None, :]), UNREACHABLE)
