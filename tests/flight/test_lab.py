"""``rpf-fly lab``: simulated drones that outlive their ground stations, as real ones do. ``check --lab`` then
``fly --lab`` fly every drone, also after a plain cflib program latched one; a ground station SIGKILLed during the
take-off, the planning or the landing leaves no drone flying on (the firmware's emergency-stop watchdog), judged on
the lab's own log."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import jsonschema
import pytest
from lab_harness import LabProcess
from mcap.reader import make_reader

from rpf_fly.flight.lab import after_ground_station, reach_after_death_m
from rpf_fly.log.reader import read_log
from rpf_fly.mission import parse_mission

pytestmark = pytest.mark.xdist_group("lab")

LAB_3 = """\
name: lab-short-3
arena: {x: [-2.0, 2.0], y: [-2.0, 2.0], z: [0.0, 1.5]}
flight: {height: 0.5, speed: 0.5, rate_hz: 10, goal_tolerance: 0.1, takeoff_s: 1.5, land_s: 1.5, timeout_s: 40}
planner: {kind: apf, margin: 0}
mocap: {kind: natnet, server: 127.0.0.1, rate_hz: 100}
drones:
  - {name: cf1, uri: radio://0/80/2M/E7E7E7E701, start: [-1.0, -0.6], goal: [1.0, -0.6]}
  - {name: cf2, uri: radio://0/80/2M/E7E7E7E702, start: [-1.0, 0.0], goal: [1.0, 0.0]}
  - {name: cf3, uri: radio://0/80/2M/E7E7E7E703, start: [-1.0, 0.6], goal: [1.0, 0.6]}
"""

SIX = """\
name: lab-six
arena: {x: [-3.0, 3.0], y: [-3.0, 3.0], z: [0.0, 2.0]}
flight: {height: 0.6, speed: 0.5, rate_hz: 10, goal_tolerance: 0.1, takeoff_s: 2.0, land_s: 2.0, timeout_s: 40}
planner: {kind: apf, margin: 0}
mocap: {kind: natnet, server: 127.0.0.1, rate_hz: 100}
radio: {extpos_rate_hz: 20}  # six drones' extpos at 30 Hz: over one Crazyradio PA's budget (docs/radio.md)
drones:
  - {name: cf1, uri: radio://0/80/2M/E7E7E7E701, start: [-1.5, -1.0], goal: [1.5, -1.0]}
  - {name: cf2, uri: radio://0/80/2M/E7E7E7E702, start: [-1.5, 0.0], goal: [1.5, 0.0]}
  - {name: cf3, uri: radio://0/80/2M/E7E7E7E703, start: [-1.5, 1.0], goal: [1.5, 1.0]}
  - {name: cf4, uri: radio://0/80/2M/E7E7E7E704, start: [1.5, -0.5], goal: [-1.5, -0.5]}
  - {name: cf5, uri: radio://0/80/2M/E7E7E7E705, start: [1.5, 0.5], goal: [-1.5, 0.5]}
  - {name: cf6, uri: radio://0/80/2M/E7E7E7E706, start: [1.5, 1.5], goal: [-1.5, 1.5]}
"""

LATCH = """\
import sys, time
import cflib.crtp
from cflib.crazyflie import Crazyflie
from cflib.crazyflie.syncCrazyflie import SyncCrazyflie
from rpf_fly.emulator import fake_radio
from rpf_fly.flight.lab import lab_world

fake_radio.register(lab_world())
cflib.crtp.init_drivers()
with SyncCrazyflie(sys.argv[1], cf=Crazyflie(rw_cache=sys.argv[2])) as scf:
    scf.cf.commander.send_setpoint(0, 0, 0, 0)
    time.sleep(0.2)
"""


def test_check_then_fly_against_one_lab_flies_every_drone_also_one_latched_by_a_cflib_program(tmp_path):
    mission = tmp_path / "lab-short-3.yaml"
    mission.write_text(LAB_3)
    lab = LabProcess(tmp_path, mission)
    try:
        script = tmp_path / "latch.py"
        script.write_text(LATCH)
        latch = subprocess.run(
            [sys.executable, str(script), "fake://0/80/2M/E7E7E7E702", str(tmp_path / "toc")],
            capture_output=True,
            text=True,
            env=lab.env,
            timeout=60,
        )
        assert latch.returncode == 0, latch.stderr
        check = lab.run("check", str(mission), "--lab")
        assert check.returncode == 0, check.stdout + check.stderr
        assert "cf2: ok" in check.stdout
        fly = lab.run("fly", str(mission), "--lab", "--no-console", "--log", str(tmp_path / "flight.mcap"))
        assert fly.returncode == 0, fly.stdout + fly.stderr
        for name in ("cf1", "cf2", "cf3"):
            assert f"{name}: reached" in fly.stdout, fly.stdout
    finally:
        out = lab.stop()
    assert "lab stopped (SIGTERM)" in out
    data = read_log(lab.log)
    assert not data.truncated
    for name in ("cf1", "cf2", "cf3"):
        truth = data.messages(f"/truth/{name}")
        span_s = (truth[-1].log_time - truth[0].log_time) / 1e9
        assert len(truth) / span_s >= 50.0, (name, len(truth), span_s)
        assert max(m.data["position"]["z"] for m in truth) > 0.4  # it flew
        final = truth[-1].data["position"]
        assert abs(final["x"] - 1.0) < 0.2 and final["z"] < 0.05  # and landed at its goal
        firmware = data.messages(f"/firmware/{name}")
        assert len(firmware) / span_s >= 5.0, name
        assert "Flying" in {m.data["supervisor"] for m in firmware}, name
        commanders = {m.data["commander"] for m in firmware}
        assert "high-level" in commanders and any(c.startswith("crtp") for c in commanders), commanders
    events = [m.data["message"] for m in data.messages("/events")]
    # the latch program, check and fly: three ground stations, each closed its connection
    assert sum("connected" in e for e in events) >= 2, events
    assert any("closed its connection" in e for e in events), events
    with open(lab.log, "rb") as f:  # every message validates against the schema in the file
        validators: dict = {}
        for schema, _channel, message in make_reader(f).iter_messages():
            if schema.id not in validators:
                validators[schema.id] = jsonschema.Draft7Validator(json.loads(schema.data))
            validators[schema.id].validate(json.loads(message.data))


def _kill_when(proc: subprocess.Popen, line: str, delay_s: float) -> int:
    """Wait for ``line`` on the flight's stderr, then ``delay_s``, then SIGKILL it; the kill's time (Unix ns)."""
    deadline = time.monotonic() + 90
    seen = []
    while time.monotonic() < deadline:
        text = proc.stderr.readline()  # type: ignore[union-attr]
        assert text, f"the flight ended before {line!r}: {''.join(seen)}"
        seen.append(text)
        if line in text:
            break
    time.sleep(delay_s)
    killed = time.time_ns()
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=10)
    return killed


@pytest.mark.parametrize(
    "phase, line, delay_s",
    [
        ("takeoff", "take-off commanded", 1.5),  # the cascade lifts off late: 1.0 s in it is on the floor
        ("planning", "swarm: flying", 2.0),
        ("landing", "swarm: landing", 0.7),
    ],
)
def test_a_ground_station_killed_leaves_no_drone_flying_on(tmp_path, phase, line, delay_s):
    """SIGKILL of ``fly --lab``: within 1.5 s every drone's motors are off or it is on the floor, none moved further
    after the kill than the firmware lets it (to its last setpoint, levelled out, falling: `reach_after_death_m`,
    1.08 m for this mission at 0.66 m), and none is above the floor with motors on 5 s after (the lab's truth)."""
    mission = tmp_path / "six.yaml"
    text = SIX if phase != "landing" else SIX.replace("timeout_s: 40", "timeout_s: 3")
    mission.write_text(text)
    lab = LabProcess(tmp_path, mission)
    try:
        flight = lab.start("fly", str(mission), "--lab", "--no-console", "--log", str(tmp_path / "flight.mcap"))
        killed = _kill_when(flight, line, delay_s)
        time.sleep(6.0)
    finally:
        lab.stop()
    data = read_log(lab.log)
    judged = after_ground_station({f"cf{i}": data.messages(f"/truth/cf{i}") for i in range(1, 7)}, killed)
    assert any(d.motors_at_death and d.z_at_death > 0.05 for d in judged.values()), judged  # they were flying
    for name, d in judged.items():
        assert d.down_after_s is not None and d.down_after_s <= 1.5, (name, d)
        assert d.moved_m <= reach_after_death_m(parse_mission(text), d.z_at_death), (name, d)
        assert not d.flying_at_s[5.0], (name, d)


def test_a_lab_whose_host_stops_it_says_so_in_its_log_and_last_line(tmp_path):
    """The lab's process not scheduled for 0.6 s (SIGSTOP: what a starved host does to it, longer): its world steps
    and mocap frames run late, the lab's log says how long on /lab/host and as an event, and its last line says
    its verdicts are not evidence."""
    mission = tmp_path / "lab-short-3.yaml"
    mission.write_text(LAB_3)
    lab = LabProcess(tmp_path, mission)
    try:
        time.sleep(1.5)
        os.kill(lab.proc.pid, signal.SIGSTOP)
        time.sleep(0.6)
        os.kill(lab.proc.pid, signal.SIGCONT)
        time.sleep(1.5)
    finally:
        out = lab.stop()
    assert "the host could not keep up for" in out.strip().splitlines()[-1], out
    data = read_log(lab.log)
    host = [m.data for m in data.messages("/lab/host")]
    assert host[-1]["behind_s"] >= 0.5 and host[-1]["world"]["max_late_s"] >= 0.5, host[-1]
    assert host[0]["behind_s"] < 0.1, host[0]  # it kept up before
    events = [m.data["message"] for m in data.messages("/events")]
    assert any("could not keep up" in e and "not evidence" in e for e in events), events


def test_a_dry_run_whose_simulated_drones_were_starved_says_it_is_not_evidence(tmp_path):
    """The private world process of ``fly --dry-run`` stopped for 0.6 s mid-flight: the flight says so as it
    happens and in its last line, whatever its verdict."""
    from test_fly_signals import start_flight, wait_until_flying, world_process_of

    proc, _ = start_flight(tmp_path)
    world = world_process_of(proc.pid)
    before = "".join(wait_until_flying(proc))
    os.kill(world, signal.SIGSTOP)
    time.sleep(0.6)
    os.kill(world, signal.SIGCONT)
    out, err = proc.communicate(timeout=90)
    lines = out.strip().splitlines()
    assert lines and "the host could not keep up for" in lines[-1] and "not evidence" in lines[-1], out
    # said during the flight: at the stop, or already before it where a loaded host held the flight back then (the
    # watch says it again only a further second behind)
    assert "[host]" in before + err, before + err
