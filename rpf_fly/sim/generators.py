"""Scene families: seeded generators of corridors, doorways, U-traps, pillar forests, crossings, circle swaps,
narrow passages and the paper's arenas A and B, each checked valid and feasible (docs/bench.md, *Scene families*).

``generate(family, seed, split=...)`` is pure and deterministic: the scene is drawn from a numpy generator seeded
with ``SeedSequence([split tag, family tag, seed])``. The split tag makes the training stream (``split="train"``,
the trainer's curriculum) and the bench stream (``split="bench"``, ``rpf-fly bench --suite families``) two
different seed streams by construction: training never draws a bench scene, whatever seeds either uses.

Every generated scene passes :func:`check_scene` before it is returned (a draw that fails is redrawn from the same
generator, so the result is still a function of the seed):

- starts and goals inside the arena, none inside an obstacle inflated by ``r + margin``;
- no two starts (and no two goals) closer than ``2r + margin``;
- every drone's goal reachable from its start by a path that keeps ``r + margin`` from every obstacle surface:
  a 4-connected flood fill on a grid of ``FEASIBILITY_CELL`` m cells whose centres keep ``r + margin + cell/2``
  (the distance to a surface is 1-Lipschitz, so every segment between two free neighbouring centres keeps
  ``r + margin``; start and goal join a free cell within their own spare clearance). Static obstacles only: that
  the drones can also pass each other is what the planners are benched on.

Geometry: positions are complex ``x + iy`` (metres); obstacles are vertical circles and axis-aligned boxes; every
family but the circle swaps is drawn in a square arena ``[-h, h]^2`` and then turned by a random multiple of 90
degrees and mirrored at random, so no family has a preferred direction. Pure numpy: no torch, no clock.
"""

from __future__ import annotations

import zlib
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from rpf_fly.mission.model import BoxObstacle, CircleObstacle, Obstacle
from rpf_fly.planning.obstacles import ObstacleSet
from rpf_fly.sim.scenario import Scenario, arena_a, arena_b, make_scenario

SPLITS = {"train": 0, "bench": 1}
"""Seed-stream tags: the first word of every scene's ``SeedSequence``. Never renumber them."""
DEFAULT_MARGIN = 0.05
"""m: the safety margin of the validity check (the planner's ``planner.margin`` default)."""
FEASIBILITY_CELL = 0.1
"""m: the flood fill's grid cell."""
MAX_ATTEMPTS = 200
"""Draws per scene before a generator gives up (a family's parameters always allow a valid draw long before)."""


class GeneratorError(ValueError):
    """An unknown family or split, a negative seed, or parameters no valid scene can be drawn for."""


@dataclass(frozen=True)
class Family:
    """A scene family: its generator, default drone count, and the most circles and boxes a scene of it holds
    (the training environment sizes its padded obstacle arrays with these)."""

    name: str
    draw: Callable[[np.random.Generator, int, float], Scenario]
    default_drones: int
    max_circles: int
    max_boxes: int
    about: str
    default_drones_range: tuple[int, int] | None = None
    """When set, the drone count is drawn from this inclusive range unless one is asked for (circle swaps)."""


# ---------------------------------------------------------------------------------------------- helpers

SPACING = 0.4
"""m: starts (and goals) of one scene are at least this far apart (4r, as the paper's arena A)."""
CLEARANCE = 0.35
"""m: generated starts and goals keep at least this from obstacle surfaces (more than the check's ``r + margin``:
a goal closer to an obstacle than where the repulsion beats the attraction cannot be settled on by the fixed-gain
APF, docs/algorithm.md; these families test passing obstacles, not parking beside them)."""


def _box(x0: float, x1: float, y0: float, y1: float) -> BoxObstacle:
    return BoxObstacle((min(x0, x1), min(y0, y1)), (max(x0, x1), max(y0, y1)))


ROOM_WALL = 0.2
"""m: thickness of the room walls around the walled families (just outside the arena)."""


def _room(h: float) -> list[Obstacle]:
    """The walls of a square room ``[-h, h]^2`` (outside it, touching the geofence). A wall across the arena with
    a door makes a dead end against the geofence, which no planner senses: the room's walls make it an obstacle
    the planners see, as a lab's walls or net are."""
    w = ROOM_WALL
    return [
        _box(-h - w, h + w, h, h + w),
        _box(-h - w, h + w, -h - w, -h),
        _box(h, h + w, -h, h),
        _box(-h - w, -h, -h, h),
    ]


