"""``rpf-fly fly --dry-run`` as a process: Ctrl-C lands everyone and closes the log; SIGKILL leaves a salvageable log."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from flight_harness import SHORT_MISSION
from mcap.reader import make_reader

from rpf_fly.log.reader import read_log, salvage


def start_flight(tmp_path: Path) -> tuple[subprocess.Popen, Path]:
    mission = tmp_path / "short.yaml"
    mission.write_text(SHORT_MISSION.replace("timeout_s: 30", "timeout_s: 60").replace("goal: [1.0,", "goal: [1.5,"))
    log = tmp_path / "flight.mcap"
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    proc = subprocess.Popen(
        [sys.executable, "-m", "rpf_fly", "fly", str(mission), "--dry-run", "--no-console", "--log", str(log)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=tmp_path,
    )
    return proc, log


def wait_until_flying(proc: subprocess.Popen, timeout_s: float = 60.0) -> list[str]:
    lines: list[str] = []
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        line = proc.stderr.readline()
        if not line:
            break
        lines.append(line)
        if "swarm: flying" in line:
            return lines
    raise AssertionError("the flight never started:\n" + "".join(lines))


def test_sigint_lands_every_drone_and_closes_the_log(tmp_path):
    proc, log = start_flight(tmp_path)
    wait_until_flying(proc)
    time.sleep(1.0)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    data = read_log(log)
    assert not data.truncated  # finished file: summary and footer written
    with open(log, "rb") as f:
        assert make_reader(f).get_summary().statistics.message_count == data.message_count
    messages = [m.data["message"] for m in data.messages("/events")]
    assert any("interrupted" in m for m in messages)
    for name in ("cf1", "cf2", "cf3"):
        final = data.messages(f"/{name}/status")[-1].data
        assert final["state"] == "landed" and final["outcome"] == "landed_early"
        assert data.messages(f"/mocap/{name}")[-1].data["pose"]["position"]["z"] < 0.05  # on the floor
    assert "landed_early" in out


def test_sigkill_leaves_a_salvageable_log(tmp_path):
    proc, log = start_flight(tmp_path)
    wait_until_flying(proc)
    time.sleep(2.5)
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=10)
    data = read_log(log)
    assert data.truncated
    poses = data.messages("/mocap/cf1")
    assert len(poses) > 100  # the complete chunks: everything up to about a second before the kill
    sequences = [m.sequence for m in poses]
    assert sequences == list(range(sequences[0], sequences[0] + len(sequences)))
    assert data.metadata["mission"]["name"] == "short-3"
    fixed = tmp_path / "salvaged.mcap"
    result = salvage(log, fixed)
    with open(fixed, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary.statistics.message_count == data.message_count
    assert read_log(fixed).messages("/mocap/cf1")[-1].sequence == sequences[-1]
    assert result is not None


def test_sigint_twice_stops_every_motor_and_closes_the_log(tmp_path):
    """The second Ctrl-C cuts every motor at once (sent by the safety thread: the handler only sets flags)."""
    proc, log = start_flight(tmp_path)
    wait_until_flying(proc)
    time.sleep(1.0)
    proc.send_signal(signal.SIGINT)
    time.sleep(0.2)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert "Traceback" not in err
    data = read_log(log)
    assert not data.truncated
    messages = [m.data["message"] for m in data.messages("/events")]
    assert any("second Ctrl-C: emergency stop" in m for m in messages)
    for name in ("cf1", "cf2", "cf3"):
        final = data.messages(f"/{name}/status")[-1].data
        assert final["state"] == "emergency" and final["outcome"] == "emergency"
    assert "emergency" in out


def run_cli(tmp_path: Path, *args: str, mission_text: str) -> subprocess.CompletedProcess:
    mission = tmp_path / "m.yaml"
    mission.write_text(mission_text)
    return subprocess.run([sys.executable, "-m", "rpf_fly", *args, str(mission)], capture_output=True, text=True,
                          cwd=tmp_path, timeout=60)


NATNET_MISSION = SHORT_MISSION.replace("mocap: {kind: sim, rate_hz: 100}", "mocap: {kind: natnet, server: SERVER}")


def test_an_unresolvable_mocap_server_is_one_line_and_exit_2(tmp_path):
    for command in (("check",), ("fly", "--no-console")):
        done = run_cli(tmp_path, *command, mission_text=NATNET_MISSION.replace("SERVER", "no-such-host.invalid"))
        assert done.returncode == 2, (command, done.stderr)
        lines = done.stderr.strip().splitlines()
        assert len(lines) == 1 and "Traceback" not in done.stderr, done.stderr
        assert lines[0].startswith(f"{tmp_path / 'm.yaml'}:") and "mocap.server: cannot resolve" in lines[0]


def test_a_malformed_mocap_server_is_refused_at_validation(tmp_path):
    for server in ("192.168.1.1000", "192.168.1"):
        done = run_cli(tmp_path, "check", mission_text=NATNET_MISSION.replace("SERVER", server))
        assert done.returncode == 2 and "Traceback" not in done.stderr
        assert "mocap.server: expected a host name or IP address" in done.stderr and done.stdout == ""
