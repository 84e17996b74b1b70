"""The APF forces against numbers worked by hand from the paper's equations (Section III-B)."""

import math
from dataclasses import replace

import numpy as np
import pytest

from rpf_fly.planning import ObstacleSet, PlannerConfig, nearest_obstacle
from rpf_fly.planning.forces import attractive, inter_robot, repulsive
from rpf_fly.planning.obstacles import FAR

PAPER = PlannerConfig.paper()
ROBUST = PlannerConfig.robust()


def test_attractive_is_unit_vector_to_goal():
    f_a, d_g = attractive(0j, 3 + 4j)
    assert d_g == pytest.approx(5.0)
    assert f_a == pytest.approx(0.6 + 0.8j)


def test_attractive_is_zero_at_goal():
    f_a, d_g = attractive(1 + 1j, 1 + 1j)
    assert f_a == 0 and d_g == 0


def test_repulsive_circle_hand_worked():
    # Circle centre (2, 0), radius 0.5; robot at the origin: d_o = 1.5, p_o = (1.5, 0).
    # F_r = eta (1/d_o - 1/rho) (p - p_o) / d_o^3 = 0.05 (1/1.5 - 1/10) (-1.5, 0) / 3.375 = (-0.0125926, 0)
    obstacles = ObstacleSet.from_shapes(circles=[((2.0, 0.0), 0.5)])
    nearest = nearest_obstacle(0j, obstacles)
    assert nearest.distance == pytest.approx(1.5)
    surface_point = 0j - nearest.distance * nearest.normal
    assert surface_point == pytest.approx(1.5 + 0j)
    f_r = repulsive(nearest, 0.05, PAPER)
    assert f_r == pytest.approx(-0.05 * (1 / 1.5 - 0.1) * 1.5 / 1.5**3 + 0j)
    assert f_r == pytest.approx(-0.0125926 + 0j, abs=1e-7)


def test_repulsive_box_face_and_corner_hand_worked():
    obstacles = ObstacleSet.from_shapes(boxes=[((1.0, -1.0), (2.0, 1.0))])
    # Facing the -x face: nearest point (1, 0), d_o = 1 -> F_r = 0.05 (1 - 0.1) (-1, 0) / 1 = (-0.045, 0).
    face = nearest_obstacle(0j, obstacles)
    assert face.distance == pytest.approx(1.0)
    assert repulsive(face, 0.05, PAPER) == pytest.approx(-0.045 + 0j)
    # Diagonal to the corner (1, 1) from (0, 3): p - p_o = (-1, 2), d_o = sqrt 5.
    corner = nearest_obstacle(3j, obstacles)
    assert corner.distance == pytest.approx(math.sqrt(5))
    expected = 0.05 * (1 / math.sqrt(5) - 0.1) * (-1 + 2j) / math.sqrt(5) ** 3
    assert repulsive(corner, 0.05, PAPER) == pytest.approx(expected)
    assert expected == pytest.approx(-0.0015528 + 0.0031056j, abs=1e-7)


def test_inside_box_distance_is_negative_with_outward_normal():
    obstacles = ObstacleSet.from_shapes(boxes=[((1.0, -1.0), (2.0, 1.0))])
    inside = nearest_obstacle(1.1 + 0j, obstacles)
    assert inside.distance == pytest.approx(-0.1)
    assert inside.normal == pytest.approx(-1 + 0j)
    assert 1.1 - inside.distance * inside.normal == pytest.approx(1.0 + 0j)
    # The clamped repulsion still pushes out of the nearest face.
    assert repulsive(inside, 0.05, PAPER).real < -1e3


def test_inside_circle_is_negative():
    obstacles = ObstacleSet.from_shapes(circles=[((0.0, 0.0), 1.0)])
    inside = nearest_obstacle(0.25 + 0j, obstacles)
    assert inside.distance == pytest.approx(-0.75)
    assert inside.normal == pytest.approx(1 + 0j)


def test_nearest_picks_the_closest_of_circles_and_boxes():
    obstacles = ObstacleSet.from_shapes(circles=[((5.0, 0.0), 0.5)], boxes=[((-2.0, -1.0), (-1.5, 1.0))])
    nearest = nearest_obstacle(0j, obstacles)
    assert nearest.distance == pytest.approx(1.5)
    assert nearest.normal == pytest.approx(1 + 0j)


