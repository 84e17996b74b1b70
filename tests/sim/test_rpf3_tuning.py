"""RPF-3's tuning (docs/algorithm.md, *RPF-3's tuning*): what the ``rpf3`` kind flies on top of the robust preset,
and that it shortens paths in the kinematic world without giving up the margin. The paper's kinds never get it."""

from dataclasses import replace

import numpy as np
import pytest

from rpf_fly.mission.model import BoxObstacle, PlannerSettings
from rpf_fly.planning import FixedGains, Planner, PlannerConfig
from rpf_fly.planning.config import RPF3_TUNING
from rpf_fly.planning.factory import planner_config
from rpf_fly.sim import SimParams, compute_metrics, make_scenario, rollout

R, MARGIN = 0.1, 0.05


@pytest.mark.parametrize("kind", ["apf", "apf-paper", "rpf", "rpf-mean", "ppo", "orca"])
def test_only_the_rpf3_kind_gets_the_tuning(kind):
    config = planner_config(PlannerSettings(kind=kind))
    tuned = planner_config(PlannerSettings(kind="rpf3"))
    paper_rpf3 = planner_config(PlannerSettings(kind="rpf3", preset="paper"))
    base = PlannerConfig.paper() if kind == "apf-paper" else PlannerConfig()
    for key, value in RPF3_TUNING.items():
        assert getattr(config, key) == getattr(base, key) != value
        assert getattr(paper_rpf3, key) == getattr(PlannerConfig.paper(), key)
        assert getattr(tuned, key) == value


def fly(scenario, config, gains):
    params = SimParams()
    result = rollout(scenario, Planner(scenario.obstacles, config, gains, (scenario.arena_x, scenario.arena_y)), params)
    return compute_metrics(
        result.positions,
        scenario.goals,
        params.dt,
        params.goal_tolerance,
        R,
        scenario.obstacles,
        scenario.names,
        margin=MARGIN,
    )


GAINS = FixedGains(eta=0.047, lam=1.2)
"""The gains RPF-3's policy gives on average in the walled families (eta 0.047, lambda 1.2)."""
TUNED = planner_config(PlannerSettings(kind="rpf3"))
KEEP_RIGHT_20 = replace(TUNED, keep_right_deg=20.0)
"""The tuning with the robust preset's keep-right angle: the step at which the neighbour range and yielding were
measured (the 45 degrees came last)."""


def test_guided_repulsion_range_lets_a_drone_hug_its_path_round_a_wall_and_keep_the_margin():
    # One drone round the end of a wall (guidance on): the path's corner clears the wall by r + m.
    wall = (BoxObstacle(min=(-0.1, -1.0), max=(0.1, 3.0)),)
    scenario = make_scenario("wall", np.array([-2 + 1j]), np.array([2 + 1j]), wall, (-4, 4), (-3, 4))
    before = fly(scenario, replace(TUNED, guided_influence_range=0.0), GAINS)
    after = fly(scenario, TUNED, GAINS)
    assert before.success and after.success and after.margin_held
    assert after.travel_distance_m < before.travel_distance_m - 0.2
    assert after.min_obstacle_clearance_m < before.min_obstacle_clearance_m


def crossing():  # type: ignore[no-untyped-def]
    """Two pairs crossing at right angles in the open."""
    return make_scenario(
        "cross",
        np.array([-3 + 0.3j, -3 - 0.3j, 0.3 - 3j, -0.3 - 3j]),
        np.array([3 + 0.3j, 3 - 0.3j, 0.3 + 3j, -0.3 + 3j]),
    )


def test_neighbour_range_shortens_the_detour_of_a_crossing_and_keeps_the_margin():
    scenario = crossing()
    before = fly(scenario, replace(KEEP_RIGHT_20, neighbour_range=0.0), GAINS)
    after = fly(scenario, KEEP_RIGHT_20, GAINS)
    assert before.success and after.success and after.margin_held
    assert after.travel_distance_m < before.travel_distance_m - 0.3
    assert after.makespan_s < before.makespan_s


def test_yielding_shortens_the_crossing_further_and_keeps_the_margin():
    # The same crossing: with the neighbour range alone the pairs still swerve; yielding lets one pass first.
    scenario = crossing()
    assert TUNED.yield_gain > 0
    before = fly(scenario, replace(KEEP_RIGHT_20, yield_gain=0.0), GAINS)
    after = fly(scenario, KEEP_RIGHT_20, GAINS)
    assert before.success and after.success and after.margin_held
    assert after.travel_distance_m < before.travel_distance_m - 0.2
    assert after.makespan_s < before.makespan_s
    assert after.smoothness < before.smoothness


def test_keep_right_45_makes_a_small_circle_swap_shorter_and_smoother_and_keeps_the_margin():
    # Six drones swapping across a 2 m circle (arena-b's shape): the wider turn to the right settles the
    # roundabout sooner than the robust preset's 20 degrees.
    angles = 2 * np.pi * np.arange(6) / 6 + 0.1
    scenario = make_scenario("swap", np.exp(1j * angles), -np.exp(1j * angles))
    assert TUNED.keep_right_deg == 45.0
    before, after = fly(scenario, KEEP_RIGHT_20, GAINS), fly(scenario, TUNED, GAINS)
    assert before.success and after.success and after.margin_held
    assert after.smoothness < before.smoothness - 0.005
    assert after.travel_distance_m < before.travel_distance_m and after.makespan_s < before.makespan_s


def test_a_drone_is_routed_round_a_drone_parked_in_the_gap_of_its_path():
    """Fresh arena-a seed 192 with the shipped RPF-3: drone 3's map path runs between two pillars where drone 0 has
    parked on its goal. Without the detour it stalls there to the time limit; with it, it goes round by the next
    gap and every drone arrives, with the margin held (docs/algorithm.md, *Guidance round parked drones*)."""
    from rpf_fly.mission.policy_paths import PROJECT_POLICIES
    from rpf_fly.planning.factory import make_planner
    from rpf_fly.sim.generators import generate

    scenario = generate("arena-a", 192, split="bench")
    settings = PlannerSettings(kind="rpf3", policy=PROJECT_POLICIES / "rpf3.onnx")
    bounds = (scenario.arena_x, scenario.arena_y)
    shipped = make_planner(settings, scenario.obstacles, bounds, scenario.goals)
    assert shipped.config.guide_around_parked
    params = SimParams()

    def outcome(planner):  # type: ignore[no-untyped-def]
        result = rollout(scenario, planner, params)
        return compute_metrics(
            result.positions,
            scenario.goals,
            params.dt,
            params.goal_tolerance,
            R,
            scenario.obstacles,
            scenario.names,
            margin=MARGIN,
        )

    without = Planner(scenario.obstacles, replace(shipped.config, guide_around_parked=False), shipped.gains, bounds)
    before, after = outcome(without), outcome(shipped)
    assert not before.success and before.reached == 5
    assert after.success and after.margin_held and shipped.guidance.detours_built > 0
