"""Global guidance: shortest paths around the mission's static obstacles, and each drone's next visible waypoint.

The obstacles of a mission are known before take-off, so the planner does not have to discover a concave trap by
falling into it. Each obstacle is inflated by ``delta = r + margin`` (the clearance the planner keeps) and replaced
by the corners of a polygon that contains the inflated shape (a box: the box grown by ``delta``; a circle: the
circumscribed ``CIRCLE_SIDES``-gon of radius ``rho + delta``). Those corners are the nodes of a *visibility graph*:
two nodes are joined when the straight segment between them crosses no inflated obstacle, and the shortest path
between any two points of the plane that stays out of the inflated obstacles runs along such segments. The
all-pairs node distances are computed once per obstacle set (Floyd-Warshall); a goal adds one row, its cost-to-go
``c_g(v)`` for every node (docs/algorithm.md, *Global guidance*, has the choice against a grid search and its
measurements).

Per tick a drone at ``p`` with goal ``g`` needs only its **next visible waypoint**: ``g`` itself when the segment
``p -> g`` is free, else the node ``v`` visible from ``p`` that minimises ``|p - v| + c_g(v)``: the first corner of
the shortest path from where the drone is now. Nothing is stored per drone: the path is re-derived from the
drone's position every tick at the cost of one visibility test against each node, so a drone pushed off its
path by the others (the reactive layer) is never guided back to a stale corridor, and a goal change costs one new
cost-to-go row (cached per goal). Everything is numpy over leading shapes ``S``: the simulator, the training
environment (one graph per arena, padded) and the flight loop call the same functions.

A drone may also route round the drones it sees parked (static neighbours: arrived, or holding), which the map
does not hold: :meth:`Guidance.detour` builds the graph of the map plus those drones from the map's own edges
(docs/algorithm.md, *Guidance round parked drones*).

Inflated obstacles that contain an end point of a segment are ignored for that segment: a drone that is already
inside the inflated band of an obstacle (closer than ``delta``) still sees its way out, the repulsion is what
pushes it back. Without a free path (every node hidden, or the goal cut off) the waypoint is the goal: plain APF.
Metres; points complex.
"""

from __future__ import annotations

import dataclasses
import math
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from rpf_fly.planning.obstacles import FAR, ObstacleSet

CIRCLE_SIDES = 8
"""Corners of the polygon that replaces an inflated circle (its circumscribed regular polygon)."""

NODE_PUSH = 1e-6
"""Relative outward push of every node off its polygon, so that segments along a polygon's edge are not blocked by
rounding (metres per metre of the node's offset)."""

UNREACHABLE = np.inf

PARKED_QUANTUM = 0.05
"""Metres: parked drones are placed on a grid of this pitch before their detour graph is built, so a hovering
drone's few centimetres of wobble reuse one graph instead of building a new one every tick."""

