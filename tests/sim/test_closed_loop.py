"""The closed loop on the firmware model (rpf_fly/sim/closed_loop.py): planners fly simulated Crazyflies through the
flight's own setpoint code, the drones trail their setpoints as the model does, and safety is judged on the 100 Hz
truth, between the planning ticks too."""

from dataclasses import replace

import numpy as np
import pytest

from rpf_fly.planning.factory import make_planner
from rpf_fly.sim.closed_loop import STEP_S, FirmwareParams, firmware_metrics, firmware_rollouts, run_firmware
from rpf_fly.sim.evaluate import planner_settings, run_scenario
from rpf_fly.sim.rollout import DroneOutcome, SimParams
from rpf_fly.sim.scenario import make_scenario

MODEL_LAG_S = 0.55
"""docs/dynamics.md: the model trails a moving setpoint by 0.55 s x its speed."""

FAST = FirmwareParams(settle_s=1.0, hold_tail_s=1.0)
"""A shorter hover before t = 0 and tail after the arrivals than the bench's, to keep the tests short."""


@pytest.fixture(scope="module")
def lanes():
    """Two drones flying 3 m along parallel lanes 0.6 m apart, APF, on the firmware model and kinematically."""
    scenario = make_scenario("lanes", np.array([0, 0.6j]), np.array([3, 3 + 0.6j]), arena_x=(-1, 4), arena_y=(-1, 2))
    settings = planner_settings("apf")
    [run] = run_firmware([scenario], settings, SimParams(), [0], ["lanes"], FAST, keep=True)
    kinematic = run_scenario(scenario, settings, SimParams(), 0, "lanes", keep=True)
    return scenario, run, kinematic


def test_a_closed_loop_run_reaches_its_goals(lanes):
    scenario, run, _ = lanes
    m, r = run.metrics, run.rollout
    assert m.success and m.reached == 2 and r.outcomes == (DroneOutcome.REACHED,) * 2
    assert np.all(abs(r.positions[-1] - scenario.goals) < 0.1)
    # the planning ticks are every tenth truth sample; the hold tail follows the last tick
    ticks = r.positions.shape[0] - 1
    assert r.truth.shape[0] == ticks * 10 + 1 + round(FAST.hold_tail_s / STEP_S)
    assert np.array_equal(r.truth[: ticks * 10 + 1 : 10], r.positions)
    assert r.setpoints.shape == (ticks, 2) and r.velocity.shape == r.positions.shape


def test_the_drones_trail_their_setpoints_by_the_model_lag(lanes):
    """The setpoint in effect leads the true position by 0.55 s x the speed while cruising; the kinematic drone
    has no lag at all, so it arrives sooner by at least that lag."""
    _, run, kinematic = lanes
    r = run.rollout
    in_effect = np.repeat(r.setpoints, 10, axis=0)  # each tick's setpoint holds for its ten 10 ms steps
    truth = r.truth[1 : in_effect.shape[0] + 1]
    cruise = slice(int(2.0 / STEP_S), int(5.0 / STEP_S))  # after the start, before the approach
    speed = (abs(np.diff(r.truth, axis=0)) / STEP_S)[cruise].mean(axis=0)
    assert speed == pytest.approx([0.5, 0.5], abs=0.02)
    lag_s = abs(in_effect - truth)[cruise].mean(axis=0) / speed
    assert lag_s == pytest.approx([MODEL_LAG_S, MODEL_LAG_S], abs=0.05)
    assert run.metrics.makespan_s >= kinematic.metrics.makespan_s + MODEL_LAG_S


def test_scenes_flown_together_fly_as_each_alone():
    """Drones of different scenes in one swarm never interact: a scene's run is the same alone or with others."""
    a = make_scenario("a", np.array([0, 1j]), np.array([1.5j, 1.5]), arena_x=(-1, 3), arena_y=(-1, 3))
    b = make_scenario("b", np.array([1.5, 1.5 + 1.5j]), np.array([0.2j, 1.4j]), arena_x=(-1, 3), arena_y=(-1, 3))
    settings = planner_settings("orca")
    fast = replace(FAST, hold_tail_s=0.3)
    alone = run_firmware([b], settings, SimParams(time_limit_s=2.5), [1], ["b"], fast, keep=True)[0]
    both = run_firmware([a, b], settings, SimParams(time_limit_s=2.5), [0, 1], ["a", "b"], fast, keep=True)[1]
    assert np.array_equal(alone.rollout.truth, both.rollout.truth)
    assert alone.metrics == both.metrics


def test_collisions_and_separation_are_judged_between_the_ticks():
    """Two drones that cross between two planning ticks: the ticks see them 0.5 m apart, the 100 Hz truth sees
    the collision and the true smallest separation."""
    scenario = make_scenario("cross", np.array([-0.25 + 0j, 0.25 + 0j]), np.array([5 + 0j, -5 + 0j]))
    settings = planner_settings("apf")
    planner = make_planner(settings, scenario.obstacles)
    [r] = firmware_rollouts([scenario], [planner], SimParams(time_limit_s=0.0), [settings], FAST)  # the start only
    t = np.arange(11)[:, None] * STEP_S  # one tick interval at 100 Hz: the pair swaps sides at 5 m/s
    truth = np.hstack([-0.25 + 5 * t, 0.25 - 5 * t]) + 0j
    crossing = replace(r, truth=truth, positions=truth[::10], truth_dt=STEP_S)
    m = firmware_metrics(crossing, settings)
    assert abs(crossing.positions[:, 0] - crossing.positions[:, 1]).min() == pytest.approx(0.5)
    assert m.collisions_drone_drone == 1 and not m.success
    assert m.min_separation_m == pytest.approx(0.0, abs=1e-9)
    assert m.margin_breaches_drone_drone == 1
    assert all(row.collided for row in m.per_drone)
