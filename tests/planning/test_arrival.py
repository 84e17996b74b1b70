"""The capture rule (rpf_fly/planning/arrival.py): the last centimetres to a goal the repulsion would not let go."""

import numpy as np
import pytest

from rpf_fly.planning import FixedGains, ObstacleSet, Planner, PlannerConfig, view_of_drone, views_from_states
from rpf_fly.planning.arrival import capture, captured
from rpf_fly.planning.wall_following import MODE_APF

POLE = ObstacleSet.from_shapes(circles=[((3.0, 0.0), 0.25)])
OBSTACLES = ObstacleSet.from_shapes(
    circles=[((0.5, 0.5), 0.5), ((-2.0, 1.0), 0.1), ((2.5, -2.0), 0.3)],
    boxes=[((-3.0, -3.0), (-1.0, -2.5)), ((1.0, 2.0), (1.2, 3.5))],
)


def test_paper_preset_has_no_capture_and_robust_has():
    assert PlannerConfig.paper().capture_radius == 0.0
    assert PlannerConfig.robust().capture_radius == pytest.approx(0.3)


def test_goal_in_the_band_where_repulsion_wins_is_captured():
    """Goal 0.25 m from a pole's surface: with the margin the pole pushes 6x the unit attraction there, and the
    wall-following turns the drone around the pole. Within 0.3 m of the goal and nearer it than the pole, the rule
    heads straight at the goal, mode apf."""
    config = PlannerConfig.robust(margin=0.05)
    goal = 2.5 + 0j
    view = view_of_drone(2.5 + 0.18j, goal, 1 + 0j, np.zeros(0), np.zeros(0), 6.0)
    free = Planner(POLE, PlannerConfig.robust(margin=0.05, capture_radius=0.0)).step(view)
    assert free.mode != MODE_APF and abs(free.f_r) > 3.0  # the wall-following turn that orbits the pole
    assert (free.direction * np.conj(free.f_a)).real < 0  # ... away from the goal
    step = Planner(POLE, config).step(view)
    assert step.direction == pytest.approx(-1j, abs=1e-12)
    assert step.mode == MODE_APF


def test_not_captured_when_an_obstacle_is_nearer_than_the_goal():
    """The disc of radius d_g must be free, so the straight segment to the goal crosses nothing."""
    config = PlannerConfig.robust()
    position, goal = 2.5 + 0.0j, 2.5 + 0.29j
    assert not captured(position, goal, 0.2, config)  # the surface at 0.2 m, the goal at 0.29 m
    assert captured(position, goal, 0.3, config)
    assert not captured(position, 2.5 + 0.31j, 1.0, config)  # beyond the capture radius


def test_capture_keeps_the_moving_neighbours_force_capped_and_passes_the_rest_through():
    """The moving neighbours' force, capped at 0.5, deflects the captured drone but never stops it: two drones
    near their goals that push each other away (the APF's circles of 24, before the cap) still close in."""
    config = PlannerConfig.robust()
    direction = np.array([1j, 1j, 1j])
    mode = np.array([2, 2, 0], dtype=np.int8)
    position = np.array([0j, 0j, 0j])
    goal = np.array([0.2 + 0j, 5 + 0j, 0.2 + 0j])
    f_in = np.array([0.5j, 0j, -0.99 + 0j])
    distance = np.array([1.0, 1.0, 1.0])
    out, modes = capture(direction, mode, position, goal, f_in, distance, config)
    assert out[0] == pytest.approx((1 + 0.5j) / abs(1 + 0.5j))
    assert out[1] == 1j and modes.tolist() == [MODE_APF, 2, MODE_APF]
    assert out[2] == pytest.approx(1 + 0j)  # 1 - 0.5 along the goal: closing in at full speed
    same = capture(direction, mode, position, goal, f_in, distance, PlannerConfig.paper())
    assert same[0] is direction and same[1] is mode


@pytest.mark.parametrize("guidance", ["none", "path"])
def test_one_drone_call_equals_batched_call_near_goals(guidance):
    """Swarms whose goals lie within the capture radius of several drones: both paths capture the same ones."""
    rng = np.random.default_rng(11)
    config = PlannerConfig.robust(margin=0.05, guidance=guidance)
    planner = Planner(OBSTACLES, config, FixedGains(), ((-5.0, 5.0), (-5.0, 5.0)))
    seen = 0
    for _ in range(40):
        n = 7
        positions = rng.uniform(-4, 4, n) + 1j * rng.uniform(-4, 4, n)
        goals = positions + 0.35 * rng.uniform(0, 1, n) * np.exp(1j * rng.uniform(-np.pi, np.pi, n))
        velocities = 0.5 * np.exp(1j * rng.uniform(-np.pi, np.pi, n)) * (rng.uniform(size=n) > 0.5)
        headings = np.exp(1j * rng.uniform(-np.pi, np.pi, n))
        batch = planner.step(views_from_states(positions, velocities, goals, headings, config.sensing_range))
        seen += int(captured(positions, goals, batch.obstacle_distance, config).sum())
        for i in range(n):
            others = np.delete(np.arange(n), i)
            view = view_of_drone(positions[i], goals[i], headings[i], positions[others], velocities[others], 6.0)
            one = planner.step(view)
            assert one.direction == pytest.approx(batch.direction[i], abs=1e-12)
            assert one.mode == batch.mode[i]
    assert seen > 20
