"""Scene families: every family valid and feasible at many seeds, deterministic, train and bench streams disjoint,
and the feasibility check itself able to say no."""

import numpy as np
import pytest

from rpf_fly.mission.model import BoxObstacle, CircleObstacle
from rpf_fly.sim.generators import (
    DEFAULT_MARGIN,
    FAMILIES,
    SPLITS,
    GeneratorError,
    check_scene,
    generate,
    grid_distance,
    reachable,
    scene_rng,
)
from rpf_fly.sim.scenario import make_scenario

R = 0.1
SEEDS = range(20)


def _independent_validity(scene, r=R, margin=DEFAULT_MARGIN):
    """The brief's rules, measured here without the generator's own check."""
    (x0, x1), (y0, y1) = scene.arena_x, scene.arena_y
    for pts in (scene.starts, scene.goals):
        assert ((pts.real >= x0) & (pts.real <= x1) & (pts.imag >= y0) & (pts.imag <= y1)).all()
        if not scene.obstacles.is_empty:
            assert scene.obstacles.signed_distance(pts).min() >= r + margin
        d = abs(pts[:, None] - pts[None, :])
        np.fill_diagonal(d, np.inf)
        assert d.min() >= 2 * r + margin
    assert (abs(scene.goals - scene.starts) > 1.0).all()


@pytest.mark.parametrize("family", list(FAMILIES))
def test_every_family_is_valid_and_feasible_at_many_seeds(family):
    for split in SPLITS:
        for seed in SEEDS:
            scene = generate(family, seed, split=split)
            assert scene.name == family
            _independent_validity(scene)
            assert reachable(scene, R + DEFAULT_MARGIN).all()
            assert check_scene(scene) == []
            spec = FAMILIES[family]
            assert scene.obstacles.n_circles <= spec.max_circles and scene.obstacles.n_boxes <= spec.max_boxes


@pytest.mark.parametrize("family", list(FAMILIES))
def test_seeds_are_deterministic_and_distinct(family):
    a, b, c = (generate(family, s, split="bench") for s in (7, 7, 8))
    assert np.array_equal(a.starts, b.starts) and np.array_equal(a.goals, b.goals) and a.shapes == b.shapes
    assert not (a.starts.shape == c.starts.shape and np.allclose(a.starts, c.starts))


@pytest.mark.parametrize("family", list(FAMILIES))
def test_train_and_bench_streams_are_disjoint(family):
    def key(scene):
        return tuple(np.round(np.concatenate([scene.starts, scene.goals]), 6))

    train = {key(generate(family, s, split="train")) for s in range(30)}
    bench = {key(generate(family, s, split="bench")) for s in range(30)}
    assert len(train) == 30 and len(bench) == 30
    assert not train & bench
    # the streams differ in the first word of the seed sequence, whatever the seed
    x = scene_rng(family, 5, "train").random(4)
    y = scene_rng(family, 5, "bench").random(4)
    assert not np.allclose(x, y)


def test_drone_counts():
    for family in FAMILIES:
        assert generate(family, 3, split="train", n_drones=6).n_drones == 6
    counts = {generate("circle", s, split="bench").n_drones for s in range(30)}
    assert min(counts) >= 8 and max(counts) <= 24 and len(counts) > 5
    big = generate("circle", 0, split="bench", n_drones=24)
    assert big.n_drones == 24 and np.allclose(big.goals, -big.starts)


def test_u_trap_puts_the_concave_side_in_every_straight_line():
    for seed in range(10):
        scene = generate("u-trap", seed, split="bench")
        for s, g in zip(scene.starts, scene.goals):
            line = s + (g - s) * np.linspace(0, 1, 400)
            assert scene.obstacles.signed_distance(line).min() < 0  # the straight line runs into the U


def test_crossing_groups_fly_at_right_angles():
    scene = generate("crossing", 4, split="bench")
    travel = scene.goals - scene.starts
    directions = np.unique(np.round(np.angle(travel) / (np.pi / 2)) % 4)
    assert len(directions) == 2 and (directions[1] - directions[0]) % 2 == 1
    assert np.allclose(abs(np.sin(np.angle(travel) * 2)), 0, atol=0.1)


def test_doorway_and_corridor_block_everything_but_the_gap():
    for family in ("doorway", "corridor", "passage"):
        scene = generate(family, 2, split="bench")
        boxes = [s for s in scene.shapes if isinstance(s, BoxObstacle)][:2]  # the dividing wall (then the room)
        walled = make_scenario(
            "walled", scene.starts, scene.goals, tuple(boxes) + _plugs(boxes), scene.arena_x, scene.arena_y
        )
        assert not reachable(walled, R + DEFAULT_MARGIN).any()


def _plugs(boxes):
    """A box filling the gap between the two walls."""
    a, b = boxes
    lo = (min(a.min[0], b.min[0]), min(a.min[1], b.min[1]))
    hi = (max(a.max[0], b.max[0]), max(a.max[1], b.max[1]))
    return (BoxObstacle(lo, hi),)


def test_the_grid_distance_is_the_obstacle_distance():
    for family in ("pillars", "u-trap", "corridor"):
        scene = generate(family, 1, split="bench")
        xs, ys = np.linspace(-6, 6, 37), np.linspace(-6, 6, 41)
        exact = scene.obstacles.signed_distance(xs[None, :] + 1j * ys[:, None])
        assert np.allclose(grid_distance(xs, ys, scene.obstacles), exact, atol=1e-12)


def test_reachable_follows_the_gap_width():
    r, m = R, DEFAULT_MARGIN
    starts, goals = np.array([-2 + 0j]), np.array([2 + 0j])

    def wall_with_gap(gap):
        shapes = (BoxObstacle((-0.1, gap / 2), (0.1, 3.0)), BoxObstacle((-0.1, -3.0), (0.1, -gap / 2)))
        return make_scenario("gap", starts, goals, shapes, (-3, 3), (-3, 3))

    assert not reachable(wall_with_gap(2 * (r + m) - 0.02), r + m)[0]  # narrower than the inflated drone
    assert reachable(wall_with_gap(2 * (r + m) + 0.25), r + m)[0]
    closed = make_scenario("closed", starts, goals, (BoxObstacle((-0.1, -3), (0.1, 3)),), (-3, 3), (-3, 3))
    assert not reachable(closed, r + m)[0]
    assert "goal not reachable" in check_scene(closed)[0]


def test_check_scene_rejects_crowded_and_buried_endpoints():
    pillar = (CircleObstacle((0.0, 0.0), 0.5),)
    inside = make_scenario("s", np.array([0.6 + 0j, -2 + 0j]), np.array([2 + 2j, 2 - 2j]), pillar, (-3, 3), (-3, 3))
    assert any("from an obstacle" in why for why in check_scene(inside))
    crowded = make_scenario("s", np.array([-2 + 0j, -2 + 0.2j]), np.array([2 + 0j, 2 + 1j]), (), (-3, 3), (-3, 3))
    assert any("two starts" in why for why in check_scene(crowded))


def test_bad_arguments():
    with pytest.raises(GeneratorError):
        generate("maze", 0, split="bench")
    with pytest.raises(GeneratorError):
        generate("corridor", 0, split="test")
    with pytest.raises(GeneratorError):
        generate("corridor", -1, split="train")
    with pytest.raises(TypeError):
        generate("corridor", 0)  # the split must be named
