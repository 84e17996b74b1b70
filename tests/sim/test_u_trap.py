"""The U-trap test scene (missions/u-trap.yaml): the fixed-gains APF escapes it with guidance and not without,
and with guidance and the margin it keeps 2r + margin and r + margin."""

from pathlib import Path

import pytest

from rpf_fly.mission import load_mission
from rpf_fly.mission.load import with_planner
from rpf_fly.sim.evaluate import run_scenario, sim_params
from rpf_fly.sim.scenario import scenario_from_mission

MISSION = Path(__file__).resolve().parents[2] / "missions" / "u-trap.yaml"


def run(guidance: str):  # type: ignore[no-untyped-def]
    mission = with_planner(load_mission(MISSION), "apf", guidance=guidance)
    return mission, run_scenario(
        scenario_from_mission(mission, 0), mission.planner, sim_params(mission), 0, "u-trap"
    ).metrics


def test_apf_stalls_in_the_u_without_guidance():
    _, metrics = run("none")
    assert not metrics.success and metrics.reached < metrics.drones


def test_apf_escapes_the_u_with_guidance_and_keeps_the_margin():
    mission, metrics = run("path")
    r, m = mission.planner.safety_radius, mission.planner.margin_m
    assert m == pytest.approx(0.05)  # the product planner's default
    assert metrics.success
    assert metrics.min_separation_m >= 2 * r + m
    assert metrics.min_obstacle_clearance_m >= r + m
