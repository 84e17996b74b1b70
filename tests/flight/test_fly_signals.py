"""``rpf-fly fly --dry-run`` as a process: Ctrl-C lands everyone and closes the log; SIGKILL leaves a salvageable log
and the simulated drones fall by their firmware's watchdog, as real ones would; the simulated drones' process never
outlives the flight for long."""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from flight_harness import SHORT_MISSION
from mcap.reader import make_reader

from rpf_fly.emulator.world_orphan import ORPHAN_CAP_S
from rpf_fly.flight.dry_run import world_exit_report_for
from rpf_fly.log.reader import read_log, salvage

WORLD_MODULE = "rpf_fly.emulator.world_process"


def start_flight(
    tmp_path: Path, *, goal_x: float = 1.5, timeout_s: int = 60, stderr: Path | None = None
) -> tuple[subprocess.Popen, Path]:
    """``rpf-fly fly`` of the short mission (its goals at ``goal_x``) as a subprocess; stderr piped, or to a file."""
    mission = tmp_path / "short.yaml"
    mission.write_text(
        SHORT_MISSION.replace("timeout_s: 30", f"timeout_s: {timeout_s}").replace("goal: [1.0,", f"goal: [{goal_x},")
    )
    log = tmp_path / "flight.mcap"
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    err = open(stderr, "w") if stderr is not None else subprocess.PIPE  # noqa: SIM115 - the child owns it
    proc = subprocess.Popen(
        [sys.executable, "-m", "rpf_fly", "fly", str(mission), "--dry-run", "--no-console", "--log", str(log)],
        stdout=subprocess.PIPE if stderr is None else subprocess.DEVNULL,
        stderr=err,
        text=True,
        env=env,
        cwd=tmp_path,
    )
    if stderr is not None:
        err.close()  # type: ignore[union-attr]
    return proc, log


def world_process_of(parent: int, timeout_s: float = 30.0) -> int:
    """The pid of the simulated drones' process the flight ``parent`` started (from /proc, while it runs)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        for entry in Path("/proc").iterdir():
            if not entry.name.isdigit():
                continue
            try:
                stat = (entry / "stat").read_text()
                cmdline = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode()
            except OSError:
                continue
            if int(stat.rpartition(")")[2].split()[1]) == parent and WORLD_MODULE in cmdline:
                return int(entry.name)
        time.sleep(0.05)
    raise AssertionError(f"process {parent} started no {WORLD_MODULE}")


def alive(pid: int) -> bool:
    """True while ``pid`` runs (a zombie, dead but not yet reaped by whoever adopted it, counts as gone)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rpartition(")")[2].split()[0] != "Z"


def wait_gone(pid: int, timeout_s: float) -> float | None:
    """Seconds until ``pid`` is gone, None if it still runs after ``timeout_s``."""
    start = time.monotonic()
    while time.monotonic() - start < timeout_s:
        if not alive(pid):
            return time.monotonic() - start
        time.sleep(0.02)
    return None


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
    world = world_process_of(proc.pid)
    wait_until_flying(proc)
    time.sleep(1.0)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert not alive(world)  # closed by the flight (its stderr pipe is closed too: communicate waited for it) ...
    assert not world_exit_report_for(log).exists()  # ... not orphaned
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


