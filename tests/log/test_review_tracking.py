"""``rpf-fly review`` says what setpoint tracking error to expect at the flown speed (a drone trails a moving
setpoint by its lag x the speed) and flags a drone outside it."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from rpf_fly.cli import get_app
from rpf_fly.log.reader import read_log
from rpf_fly.log.review import review
from rpf_fly.log.review_tracking import CRAZYFLIE_LAG_S, DRY_RUN_LAG_S
from rpf_fly.log.writer import FlightLog

T0 = 1_700_000_000_000_000_000
MS = 1_000_000
SPEED = 0.5


def carrot_log(path, source: str, behind: dict[str, float], yaml: str = "name: carrot\n"):  # type: ignore[no-untyped-def]
    """Each drone's setpoint moves along x at 0.5 m/s for 6 s (10 Hz) from a 1 s hover; the drone (mocap at 100 Hz)
    is ``behind[drone]`` metres behind it once moving (the lag building up over the first second)."""
    mission = {"name": "carrot", "yaml": yaml, "seed": 0, "source": source, "planner": "apf"}
    scenario = {
        "json": json.dumps(
            {
                "names": list(behind),
                "goals": [[3.0, float(i)] for i in range(len(behind))],
                "obstacles": [],
                "dt": 0.1,
                "goal_tolerance": 0.1,
                "safety_radius": 0.1,
            }
        )
    }

    def setpoint_x(t: float) -> float:
        return max(0.0, t - 1.0) * SPEED

    def lag(t: float, full: float) -> float:
        return full * min(1.0, max(0.0, t - 1.0))

    with FlightLog(path, mission, scenario, clock=None) as log:
        for k in range(700):
            t = k * 0.01
            for i, (drone, full) in enumerate(behind.items()):
                log.pose(drone, T0 + k * 10 * MS, (setpoint_x(t) - lag(t, full), float(i), 0.6))
                if k % 10 == 0:
                    x = setpoint_x(t) - lag(t, full)
                    log.setpoint(drone, T0 + k * 10 * MS, (setpoint_x(t), float(i), 0.6))
                    log.planner_step(
                        drone,
                        T0 + k * 10 * MS,
                        tick=k // 10,
                        position=(x, float(i), 0.6),
                        goal=complex(3.0, i),
                        mode="apf",
                        eta=0.05,
                        lam=2.0,
                        f_a=1 + 0j,
                        f_r=0j,
                        f_in=0j,
                        direction=1 + 0j,
                        heading=0.0,
                        neighbours=1,
                        obstacle_distance=1.0,
                    )
    return path


def test_a_crazyflie_trailing_by_its_lag_is_as_expected_and_one_trailing_far_more_is_flagged(tmp_path):
    expected = CRAZYFLIE_LAG_S * SPEED  # 0.275 m
    path = carrot_log(tmp_path / "flight.mcap", "flight", {"cf1": 0.28, "cf2": 0.6})
    result = review(read_log(path))
    cf1, cf2 = result.tracking_expected["cf1"], result.tracking_expected["cf2"]
    assert cf1.lag_s == CRAZYFLIE_LAG_S and cf1.speed_m_s == pytest.approx(SPEED, abs=0.01)
    assert cf1.expected_m == pytest.approx(expected, abs=0.01)
    assert cf1.measured_m == pytest.approx(0.28, abs=0.005) and not cf1.outside
    assert cf2.measured_m == pytest.approx(0.6, abs=0.01) and cf2.outside

    text = CliRunner().invoke(get_app(), ["review", str(path)])
    assert text.exit_code == 0, text.output
    lines = text.stdout.splitlines()
    said = next(line for line in lines if line.startswith("expected while cruising"))
    assert said == (
        "expected while cruising: Crazyflies with the firmware's default gains trail a moving setpoint "
        "by about 0.55 s x its speed: 0.28 m at the flown 0.50 m/s; measured (median) cf1 0.28, cf2 0.60 m"
    )
    flagged = [line.strip() for line in lines if "outside the expected" in line]
    assert flagged == [
        "cf2: 0.60 m from its setpoint while cruising at 0.50 m/s, outside the expected 0.19-0.36 m "
        "(pushed: a gust, a contact; late poses; other gains than expected)"
    ]

    doc = json.loads(CliRunner().invoke(get_app(), ["review", str(path), "--json"]).stdout)
    assert doc["tracking_expected"]["lag_s"] == CRAZYFLIE_LAG_S
    assert doc["tracking_expected"]["per_drone"]["cf1"]["outside"] is False
    assert doc["tracking_expected"]["per_drone"]["cf2"]["outside"] is True
    assert doc["tracking_expected"]["per_drone"]["cf2"]["measured_m"] == pytest.approx(0.6, abs=0.01)


def test_a_dry_run_is_judged_against_its_simulated_drones_lag(tmp_path):
    """The dry run's drones trail by 0.25 s x speed: one trailing as a default-gain Crazyflie would is outside."""
    path = carrot_log(tmp_path / "dry.mcap", "dry-run", {"cf1": DRY_RUN_LAG_S * SPEED, "cf2": CRAZYFLIE_LAG_S * SPEED})
    result = review(read_log(path))
    assert not result.tracking_expected["cf1"].outside and result.tracking_expected["cf2"].outside
    text = CliRunner().invoke(get_app(), ["review", str(path)]).stdout
    assert (
        "expected while cruising: the dry run's simulated drones trail a moving setpoint by about 0.25 s x its "
        "speed (a Crazyflie with the firmware's default gains: about 0.55 s): 0.12 m at the flown 0.50 m/s"
    ) in " ".join(text.split())