def test_repulsion_zero_beyond_influence_range_and_beyond_sensing_range():
    config = PlannerConfig.paper(influence_range=10.0, sensing_range=6.0)
    obstacles = ObstacleSet.from_shapes(circles=[((7.0, 0.0), 0.5)])  # surface at 6.5 m: within rho, unseen
    assert repulsive(nearest_obstacle(0j, obstacles), 0.05, config) == 0
    config = PlannerConfig.paper(influence_range=3.0, sensing_range=6.0)  # surface at 6.5 m: beyond rho
    assert repulsive(nearest_obstacle(0j, obstacles), 0.05, config) == 0
    config = PlannerConfig.paper(influence_range=10.0, sensing_range=7.0)  # now seen and within rho
    assert repulsive(nearest_obstacle(0j, obstacles), 0.05, config).real < 0


def test_no_obstacles_means_no_repulsion():
    nearest = nearest_obstacle(0j, ObstacleSet.empty())
    assert nearest.distance == FAR
    assert repulsive(nearest, 0.05, PAPER) == 0


def test_inter_robot_paper_sum_and_mean_hand_worked():
    # Neighbours at (1, 0) and (0, 2), lambda 2:
    # (0.5 - 2/1)(1, 0)/1 + (0.5 - 2/2)(0, 2)/2 = (-1.5, 0) + (0, -0.5)
    neighbours = np.array([1 + 0j, 2j])
    mask = np.array([True, True])
    f_in, count = inter_robot(0j, neighbours, mask, 2.0, PAPER)
    assert count == 2
    assert f_in == pytest.approx(-1.5 - 0.5j)
    mean = PlannerConfig.paper(neighbour_aggregate="mean")
    f_mean, _ = inter_robot(0j, neighbours, mask, 2.0, mean)
    assert f_mean == pytest.approx(-0.75 - 0.25j)


def test_inter_robot_paper_attracts_far_neighbours_robust_does_not():
    # At d = 5 > 2 lambda = 4 the paper's term is attractive: (0.5 - 2/5) = +0.1 toward the neighbour.
    f_paper, _ = inter_robot(0j, np.array([5 + 0j]), np.array([True]), 2.0, PAPER)
    assert f_paper == pytest.approx(0.1 + 0j)
    f_robust, _ = inter_robot(0j, np.array([5 + 0j]), np.array([True]), 2.0, ROBUST)
    assert f_robust == 0


def test_inter_robot_robust_rotates_repulsion_counter_clockwise():
    # Head-on neighbour ahead (+x): repulsion (-1.5, 0) turned 20 degrees CCW points to -y, the drone's right.
    f_in, _ = inter_robot(0j, np.array([1 + 0j]), np.array([True]), 2.0, ROBUST)
    angle = math.radians(20)
    assert f_in == pytest.approx(-1.5 * complex(math.cos(angle), math.sin(angle)))
    assert f_in.imag < 0


def test_inter_robot_excludes_neighbours_outside_sensing_range():
    config = PlannerConfig.paper(sensing_range=6.0)
    inside, count_in = inter_robot(0j, np.array([5.99 + 0j]), np.array([True]), 2.0, config)
    outside, count_out = inter_robot(0j, np.array([6.0 + 0j]), np.array([True]), 2.0, config)
    assert count_in == 1 and inside != 0
    assert count_out == 0 and outside == 0


def test_inter_robot_respects_mask_and_empty_neighbour_set():
    f_in, count = inter_robot(0j, np.array([1 + 0j]), np.array([False]), 2.0, PAPER)
    assert count == 0 and f_in == 0
    f_in, count = inter_robot(0j, np.zeros(0, dtype=complex), np.zeros(0, dtype=bool), 2.0, PAPER)
    assert count == 0 and f_in == 0


def test_inter_robot_per_robot_lambda_broadcasts():
    positions = np.array([0j, 10 + 0j])
    neighbours = np.array([[1 + 0j], [11 + 0j]])
    mask = np.ones((2, 1), dtype=bool)
    f_in, _ = inter_robot(positions, neighbours, mask, np.array([2.0, 1.0]), PAPER)
    assert f_in == pytest.approx(np.array([-1.5 + 0j, -0.5 + 0j]))


