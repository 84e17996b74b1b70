"""Arrival in the kinematic world: goals the repulsion alone keeps a drone circling are reached with the capture rule.

Without the capture rule (``capture_radius=0``) each of these drones orbits the pole or the arrived
neighbour beside its goal, passing it at 0.11-0.24 m once a lap, until the time limit.
"""

import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from rpf_fly.mission.model import CircleObstacle
from rpf_fly.planning import FixedGains, Planner, PlannerConfig
from rpf_fly.sim import DroneOutcome, SimParams, compute_metrics, make_scenario, rollout

R, MARGIN = 0.1, 0.05


def run(scenario, capture_radius=None):
    overrides = {} if capture_radius is None else {"capture_radius": capture_radius}
    config = PlannerConfig.robust(margin=MARGIN, **overrides)
    params = SimParams()
    result = rollout(scenario, Planner(scenario.obstacles, config, FixedGains()), params)
    metrics = compute_metrics(
        result.positions,
        scenario.goals,
        params.dt,
        params.goal_tolerance,
        R,
        scenario.obstacles,
        scenario.names,
        margin=MARGIN,
    )
    return result, metrics


@pytest.mark.parametrize("goal", [2.5 + 0j, 3 + 0.5j, 2.6 + 0.2j], ids=["front", "side", "close"])
def test_goal_beside_a_pole_is_reached(goal):
    """Goals 0.20-0.25 m from a pole's surface (>= r + m): without the capture rule the fixed-gain APF orbits it."""
    scenario = make_scenario("pole", np.array([0j]), np.array([goal]), (CircleObstacle((3.0, 0.0), 0.25),))
    before, _ = run(scenario, capture_radius=0.0)
    assert before.outcomes == (DroneOutcome.TIMEOUT,)
    result, metrics = run(scenario)
    assert result.outcomes == (DroneOutcome.REACHED,)
    assert metrics.success and result.steps < 80
    clearance = (abs(result.positions[:, 0] - 3.0) - 0.25).min()
    assert clearance >= min(R + MARGIN, abs(goal - 3.0) - 0.25)


@pytest.mark.parametrize("gap", [0.4, 0.45])
def test_goal_beside_an_arrived_neighbour_is_reached(gap):
    """A neighbour hovering at its goal 0.40-0.45 m from this drone's goal (a static obstacle of radius r, seen
    m nearer): without the capture rule the drone circles it; with it, it settles and keeps 2r + m."""
    starts, goals = np.array([0j, -3 + 0.5j]), np.array([0j, gap + 0j])
    scenario = make_scenario("pair", starts, goals, ())
    before, _ = run(scenario, capture_radius=0.0)
    assert before.outcomes[1] == DroneOutcome.TIMEOUT
    result, metrics = run(scenario)
    assert result.outcomes == (DroneOutcome.REACHED, DroneOutcome.REACHED)
    assert metrics.success and result.steps < 90
    assert abs(result.positions[:, 1] - result.positions[:, 0]).min() >= 2 * R + MARGIN


def test_line_of_goals_settles_with_the_margin():
    """The flight tests' 3-drone mission (goals 0.6 m apart beside a pole) at the product's margin 0.05: 12.2 s in
    the kinematic simulation before the rule, 7.0 s at margin 0; now within a step of the latter."""
    sys.path.insert(0, str(Path(__file__).parents[1] / "flight"))
    from flight_harness import SHORT_MISSION

    from rpf_fly.mission import parse_mission
    from rpf_fly.sim.evaluate import run_scenario, sim_params
    from rpf_fly.sim.scenario import scenario_from_mission

    mission = parse_mission(SHORT_MISSION)
    settings = replace(mission.planner, margin=MARGIN)
    run_ = run_scenario(scenario_from_mission(mission, 0), settings, sim_params(mission), 0, "short-3")
    assert run_.metrics.success
    assert run_.metrics.makespan_s <= 7.5
    assert run_.metrics.min_separation_m >= 2 * R + MARGIN


def test_the_mission_key_sets_the_capture_radius_and_zero_turns_the_rule_off():
    """``planner.capture_radius``: the mission's value reaches the planner (0 reproduces the orbit of the pole)."""
    from rpf_fly.mission import parse_mission
    from rpf_fly.planning.factory import planner_config
    from rpf_fly.sim.evaluate import run_scenario, sim_params
    from rpf_fly.sim.scenario import scenario_from_mission

    text = (
        "name: pole\narena: {x: [-1, 5], y: [-2, 2]}\nflight: {speed: 0.5}\nobstacles:\n"
        "  - {shape: circle, center: [3.0, 0.0], radius: 0.25}\n"
        "drones:\n  - {name: cf1, uri: radio://0/80/2M/E7E7E7E701, start: [0, 0], goal: [2.5, 0]}\n"
    )
    runs = {}
    for key in ("", ", capture_radius: 0", ", capture_radius: 0.3"):
        mission = parse_mission(text + f"planner: {{kind: apf, guidance: none{key}}}\n")
        assert planner_config(mission.planner).capture_radius == (0.0 if key.endswith(" 0") else 0.3)
        runs[key] = run_scenario(scenario_from_mission(mission, 0), mission.planner, sim_params(mission), 0, "pole")
    assert runs[""].metrics.success and runs[", capture_radius: 0.3"].metrics.success
    assert not runs[", capture_radius: 0"].metrics.success
    from rpf_fly.mission.model import PlannerSettings

    for kind in ("apf-paper", "rpf", "rpf-mean", "ppo"):  # the paper's planners stay as the paper wrote them
        assert PlannerSettings(kind=kind).capture_radius_m == 0.0
    assert PlannerSettings(kind="rpf3").capture_radius_m == PlannerSettings(kind="apf").capture_radius_m == 0.3
    assert PlannerSettings(kind="apf", preset="paper").capture_radius_m == 0.0