def test_sigkill_the_drones_fall_by_the_firmware_watchdog_and_the_log_is_salvageable(tmp_path):
    """A real Crazyflie whose ground station is SIGKILLed gets no more keep-alives: its emergency-stop watchdog cuts
    its motors 1 s after the last one, then it falls. The simulated drones' process notices its parent's death, keeps
    simulating until every drone lies on the floor, writes its exit report next to the log and exits by itself."""
    proc, log = start_flight(tmp_path)
    world = world_process_of(proc.pid)
    wait_until_flying(proc)  # the planning phase: every drone streams position setpoints
    time.sleep(2.5)
    proc.send_signal(signal.SIGKILL)
    killed = time.monotonic()
    proc.wait(timeout=10)
    exited = wait_gone(world, ORPHAN_CAP_S + 3.0)
    assert exited is not None, "the simulated drones' process outlived its cap"
    report = json.loads(world_exit_report_for(log).read_text())
    assert report["all_down"] and not report["capped"] and report["world_pid"] == world
    assert report["widest_step_s"] >= 0.009  # the world's 10 ms step at least
    assert report["detected_by"] in (
        "the control connection closed without a close call",  # whichever is first
        "the parent process is gone (the child was re-parented)",
    )
    assert report["parent_death_monotonic_s"] - killed < 0.5  # noticed at once
    assert exited < report["elapsed_s"] + 1.5  # and exited right after the last drone came down
    assert set(report["drones"]) == {"cf1", "cf2", "cf3"}
    for name, drone in report["drones"].items():
        assert drone["motors_on_at_death"] and drone["z_at_death"] > 0.4, (name, drone)
        assert drone["control_source_at_death"].startswith("crtp-"), (name, drone)  # streamed setpoints
        assert not drone["motors_on"] and drone["at_rest"] and not drone["crashed"], (name, drone)
        assert drone["z"] == drone["floor_z"] == 0.0, (name, drone)
        assert drone["supervisor_state"] == "Locked" and drone["locked"], (name, drone)  # the watchdog's lock
        # the firmware's emergency-stop watchdog (fed 5 times a second from take-off on), not an instant cut and not
        # the setpoint watchdog's 2 s: 1 s after the last keep-alive (sent up to 0.2 s before death), at a 25 Hz
        # supervisor tick
        assert 0.7 < drone["motors_off_after_s"] < 1.25, (name, drone)
        # then a fall from where it was: about 0.5 m, as the estimate it held without extpos drifted for a second;
        # no faster than a free fall, and slower only by the rotors' spin-down (the motors' 0.1 s lag, docs/dynamics.md)
        cut_z = drone["z_at_motors_off"]
        assert 0.3 < cut_z < 0.7, (name, drone)
        fall = drone["at_rest_after_s"] - drone["motors_off_after_s"]
        # a throw from that height at the vertical speed it had (a drone whose estimate drifted up sank at up to
        # 0.3 m/s: the fall was 30 ms shorter than a drop from rest), to the world step at both ends (10 ms, or the
        # widest a host that held the world back made it)
        down = -drone["vz_at_motors_off"]
        thrown = (math.sqrt(down * down + 2.0 * 9.81 * cut_z) - down) / 9.81
        assert abs(drone["vz_at_motors_off"]) < 1.0, (name, drone)
        # the firmware model spins its motors down after the cut (its motor lag): the fall may end up to 0.2 s later
        step = 0.01 + 2 * report["widest_step_s"]
        assert -step < fall - thrown < 0.2 + step, (name, drone, thrown)
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


def test_a_normal_exit_closes_the_simulated_drones_process(tmp_path):
    """A flight that ends by itself closes its world process before it exits: nothing left running, no report."""
    stderr = tmp_path / "stderr.txt"
    proc, log = start_flight(tmp_path, goal_x=-0.6, timeout_s=30, stderr=stderr)
    world = world_process_of(proc.pid)
    assert proc.wait(timeout=60) == 0, stderr.read_text()
    gone = wait_gone(world, 1.0)
    assert gone is not None and gone < 0.5, "the simulated drones' process outlived a normal exit"
    assert not world_exit_report_for(log).exists()
    assert "rpf-fly dry run: the flight's process died" not in stderr.read_text()


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
    return subprocess.run(
        [sys.executable, "-m", "rpf_fly", *args, str(mission)], capture_output=True, text=True, cwd=tmp_path, timeout=60
    )


NATNET_MISSION = SHORT_MISSION.replace("mocap: {kind: sim, rate_hz: 100}", "mocap: {kind: natnet, server: SERVER}")


def test_an_unresolvable_mocap_server_is_one_line_and_exit_2(tmp_path):
    for command in (("check",), ("fly", "--no-console")):
        done = run_cli(tmp_path, *command, mission_text=NATNET_MISSION.replace("SERVER", "no-such-host.invalid"))
        assert done.returncode == 2, (command, done.stderr)
        lines = done.stderr.strip().splitlines()
        assert len(lines) == 1 and "Traceback" not in done.stderr, done.stderr
        # the line of mocap.server in the file (SHORT_MISSION's line 5), not 0 (the command line's)
        assert lines[0].startswith(f"{tmp_path / 'm.yaml'}:5: mocap.server: cannot resolve"), lines[0]


def test_a_malformed_mocap_server_is_refused_at_validation(tmp_path):
    for server in ("192.168.1.1000", "192.168.1"):
        done = run_cli(tmp_path, "check", mission_text=NATNET_MISSION.replace("SERVER", server))
        assert done.returncode == 2 and "Traceback" not in done.stderr
        assert "mocap.server: expected a host name or IP address" in done.stderr and done.stdout == ""
