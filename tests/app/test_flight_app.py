"""The application layer on its own, without the CLI: a refused request is a :class:`UserError` carrying the line
and the exit code the commands print, the checks come in the commands' order, and a flight's Ctrl-C handlers are
put back when it ends. Nothing here connects or flies."""

from __future__ import annotations

import signal
from pathlib import Path

import pytest

from rpf_fly.app.errors import UserError
from rpf_fly.app.flight import FlightApp, FlightRequest
from rpf_fly.app.scenario import ScenarioRequest, prepare_scenario
from rpf_fly.app.signals import LoopSignals
from rpf_fly.app.worker import WorkerRequest

MISSION = """\
name: app-2
arena: {x: [-2.0, 2.0], y: [-2.0, 2.0], z: [0.0, 1.5]}
flight: {height: 0.5, speed: 0.5, rate_hz: 10, goal_tolerance: 0.1, takeoff_s: 1.0, land_s: 1.0, timeout_s: 30}
planner: {kind: apf}
mocap: {kind: sim, rate_hz: 100}
drones:
  - {name: cf1, uri: radio://0/80/2M/E7E7E7E701, start: [-1.0, -0.3], goal: [1.0, -0.3]}
  - {name: cf2, uri: radio://0/80/2M/E7E7E7E702, start: [-1.0, 0.3], goal: [1.0, 0.3]}
"""


@pytest.fixture
def mission(tmp_path: Path) -> Path:
    path = tmp_path / "app-2.yaml"
    path.write_text(MISSION)
    return path


def refused(call) -> UserError:  # type: ignore[no-untyped-def]
    with pytest.raises(UserError) as caught:
        call()
    return caught.value


def test_an_invalid_mission_is_one_line_naming_its_file_and_line(tmp_path: Path):
    path = tmp_path / "bad.yaml"
    path.write_text(MISSION.replace("planner: {kind: apf}", "planner: {kind: nope}"))
    err = refused(lambda: FlightApp(path))
    assert err.code == 2
    assert str(err).startswith(f"{path}:4: planner.kind: ") and "\n" not in str(err)


@pytest.mark.parametrize(
    "request_, line",
    [
        (
            FlightRequest(lab=True, dry_run=True),
            "--lab and --dry-run: choose one (--lab flies a running lab's drones, --dry-run private ones)",
        ),
        (FlightRequest(remote_dongles="1"), "--remote-dongles and --listen go with --distributed"),
        (FlightRequest(dry_run=True, mocap="vicon"), "--mocap: expected natnet, motioncapture or sim, got 'vicon'"),
        (
            FlightRequest(dry_run=True, distributed=True, live=True),
            "--distributed flies without --foxglove or --mocap sim (docs/distributed.md)",
        ),
        (
            FlightRequest(dry_run=True, distributed=True, listen=("nowhere",)),
            "--listen: expected a Zenoh endpoint such as tcp/127.0.0.1:7447, got 'nowhere'",
        ),
    ],
)
def test_fly_refuses_what_the_command_refuses(mission: Path, tmp_path: Path, request_: FlightRequest, line: str):
    request_ = FlightRequest(**{**request_.__dict__, "log": tmp_path / "f.mcap"})
    err = refused(lambda: FlightApp(mission).prepare_flight(request_))
    assert (str(err), err.code) == (line, 2)


def test_a_real_flight_of_a_simulated_mocap_is_refused_at_its_field(mission: Path):
    err = refused(lambda: FlightApp(mission).prepare_flight(FlightRequest()))
    assert str(err) == f"{mission}:5: mocap.kind: 'sim' can only fly with --dry-run (real drones need motion capture)"


def test_faults_without_a_dry_run_are_refused_before_the_schedule_is_read(mission: Path, tmp_path: Path):
    faults = tmp_path / "missing.yaml"
    err = refused(lambda: FlightApp(mission).prepare_flight(FlightRequest(faults=faults)))
    assert str(err) == f"--faults: {faults}: faults are injected into simulated drones only; add --dry-run"


def test_a_dry_run_past_its_checks_is_ready_to_fly(mission: Path, tmp_path: Path):
    flight = FlightApp(mission).prepare_flight(FlightRequest(dry_run=True, log=tmp_path / "logs" / "f.mcap"))
    assert (flight.dry_run, flight.mocap, flight.distributed, flight.lab) == (True, "natnet", False, None)
    assert (tmp_path / "logs").is_dir() and not (tmp_path / "logs" / "f.mcap").exists()
    assert {type(flight.factory(d)).__name__ for d in flight.mission.drones} == {"Planner"}
    assert flight.factory(flight.mission.drones[0]) is not flight.factory(flight.mission.drones[0])


def test_an_unwritable_log_is_refused_before_anything_connects(mission: Path, tmp_path: Path):
    blocker = tmp_path / "file"
    blocker.write_text("")
    err = refused(lambda: FlightApp(mission).prepare_flight(FlightRequest(dry_run=True, log=blocker / "f.mcap")))
    assert str(err).startswith(f"--log {blocker / 'f.mcap'}: cannot make its folder: ")


def test_a_worker_without_the_flights_secret_is_refused(mission: Path):
    request = WorkerRequest(dongle=0, dry_run=True, environ={})
    err = refused(lambda: FlightApp(mission).prepare_worker(request))
    assert str(err).startswith("RPF_FLY_SECRET: the flight's secret is missing")
    worker = FlightApp(mission).prepare_worker(
        WorkerRequest(dongle=0, dry_run=True, flight="f1", environ={"RPF_FLY_SECRET": "s" * 32})
    )
    assert worker.text_log == Path("rpf-fly-worker-f1-dongle-0.log")


def test_a_scenario_for_a_real_drone_needs_its_mission(tmp_path: Path):
    missing = tmp_path / "nope.yaml"
    assert str(refused(lambda: prepare_scenario(ScenarioRequest(missing, dry_run=True)))) == f"{missing}: no such file"
    assert (
        str(refused(lambda: prepare_scenario(ScenarioRequest(missing, dry_run=True, lab=True))))
        == "--dry-run and --lab: choose one"
    )


class Loop:
    def __init__(self) -> None:
        self.calls: list[tuple[str, tuple]] = []

    def request_stop(self, *args: str) -> None:
        self.calls.append(("stop", args))

    def emergency_stop(self, reason: str) -> None:
        self.calls.append(("emergency", (reason,)))


def test_the_first_ctrl_c_lands_the_second_stops_the_motors_and_the_handlers_come_back():
    before = signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)
    signals = LoopSignals("this worker's drones")
    signals.install()
    try:
        signals.attach(loop := Loop())
        signal.raise_signal(signal.SIGINT)
        signal.raise_signal(signal.SIGINT)
    finally:
        signals.restore()
    assert (signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)) == before
    assert loop.calls[0][0] == "stop" and "this worker's drones" in loop.calls[0][1][1]
    assert loop.calls[1] == ("emergency", ("second Ctrl-C: emergency stop, motors off",))
    signals = LoopSignals()
    signals.install()
    try:
        signals.attach(loop := Loop())
        signal.raise_signal(signal.SIGTERM)
        signal.raise_signal(signal.SIGTERM)
    finally:
        signals.restore()
    assert loop.calls == [("stop", ("interrupted by SIGTERM", "SIGTERM: all drones land"))] * 2
