"""The composed planner: one drone vs a batch, static neighbours, observations, gains."""

import math

import numpy as np
import pytest

from rpf_fly.planning import (
    FixedGains,
    ObstacleSet,
    Planner,
    PlannerConfig,
    build_observation,
    nearest_obstacle,
    view_of_drone,
    views_from_states,
)
from rpf_fly.planning.config import RPF3_TUNING


def random_swarm(rng, n=7):
    positions = rng.uniform(-4, 4, n) + 1j * rng.uniform(-4, 4, n)
    goals = rng.uniform(-4, 4, n) + 1j * rng.uniform(-4, 4, n)
    velocities = 0.5 * np.exp(1j * rng.uniform(-np.pi, np.pi, n)) * (rng.uniform(size=n) > 0.3)
    headings = np.exp(1j * rng.uniform(-np.pi, np.pi, n))
    return positions, goals, velocities, headings


OBSTACLES = ObstacleSet.from_shapes(
    circles=[((0.5, 0.5), 0.5), ((-2.0, 1.0), 0.1), ((2.5, -2.0), 0.3)],
    boxes=[((-3.0, -3.0), (-1.0, -2.5)), ((1.0, 2.0), (1.2, 3.5))],
)


RPF3 = PlannerConfig.robust(margin=0.05, guidance="path", **RPF3_TUNING)
"""The rpf3 kind's configuration: guidance, summed repulsion, the corner reach, yielding and braking."""


@pytest.mark.parametrize(
    "config", [PlannerConfig.robust(), PlannerConfig.paper(), RPF3], ids=["robust", "paper", "rpf3"]
)
def test_one_drone_call_equals_batched_call(config):
    """The flight path (one drone, Python numbers) and the simulator path (arrays) are the same function."""
    rng = np.random.default_rng(3)
    planner = Planner(OBSTACLES, config, FixedGains())
    for _ in range(40):
        positions, goals, velocities, headings = random_swarm(rng)
        batch = planner.step(views_from_states(positions, velocities, goals, headings, config.sensing_range))
        for i in range(len(positions)):
            others = np.delete(np.arange(len(positions)), i)
            view = view_of_drone(
                positions[i], goals[i], headings[i], positions[others], velocities[others], config.sensing_range
            )
            one = planner.step(view)
            assert one.direction == pytest.approx(batch.direction[i], abs=1e-12)
            assert one.mode == batch.mode[i]
            assert one.f_in == pytest.approx(batch.f_in[i], abs=1e-12)
            assert one.obstacle_distance == pytest.approx(batch.obstacle_distance[i], abs=1e-12)


@pytest.mark.parametrize("config", [PlannerConfig.robust(), RPF3], ids=["robust", "rpf3"])
def test_batched_over_many_arenas_equals_each_arena(config):
    rng = np.random.default_rng(5)
    planner = Planner(OBSTACLES, config)
    arenas = [random_swarm(rng, 5) for _ in range(3)]
    stacked = [np.stack([a[k] for a in arenas]) for k in range(4)]
    positions, goals, velocities, headings = stacked
    batch = planner.step(views_from_states(positions, velocities, goals, headings, config.sensing_range))
    for b, (p, g, v, h) in enumerate(arenas):
        single = planner.step(views_from_states(p, v, g, h, config.sensing_range))
        assert batch.direction[b] == pytest.approx(single.direction, abs=1e-12)


def test_robust_treats_static_neighbour_as_obstacle_of_radius_r():
    config = PlannerConfig.robust()
    planner = Planner(ObstacleSet.empty(), config)
    hovering = view_of_drone(0j, 6 + 0j, 1 + 0j, np.array([1 + 0j]), np.array([0j]), 6.0)
    step = planner.step(hovering)
    assert step.neighbours == 0  # not a lambda-neighbour
    assert step.obstacle_distance == pytest.approx(1.0 - config.safety_radius)
    moving = view_of_drone(0j, 6 + 0j, 1 + 0j, np.array([1 + 0j]), np.array([0.5j]), 6.0)
    step = planner.step(moving)
    assert step.neighbours == 1
    paper = Planner(ObstacleSet.empty(), PlannerConfig.paper()).step(hovering)
    assert paper.neighbours == 1  # the paper keeps arrived drones as lambda-neighbours


def test_drone_ignores_neighbours_beyond_sensing_range():
    planner = Planner(ObstacleSet.empty(), PlannerConfig.paper())
    far = view_of_drone(0j, 6 + 0j, 1 + 0j, np.array([6.5j]), np.array([0.5 + 0j]), 6.0)
    alone = view_of_drone(0j, 6 + 0j, 1 + 0j, np.zeros(0), np.zeros(0), 6.0)
    assert planner.step(far).direction == planner.step(alone).direction == pytest.approx(1 + 0j)