def _scatter(
    rng: np.random.Generator,
    n: int,
    x: tuple[float, float],
    y: tuple[float, float],
    spacing: float = SPACING,
    keep: Callable[[complex], bool] | None = None,
) -> np.ndarray | None:
    """``n`` points uniform in the rectangle, pairwise at least ``spacing`` apart (None if they do not fit)."""
    points: list[complex] = []
    for _ in range(200 * n):
        if len(points) == n:
            break
        p = complex(rng.uniform(*x), rng.uniform(*y))
        if keep is not None and not keep(p):
            continue
        if all(abs(p - q) >= spacing for q in points):
            points.append(p)
    return np.array(points) if len(points) == n else None


def _transform(
    name: str, rng: np.random.Generator, starts: np.ndarray, goals: np.ndarray, shapes: list[Obstacle], half: float
) -> Scenario:
    """Turn the scene by a random multiple of 90 degrees and mirror it at random (square arena ``[-half, half]``)."""
    turn = 1j ** int(rng.integers(4))
    mirror = bool(rng.integers(2))

    def point(p: np.ndarray | complex) -> np.ndarray | complex:
        q = np.conj(p) if mirror else p
        return q * turn

    out: list[Obstacle] = []
    for s in shapes:
        if isinstance(s, CircleObstacle):
            c = complex(point(complex(*s.center)))
            out.append(CircleObstacle((c.real, c.imag), s.radius))
        else:
            a = complex(point(complex(*s.min)))
            b = complex(point(complex(*s.max)))
            out.append(_box(a.real, b.real, a.imag, b.imag))
    return make_scenario(
        name, np.asarray(point(starts)), np.asarray(point(goals)), tuple(out), (-half, half), (-half, half)
    )


