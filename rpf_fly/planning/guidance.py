"""Global guidance: shortest paths around the mission's static obstacles, and each drone's next visible waypoint.

The obstacles of a mission are known before take-off, so the planner does not have to discover a concave trap by
falling into it. The mission's obstacles, inflated by the clearance the planner keeps, give a *visibility graph*
(rpf_fly/planning/visibility.py); :class:`Guidance` holds it for one obstacle set, with a cost-to-go row cached per
goal, and answers each drone's **next visible waypoint** (rpf_fly/planning/waypoints.py): the goal when it is in
sight, else the first corner of the shortest path from where the drone is now (docs/algorithm.md, *Global
guidance*, has the choice against a grid search and its measurements). Nothing is stored per drone: the path is
re-derived from the drone's position every tick at the cost of one visibility test against each node, so a drone
pushed off its path by the others (the reactive layer) is never guided back to a stale corridor, and a goal change
costs one new cost-to-go row (cached per goal). Everything is numpy over leading shapes ``S``: the simulator, the
training environment (one graph per arena, padded) and the flight loop call the same functions.

A drone may also route round the drones it sees parked (static neighbours: arrived, or holding), which the map
does not hold: :meth:`Guidance.detour` builds the graph of the map plus those drones from the map's own edges
(docs/algorithm.md, *Guidance round parked drones*). Metres; points complex.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from rpf_fly.planning.obstacles import ObstacleSet
from rpf_fly.planning.vectors import Planar, Scalar
from rpf_fly.planning.visibility import (
    UNREACHABLE,
    Bounds,
    Inflated,
    adjacency,
    adjacency_between,
    all_pairs,
    blocked,
    cost_to_go,
    graph_nodes,
    shortest_from,
)
from rpf_fly.planning.waypoints import free_one, inside_one, next_waypoint

PARKED_QUANTUM = 0.05
"""Metres: parked drones are placed on a grid of this pitch before their detour graph is built, so a hovering
drone's few centimetres of wobble reuse one graph instead of building a new one every tick."""