def test_observation_layout_in_heading_frame():
    config = PlannerConfig.robust()
    obstacles = ObstacleSet.from_shapes(circles=[((0.0, 2.0), 0.5)])
    # Heading +y: the obstacle straight ahead (phi 0), the goal to the right (-pi/2).
    view = view_of_drone(0j, 3 + 0j, 1j, np.array([-1 + 0j, 2j + 2]), np.array([0j, 0.5 + 0j]), 6.0)
    nearest = nearest_obstacle(view.position, obstacles)
    obs = build_observation(view, nearest, config, max_neighbours=4)
    assert obs.local.shape == (4,) and obs.neighbours.shape == (4, 3) and obs.mask.shape == (4,)
    assert obs.local == pytest.approx([1.5, 0.0, 3.0, -np.pi / 2], abs=1e-6)
    # Nearest neighbour first: (-1, 0) is 1 m away, to the left (+pi/2), static (psi 0).
    assert obs.neighbours[0] == pytest.approx([1.0, np.pi / 2, 0.0], abs=1e-6)
    # Second: (2, 2), 45 degrees right of +y, moving +x: relative heading -pi/2.
    assert obs.neighbours[1] == pytest.approx([np.sqrt(8), -np.pi / 4, -np.pi / 2], abs=1e-6)
    assert obs.mask.tolist() == [True, True, False, False]
    assert not obs.neighbours[2:].any()


def test_observation_without_obstacles_or_neighbours():
    config = PlannerConfig.robust()
    view = view_of_drone(0j, 3 + 0j, 1 + 0j, np.zeros(0), np.zeros(0), 6.0)
    obs = build_observation(view, nearest_obstacle(0j, ObstacleSet.empty()), config, max_neighbours=3)
    assert obs.local == pytest.approx([6.0, 0.0, 3.0, 0.0])
    assert not obs.mask.any()


def test_gains_policy_is_asked_only_when_it_needs_observations():
    class Recording:
        needs_observation = True
        max_neighbours = 2

        def __init__(self):
            self.seen = []

        def gains(self, observation):
            self.seen.append(observation)
            return np.full(observation.local.shape[:-1], 0.07), np.full(observation.local.shape[:-1], 1.5)

    policy = Recording()
    planner = Planner(ObstacleSet.empty(), PlannerConfig.robust(), policy)
    positions = np.array([0j, 1 + 0j, 3j])
    step = planner.step(views_from_states(positions, np.zeros(3, complex), positions + 5, np.ones(3, complex), 6.0))
    assert len(policy.seen) == 1 and policy.seen[0].neighbours.shape == (3, 2, 3)
    assert np.allclose(step.eta, 0.07) and np.allclose(step.lam, 1.5)


def test_phase_is_in_the_half_open_interval_for_signed_zeros():
    """atan2 gives -pi for (-1, -0.0); the planner's bearings are in (-pi, pi], for numbers and arrays alike."""
    from rpf_fly.planning.vectors import phase

    assert phase(complex(-1.0, -0.0)) == math.pi
    assert phase(complex(-1.0, 0.0)) == math.pi
    got = phase(np.array([complex(-1.0, -0.0), -1 + 0j, 1j, -1j, 0j, 1 - 1j]))
    np.testing.assert_array_equal(got, [math.pi, math.pi, math.pi / 2, -math.pi / 2, 0.0, -math.pi / 4])


def test_a_corner_within_reach_counts_as_reached_and_the_pull_moves_on():
    """``waypoint_reach``: 3 cm short of the first corner of a wall (beside it) the drone is pulled to the second
    corner, not back to the first (one-drone and batched alike); farther off, or with the reach 0, the first corner
    stays."""
    from rpf_fly.planning.planner import guided_view, make_guidance

    wall = ObstacleSet.from_shapes(boxes=[((-0.1, -1.0), (0.1, 3.0))])
    config = PlannerConfig.robust(margin=0.05, guidance="path")
    guidance = make_guidance(wall, config)
    goal = 2 + 1j
    first, second = -0.25 - 1.15j, 0.25 - 1.15j
    near, far = first - 0.02 + 0.02j, first - 0.35 + 0.65j
    for reach, expect_near in ((0.0, first), (0.05, second)):
        one = guided_view(view_of_drone(near, goal, 1j, np.zeros(0), np.zeros(0), 6.0), guidance, reach)[1]
        assert one == pytest.approx(expect_near, abs=1e-5)
        views = views_from_states(
            np.array([near, far]), np.zeros(2, complex), np.array([goal, goal]), np.array([1j, 1j]), 6.0
        )
        batch = guided_view(views, guidance, reach)[1]
        assert batch == pytest.approx([expect_near, first], abs=1e-5)
