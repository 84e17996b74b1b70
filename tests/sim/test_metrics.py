"""Every metric on hand-made trajectories (docs/metrics.md)."""

import math

import numpy as np
import pytest

from rpf_fly.planning import ObstacleSet
from rpf_fly.sim.metrics import compute_metrics


def two_drone_case():
    # dt 0.5, r 0.6 (2r = 1.2), goal tolerance 0.1.
    # A: (0,0) (1,0) (2,0) (2,1), goal (2,1): arrives at sample 3.
    # B: (5,0) (4,0) (3,0) (3,0), goal (0,0): never arrives.
    a = np.array([0, 1, 2, 2 + 1j])
    b = np.array([5, 4, 3, 3 + 0j])
    positions = np.stack([a, b], axis=1)
    goals = np.array([2 + 1j, 0j])
    obstacles = ObstacleSet.from_shapes(circles=[((2.0, -1.0), 0.5)])
    return compute_metrics(positions, goals, 0.5, 0.1, 0.6, obstacles, ["a", "b"], "hand", "apf", 7)


def test_travel_time_and_arrival():
    m = two_drone_case()
    a, b = m.per_drone
    assert a.reached and not b.reached
    assert a.travel_distance_m == pytest.approx(3.0)
    assert a.time_to_goal_s == pytest.approx(1.5)
    assert b.travel_distance_m == pytest.approx(2.0)  # the whole track of a drone that never arrived
    assert b.time_to_goal_s is None
    assert m.reached == 1 and m.drones == 2
    assert m.travel_distance_m == pytest.approx(3.0)  # mean over the drones that arrived
    assert m.makespan_s is None
    assert not m.success


def test_smoothness():
    m = two_drone_case()
    a, b = m.per_drone
    # A: v = (1,0), (1,0), (0,1): changes 0 and |(0,1) - (1,0)| / |(0,1)| = sqrt 2, over T_A = 3 steps.
    assert a.smoothness == pytest.approx(math.sqrt(2) / 3)
    # B: v = (-1,0), (-1,0), (0,0): change 0, then a zero velocity (skipped).
    assert b.smoothness == pytest.approx(0.0)
    assert m.smoothness == pytest.approx(math.sqrt(2) / 3)


def test_collisions_separation_and_clearance():
    m = two_drone_case()
    # Pair distances 5, 4, 1, sqrt 2: enters 2r = 1.2 once at sample 2.
    assert m.collisions_drone_drone == 1
    assert m.min_separation_m == pytest.approx(1.0)
    # A's clearance to the circle (2,-1) r 0.5: 1.736, 0.914, 0.5, 1.5: enters r = 0.6 once.
    assert m.collisions_drone_obstacle == 1
    assert m.min_obstacle_clearance_m == pytest.approx(0.5)
    assert m.per_drone[0].collided and m.per_drone[1].collided


def test_collision_counted_once_per_entry():
    # Separations 2, 1, 2, 1, 1, 2 with 2r = 1.2: two entries.
    gaps = np.array([2, 1, 2, 1, 1, 2.0])
    positions = np.stack([np.zeros(6, complex), gaps + 0j], axis=1)
    m = compute_metrics(positions, np.array([9j, 9 + 9j]), 0.1, 0.1, 0.6, ObstacleSet.empty(), ["a", "b"])
    assert m.collisions_drone_drone == 2
    assert m.collisions_drone_obstacle == 0
    assert m.min_obstacle_clearance_m is None


def test_collision_at_first_sample_counts():
    positions = np.array([[0j, 0.1 + 0j], [0j, 5 + 0j]])
    m = compute_metrics(positions, np.array([9j, 9 + 9j]), 0.1, 0.1, 0.1, ObstacleSet.empty(), ["a", "b"])
    assert m.collisions_drone_drone == 1


def test_success_and_makespan_when_all_arrive():
    a = np.array([0, 0.5, 1.0 + 0j])
    b = np.array([5j, 4.5j, 4.5j])  # arrives at sample 1 and stays
    positions = np.stack([a, b], axis=1)
    m = compute_metrics(positions, np.array([1 + 0j, 4.5j]), 0.1, 0.05, 0.1, ObstacleSet.empty(), ["a", "b"])
    assert m.success and m.reached == 2
    assert m.makespan_s == pytest.approx(0.2)
    assert m.per_drone[1].time_to_goal_s == pytest.approx(0.1)
    assert m.travel_distance_m == pytest.approx((1.0 + 0.5) / 2)
    assert m.min_separation_m == pytest.approx(abs(0.5 - 4.5j))  # closest at sample 1


def test_json_shape_matches_contract():
    d = two_drone_case().to_json_dict()
    assert list(d) == [
        "mission",
        "planner",
        "seed",
        "drones",
        "reached",
        "success",
        "collisions",
        "margin",
        "min_separation_m",
        "min_obstacle_clearance_m",
        "travel_distance_m",
        "smoothness",
        "makespan_s",
        "per_drone",
    ]
    assert d["collisions"] == {"drone_drone": 1, "drone_obstacle": 1}
    assert d["seed"] == 7 and d["mission"] == "hand" and d["planner"] == "apf"
    assert set(d["per_drone"][0]) >= {"name", "reached", "collided", "travel_distance_m", "time_to_goal_s"}


def test_single_drone_has_no_separation():
    positions = np.array([[0j], [0.5 + 0j]])
    m = compute_metrics(positions, np.array([0.5 + 0j]), 0.1, 0.1, 0.1, ObstacleSet.empty(), ["a"])
    assert m.min_separation_m is None and m.success


def test_margin_breaches_are_counted_beyond_contact():
    """Two drones passing 0.22 m apart beside a pole 0.13 m away: no collision at r 0.1; with margin 0.05 one pair
    breach (< 2r + m = 0.25) and one obstacle breach (< r + m = 0.15); with margin 0.01 the margin holds."""
    positions = np.array([[-1 + 0j, -1 + 0.22j], [0j, 0.22j], [1 + 0j, 1 + 0.22j]])
    pole = ObstacleSet.from_shapes(circles=[((0.0, -0.23), 0.1)])
    goals = np.array([1 + 0j, 1 + 0.22j])
    m = compute_metrics(positions, goals, 0.1, 0.1, 0.1, pole, ["a", "b"], margin=0.05)
    assert m.collisions_drone_drone == 0 and m.collisions_drone_obstacle == 0
    assert (m.margin_breaches_drone_drone, m.margin_breaches_drone_obstacle) == (1, 1) and not m.margin_held
    assert m.to_json_dict()["margin"] == {"m": 0.05, "held": False, "drone_drone": 1, "drone_obstacle": 1}
    assert compute_metrics(positions, goals, 0.1, 0.1, 0.1, pole, ["a", "b"], margin=0.01).margin_held
