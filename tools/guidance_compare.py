"""Visibility graph against grid search for the global guidance: build cost, per-tick cost and path length.

    python tools/guidance_compare.py [--cell 0.05] [--repeats 5]

For each scene (missions lab-3, arena-a-6, u-trap; the obstacles inflated by r + margin = 0.15 m) and each drone's
start and goal: the visibility graph of rpf_fly.planning.guidance (build once per obstacle set, one cost-to-go row
per goal, one next-waypoint query per tick) against an 8-connected grid Dijkstra over cells of ``--cell`` metres
(build: the occupancy grid and one distance field per goal; a tick: the field's steepest-descent neighbour; path:
the cell path, then shortcut by line of sight on the grid, which is what a grid planner would fly). Path lengths
are compared with the exact shortest path around the inflated shapes being at most the visibility graph's (its
polygons circumscribe circles). Not part of the planner: the grid search lives here only to be measured.
"""

from __future__ import annotations

import argparse
import heapq
import math
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from rpf_fly.mission import load_mission  # noqa: E402
from rpf_fly.planning.guidance import Guidance, path_length  # noqa: E402
from rpf_fly.planning.visibility import cost_to_go  # noqa: E402
from rpf_fly.sim.scenario import obstacle_set  # noqa: E402

DELTA = 0.15


class Grid:
    """Occupancy grid of the inflated obstacles (true shapes: a cell is blocked if its centre is within delta)."""

    def __init__(self, obstacles, bounds, cell: float):  # type: ignore[no-untyped-def]
        (x0, x1), (y0, y1) = bounds
        self.cell, self.x0, self.y0 = cell, x0, y0
        self.nx, self.ny = int(math.ceil((x1 - x0) / cell)) + 1, int(math.ceil((y1 - y0) / cell)) + 1
        xs = x0 + cell * np.arange(self.nx)
        ys = y0 + cell * np.arange(self.ny)
        pts = xs[:, None] + 1j * ys[None, :]
        self.blocked = obstacles.signed_distance(pts.reshape(-1)).reshape(pts.shape) < DELTA

    def index(self, p: complex) -> tuple[int, int]:
        return (
            min(max(int(round((p.real - self.x0) / self.cell)), 0), self.nx - 1),
            min(max(int(round((p.imag - self.y0) / self.cell)), 0), self.ny - 1),
        )

    def point(self, i: int, j: int) -> complex:
        return complex(self.x0 + i * self.cell, self.y0 + j * self.cell)

    def field(self, goal: complex) -> np.ndarray:
        """Dijkstra distance-to-goal over 8-connected free cells (inf where unreachable)."""
        dist = np.full((self.nx, self.ny), np.inf)
        gi = self.index(goal)
        dist[gi] = 0.0
        heap = [(0.0, gi)]
        steps = [(di, dj, self.cell * math.hypot(di, dj)) for di in (-1, 0, 1) for dj in (-1, 0, 1) if di or dj]
        blocked = self.blocked
        while heap:
            d, (i, j) = heapq.heappop(heap)
            if d > dist[i, j]:
                continue
            for di, dj, w in steps:
                a, b = i + di, j + dj
                if 0 <= a < self.nx and 0 <= b < self.ny and not blocked[a, b] and d + w < dist[a, b]:
                    dist[a, b] = d + w
                    heapq.heappush(heap, (d + w, (a, b)))
        return dist

    def descend(self, field: np.ndarray, i: int, j: int) -> tuple[int, int]:
        best, at = field[i, j], (i, j)
        for di in (-1, 0, 1):
            for dj in (-1, 0, 1):
                a, b = i + di, j + dj
                if 0 <= a < self.nx and 0 <= b < self.ny and field[a, b] < best:
                    best, at = field[a, b], (a, b)
        return at

    def path(self, field: np.ndarray, start: complex, goal: complex) -> list[complex]:
        cells = [self.index(start)]
        while field[cells[-1]] > 0 and len(cells) < 100000:
            nxt = self.descend(field, *cells[-1])
            if nxt == cells[-1]:
                break
            cells.append(nxt)
        return [start] + [self.point(*c) for c in cells[1:-1]] + [goal]

    def free_line(self, a: complex, b: complex) -> bool:
        n = max(2, int(abs(b - a) / (self.cell / 2)))
        return not any(self.blocked[self.index(a + (b - a) * k / n)] for k in range(n + 1))

    def shortcut(self, points: list[complex]) -> list[complex]:
        out, k = [points[0]], 0
        while k < len(points) - 1:
            far = len(points) - 1
            while far > k + 1 and not self.free_line(points[k], points[far]):
                far -= 1
            out.append(points[far])
            k = far
        return out


def timed(fn, repeats: int) -> float:  # type: ignore[no-untyped-def]
    samples = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        samples.append(time.perf_counter() - t0)
    return statistics.median(samples)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cell", type=float, default=0.05)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    print(
        "| scene | nodes / cells | VG build [ms] | VG goal row [ms] | VG tick [us] | "
        "grid build [ms] | grid field per goal [ms] "
        "| grid tick [us] | VG path [m] | grid path [m] | grid shortcut [m] |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for name in ("lab-3", "arena-a-6", "u-trap"):
        mission = load_mission(ROOT / "missions" / f"{name}.yaml")
        obstacles = obstacle_set(mission.obstacles)
        bounds = (mission.arena.x, mission.arena.y)
        starts = [complex(*d.start) for d in mission.drones]
        goals = [complex(*d.goal) for d in mission.drones]
        vg_build = timed(lambda: Guidance(obstacles, DELTA, bounds), args.repeats)
        g = Guidance(obstacles, DELTA, bounds)

        vg_rows = timed(lambda: cost_to_go(np.array(goals), g.nodes, g.pairs, g.inflated), args.repeats) / len(goals)
        g.prepare(np.array(goals))
        tick = timed(lambda: [g.waypoint(s, q) for s, q in zip(starts, goals) for _ in range(50)], args.repeats) / (
            50 * len(goals)
        )
        vg_len = statistics.mean(path_length(g.path(s, q)) for s, q in zip(starts, goals))
        grid_build = timed(lambda: Grid(obstacles, bounds, args.cell), args.repeats)
        grid = Grid(obstacles, bounds, args.cell)
        field_s = timed(lambda: grid.field(goals[0]), max(1, args.repeats // 2))
        fields = [grid.field(q) for q in goals]
        grid_tick = timed(
            lambda: [grid.descend(f, *grid.index(s)) for f, s in zip(fields, starts) for _ in range(50)], args.repeats
        ) / (50 * len(goals))
        paths = [grid.path(f, s, q) for f, s, q in zip(fields, starts, goals)]
        grid_len = statistics.mean(path_length(p) for p in paths)
        short_len = statistics.mean(path_length(grid.shortcut(p)) for p in paths)
        print(
            f"| {name} | {g.nodes.shape[0]} / {grid.nx * grid.ny} | {vg_build * 1e3:.2f} | "
            f"{vg_rows * 1e3:.3f} | {tick * 1e6:.1f} | "
            f"{grid_build * 1e3:.1f} | {field_s * 1e3:.0f} | {grid_tick * 1e6:.1f} | "
            f"{vg_len:.3f} | {grid_len:.3f} | {short_len:.3f} |"
        )


if __name__ == "__main__":
    main()
