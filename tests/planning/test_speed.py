"""Yielding (rpf_fly.planning.speed): slower where the moving neighbours push against the motion, never below the
floor, full speed otherwise; off (the same object) at gain 0."""

import numpy as np
import pytest

from rpf_fly.planning import PlannerConfig
from rpf_fly.planning.speed import yield_speed

CONFIG = PlannerConfig.robust(yield_gain=0.5, min_speed_fraction=0.2)


def test_push_against_the_motion_slows_by_the_hand_worked_factor():
    # Heading +x, neighbours pushing -0.8 along it: 1 + 0.5 * (-0.8) = 0.6 of the speed, direction kept.
    assert yield_speed(1 + 0j, -0.8 + 0.3j, CONFIG) == pytest.approx(0.6 + 0j)


def test_sideways_or_following_push_keeps_full_speed_and_the_floor_holds():
    assert yield_speed(1j, 2.0 + 0j, CONFIG) == pytest.approx(1j)
    assert yield_speed(1j, 0.5j, CONFIG) == pytest.approx(1j)
    assert yield_speed(1 + 0j, -10 + 0j, CONFIG) == pytest.approx(0.2 + 0j)


def test_batched_and_one_drone_calls_agree_and_gain_zero_is_the_identity():
    direction = np.exp(1j * np.array([0.0, 1.0, 2.0, 3.0]))
    f_in = np.array([-0.8 + 0j, 0.3 - 1.2j, 5 + 0j, -1 - 1j])
    batched = yield_speed(direction, f_in, CONFIG)
    assert batched == pytest.approx([yield_speed(complex(d), complex(f), CONFIG) for d, f in zip(direction, f_in)])
    assert np.all(abs(batched) <= 1 + 1e-12) and np.all(abs(batched) >= 0.2 - 1e-12)
    assert yield_speed(direction, f_in, PlannerConfig.robust()) is direction


def test_brake_slows_toward_a_neighbour_in_proportion_to_the_gap_and_never_away():
    from rpf_fly.planning.speed import brake

    config = PlannerConfig.robust(margin=0.05, brake_distance=0.1, brake_buffer=0.01)
    neighbours, mask = np.array([0.31 + 0j]), np.array([True])
    # Gap 0.31 - 0.26 = 0.05 of 0.1: half speed toward it; full speed away; nothing for a masked-out one.
    assert brake(1 + 0j, 0j, neighbours, mask, config) == pytest.approx(0.5 + 0j)
    assert brake(-1 + 0j, 0j, neighbours, mask, config) == pytest.approx(-1 + 0j)
    assert brake(1 + 0j, 0j, neighbours, np.array([False]), config) == pytest.approx(1 + 0j)
    # At the bar: stop; batched rows equal one-drone calls.
    positions = np.array([0j, 1 + 0j])
    rows = np.array([[0.26 + 0j], [1.31 + 0j]])
    batched = brake(np.array([1 + 0j, 1 + 0j]), positions, rows, np.array([[True], [True]]), config)
    assert batched == pytest.approx([0j, 0.5 + 0j])
    assert brake(1 + 0j, 0j, neighbours, mask, PlannerConfig.robust()) == 1 + 0j


def test_brake_toward_a_wall_scales_only_the_inward_part_of_the_step():
    from rpf_fly.planning.obstacles import NearestObstacle
    from rpf_fly.planning.speed import brake

    config = PlannerConfig.robust(margin=0.05, brake_distance=0.1, brake_buffer=0.01)
    # Wall below (outward normal +y), 0.21 m away: gap 0.21 - 0.16 = 0.05 of 0.1, so half the inward part stays.
    wall = NearestObstacle(0.21, 1j)
    heading = np.exp(-1j * np.pi / 4)  # 45 degrees down into the wall
    slid = brake(heading, 0j, np.zeros(0, complex), np.zeros(0, bool), config, wall)
    assert slid == pytest.approx(complex(heading.real, 0.5 * heading.imag))
    # Away from the wall, or at gap 0 along it: untouched / only the tangential part.
    assert brake(np.conj(heading), 0j, np.zeros(0, complex), np.zeros(0, bool), config, wall) == np.conj(heading)
    at_bar = brake(heading, 0j, np.zeros(0, complex), np.zeros(0, bool), config, NearestObstacle(0.16, 1j))
    assert at_bar == pytest.approx(complex(heading.real, 0.0))
    # Batched rows equal one-drone calls.
    walls = NearestObstacle(np.array([0.21, 0.16]), np.array([1j, 1j]))
    rows = brake(
        np.array([heading, heading]),
        np.zeros(2, complex),
        np.zeros((2, 0), complex),
        np.zeros((2, 0), bool),
        config,
        walls,
    )
    assert rows == pytest.approx([slid, at_bar])
