"""Wall-following (mode A), the soft rule (mode B), the side choice and the soft rule's continuity."""

import math

import numpy as np
import pytest

from rpf_fly.planning import MODE_APF, MODE_SOFT, MODE_WALL, ObstacleSet, Planner, PlannerConfig, view_of_drone
from rpf_fly.planning.wall_following import choose_tangent, select_heading

PAPER = PlannerConfig.paper()
ROBUST = PlannerConfig.robust()


def plan_alone(obstacles, position=0j, goal=6 + 0j, heading=1 + 0j, config=PAPER):
    view = view_of_drone(position, goal, heading, np.zeros(0), np.zeros(0), config.sensing_range)
    return Planner(obstacles, config).step(view)


def test_soft_rule_hand_worked():
    # Circle at (1, 0), radius 0.5, robot at the origin heading to (6, 0): d_o = 0.5,
    # F_r = 0.05 (2 - 0.1)(-0.5, 0)/0.125 = (-0.38, 0). F_ar . F_a = 0.62 >= 0 and F_r . F_a < 0: mode B.
    # n1 = rot90(F_r)/|F_r| = (0, -1); heading (1, 0) is a tie, which takes n1.
    # F_soft = unit((0.62, 0) + 2 * 0.38 * (0, -1)) = unit(0.62, -0.76)
    step = plan_alone(ObstacleSet.from_shapes(circles=[((1.0, 0.0), 0.5)]))
    assert step.f_r == pytest.approx(-0.38 + 0j)
    assert step.mode == MODE_SOFT
    expected = complex(0.62, -0.76) / abs(complex(0.62, -0.76))
    assert step.direction == pytest.approx(expected)


def test_wall_mode_hand_worked_and_side_follows_heading():
    # Circle at (0.35, 0), r 0.1: d_o = 0.25, F_r = 0.05 (4 - 0.1)(-0.25)/0.015625 = -3.12: F_ar . F_a < 0.
    obstacles = ObstacleSet.from_shapes(circles=[((0.35, 0.0), 0.1)])
    step = plan_alone(obstacles)
    assert step.f_r == pytest.approx(-3.12 + 0j)
    assert step.mode == MODE_WALL
    assert step.direction == pytest.approx(-1j)  # n1: turn right
    # Heading up-right: n1 = (0, -1) makes an obtuse angle with it, so n2 = (0, 1) is chosen.
    step = plan_alone(obstacles, heading=0.6 + 0.8j)
    assert step.direction == pytest.approx(1j)


def test_trigger_regions():
    # Obstacle behind the drone: F_r . F_a > 0, no wall-following.
    step = plan_alone(ObstacleSet.from_shapes(circles=[((-1.0, 0.0), 0.5)]))
    assert step.mode == MODE_APF
    assert step.direction == pytest.approx((step.f_a + step.f_r) / abs(step.f_a + step.f_r))


@pytest.mark.parametrize(
    "f_in, config, expected",
    [
        # paper: |F_in| = 2.06 >= 1, n1 . F_in = -0.5 < 0 -> n2
        (-2 + 0.5j, PAPER, 1j),
        # robust: tangential part |n1 . F_in| = 0.5 < 1 -> heading rule; heading (1, 0) ties -> n1
        (-2 + 0.5j, ROBUST, -1j),
        # both: strong tangential push toward +y -> n2
        (1.5j, PAPER, 1j),
        (1.5j, ROBUST, 1j),
        # weak F_in: heading decides (tie -> n1)
        (0.3j, PAPER, -1j),
    ],
)
def test_side_choice(f_in, config, expected):
    n = choose_tangent(-1 + 0j, f_in, 1 + 0j, config)
    assert n == pytest.approx(expected)


def test_exact_tie_takes_n1_both_ways_round():
    # n1 . heading is exactly 0 for heading (1, 0) and F_r (-1, 0): n1 = (0, -1) whichever tiny sign noise.
    assert choose_tangent(-1 + 0j, 0j, 1 + 1e-17j, PAPER) == pytest.approx(-1j)
    assert choose_tangent(-1 + 0j, 0j, 1 - 1e-17j, PAPER) == pytest.approx(-1j)


