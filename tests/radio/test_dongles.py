"""No Crazyradio on USB: ``check`` and ``fly`` of a real ``radio://`` mission say so in one line before any link is
tried (this machine has none, so the real lookup answers); the real connection path gives one reason, prefixed
once, and cflib's tracebacks go to the log file, not the screen."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from rpf_fly.emulator.simulated_mocap import SimulatedMocap
from rpf_fly.flight.loop import FlightLoop
from rpf_fly.log.text_log import route_logging
from rpf_fly.mission import load_mission
from rpf_fly.planning.factory import make_planner
from rpf_fly.radio.cflib_backend import CflibBackend
from rpf_fly.radio.dongles import NO_RADIO, find_radios, radio_problem
from rpf_fly.sim.scenario import obstacle_set

ROOT = Path(__file__).resolve().parents[2]

try:
    RADIOS = len(find_radios())
except Exception:  # noqa: BLE001 - no USB backend at all: the tests that need the real lookup are skipped
    RADIOS = -1
needs_no_radio = pytest.mark.skipif(RADIOS != 0, reason="needs a machine without a Crazyradio on USB")


def radio_mission(tmp_path: Path) -> Path:
    """missions/lab-3.yaml as a user would copy it: radio:// URIs, NatNet mocap on this machine."""
    text = (ROOT / "missions" / "lab-3.yaml").read_text().replace("server: 192.168.1.100", "server: 127.0.0.1")
    path = tmp_path / "lab.yaml"
    path.write_text(text)
    return path


@needs_no_radio
@pytest.mark.parametrize("command", [("check",), ("fly", "--no-console"), ("fly",)])
def test_no_crazyradio_is_one_line_exit_2_and_nothing_connects(tmp_path, command):
    mission = radio_mission(tmp_path)
    proc = subprocess.run(
        [sys.executable, "-m", "rpf_fly", *command, mission.name],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        timeout=60,
        env={**_env(), "HOME": str(tmp_path)},
    )
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr == NO_RADIO + "\n"
    if command[0] == "check":
        assert f"{mission.name}: valid mission 'lab-3' with 3 drones, planner rpf3 (" in proc.stdout
    else:
        assert proc.stdout == ""
    assert not (tmp_path / "flights").exists()  # no log: nothing was started


def test_radio_problem_counts_dongles_and_reads_serials_only_when_named():
    uris = ["radio://0/80/2M/E7E7E7E701", "radio://1/90/2M/E7E7E7E702"]
    assert radio_problem(["fake://0/80/2M/E7E7E7E701"], find=lambda: []) is None  # no radio: no lookup
    assert radio_problem(uris, find=lambda: []) == NO_RADIO
    assert radio_problem(uris, find=lambda: ["A"]).startswith("radio://1/90/2M/E7E7E7E702 needs Crazyradio number 1")
    assert radio_problem(uris, find=lambda: ["A", "B"]) is None
    assert radio_problem(["radio://ABCDEF1234/80/2M/E7E7E7E701"], find=lambda: ["abcdef1234"]) is None
    assert "no Crazyradio with serial 0000000001" in radio_problem(
        ["radio://0000000001/80/2M/E7E7E7E701"], find=lambda: ["ABCDEF1234"]
    )

    def no_usb():
        raise OSError("No backend available")

    problem = radio_problem(uris, find=no_usb)
    assert problem.startswith("cannot look for a Crazyradio on USB (OSError: No backend available)")
    assert "\n" not in problem


@needs_no_radio
def test_a_failed_link_gives_one_reason_and_its_traceback_goes_to_the_log_file(tmp_path, capfd):
    mission = load_mission(radio_mission(tmp_path))
    obstacles = obstacle_set(mission.obstacles)
    mocap = SimulatedMocap(lambda: {}, rate_hz=100.0)
    backend = CflibBackend(cache_dir=tmp_path / "toc")
    loop = FlightLoop(mission, backend, mocap, lambda drone: make_planner(mission.planner, obstacles))
    with route_logging(tmp_path / "check.log") as logs:
        problems = loop.preflight_only()  # the real cflib radio driver, no dongle: every link fails
    mocap.close()
    assert set(problems) == {"cf1", "cf2", "cf3"}
    for problem in problems.values():
        assert problem == "connection failed: Couldn't load link driver: Cannot find a Crazyradio Dongle"
    captured = capfd.readouterr()
    assert "Traceback" not in captured.err and "Crazyradio" not in captured.err
    text = (tmp_path / "check.log").read_text()
    assert text.count("Traceback") >= 3 and "cflib.crazyflie" in text and logs.warnings >= 3


def test_verbose_routing_also_prints_on_stderr(tmp_path, capfd):
    import logging

    before = list(logging.getLogger().handlers)
    with route_logging(tmp_path / "x.log", verbose=True):
        logging.getLogger("cflib.crazyflie").error("link driver trouble")
    with route_logging(tmp_path / "y.log"):
        logging.getLogger("cflib.crazyflie").error("quiet trouble")
    err = capfd.readouterr().err
    assert "link driver trouble" in err and "quiet trouble" not in err
    assert "quiet trouble" in (tmp_path / "y.log").read_text()
    assert logging.getLogger().handlers == before  # the routing is removed again


def _env() -> dict[str, str]:
    import os

    return dict(os.environ)