DETOUR_CACHE = 16
"""Detour graphs kept per :class:`Guidance` (least recently used dropped first). A run of the families bench builds
1-3 (median; 14 at most) for all its drones together; each holds a dense ``V x V`` graph (0.5 MB for 250 nodes)."""


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
    def of(obstacles: ObstacleSet, delta: float) -> "Inflated":
        c = np.asarray(obstacles.centers)
        b = np.asarray(obstacles.box_center)
        hx, hy = np.asarray(obstacles.box_half_x) + delta, np.asarray(obstacles.box_half_y) + delta
        return Inflated(c.real, c.imag, np.asarray(obstacles.radii) + delta,
                        b.real - hx, b.real + hx, b.imag - hy, b.imag + hy)

    @property
    def n_circles(self) -> int:
        return int(self.cr.shape[-1])

    @property
    def n_boxes(self) -> int:
        return int(self.x0.shape[-1])

    def inside(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Points ``(x, y)`` (float arrays ``S``) strictly inside each inflated circle ``S + (Mc,)`` / box ``S + (Mb,)``."""
        x, y = x[..., None], y[..., None]
        in_c = (x - self.cx) ** 2 + (y - self.cy) ** 2 < self.cr**2
        in_b = (x > self.x0) & (x < self.x1) & (y > self.y0) & (y < self.y1)
        return in_c, in_b

    def axis(self) -> "Inflated":
        """The same obstacles with an axis inserted before the obstacle axis (for ``S + (T, M)`` tests)."""
        return Inflated(*(getattr(self, f.name)[..., None, :] for f in dataclasses.fields(Inflated)))


def blocked(a: np.ndarray, b: np.ndarray, inf: Inflated, a_inside: tuple[np.ndarray, np.ndarray] | None = None,
            b_inside: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
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
    t_in = tuple(np.concatenate([gi[..., None, :], np.zeros(gi.shape[:-1] + (n, gi.shape[-1]), bool)], axis=-2)
                 for gi in g_in)
    return ~blocked(position[..., None], targets, wide, tuple(pi[..., None, :] for pi in p_in), t_in)


def next_waypoint(
    position: np.ndarray, goal: np.ndarray, nodes: np.ndarray, cost: np.ndarray, inf: Inflated,
    wide: Inflated | None = None, candidates: int | None = CANDIDATES,
) -> tuple[np.ndarray, np.ndarray]:
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
        w2, r2, _ = _choose(position[rows], goal[rows], direct[rows], all_nodes[rows], bound[rows], full, sub, sub.axis())
        waypoint = waypoint.copy()
        remaining = remaining.copy()
        waypoint[rows] = w2
        remaining[rows] = r2
    if waypoint.ndim == 0:
        return complex(waypoint), float(remaining)
    return waypoint, remaining


def _choose(position, goal, direct, nodes, bound, pick, inf, wide):  # type: ignore[no-untyped-def]
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


def _inside_one(x: float, y: float, circles: list, boxes: list) -> tuple[set, set]:
    ic = {k for k, (cx, cy, r2) in enumerate(circles) if (x - cx) ** 2 + (y - cy) ** 2 < r2}
    ib = {k for k, (x0, x1, y0, y1) in enumerate(boxes) if x0 < x < x1 and y0 < y < y1}
    return ic, ib


def _free_one(ax: float, ay: float, bx: float, by: float, circles: list, boxes: list, skip: tuple[set, set]) -> bool:
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


@dataclass
class Guidance:
    """The visibility graph of one obstacle set, with a cost-to-go row cached per goal.

    Built once per mission (``Planner`` builds it from its obstacles; :meth:`prepare` with the mission's goals
    computes their rows at load time, so a flight tick only runs :meth:`waypoint`)."""

    obstacles: ObstacleSet
    delta: float
    bounds: Bounds | None = None
    parked_radius: float = 0.0
    """Radius (metres, before the inflation by ``delta``) of a parked drone as an obstacle of its detour graph
    (:meth:`detour`); 0: parked drones are not routed around."""
    parked_min_radius: float = 0.0
    """Where no way leads round the parked drones at :attr:`parked_radius`, the detour tries them again at this
    radius (the drone's body, ``r``: contact plus the margin, no more) before it gives up; 0: it does not."""
    nodes: np.ndarray = field(init=False)
    direct: np.ndarray = field(init=False, repr=False)
    pairs: np.ndarray | None = field(init=False, repr=False)
    inflated: Inflated = field(init=False)
    _goals: list[complex] = field(init=False, default_factory=list)
    _rows: np.ndarray = field(init=False)
    _index: dict[complex, int] = field(init=False, default_factory=dict)
    _wide: Inflated = field(init=False, repr=False)
    _circles: list = field(init=False, repr=False)
    _boxes: list = field(init=False, repr=False)
    _node_xy: list = field(init=False, repr=False)
    _row_arrays: dict = field(init=False, repr=False, default_factory=dict)
    _detours: OrderedDict = field(init=False, repr=False, default_factory=OrderedDict)
    detours_built: int = field(init=False, default=0)
    """How many detour graphs this guidance has built (for the measurements)."""

    def __post_init__(self) -> None:
        self.inflated = Inflated.of(self.obstacles, self.delta)
        self.nodes = graph_nodes(self.obstacles, self.delta, self.bounds)
        self.direct = adjacency(self.nodes, self.inflated) if self.nodes.shape[0] else np.zeros((0, 0))
        self.pairs = all_pairs(self.nodes, self.inflated, self.direct)
        self._derived()

    def _derived(self) -> None:
        """The caches every query uses, from ``obstacles``, ``inflated`` and ``nodes``."""
        self._rows = np.zeros((0, self.nodes.shape[0]))
        self._wide = self.inflated.axis()
        inf = self.inflated
        self._circles = [(float(x), float(y), float(r) ** 2) for x, y, r in zip(inf.cx.ravel(), inf.cy.ravel(), inf.cr.ravel())]
        self._boxes = [tuple(map(float, b)) for b in zip(inf.x0.ravel(), inf.x1.ravel(), inf.y0.ravel(), inf.y1.ravel())]
        self._node_xy = [(float(v.real), float(v.imag)) for v in self.nodes]

    def prepare(self, goals: np.ndarray) -> None:
        """Compute (and cache) the cost-to-go rows of these goals."""
        new = [complex(g) for g in np.asarray(goals, dtype=complex).reshape(-1) if complex(g) not in self._index]
        new = list(dict.fromkeys(new))
        if not new:
            return
        rows = cost_to_go(np.array(new), self.nodes, self.pairs, self.inflated)
        for g in new:
            self._index[g] = len(self._goals)
            self._goals.append(g)
        self._rows = np.concatenate([self._rows, rows.reshape(len(new), -1)])

    def rows(self, goal: np.ndarray | complex) -> np.ndarray:
        """Cost-to-go rows ``S + (V,)`` for goals ``S`` (computed on first use of a goal)."""
        goal = np.asarray(goal, dtype=complex)
        flat = goal.reshape(-1)
        if any(complex(g) not in self._index for g in flat):
            self.prepare(flat)
        index = np.fromiter((self._index[complex(g)] for g in flat), dtype=int, count=flat.shape[0])
        return self._rows[index].reshape(goal.shape + (self.nodes.shape[0],))

    def waypoint(
        self, position: np.ndarray | complex, goal: np.ndarray | complex,
        parked: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Next visible waypoint and remaining path length for every drone (shapes of ``position``).

        ``parked``: what each drone sees parked (static neighbours), as positions (complex ``S + (K,)``) and a mask
        ``S + (K,)``. With :attr:`parked_radius` set, a drone flies the detour graph (:meth:`detour`) of the parked
        drones that may lie in its way: those ``q`` with ``|p - q| + |q - g|`` under its remaining path length plus
        ``2 (parked_radius + delta)`` (every drone within ``parked_radius + delta`` of its path is among them). The
        set is the whole of what may block the path, not its first leg: a drone routed round by the detour is not
        sent back through the gap once the leg in front of it is clear. No way round: the map's path."""
        one = np.ndim(position) == 0 and np.ndim(goal) == 0
        if one:
            p, g = complex(position), complex(goal)
            w, remaining = self._waypoint_one(p, g)
            if parked is not None and self.parked_radius:
                return self._around_one(p, g, w, remaining, parked)
            return w, remaining
        w, remaining = next_waypoint(position, goal, self.nodes, self.rows(goal), self.inflated, self._wide)
        if parked is not None and self.parked_radius:
            return self._around(position, goal, w, remaining, parked)
        return w, remaining

    def detour(self, parked: Sequence[complex], radius: float | None = None) -> "Guidance":
        """The guidance of the mission's obstacles plus these parked drones, each a circle of radius
        :attr:`parked_radius` (inflated by ``delta`` like every obstacle), placed on the :data:`PARKED_QUANTUM`
        grid; built on first use of a set and cached (:data:`DETOUR_CACHE`).

        Why: the map's shortest path may run through a gap that a drone parked on its goal has closed; the
        repulsion then holds the drone at the gap (RPF-3 in arena-a: 7 of 220 fresh runs, one drone circling or
        stalled there to the time limit; docs/algorithm.md, *Guidance round parked drones*). Routed around the
        parked drone, it flies the next gap instead."""
        radius = self.parked_radius if radius is None else radius
        cells = tuple(sorted((round(q.real / PARKED_QUANTUM), round(q.imag / PARKED_QUANTUM)) for q in parked))
        key = (radius, cells)
        found = self._detours.get(key)
        if found is not None:
            self._detours.move_to_end(key)
            return found
        centers = np.array([complex(i, j) * PARKED_QUANTUM for i, j in cells], dtype=complex)
        found = _Detour.around(self, centers, radius)
        self.detours_built += 1
        self._detours[key] = found
        if len(self._detours) > DETOUR_CACHE:
            self._detours.popitem(last=False)
        return found

    def _around_one(self, p: complex, g: complex, w: complex, remaining: float,
                    parked: tuple[np.ndarray, np.ndarray]) -> tuple[complex, float]:
        """One drone: its waypoint over the detour graph of the parked drones that may be in its way."""
        positions, mask = parked
        seen = [q for q, keep in zip(np.ravel(positions).tolist(), np.ravel(mask).tolist()) if keep]
        found = self._detour_of(p, g, w, remaining, seen)
        return (w, remaining) if found is None else found

    DETOUR_ROUNDS = 3
    """Times the set of parked drones in the way is widened to the detour's own length (:meth:`_detour_of`)."""

    def _detour_of(self, p: complex, g: complex, w: complex, remaining: float,
                   seen: list[complex]) -> tuple[complex, float] | None:
        """The detour past the parked drones ``seen`` that may lie in the way (None: none is, or no way round).

        Which ones may: ``|p - q| + |q - g|`` under the path length plus ``2 (parked_radius + delta)``; first the
        map's path length, then the detour's own (longer) one, until the set stops growing: a detour that leads
        past a parked drone the map's path did not pass must know that one too, or the drone is led into a gap it
        closes and sent back once near it."""
        slack = 2.0 * (self.parked_radius + self.delta)
        found = None
        others: list[complex] = []
        length = remaining
        for _ in range(self.DETOUR_ROUNDS):
            wider = [q for q in seen if abs(q - p) + abs(g - q) < length + slack]
            if len(wider) == len(others):
                break
            others = wider
            attempt = self._detour_one(p, g, w, others)
            if attempt is None:
                break
            found = attempt
            length = attempt[1]
        return found

    def _detour_one(self, p: complex, g: complex, w: complex, others: list[complex]) -> tuple[complex, float] | None:
        """The detour waypoint at :attr:`parked_radius`, else at :attr:`parked_min_radius`; None without a way round
        (the map's path then: the repulsion alone keeps the drones apart)."""
        for radius in (self.parked_radius, self.parked_min_radius):
            if radius <= 0.0:
                continue
            detour = self.detour(others, radius)
            w2, r2 = detour._waypoint_one(p, g)
            if w2 != g or detour._sees_one(p, g):  # else the goal is hidden and no node leads there: no way round
                return w2, r2
        return None

    def _around(self, position: np.ndarray, goal: np.ndarray, w: np.ndarray, remaining: np.ndarray,
                parked: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`_around_one` over leading shapes ``S`` (the drones with a parked one in the way: a loop)."""
        positions, mask = parked
        if not np.shape(mask) or not np.shape(mask)[-1] or not np.any(mask):
            return w, remaining
        lead = np.shape(w)
        p = np.broadcast_to(np.asarray(position, dtype=complex), lead)
        g = np.broadcast_to(np.asarray(goal, dtype=complex), lead)
        slack = 2.0 * (self.parked_radius + self.delta)
        relevant = mask & (abs(positions - p[..., None]) + abs(g[..., None] - positions) < (remaining + slack)[..., None])
        rows = np.nonzero(relevant.any(axis=-1))
        if not rows[0].size:
            return w, remaining
        w, remaining = np.array(w, copy=True), np.array(remaining, copy=True)
        for index in zip(*rows):
            found = self._detour_of(complex(p[index]), complex(g[index]), complex(w[index]), float(remaining[index]),
                                    positions[index][mask[index]].tolist())
            if found is not None:
                w[index], remaining[index] = found
        return w, remaining

    def _sees_one(self, p: complex, g: complex, skip: tuple[set, set] | None = None) -> bool:
        """Whether the segment ``p -> g`` is free (obstacles holding either end ignored), in plain Python."""
        circles, boxes = self._circles, self._boxes
        if skip is None:
            skip = _inside_one(p.real, p.imag, circles, boxes)
        goal_skip = _inside_one(g.real, g.imag, circles, boxes)
        return _free_one(p.real, p.imag, g.real, g.imag, circles, boxes, (skip[0] | goal_skip[0], skip[1] | goal_skip[1]))

    def _waypoint_one(self, p: complex, g: complex) -> tuple[complex, float]:
        """:func:`next_waypoint` for one drone in plain Python: the goal's segment first, then the nodes in the order
        of their key, stopping at the first one in sight (the flight loop's one-drone call)."""
        direct = abs(g - p)
        if not self._node_xy:
            return g, direct
        circles, boxes = self._circles, self._boxes
        ax, ay = p.real, p.imag
        skip = _inside_one(ax, ay, circles, boxes)
        if self._sees_one(p, g, skip):
            return g, direct
        row = self._row_arrays.get(g)
        if row is None:
            row = self._row_arrays[g] = self.rows(g)
        keys = abs(self.nodes - p) + row  # numpy: 5x quicker than a Python loop over ~100 nodes
        for k in np.argsort(keys, kind="stable").tolist():
            key = float(keys[k])
            if not math.isfinite(key):
                break
            x, y = self._node_xy[k]
            if (x - ax) ** 2 + (y - ay) ** 2 > 1e-18 and _free_one(ax, ay, x, y, circles, boxes, skip):
                return complex(x, y), key
        return g, direct

    def path(self, start: complex, goal: complex, limit: int = 1000) -> list[complex]:
        """The whole path from ``start`` to ``goal`` as the waypoints would lead a drone that follows them exactly
        (for plots, tests and the measurements; the planner itself only ever asks for the next waypoint)."""
        points = [complex(start)]
        p = complex(start)
        for _ in range(limit):
            w, _ = self.waypoint(p, goal)
            points.append(complex(w))
            if w == goal:
                break
            p = complex(w)
        return points


class _Detour(Guidance):
    """A :class:`Guidance` over the mission's obstacles plus parked drones, built from the mission's graph
    (:meth:`Guidance.detour`): its visibility edges are kept unless a parked drone cuts them, the parked drones'
    corners are joined to every node, and each goal's cost-to-go comes from :func:`shortest_from` (no all-pairs
    table). The same graph, nodes and paths as a :class:`Guidance` built on the grown obstacle set from scratch
    (tested), at a fraction of the cost: 28 pillars and 5 parked drones took 42 ms from scratch."""

    @classmethod
    def around(cls, base: Guidance, centers: np.ndarray, radius: float) -> "_Detour":
        o = base.obstacles
        parked = ObstacleSet(centers, np.full(centers.shape[0], radius), np.zeros(0, complex), np.zeros(0), np.zeros(0))
        self = cls.__new__(cls)
        self.obstacles = ObstacleSet(
            np.concatenate([np.ravel(o.centers), centers]), np.concatenate([np.ravel(o.radii), parked.radii]),
            np.ravel(o.box_center), np.ravel(o.box_half_x), np.ravel(o.box_half_y),
        )
        self.delta, self.bounds, self.parked_radius, self.parked_min_radius = base.delta, base.bounds, 0.0, 0.0
        self.inflated = Inflated.of(self.obstacles, self.delta)
        around = Inflated.of(parked, self.delta)
        old = base.nodes
        kept = ~around.inside(old.real, old.imag)[0].any(axis=-1)  # a mission corner under a parked drone is gone
        new = graph_nodes(parked, self.delta, self.bounds)
        in_c, in_b = base.inflated.inside(new.real, new.imag)
        new = new[~(in_c.any(axis=-1) | in_b.any(axis=-1))]
        self.nodes = np.concatenate([old, new])
        n_old, n = old.shape[0], self.nodes.shape[0]
        direct = np.full((n, n), UNREACHABLE)
        kept_edges = base.direct.copy()
        i, j = np.nonzero(np.triu(np.isfinite(kept_edges), 1))
        cut = blocked(old[i], old[j], around)
        kept_edges[i[cut], j[cut]] = UNREACHABLE
        kept_edges[j[cut], i[cut]] = UNREACHABLE
        direct[:n_old, :n_old] = kept_edges
        if new.shape[0]:
            edges = adjacency_between(new, self.nodes, self.inflated)
            direct[n_old:, :] = edges
            direct[:, n_old:] = edges.T
        usable = np.concatenate([kept, np.ones(new.shape[0], dtype=bool)])
        direct[~usable, :] = UNREACHABLE
        direct[:, ~usable] = UNREACHABLE
        np.fill_diagonal(direct, 0.0)
        self.direct, self.pairs = direct, None
        self._usable = usable
        self._goals, self._index, self._row_arrays = [], {}, {}
        self._detours, self.detours_built = OrderedDict(), 0
        self._derived()
        return self

    def prepare(self, goals: np.ndarray) -> None:
        new = [complex(g) for g in np.asarray(goals, dtype=complex).reshape(-1) if complex(g) not in self._index]
        new = list(dict.fromkeys(new))
        if not new:
            return
        rows = []
        for g in new:
            seen = ~blocked(np.full(self.nodes.shape, g), self.nodes, self.inflated)
            leg = np.where(seen & self._usable, abs(g - self.nodes), UNREACHABLE)
            rows.append(shortest_from(leg, self.direct))
            self._index[g] = len(self._goals)
            self._goals.append(g)
        self._rows = np.concatenate([self._rows, np.array(rows).reshape(len(new), -1)])


def adjacency_between(a: np.ndarray, b: np.ndarray, inf: Inflated) -> np.ndarray:
    """``(A, B)``: the straight distance from each node of ``a`` to each of ``b`` it sees, inf otherwise."""
    return np.where(~blocked(a[:, None], b[None, :], inf), abs(a[:, None] - b[None, :]), UNREACHABLE)


def path_length(points: list[complex]) -> float:
    return float(sum(abs(b - a) for a, b in zip(points[:-1], points[1:])))