def test_the_dry_run_lag_is_the_simulated_drones():
    from rpf_fly.emulator.vehicle_figures import TRACK_TAU_S

    assert DRY_RUN_LAG_S == TRACK_TAU_S  # a first-order follower trails a moving setpoint by tau x speed


def test_the_simulated_drones_logs_are_judged_on_their_lag():
    from rpf_fly.log.review_tracking import tracking_lag

    assert tracking_lag("dry-run")[0] == tracking_lag("lab")[0] == DRY_RUN_LAG_S
    assert tracking_lag("flight")[0] == tracking_lag("")[0] == CRAZYFLIE_LAG_S


def test_a_dry_run_whose_drones_fly_the_firmwares_cascade_is_judged_as_crazyflies(tmp_path):
    """``dry_run: {dynamics: firmware}`` in the logged mission: the simulated drones trail as a default-gain
    Crazyflie."""
    from rpf_fly.log.review_tracking import dry_run_dynamics, logged_dynamics, tracking_lag

    assert dry_run_dynamics("name: m\ndry_run: {dynamics: firmware}\n") == "firmware"
    assert dry_run_dynamics("name: m\n") == dry_run_dynamics("{not yaml") == ""
    assert tracking_lag("dry-run", "firmware")[0] == CRAZYFLIE_LAG_S
    assert tracking_lag("dry-run", "first-order")[0] == DRY_RUN_LAG_S
    assert logged_dynamics({"dynamics": "firmware", "yaml": "name: m\n"}) == "firmware"  # the record says it
    assert logged_dynamics({"yaml": "name: m\ndry_run: {dynamics: firmware}\n"}) == "firmware"
    assert logged_dynamics({"yaml": "name: m\n"}) == "first-order"  # written before the record said it
    path = carrot_log(
        tmp_path / "cascade.mcap",
        "dry-run",
        {"cf1": CRAZYFLIE_LAG_S * SPEED},
        yaml="name: carrot\ndry_run: {dynamics: firmware}\n",
    )
    result = review(read_log(path))
    assert result.tracking_lag[0] == CRAZYFLIE_LAG_S and not result.tracking_expected["cf1"].outside


def test_a_dry_runs_log_says_which_model_its_drones_flew():
    """The ``mission`` record of a dry run or a lab names the model (``dynamics``), whatever the mission's text
    says or leaves to the default; a flight's says none."""
    from rpf_fly.log.metadata import mission_metadata
    from rpf_fly.mission.load import parse_mission

    mission = parse_mission(
        "name: m\narena: {x: [-2, 2], y: [-2, 2], z: [0, 1.5]}\nplanner: {kind: apf}\nmocap: {kind: sim}\n"
        "drones:\n  - {name: cf1, uri: radio://0/80/2M/E7E7E7E701, start: [-1, 0], goal: [1, 0]}\n"
    )
    assert mission_metadata(mission, source="dry-run")["dynamics"] == "firmware"  # the mission's default
    assert mission_metadata(mission, source="lab", dynamics="firmware")["dynamics"] == "firmware"
    assert mission_metadata(mission, source="dry-run", dynamics="first_order")["dynamics"] == "first-order"
    assert "dynamics" not in mission_metadata(mission, source="flight")
