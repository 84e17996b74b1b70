"""``rpf-fly scenario FILE --dry-run --json``: one simulated drone flies a dynamics scenario through cflib, the fake
radio, the NatNet emulator and extpos, and the trace comes out in the reference's trace format."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from rpf_fly.emulator.cf_scenario import Scenario, figures
from rpf_fly.flight.scenario_flight import plan_point, scenario_mission

pytestmark = pytest.mark.xdist_group("scenario")

DATA = Path(__file__).resolve().parents[1] / "data" / "crazyflie_dynamics" / "scenarios"


def run(tmp_path: Path, scenario: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "rpf_fly", "scenario", str(scenario), "--dry-run", "--json",
                           "--log", str(tmp_path / "scenario.mcap")], capture_output=True, text=True,
                          cwd=tmp_path, timeout=180)


def test_a_carrot_scenario_flies_through_the_stack_and_prints_its_trace(tmp_path):
    done = run(tmp_path, DATA / "c_carrot_0p5.yaml")
    assert done.returncode == 0, done.stderr
    trace = json.loads(done.stdout)
    assert trace["name"] == "c_carrot_0p5" and len(trace["t"]) == len(trace["sp"]) == len(trace["pos"])
    assert abs(trace["t"][1] - trace["t"][0] - 0.02) < 1e-6 and trace["t"][-1] > 7.9  # 50 Hz over 8 s
    scenario = Scenario.load(DATA / "c_carrot_0p5.yaml")
    assert trace["figures"]["lag_cm"] == pytest.approx(figures(trace, scenario)["lag_cm"])
    # the drone follows the carrot: it ends near 1.5 m (0.5 m/s for 3 s), having trailed it
    assert abs(trace["pos"][-1][0] - 1.5) < 0.1 and trace["figures"]["lag_cm"] > 5.0
    assert (tmp_path / "scenario.mcap").stat().st_size > 0


def test_a_command_scenario_traces_the_high_level_plan(tmp_path):
    done = run(tmp_path, DATA / "p_hl_slow.yaml")
    assert done.returncode == 0, done.stderr
    trace = json.loads(done.stdout)
    z = [p[2] for p in trace["pos"]]
    assert max(z) > 0.45 and z[-1] < 0.02  # took off, landed
    assert trace["sp"][0][2] == 0.0 and max(p[2] for p in trace["sp"]) == pytest.approx(0.5, abs=1e-6)
    assert trace["figures"]["touchdown_after_land_s"] is not None


def test_the_plan_is_the_firmwares_rest_to_rest_piece():
    assert plan_point((0, 0, 0), (1, 0, 0), 2.0, 1.0)[0] == pytest.approx(0.5)  # symmetric
    assert plan_point((0, 0, 0), (1, 0, 0), 2.0, 2.5)[0] == 1.0
    # peak speed 2.1875 x distance / duration at mid-time
    dt = 1e-5
    v = (plan_point((0, 0, 0), (1, 0, 0), 2.0, 1.0 + dt)[0] - plan_point((0, 0, 0), (1, 0, 0), 2.0, 1.0)[0]) / dt
    assert v == pytest.approx(2.1875 / 2.0, rel=1e-3)


def test_the_made_mission_holds_every_point_of_the_scenario():
    scenario = Scenario.load(DATA / "p_circle_r0p5_v0p3.yaml")
    mission = scenario_mission(scenario)
    xs = [p[1] for p in scenario.setpoints]
    assert mission.arena.x[0] < min(xs) and max(xs) < mission.arena.x[1]
    assert mission.flight.height == pytest.approx(scenario.start[2])
