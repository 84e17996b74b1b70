"""Dry runs of a `mocap: {kind: motioncapture, type: mock}` mission: the simulated drones' poses reach the flight
through the real motioncapture library (its OptiTrack decoder reading the NatNet emulator, multicast on 127.0.0.1)
in its own child process. When that process dies mid-flight (killed, or the library's own C++ parser segfaulting
on a malformed datagram), the flight sees mocap loss: every drone holds, then lands; the flight itself carries on."""

from __future__ import annotations

import os
import signal
import socket
import struct
import subprocess
import sys
import time

from flight_harness import fly

from rpf_fly.flight.phases import FlightOutcome, SwarmPhase
from rpf_fly.mission import parse_mission
from rpf_fly.mocap.motioncapture_source import MotioncaptureSource
from rpf_fly.mocap.natnet_protocol import ConnectRequest, decode_header, decode_server_info, encode_connect

MOCK_MISSION = """\
name: mock-3
arena: {x: [-2.0, 2.0], y: [-2.0, 2.0], z: [0.0, 1.5]}
flight: {height: 0.5, speed: 0.5, rate_hz: 10, goal_tolerance: 0.1, takeoff_s: 1.0, land_s: 1.0, timeout_s: 30}
planner: {kind: apf, margin: 0}
mocap: {kind: motioncapture, type: mock, up_axis: y}
obstacles:
  - {shape: circle, center: [0.0, 0.9], radius: 0.1}
drones:
  - {name: cf1, uri: radio://0/80/2M/E7E7E7E701, start: [-1.0, -0.6], goal: [1.0, -0.6]}
  - {name: cf2, uri: radio://0/80/2M/E7E7E7E702, start: [-1.0, 0.0], goal: [1.0, 0.0]}
  - {name: cf3, uri: radio://0/80/2M/E7E7E7E703, start: [-1.0, 0.6], goal: [1.0, 0.6]}
"""


def landed(snapshot) -> bool:
    return snapshot.position[2] < 0.05 and not snapshot.motors_on


def assert_mocap_loss_handled(flight) -> None:
    """The flight's existing mocap-lost path: all hold, then each lands; the flight ends normally. The drones fly
    0.6 m apart: at the default blind drift (0.45 m/s^2) each lands at once after the hold and has its motors cut
    near the floor once its possible drift could reach a neighbour (tests/flight/test_dry_run_flight.py,
    `assert_blind_line_lands_then_is_dropped`)."""
    assert flight.report.error is None and flight.report.phase == SwarmPhase.DONE, flight.report.error
    assert flight.events("mocap_lost")
    for name in ("cf1", "cf2", "cf3"):
        lost = [e.message for e in flight.events("pose_lost", name)]
        assert len(lost) == 2 and "landing now" in lost[0] and "motors off" in lost[1], (name, lost)
    assert all(o == FlightOutcome.EMERGENCY for o in flight.report.outcomes.values()), flight.report.reasons
    assert all(landed(s) for s in flight.snapshots.values()), flight.snapshots
    for name in ("cf1", "cf2", "cf3"):  # each drone streamed a fixed setpoint (held) before it landed
        assert "hold" in [m.data["mode"] for m in flight.log.messages(f"/{name}/planner")], name
    assert any("no fresh mocap pose for any drone" in m for m in flight.logged_events())


def test_a_mock_mission_dry_runs_through_the_library_and_reaches_its_goals(tmp_path):
    """`rpf-fly fly MOCK --dry-run`, the command a user types: exit 0, every drone reached its goal."""
    mission = tmp_path / "mock.yaml"
    mission.write_text(MOCK_MISSION)
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "rpf_fly",
            "fly",
            str(mission),
            "--dry-run",
            "--no-console",
            "--log",
            str(tmp_path / "f.mcap"),
        ],
        capture_output=True,
        text=True,
        timeout=180,
        cwd=tmp_path,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert [line for line in done.stdout.splitlines() if line.startswith("cf")] == [
        "cf1: reached",
        "cf2: reached",
        "cf3: reached",
    ]


def test_the_librarys_process_killed_mid_flight_is_mocap_loss(tmp_path):
    mission = parse_mission(MOCK_MISSION)
    seen = {}

    def kill(loop, rig):
        time.sleep(0.5)
        assert isinstance(rig.mocap.source, MotioncaptureSource) and rig.mocap.alive
        seen["pid"] = rig.mocap.pid
        os.kill(rig.mocap.pid, signal.SIGKILL)
        time.sleep(0.5)
        seen["failure"] = rig.mocap.failure

    flight = fly(mission, tmp_path, when_flying=kill, mocap="motioncapture")
    assert seen["failure"] == "killed by SIGKILL"
    assert_mocap_loss_handled(flight)


def _data_port(command_port: int) -> int:
    """The emulator's data port, from its SERVERINFO (what the library joins the multicast group on)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.settimeout(2.0)
        sock.sendto(encode_connect(ConnectRequest("test", (0, 1, 0, 0), (4, 1, 0, 0))), ("127.0.0.1", command_port))
        _, payload = decode_header(sock.recvfrom(65536)[0])
        return decode_server_info(payload).data_port


def test_the_library_segfaulting_mid_flight_is_mocap_loss_not_a_dead_flight(tmp_path):
    """A real crash inside libmotioncapture's C++ OptiTrack parser: one datagram whose marker count lies (1.1
    skips count * 12 bytes unchecked and reads 2 GiB past its buffer). The NatNet client would drop it."""
    mission = parse_mission(MOCK_MISSION)
    body = struct.pack("<iii", 999, 2, 64) + b"a\0" + struct.pack("<i", 178956970) + bytes(64)
    poison = struct.pack("<HH", 7, len(body)) + body
    seen = {}

    def crash(loop, rig):
        time.sleep(0.5)
        port = _data_port(int(rig.mocap.config["port_command"]))
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:
            sender.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton("127.0.0.1"))
            deadline = time.monotonic() + 3.0
            while rig.mocap.failure is None and time.monotonic() < deadline:
                sender.sendto(poison, ("239.255.42.99", port))
                time.sleep(0.02)
        seen["failure"] = rig.mocap.failure

    flight = fly(mission, tmp_path, when_flying=crash, mocap="motioncapture")
    assert seen["failure"] == "killed by SIGSEGV"
    assert_mocap_loss_handled(flight)