DETOUR_CACHE = 16
"""Detour graphs kept per :class:`Guidance` (least recently used dropped first). A run of the families bench builds
1-3 (median; 14 at most) for all its drones together; each holds a dense ``V x V`` graph (0.5 MB for 250 nodes)."""


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
        self._circles = [
            (float(x), float(y), float(r) ** 2) for x, y, r in zip(inf.cx.ravel(), inf.cy.ravel(), inf.cr.ravel())
        ]
        self._boxes = [
            tuple(map(float, b)) for b in zip(inf.x0.ravel(), inf.x1.ravel(), inf.y0.ravel(), inf.y1.ravel())
        ]
        self._node_xy = [(float(v.real), float(v.imag)) for v in self.nodes]

    def prepare(self, goals: np.ndarray) -> None:
        """Compute (and cache) the cost-to-go rows of these goals."""
        new = [complex(g) for g in np.asarray(goals, dtype=complex).reshape(-1) if complex(g) not in self._index]
        new = list(dict.fromkeys(new))
        if not new:
            return
        # pairs is None only in a detour graph, whose own prepare() runs shortest paths instead
        assert self.pairs is not None
        rows = cost_to_go(np.array(new), self.nodes, self.pairs, self.inflated)
        for g in new:
            self._index[g] = len(self._goals)
            self._goals.append(g)
        self._rows = np.concatenate([self._rows, rows.reshape(len(new), -1)])

    def rows(self, goal: Planar) -> np.ndarray:
        """Cost-to-go rows ``S + (V,)`` for goals ``S`` (computed on first use of a goal)."""
        goal = np.asarray(goal, dtype=complex)
        flat = goal.reshape(-1)
        if any(complex(g) not in self._index for g in flat):
            self.prepare(flat)
        index = np.fromiter((self._index[complex(g)] for g in flat), dtype=int, count=flat.shape[0])
        return self._rows[index].reshape(goal.shape + (self.nodes.shape[0],))

    def waypoint(
        self,
        position: Planar,
        goal: Planar,
        parked: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> tuple[Planar, Scalar]:
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
        waypoints, lengths = next_waypoint(position, goal, self.nodes, self.rows(goal), self.inflated, self._wide)
        if parked is not None and self.parked_radius:
            # position or goal has a drone axis here, so next_waypoint gave arrays of that shape
            assert isinstance(waypoints, np.ndarray) and isinstance(lengths, np.ndarray)
            return self._around(position, goal, waypoints, lengths, parked)
        return waypoints, lengths

    def detour(self, parked: Sequence[complex], radius: float | None = None) -> Guidance:
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

    def _around_one(
        self, p: complex, g: complex, w: complex, remaining: float, parked: tuple[np.ndarray, np.ndarray]
    ) -> tuple[complex, float]:
        """One drone: its waypoint over the detour graph of the parked drones that may be in its way."""
        positions, mask = parked
        seen = [q for q, keep in zip(np.ravel(positions).tolist(), np.ravel(mask).tolist()) if keep]
        found = self._detour_of(p, g, w, remaining, seen)
        return (w, remaining) if found is None else found

    DETOUR_ROUNDS = 3
    """Times the set of parked drones in the way is widened to the detour's own length (:meth:`_detour_of`)."""

    def _detour_of(
        self, p: complex, g: complex, w: complex, remaining: float, seen: list[complex]
    ) -> tuple[complex, float] | None:
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

    def _around(
        self,
        position: Planar,
        goal: Planar,
        w: np.ndarray,
        remaining: np.ndarray,
        parked: tuple[np.ndarray, np.ndarray],
    ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`_around_one` over leading shapes ``S`` (the drones with a parked one in the way: a loop)."""
        positions, mask = parked
        if not np.shape(mask) or not np.shape(mask)[-1] or not np.any(mask):
            return w, remaining
        lead = np.shape(w)
        p = np.broadcast_to(np.asarray(position, dtype=complex), lead)
        g = np.broadcast_to(np.asarray(goal, dtype=complex), lead)
        slack = 2.0 * (self.parked_radius + self.delta)
        relevant = mask & (
            abs(positions - p[..., None]) + abs(g[..., None] - positions) < (remaining + slack)[..., None]
        )
        rows = np.nonzero(relevant.any(axis=-1))
        if not rows[0].size:
            return w, remaining
        w, remaining = np.array(w, copy=True), np.array(remaining, copy=True)
        for index in zip(*rows):
            found = self._detour_of(
                complex(p[index]),
                complex(g[index]),
                complex(w[index]),
                float(remaining[index]),
                positions[index][mask[index]].tolist(),
            )
            if found is not None:
                w[index], remaining[index] = found
        return w, remaining

    def _sees_one(self, p: complex, g: complex, skip: tuple[set, set] | None = None) -> bool:
        """Whether the segment ``p -> g`` is free (obstacles holding either end ignored), in plain Python."""
        circles, boxes = self._circles, self._boxes
        if skip is None:
            skip = inside_one(p.real, p.imag, circles, boxes)
        goal_skip = inside_one(g.real, g.imag, circles, boxes)
        return free_one(
            p.real, p.imag, g.real, g.imag, circles, boxes, (skip[0] | goal_skip[0], skip[1] | goal_skip[1])
        )

    def _waypoint_one(self, p: complex, g: complex) -> tuple[complex, float]:
        """:func:`next_waypoint` for one drone in plain Python: the goal's segment first, then the nodes in the order
        of their key, stopping at the first one in sight (the flight loop's one-drone call)."""
        direct = abs(g - p)
        if not self._node_xy:
            return g, direct
        circles, boxes = self._circles, self._boxes
        ax, ay = p.real, p.imag
        skip = inside_one(ax, ay, circles, boxes)
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
            if (x - ax) ** 2 + (y - ay) ** 2 > 1e-18 and free_one(ax, ay, x, y, circles, boxes, skip):
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

    _usable: np.ndarray
    """Per node, whether it is kept (a mission corner under a parked drone is not)."""

    @classmethod
    def around(cls, base: Guidance, centers: np.ndarray, radius: float) -> _Detour:
        o = base.obstacles
        parked = ObstacleSet(centers, np.full(centers.shape[0], radius), np.zeros(0, complex), np.zeros(0), np.zeros(0))
        self = cls.__new__(cls)
        self.obstacles = ObstacleSet(
            np.concatenate([np.ravel(o.centers), centers]),
            np.concatenate([np.ravel(o.radii), parked.radii]),
            np.ravel(o.box_center),
            np.ravel(o.box_half_x),
            np.ravel(o.box_half_y),
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


def path_length(points: list[complex]) -> float:
    return float(sum(abs(b - a) for a, b in zip(points[:-1], points[1:])))