def test_guided_influence_range_limits_static_repulsion_only_with_guidance():
    # Surface 0.5 m away: beyond a guided rho of 0.3 the repulsion vanishes with guidance, stays without it.
    obstacles = ObstacleSet.from_shapes(circles=[((1.0, 0.0), 0.5)])
    nearest = nearest_obstacle(0j, obstacles)
    guided = PlannerConfig.robust(guidance="path", guided_influence_range=0.3)
    assert repulsive(nearest, 0.05, guided) == 0
    assert repulsive(nearest, 0.05, PlannerConfig.robust(guided_influence_range=0.3)) == repulsive(
        nearest, 0.05, ROBUST
    )
    # Inside it: eta (1/d - 1/0.3) / d^2 at d = 0.2, pointing away from the obstacle.
    near = nearest_obstacle(0.3 + 0j, obstacles)
    assert repulsive(near, 0.05, guided) == pytest.approx(-0.05 * (1 / 0.2 - 1 / 0.3) / 0.04 + 0j)


def test_neighbour_range_cuts_the_pairwise_repulsion_and_shifts_it_to_zero_there():
    # lambda 1.2: the robust term reaches 2 lambda = 2.4 m; with R = 1.5 it is max(0.5, 1.2/1.5) - 1.2/d.
    config = PlannerConfig.robust(neighbour_range=1.5, keep_right_deg=0.0)
    plain_config = PlannerConfig.robust(keep_right_deg=0.0)
    far, _ = inter_robot(0j, np.array([2.0 + 0j]), np.array([True]), 1.2, config)
    assert far == 0
    assert inter_robot(0j, np.array([2.0 + 0j]), np.array([True]), 1.2, plain_config)[0] != 0
    near, _ = inter_robot(0j, np.array([1.0 + 0j]), np.array([True]), 1.2, config)
    assert near == pytest.approx((0.8 - 1.2 / 1.0) + 0j)
    # A lambda whose own range is shorter than R keeps the paper's term.
    short, _ = inter_robot(0j, np.array([1.0 + 0j]), np.array([True]), 0.6, config)
    assert short == pytest.approx(inter_robot(0j, np.array([1.0 + 0j]), np.array([True]), 0.6, plain_config)[0])


def test_summed_repulsion_cancels_across_a_gap_where_the_nearest_one_flips_side():
    # Two pillars 0.44 m apart (surfaces): in the middle of the gap the nearest-only push is 2 (one pillar's,
    # whichever rounding picks) and jumps to the other side across it; the sum is 0 there and turns smoothly.
    from rpf_fly.planning.forces import repulsive_sum
    from rpf_fly.planning.obstacles import every_surface

    obstacles = ObstacleSet.from_shapes(circles=[((-0.72, 0.0), 0.5), ((0.72, 0.0), 0.5)])
    config = PlannerConfig.robust(guidance="path", guided_influence_range=0.2, margin=0.05)
    middle = nearest_obstacle(0j, obstacles)
    assert abs(repulsive(NearestObstacleSeen(middle, 0.05), 0.05, config)) > 1.5
    assert repulsive_sum(every_surface(0j, obstacles), 0.05, config) == pytest.approx(0j, abs=1e-12)
    for x in (-0.01, 0.01):
        nearest = nearest_obstacle(complex(x, 0), obstacles)
        alone = repulsive(NearestObstacleSeen(nearest, 0.05), 0.05, config)
        total = repulsive_sum(every_surface(complex(x, 0), obstacles), 0.05, config)
        assert np.sign(alone.real) == np.sign(total.real) == -np.sign(x)
        assert abs(total) < 0.7 * abs(alone)
    # Batched equals one-drone, and a static neighbour counts with its own (longer) range.
    points = np.array([0.05j, -0.1 + 0j])
    surfaces = every_surface(points, obstacles, np.array([[0.55j], [5 + 5j]]), 0.1, np.array([[True], [False]]))
    assert surfaces.mapped == 2 and surfaces.distance.shape == (2, 3)
    batch = repulsive_sum(surfaces, 0.05, replace(config, static_influence_range=0.5))
    one = repulsive_sum(
        every_surface(points[0], obstacles, np.array([0.55j]), 0.1, np.array([True])),
        0.05,
        replace(config, static_influence_range=0.5),
    )
    assert batch[0] == pytest.approx(one)
    # The hovering neighbour 0.5 m away (0.35 m seen): out of the guided range, inside the static one.
    assert repulsive_sum(surfaces, 0.05, config)[0] != pytest.approx(batch[0])


def NearestObstacleSeen(nearest, margin):  # noqa: N802 - the obstacle as the forces see it
    from rpf_fly.planning.obstacles import NearestObstacle

    return NearestObstacle(nearest.distance - margin, nearest.normal)
