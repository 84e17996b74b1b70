"""Rollouts on the kinematic world: the flat-wall stall, arrival, time limits, outcomes, geofence."""

import numpy as np
import pytest

from rpf_fly.mission.model import BoxObstacle
from rpf_fly.planning import FixedGains, Planner, PlannerConfig
from rpf_fly.sim import DroneOutcome, SimParams, World, circle_swap, compute_metrics, make_scenario, rollout

WALL = make_scenario("wall", np.array([0j]), np.array([6 + 0j]), (BoxObstacle((2.0, -1.5), (2.2, 1.5)),))


def run(scenario, config, params=SimParams()):
    result = rollout(scenario, Planner(scenario.obstacles, config, FixedGains()), params)
    metrics = compute_metrics(
        result.positions,
        scenario.goals,
        params.dt,
        params.goal_tolerance,
        config.safety_radius,
        scenario.obstacles,
        scenario.names,
    )
    return result, metrics


@pytest.mark.parametrize("config", [PlannerConfig.robust(), PlannerConfig.paper()], ids=["robust", "paper"])
def test_flat_wall_reached_with_wall_following(config):
    """F_r exactly opposite F_a: the soft rule turns the drone along the wall and around its end."""
    result, metrics = run(WALL, config)
    assert result.outcomes == (DroneOutcome.REACHED,)
    assert metrics.success and metrics.collisions_drone_obstacle == 0
    assert (result.modes == 2).any()  # the soft rule did the work
    assert result.positions[:, 0].imag.min() < -1.5  # it went around the end of the wall (right side: tie -> n1)


@pytest.mark.parametrize("preset", ["robust", "paper"])
def test_flat_wall_stalls_without_wall_following(preset):
    """The vanilla APF local minimum: the drone stops in front of the wall, never reaching the goal."""
    result, metrics = run(WALL, PlannerConfig.preset(preset, wall_following=False))
    assert result.outcomes == (DroneOutcome.STALLED,)
    assert not metrics.success and metrics.reached == 0
    assert result.steps == SimParams().max_steps
    track = result.positions[:, 0]
    assert track.real.max() < 2.0  # never passed the wall's face at x = 2
    assert abs(track[-1] - track[-200]) < 0.1  # no progress over the last 20 s
    assert metrics.collisions_drone_obstacle == 0


def test_world_arrived_drones_stay_and_are_static_neighbours():
    world = World(np.array([0j, 5 + 0j]), np.array([0.05 + 0j, 9 + 0j]), 0.5, 0.1, 0.1, (-10, 10), (-10, 10))
    assert world.arrived.tolist() == [True, False]
    assert world.velocity[0] == 0
    world.advance(np.array([1 + 0j, 1 + 0j]))
    assert world.position[0] == 0j  # arrived: does not move
    assert world.position[1] == pytest.approx(5.05 + 0j)
    views = world.views(6.0)
    assert views.neighbour_velocity[1, 0] == 0  # drone 1 sees drone 0 hovering


def test_world_stalled_direction_keeps_drone_in_place_and_heading():
    world = World(np.array([0j]), np.array([5 + 0j]), 0.5, 0.1, 0.1, (-10, 10), (-10, 10))
    world.advance(np.array([0j]))
    assert world.position[0] == 0j and world.heading[0] == 1 + 0j and world.velocity[0] == 0


def test_world_geofence_clamps_and_counts():
    world = World(np.array([0.98 + 0j]), np.array([5 + 0j]), 0.5, 0.1, 0.01, (-1, 1), (-1, 1))
    world.advance(np.array([1 + 0j]))
    assert world.position[0] == pytest.approx(1 + 0j)
    assert world.geofence_clamps.tolist() == [1]


def test_time_limit_stops_rollout_with_timeout_outcome():
    scenario = make_scenario("far", np.array([0j]), np.array([30 + 0j]), arena_x=(-40, 40), arena_y=(-40, 40))
    result, metrics = run(scenario, PlannerConfig.robust(), SimParams(time_limit_s=5.0))
    assert result.steps == 50
    assert result.outcomes == (DroneOutcome.TIMEOUT,)
    assert result.positions[-1, 0] == pytest.approx(2.5 + 0j)  # 5 s at 0.5 m/s


def test_rollout_stops_when_all_arrived_and_records_modes():
    result, metrics = run(circle_swap(4, 2.0), PlannerConfig.robust())
    assert all(o is DroneOutcome.REACHED for o in result.outcomes)
    assert result.steps < SimParams().max_steps
    assert result.positions.shape == (result.steps + 1, 4)
    assert result.modes.shape == result.eta.shape == (result.steps, 4)
    assert metrics.success


def test_arrived_drone_is_marked_and_holds_while_others_fly():
    scenario = make_scenario("short-long", np.array([0j, 5j]), np.array([1 + 0j, 5j + 4]))
    result, metrics = run(scenario, PlannerConfig.robust())
    first = metrics.per_drone[0].time_to_goal_s
    k = int(round(first / 0.1))
    assert (result.modes[k:, 0] == -1).all() and (result.modes[: k - 1, 0] >= 0).all()
    assert np.all(result.positions[k:, 0] == result.positions[k, 0])
    assert metrics.success and metrics.makespan_s > first


def test_collided_drones_fly_on_and_are_counted():
    # Two drones on a head-on course with wall-following off and lambda 0: no avoidance at all.
    scenario = make_scenario("head-on", np.array([0j, 4 + 0j]), np.array([4 + 0j, 0j]))
    config = PlannerConfig.paper(wall_following=False)
    result = rollout(scenario, Planner(scenario.obstacles, config, FixedGains(0.05, 0.0)), SimParams())
    metrics = compute_metrics(result.positions, scenario.goals, 0.1, 0.1, 0.1, scenario.obstacles, scenario.names)
    assert metrics.collisions_drone_drone == 1
    assert metrics.reached == 2 and not metrics.success  # they passed through each other and arrived