def test_robust_bends_tangent_away_from_surface_when_closer_than_2r():
    # Circle at (0.15, 0), r 0.1: d_o = 0.05 < 2r. k = (0.2 - 0.05)/0.1 = 1.5: unit(n + 1.5 * F_r/|F_r|).
    obstacles = ObstacleSet.from_shapes(circles=[((0.15, 0.0), 0.1)])
    paper = plan_alone(obstacles, config=PAPER)
    robust = plan_alone(obstacles, config=ROBUST)
    assert paper.mode == robust.mode == MODE_WALL
    assert paper.direction == pytest.approx(-1j)
    expected = (-1j + 1.5 * (-1)) / abs(-1j + 1.5 * (-1))
    assert robust.direction == pytest.approx(expected)
    assert robust.direction.real < 0  # away from the surface


def test_soft_rule_equals_f_ar_on_entering_mode_b():
    """F_soft = F_ar where |F_r| = 0, i.e. at the influence range; and the heading is continuous across it."""
    rho = 10.0
    config = PlannerConfig.paper(influence_range=rho, sensing_range=20.0)
    headings = []
    for gap in (1e-3, 1e-6, -1e-6, -1e-3):  # surface distance rho + gap: outside, then inside the influence range
        obstacles = ObstacleSet.from_shapes(circles=[((rho + gap + 1.0, 0.0), 1.0)])  # surface rho + gap ahead
        step = plan_alone(obstacles, goal=30 + 0j, config=config)
        headings.append(step)
    outside, inside = headings[1], headings[2]
    assert outside.mode == MODE_APF
    assert inside.mode == MODE_SOFT
    f_ar = inside.f_a + inside.f_r
    assert inside.direction == pytest.approx(f_ar / abs(f_ar), abs=1e-9)
    assert abs(inside.direction - outside.direction) < 1e-9
    # Deeper inside, the soft heading turns away from F_ar toward the tangent, monotonically.
    angles = []
    for d in (9.0, 5.0, 2.0, 1.0, 0.5):
        obstacles = ObstacleSet.from_shapes(circles=[((d + 1.0, 0.0), 1.0)])
        step = plan_alone(obstacles, goal=30 + 0j, config=config)
        assert step.mode == MODE_SOFT
        angles.append(abs(math.atan2(step.direction.imag, step.direction.real)))
    assert angles == sorted(angles)
    assert angles[0] < 1e-3 < angles[-1]


def test_wall_following_off_gives_vanilla_direction():
    obstacles = ObstacleSet.from_shapes(circles=[((1.0, 0.0), 0.5)])
    step = plan_alone(obstacles, config=PlannerConfig.paper(wall_following=False))
    assert step.mode == MODE_APF
    total = step.f_a + step.f_r + step.f_in
    assert step.direction == pytest.approx(total / abs(total))


def test_zero_resultant_gives_zero_direction():
    direction, mode = select_heading(1 + 0j, -1 + 0j, 0j, 1 + 0j, 1.0, PlannerConfig.paper(wall_following=False))
    assert direction == 0


def test_soft_rule_paper_drops_f_in_robust_keeps_it():
    f_a, f_r, f_in = 1 + 0j, -0.38 + 0j, 0.5j
    paper, mode_p = select_heading(f_a, f_r, f_in, 1 + 0j, 0.5, PAPER)
    robust, mode_r = select_heading(f_a, f_r, f_in, 1 + 0j, 0.5, ROBUST)
    assert mode_p == mode_r == MODE_SOFT
    n1 = -1j  # weak F_in: heading tie -> n1 for both presets
    assert paper == pytest.approx((0.62 + 2 * 0.38 * n1) / abs(0.62 + 2 * 0.38 * n1))
    assert robust == pytest.approx((0.62 + 0.5j + 2 * 0.38 * n1) / abs(0.62 + 0.5j + 2 * 0.38 * n1))
