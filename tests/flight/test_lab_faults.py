"""The lab's fault kinds end to end (docs/faults.md): ``rpf-fly fly --lab --faults`` against ``rpf-fly lab``, judged
on the lab's own log. A ``ground_station_kill`` SIGKILLs the flight in its planning phase and no drone flies on (the
firmware's emergency-stop watchdog); a ``dongle_unplug`` fails one dongle's links while the flight lives on: those
drones are stopped the same way, the other dongle's reach their goals, and the flight exits 1."""

from __future__ import annotations

import signal
import subprocess
import time
from pathlib import Path

import pytest
from lab_harness import LabProcess

from rpf_fly.flight.lab import after_ground_station, reach_after_death_m
from rpf_fly.log.reader import read_log
from rpf_fly.mission import parse_mission

pytestmark = pytest.mark.xdist_group("lab")

FOUR = """\
name: lab-four
arena: {x: [-3.0, 3.0], y: [-3.0, 3.0], z: [0.0, 2.0]}
flight: {height: 0.6, speed: 0.5, rate_hz: 10, goal_tolerance: 0.1, takeoff_s: 1.5, land_s: 1.5, timeout_s: 40}
planner: {kind: apf, margin: 0}
mocap: {kind: natnet, server: 127.0.0.1, rate_hz: 100}
drones:
  - {name: cf1, uri: radio://0/80/2M/E7E7E7E701, start: [-1.5, -1.0], goal: [1.5, -1.0]}
  - {name: cf2, uri: radio://0/80/2M/E7E7E7E702, start: [-1.5, 0.0], goal: [1.5, 0.0]}
  - {name: cf3, uri: radio://1/80/2M/E7E7E7E703, start: [-1.5, 1.0], goal: [1.5, 1.0]}
  - {name: cf4, uri: radio://1/80/2M/E7E7E7E704, start: [1.5, -0.5], goal: [-1.5, -0.5]}
"""
NAMES = ("cf1", "cf2", "cf3", "cf4")


def _lab_and_flight(tmp_path: Path, faults: str) -> tuple[subprocess.CompletedProcess, int, Path]:
    """``rpf-fly lab`` with a lab file of its own, then ``fly --lab --faults`` against it; the lab stopped (SIGTERM)
    6 s after the fault. Returns the flight, when its fault line came on stderr (Unix ns), and the lab's log."""
    mission = tmp_path / "four.yaml"
    mission.write_text(FOUR)
    schedule = tmp_path / "faults.yaml"
    schedule.write_text(faults)
    lab = LabProcess(tmp_path, mission)
    try:
        flight = lab.start(
            "fly",
            str(mission),
            "--lab",
            "--faults",
            str(schedule),
            "--no-console",
            "--log",
            str(tmp_path / "flight.mcap"),
            stdout=subprocess.PIPE,
        )
        struck = None
        err = []
        for line in flight.stderr:  # type: ignore[union-attr]
            if struck is None and "[fault] injected" in line:
                struck = time.time_ns()
            err.append(line)
        out = flight.stdout.read()  # type: ignore[union-attr]
        code = flight.wait(timeout=120)
        assert struck is not None, "".join(err)
        time.sleep(max(0.0, (struck + 6e9 - time.time_ns()) / 1e9))
    finally:
        lab.stop()
    return subprocess.CompletedProcess(flight.args, code, out, "".join(err)), struck, lab.log


def test_a_ground_station_killed_in_its_planning_phase_leaves_no_drone_flying(tmp_path):
    flight, struck, lab_log = _lab_and_flight(
        tmp_path, "faults:\n  - {kind: ground_station_kill, at_phase: planning, at_s: 2.0}\n"
    )
    assert flight.returncode == -signal.SIGKILL, flight.stdout + flight.stderr
    assert "Traceback" not in flight.stderr
    before = flight.stderr.split("injected ground_station_kill")[0]
    assert "[phase] swarm: flying" in before and "swarm: landing" not in before  # it struck while planning
    assert "injected ground_station_kill at planning + 2 s" in flight.stderr
    assert flight.stdout == ""  # nothing after the kill ran: no summary
    data = read_log(lab_log)
    events = [m.data["message"] for m in data.messages("/events")]
    assert any("went away without closing" in e for e in events), events
    judged = after_ground_station({n: data.messages(f"/truth/{n}") for n in NAMES}, struck)
    assert all(d.motors_at_death and d.z_at_death > 0.4 for d in judged.values()), judged  # all were flying
    for name, d in judged.items():
        assert d.down_after_s is not None and d.down_after_s <= 1.5, (name, d)
        assert d.moved_m <= reach_after_death_m(parse_mission(FOUR), d.z_at_death), (name, d)
        assert not d.flying_at_s[5.0], (name, d)
    assert not any(m.data["crashed"] for n in NAMES for m in data.messages(f"/truth/{n}"))


def test_an_unplugged_dongles_drones_stop_and_the_others_fly_on_and_land(tmp_path):
    flight, struck, lab_log = _lab_and_flight(tmp_path, "faults:\n  - {kind: dongle_unplug, dongle: 1, at_s: 2.0}\n")
    assert flight.returncode == 1, flight.stdout + flight.stderr
    assert "Traceback" not in flight.stdout + flight.stderr
    for name in ("cf3", "cf4"):
        assert f"{name}: link_lost" in flight.stdout and "probably been unplugged" in flight.stdout
    for name in ("cf1", "cf2"):
        assert f"{name}: reached" in flight.stdout, flight.stdout
    data = read_log(lab_log)
    judged = after_ground_station({n: data.messages(f"/truth/{n}") for n in ("cf3", "cf4")}, struck)
    for name, d in judged.items():
        assert d.motors_at_death and d.z_at_death > 0.4, (name, d)
        assert d.down_after_s is not None and d.down_after_s <= 1.5, (name, d)
        assert d.moved_m <= reach_after_death_m(parse_mission(FOUR), d.z_at_death), (name, d)
        assert not d.flying_at_s[5.0], (name, d)
    for name in NAMES:
        truth = data.messages(f"/truth/{name}")
        assert not any(m.data["crashed"] for m in truth)
        assert not truth[-1].data["motors"] and truth[-1].data["position"]["z"] < 0.05