def _pair_up(rng: np.random.Generator, starts: np.ndarray, goals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Assign goals to starts at random (crossing paths, as in arena A)."""
    return starts, goals[rng.permutation(goals.shape[0])]


# --------------------------------------------------------------------------------------------- families


def _corridor(rng: np.random.Generator, n: int, r: float) -> Scenario:
    """Two rooms joined by a long slot through the barrier between them: the only way from the starts (one room)
    to the goals (the other). Width 1.0-1.6 m, length 2.5-5 m; the rooms' walls are obstacles (:func:`_room`)."""
    h = 6.0
    width = rng.uniform(1.0, 1.6)
    length = rng.uniform(2.5, 5.0)
    y0 = rng.uniform(-2.0, 2.0)
    t = length / 2
    shapes: list[Obstacle] = [_box(-t, t, y0 + width / 2, h), _box(-t, t, -h, y0 - width / 2), *_room(h)]
    starts = _scatter(rng, n, (-h + 0.4, -t - 0.8), (-h + 0.4, h - 0.4))
    goals = _scatter(rng, n, (t + 0.8, h - 0.4), (-h + 0.4, h - 0.4))
    if starts is None or goals is None:
        raise _Redraw
    return _transform("corridor", rng, *_pair_up(rng, starts, goals), shapes, h)


def _doorway(rng: np.random.Generator, n: int, r: float) -> Scenario:
    """Two rooms: a thin wall across the arena with one door (0.7-1.2 m) at a random place; starts on one side,
    goals on the other; the rooms' walls are obstacles."""
    h = 5.0
    x0 = rng.uniform(-1.0, 1.0)
    thick = rng.uniform(0.15, 0.3)
    gap = rng.uniform(0.7, 1.2)
    g0 = rng.uniform(-h + 1.5, h - 1.5)
    shapes: list[Obstacle] = [
        _box(x0 - thick / 2, x0 + thick / 2, g0 + gap / 2, h),
        _box(x0 - thick / 2, x0 + thick / 2, -h, g0 - gap / 2),
        *_room(h),
    ]
    starts = _scatter(rng, n, (-h + 0.4, x0 - 1.0), (-h + 0.4, h - 0.4))
    goals = _scatter(rng, n, (x0 + 1.0, h - 0.4), (-h + 0.4, h - 0.4))
    if starts is None or goals is None:
        raise _Redraw
    return _transform("doorway", rng, *_pair_up(rng, starts, goals), shapes, h)


def _u_trap(rng: np.random.Generator, n: int, r: float) -> Scenario:
    """A U-shaped (concave) obstacle open toward the starts, its back between them and the goals: the straight
    line of every drone runs into the inside of the U. Mouth 2.0-3.5 m, depth 1.5-2.5 m."""
    h = 6.0
    mouth = rng.uniform(2.0, 3.5)
    depth = rng.uniform(1.5, 2.5)
    thick = 0.2
    back = rng.uniform(0.0, 1.5)
    yc = rng.uniform(-1.5, 1.5)
    top, bottom = yc + mouth / 2, yc - mouth / 2
    shapes: list[Obstacle] = [
        _box(back, back + thick, bottom - thick, top + thick),  # the back
        _box(back - depth, back, top, top + thick),  # the arms
        _box(back - depth, back, bottom - thick, bottom),
    ]
    inner = (bottom + CLEARANCE, top - CLEARANCE)
    starts = _scatter(rng, n, (back - depth - 1.5, back - CLEARANCE - 0.3), inner)
    goals = _scatter(rng, n, (back + thick + 1.0, h - 0.4), (bottom, top))
    if starts is None or goals is None:
        raise _Redraw
    return _transform("u-trap", rng, *_pair_up(rng, starts, goals), shapes, h)


def _pillars(rng: np.random.Generator, n: int, r: float) -> Scenario:
    """A forest of 14-30 thin pillars (radius 0.15-0.35 m) filling the band between the starts and the goals,
    surfaces at least 0.5 m apart."""
    h = 5.0
    count = int(rng.integers(14, 31))
    gap = 0.5
    centres: list[complex] = []
    radii: list[float] = []
    for _ in range(50 * count):
        if len(centres) == count:
            break
        c = complex(rng.uniform(-3.0, 3.0), rng.uniform(-h + 0.8, h - 0.8))  # a lane along the geofence
        rad = rng.uniform(0.15, 0.35)
        if all(abs(c - o) >= rad + ro + gap for o, ro in zip(centres, radii)):
            centres.append(c)
            radii.append(rad)
    shapes: list[Obstacle] = [CircleObstacle((c.real, c.imag), rad) for c, rad in zip(centres, radii)]
    starts = _scatter(rng, n, (-h + 0.3, -3.8), (-h + 0.3, h - 0.3))
    goals = _scatter(rng, n, (3.8, h - 0.3), (-h + 0.3, h - 0.3))
    if starts is None or goals is None:
        raise _Redraw
    return _transform("pillars", rng, *_pair_up(rng, starts, goals), shapes, h)


def _crossing(rng: np.random.Generator, n: int, r: float) -> Scenario:
    """Two groups crossing at right angles: one in a line abreast flying east, the other flying north, meeting
    in the middle. Spacing in the line 0.5-0.9 m, 3-4.5 m from the centre."""
    h = 5.0
    east = n - n // 2
    north = n // 2
    spacing = rng.uniform(0.5, 0.9)
    dist = rng.uniform(3.0, 4.5)

    def line(k: int) -> np.ndarray:
        return (np.arange(k) - (k - 1) / 2) * spacing + rng.uniform(-0.5, 0.5) + rng.uniform(-0.08, 0.08, k)

    ye, xn = line(east), line(north)
    lead_e = rng.uniform(-0.1, 0.1, east)
    lead_n = rng.uniform(-0.1, 0.1, north)
    starts = np.concatenate([-dist + lead_e + 1j * ye, xn + 1j * (-dist + lead_n)])
    goals = np.concatenate([dist + lead_e + 1j * ye, xn + 1j * (dist + lead_n)])
    return _transform("crossing", rng, starts, goals, [], h)


def _circle(rng: np.random.Generator, n: int, r: float) -> Scenario:
    """A circle swap of ``n`` drones (8-24 unless asked for) on a circle of 3-5 m with angular jitter of up to a
    quarter of the spacing; every goal is its start's antipode."""
    radius = rng.uniform(3.0, 5.0)
    scene = arena_b(rng, n, radius)
    return Scenario("circle", *_fields(scene)[1:])


def _arena_a(rng: np.random.Generator, n: int, r: float) -> Scenario:
    """The paper's training arena A (rpf_fly.sim.scenario.arena_a: 12 pillars of 0.5 m in 10 x 10 m)."""
    return Scenario("arena-a", *_fields(arena_a(rng, n, safety_radius=r))[1:])


def _arena_b(rng: np.random.Generator, n: int, r: float) -> Scenario:
    """The paper's training arena B (rpf_fly.sim.scenario.arena_b: a 2 m circle swap with jitter)."""
    return Scenario("arena-b", *_fields(arena_b(rng, n))[1:])


def _passage(rng: np.random.Generator, n: int, r: float) -> Scenario:
    """Two groups facing each other through one narrow passage in a wall (width 1.0-1.6 m, 0.3-1.5 m long):
    each group starts near the passage on its side and flies through it to the other side. Walled room."""
    h = 5.0
    gap = rng.uniform(1.0, 1.6)
    thick = rng.uniform(0.3, 1.5)
    g0 = rng.uniform(-2.0, 2.0)
    t = thick / 2
    shapes: list[Obstacle] = [_box(-t, t, g0 + gap / 2, h), _box(-t, t, -h, g0 - gap / 2), *_room(h)]
    left = n - n // 2
    right = n // 2
    band = (max(-h + 0.4, g0 - 2.0), min(h - 0.4, g0 + 2.0))
    ls = _scatter(rng, left, (-h + 0.4, -t - 0.8), band)
    rs = _scatter(rng, right, (t + 0.8, h - 0.4), band)
    lg = _scatter(rng, left, (t + 0.8, h - 0.4), band)
    rg = _scatter(rng, right, (-h + 0.4, -t - 0.8), band)
    if ls is None or rs is None or lg is None or rg is None:
        raise _Redraw
    # A group's goals must keep 2r + margin from the other group's starts only in time, not in space; but a goal
    # on top of a waiting start makes a drone park in another's way: keep them apart.
    if rs.size and lg.size and abs(lg[:, None] - rs[None, :]).min() < SPACING:
        raise _Redraw
    if ls.size and rg.size and abs(rg[:, None] - ls[None, :]).min() < SPACING:
        raise _Redraw
    starts = np.concatenate([ls, rs])
    goals = np.concatenate([lg[rng.permutation(left)], rg[rng.permutation(right)]])
    return _transform("passage", rng, starts, goals, shapes, h)


def _fields(scene: Scenario) -> tuple:
    return (
        scene.name,
        scene.names,
        scene.starts,
        scene.goals,
        scene.shapes,
        scene.obstacles,
        scene.arena_x,
        scene.arena_y,
    )


class _Redraw(Exception):
    """This draw does not fit: draw again from the same generator."""


FAMILIES: dict[str, Family] = {
    f.name: f
    for f in (
        Family("corridor", _corridor, 6, 0, 6, "two rooms joined by a 1.0-1.6 m wide, 2.5-5 m long slot"),
        Family("doorway", _doorway, 6, 0, 6, "two rooms, a thin wall with one 0.7-1.2 m door"),
        Family("u-trap", _u_trap, 4, 0, 3, "a U open toward the starts, its back toward the goals"),
        Family("pillars", _pillars, 6, 30, 0, "14-30 pillars of 0.15-0.35 m, surfaces 0.5 m apart"),
        Family("crossing", _crossing, 8, 0, 0, "two lines abreast crossing at right angles"),
        Family("circle", _circle, 16, 0, 0, "a circle swap of 8-24 drones on 3-5 m", (8, 24)),
        Family("arena-a", _arena_a, 6, 12, 0, "the paper's arena A: 12 pillars of 0.5 m, random starts and goals"),
        Family("arena-b", _arena_b, 6, 0, 0, "the paper's arena B: a 2 m circle swap with jitter"),
        Family("passage", _passage, 6, 0, 6, "two groups facing through one 1.0-1.6 m passage in a walled room"),
    )
}
"""Every scene family by name (the bench's order)."""


def family_tag(family: str) -> int:
    """The family's word in the seed sequence: a CRC-32 of its name (stable across versions and orderings)."""
    return zlib.crc32(family.encode())


def scene_rng(family: str, seed: int, split: str) -> np.random.Generator:
    """The generator a scene is drawn from: ``SeedSequence([split tag, family tag, seed])``."""
    if split not in SPLITS:
        raise GeneratorError(f"unknown split {split!r} (expected {' or '.join(SPLITS)})")
    if family not in FAMILIES:
        raise GeneratorError(f"unknown scene family {family!r} (expected one of {', '.join(FAMILIES)})")
    if int(seed) < 0:
        raise GeneratorError(f"seed must be non-negative, got {seed}")
    return np.random.default_rng(np.random.SeedSequence([SPLITS[split], family_tag(family), int(seed)]))


def generate(
    family: str,
    seed: int,
    *,
    split: str,
    n_drones: int | None = None,
    safety_radius: float = 0.1,
    margin: float = DEFAULT_MARGIN,
) -> Scenario:
    """The scene of ``family`` for ``seed`` in the ``split`` stream (``"train"`` or ``"bench"``), valid and
    feasible for drones of radius ``safety_radius`` with ``margin`` (:func:`check_scene`).

    ``n_drones``: the number of drones (default: the family's; circle swaps draw 8-24). The scene's ``name`` is
    the family's."""
    rng = scene_rng(family, seed, split)
    spec = FAMILIES[family]
    if n_drones is None:
        lo_hi = spec.default_drones_range
        n = int(rng.integers(lo_hi[0], lo_hi[1] + 1)) if lo_hi else spec.default_drones
    else:
        n = int(n_drones)
    if n < 1:
        raise GeneratorError(f"n_drones must be at least 1, got {n}")
    reasons: list[str] = []
    for _ in range(MAX_ATTEMPTS):
        try:
            scene = spec.draw(rng, n, safety_radius)
        except _Redraw:
            continue
        reasons = check_scene(scene, safety_radius, margin)
        if not reasons:
            return scene
    raise GeneratorError(
        f"{family} seed {seed}: no valid scene of {n} drones in {MAX_ATTEMPTS} draws"
        + (f" (last: {reasons[0]})" if reasons else "")
    )


def split_seeds(split: str, count: int, first: int = 0) -> list[int]:
    """Seeds ``first..first+count-1`` of a split (the bench uses ``bench`` seeds ``0..N-1``)."""
    if split not in SPLITS:
        raise GeneratorError(f"unknown split {split!r} (expected {' or '.join(SPLITS)})")
    return list(range(first, first + count))


# ---------------------------------------------------------------------------------------- the check


def check_scene(scene: Scenario, safety_radius: float = 0.1, margin: float = DEFAULT_MARGIN) -> list[str]:
    """What is wrong with a scene (empty when valid): an endpoint outside the arena or inside an obstacle inflated
    by ``r + margin``, two starts or two goals closer than ``2r + margin``, a goal not reachable from its start
    with ``r + margin`` clearance (:func:`reachable`)."""
    r = safety_radius
    clear = r + margin
    out: list[str] = []
    (x0, x1), (y0, y1) = scene.arena_x, scene.arena_y
    for label, pts in (("start", scene.starts), ("goal", scene.goals)):
        outside = (pts.real < x0) | (pts.real > x1) | (pts.imag < y0) | (pts.imag > y1)
        if outside.any():
            out.append(f"{label} {int(np.flatnonzero(outside)[0])} outside the arena")
        if not scene.obstacles.is_empty:
            d = scene.obstacles.signed_distance(pts)
            if d.min() < clear:
                out.append(f"{label} {int(d.argmin())} {d.min():.3f} m from an obstacle (needs {clear:g})")
        if pts.shape[0] > 1:
            gaps = abs(pts[:, None] - pts[None, :])
            np.fill_diagonal(gaps, np.inf)
            if gaps.min() < 2 * r + margin:
                out.append(f"two {label}s {gaps.min():.3f} m apart (needs {2 * r + margin:g})")
    if out:
        return out
    ok = reachable(scene, clear)
    for i in np.flatnonzero(~ok):
        out.append(f"drone {int(i)}: goal not reachable with {clear:g} m clearance")
    return out


def free_grid(scene: Scenario, clearance: float, cell: float = FEASIBILITY_CELL) -> tuple[np.ndarray, np.ndarray]:
    """Cell centres ``(ny, nx)`` complex over the arena and which are free: surface distance at least
    ``clearance + cell / 2``."""
    (x0, x1), (y0, y1) = scene.arena_x, scene.arena_y
    xs = x0 + cell / 2 + cell * np.arange(max(1, int(np.floor((x1 - x0) / cell))))
    ys = y0 + cell / 2 + cell * np.arange(max(1, int(np.floor((y1 - y0) / cell))))
    centres = xs[None, :] + 1j * ys[:, None]
    if scene.obstacles.is_empty:
        return centres, np.ones(centres.shape, dtype=bool)
    return centres, grid_distance(xs, ys, scene.obstacles) >= clearance + cell / 2


def grid_distance(xs: np.ndarray, ys: np.ndarray, obstacles: ObstacleSet) -> np.ndarray:
    """``(len(ys), len(xs))`` signed distance to the nearest obstacle surface at the grid points, as
    ``ObstacleSet.signed_distance`` gives it (circles and the box distance field), computed per axis."""
    out = np.full((ys.shape[0], xs.shape[0]), np.inf)
    for c, rad in zip(obstacles.centers.reshape(-1), obstacles.radii.reshape(-1)):
        d = np.sqrt((xs[None, :] - c.real) ** 2 + (ys[:, None] - c.imag) ** 2) - rad
        np.minimum(out, d, out=out)
    for c, hx, hy in zip(
        obstacles.box_center.reshape(-1), obstacles.box_half_x.reshape(-1), obstacles.box_half_y.reshape(-1)
    ):
        qx = (np.abs(xs - c.real) - hx)[None, :]
        qy = (np.abs(ys - c.imag) - hy)[:, None]
        d = np.hypot(np.maximum(qx, 0.0), np.maximum(qy, 0.0)) + np.minimum(np.maximum(qx, qy), 0.0)
        np.minimum(out, d, out=out)
    return out


def reachable(scene: Scenario, clearance: float, cell: float = FEASIBILITY_CELL) -> np.ndarray:
    """Per drone: is its goal reachable from its start keeping ``clearance`` from every obstacle surface (inside
    the arena)? A 4-connected flood fill over :func:`free_grid`; an endpoint joins the free cells within its own
    spare clearance (its surface distance minus ``clearance``) of it."""
    centres, free = free_grid(scene, clearance, cell)
    rows = _run_labels(free)
    cols = _run_labels(free.T).T
    n = scene.n_drones
    ok = np.zeros(n, dtype=bool)
    if scene.obstacles.is_empty:
        return np.ones(n, dtype=bool)
    spare_s = scene.obstacles.signed_distance(scene.starts) - clearance
    spare_g = scene.obstacles.signed_distance(scene.goals) - clearance
    start_cells = [free & (abs(centres - p) <= s) for p, s in zip(scene.starts, spare_s)]
    goal_cells = [free & (abs(centres - p) <= s) for p, s in zip(scene.goals, spare_g)]
    components: list[np.ndarray] = []
    for i in range(n):
        if not start_cells[i].any() or not goal_cells[i].any():
            continue
        comp = next((c for c in components if (c & start_cells[i]).any()), None)
        if comp is None:
            comp = _flood(start_cells[i], rows, cols)
            components.append(comp)
        ok[i] = bool((comp & goal_cells[i]).any())
    return ok


def _run_labels(free: np.ndarray) -> np.ndarray:
    """Label the runs of free cells along each row (1, 2, ...; 0 for blocked cells)."""
    before = np.zeros_like(free)
    before[:, 1:] = free[:, :-1]
    starts = free & ~before
    return (np.cumsum(starts.ravel()).reshape(free.shape) * free).astype(np.int64)


def _flood(seed: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """The free cells connected to ``seed``: spread along whole row runs, then whole column runs, until nothing
    changes (as many rounds as the paths have turns)."""
    reach = seed & (rows > 0)
    while True:
        before = int(reach.sum())
        for labels in (rows, cols):
            hit = np.zeros(int(labels.max()) + 1, dtype=bool)
            hit[labels[reach]] = True
            hit[0] = False
            reach = hit[labels]
        if int(reach.sum()) == before:
            return reach
