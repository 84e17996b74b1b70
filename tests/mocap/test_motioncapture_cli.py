"""`rpf-fly mocap watch --system TYPE --host HOST` over the real motioncapture library (in its child process), and
what `fly`/`check` say about a motioncapture mission that cannot fly or lacks the package: one line each."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from typer.testing import CliRunner
from watch_summary import stop_after, summary_numbers

from rpf_fly.cli import get_app
from rpf_fly.emulator.natnet_server import NatNetServer
from rpf_fly.mocap import motioncapture_source
from rpf_fly.mocap.motioncapture_options import MISSING_LIBRARY

runner = CliRunner()
app = get_app()
POSES = {
    "cf1": ((1.0, 2.0, 0.5), (0.0, 0.0, 0.0, 1.0), True),
    "cf2": ((-0.25, 0.75, 1.5), (0.0, 0.0, 0.5**0.5, 0.5**0.5), True),
    "cf3": ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0), False),
}
MISSION = """\
arena: {x: [-2, 2], y: [-2, 2], z: [0, 1.5]}
mocap: MOCAP
drones:
  - {name: cf1, uri: radio://0/80/2M/E7E7E7E701, start: [-1.5, 0], goal: [1.5, 0]}
"""


@pytest.mark.parametrize("up_axis", ["y", "z"])
def test_watch_optitrack_reads_the_emulator_through_the_library(up_axis):
    """`--system optitrack --host 127.0.0.1` reads `rpf-fly mocap emulate` (multicast on loopback: the library's
    interface_ip becomes 127.0.0.1 by itself, as the NatNet client's membership does)."""
    with NatNetServer(lambda: POSES, version="4.1", multicast=True, rate_hz=200, up_axis=up_axis) as server:
        result = runner.invoke(
            app,
            [
                "mocap",
                "watch",
                "--system",
                "optitrack",
                "--host",
                "127.0.0.1",
                "--command-port",
                str(server.command_port),
                "--up-axis",
                up_axis,
                "--frames",
                "3",
                "--json",
            ],
        )
    assert result.exit_code == 0, result.output
    objects = [json.loads(line) for line in result.stdout.splitlines()]
    assert len(objects) == 3
    for obj in objects:
        # cf3 is untracked: the library leaves it out and never saw it, so it is absent, not invalid
        assert sorted(obj["bodies"]) == ["cf1", "cf2"]
        for name, body in obj["bodies"].items():
            position, quaternion, _ = POSES[name]
            assert body["valid"] is True
            assert body["position"] == pytest.approx(position, abs=1e-6)
            assert body["quaternion"] == pytest.approx(quaternion, abs=1e-6)


def test_the_summary_tells_the_frames_span_from_the_watchs_duration():
    """`--system`'s summary as NatNet's: the stream stops after 1 s of a 3 s watch; the frames, the 1 s they span and
    the rate over it, and the watch's 3 s apart."""
    with NatNetServer(lambda: POSES, version="4.1", multicast=True, rate_hz=200, up_axis="z") as server:
        timer = stop_after(server, 1.5)
        result = runner.invoke(
            app,
            [
                "mocap",
                "watch",
                "--system",
                "optitrack",
                "--host",
                "127.0.0.1",
                "--command-port",
                str(server.command_port),
                "--duration",
                "3.5",
                "--timeout",
                "5",
                "--rate",
                "1",
            ],
        )
        timer.join()
    assert result.exit_code == 0, result.output
    head = next(line for line in result.stdout.splitlines() if line.startswith("summary: "))
    frames, span, rate, watched = summary_numbers(head)
    assert 0.5 < span < 1.9 and 3.4 < watched < 4.1, head
    assert 100 < rate < 250 and abs((frames - 1) / rate - span) < 0.06, head


def test_local_ip_is_the_librarys_interface_ip():
    """`--local-ip` reaches the library as `interface_ip`: 127.0.0.1 reads the loopback multicast, an address this
    host does not have makes the library's own multicast join fail (RFC 5737's TEST-NET-1)."""
    with NatNetServer(lambda: POSES, version="4.1", multicast=True, rate_hz=200, up_axis="z") as server:
        args = [
            "mocap",
            "watch",
            "--system",
            "optitrack",
            "--host",
            "127.0.0.1",
            "--command-port",
            str(server.command_port),
            "--frames",
            "2",
            "--json",
            "--timeout",
            "3",
        ]
        read = runner.invoke(app, [*args, "--local-ip", "127.0.0.1"])
        refused = runner.invoke(app, [*args, "--local-ip", "192.0.2.1"])
    assert read.exit_code == 0, read.output
    assert len(read.stdout.splitlines()) == 2
    assert refused.exit_code == 1, refused.output
    assert refused.stderr.startswith("error: motioncapture optitrack at 127.0.0.1: the library failed: ")
    assert len(refused.stderr.strip().splitlines()) == 1


def test_watch_mock_prints_its_bodies_and_frames():
    result = runner.invoke(
        app,
        [
            "mocap",
            "watch",
            "--system",
            "mock",
            "--frames",
            "2",
            "--json",
            "--option",
            "rigid_bodies=cf1(1,2,0.5,1,0,0,0)",
            "--option",
            "frequency=50",
        ],
    )
    assert result.exit_code == 0, result.output
    objects = [json.loads(line) for line in result.stdout.splitlines()]
    assert [o["bodies"] for o in objects] == [
        {"cf1": {"position": [1.0, 2.0, 0.5], "quaternion": [0.0, 0.0, 0.0, 1.0], "valid": True}}
    ] * 2
    assert objects[0]["frame"] < objects[1]["frame"] and all(math.isfinite(o["timestamp"]) for o in objects)


def test_watch_mock_piped_prints_at_most_rate_lines_a_second_and_a_summary():
    result = runner.invoke(
        app,
        [
            "mocap",
            "watch",
            "--system",
            "mock",
            "--duration",
            "1.5",
            "--rate",
            "4",
            "--option",
            "rigid_bodies=cf1(1,2,0.5,1,0,0,0)",
            "--option",
            "frequency=100",
        ],
    )
    assert result.exit_code == 0, result.output
    lines = result.stdout.splitlines()
    assert lines[0].startswith("motioncapture mock") and "at most 4 lines a second" in lines[0]
    shown = [line for line in lines if line.startswith("frame")]
    summary = next(line for line in lines if line.startswith("summary:"))
    frames = int(summary.split()[1])
    assert 1 <= len(shown) <= 1.5 * 4 + 2 and frames > 3 * len(shown)  # 100 Hz in, 4 lines a second out
    assert "cf1: valid 100.0 %" in result.stdout


def test_watch_mock_without_bodies_still_streams_and_says_how_to_add_them():
    result = runner.invoke(app, ["mocap", "watch", "--system", "mock", "--frames", "2", "--rate", "0"])
    assert result.exit_code == 0, result.output
    shown = [line for line in result.stdout.splitlines() if line.startswith("frame")]
    assert [line.endswith("no rigid bodies") for line in shown] == [True, True]
    assert "summary: 2 frames" in result.stdout
    assert "--option 'rigid_bodies=" in result.stderr


@pytest.mark.parametrize(
    "args, code, line",
    [
        (
            ["--system", "vicon", "--option", "enable_objects=yes"],
            2,
            "error: --option enable_objects: expected true or false, got 'yes'",
        ),
        (
            ["--system", "vicon", "--option", "enable_pointcloud=true"],
            2,
            "error: --option enable_pointcloud: unknown option 'enable_pointcloud' of type 'vicon' (did you mean "
            "'enable_pointclout'?); vicon takes enable_objects, enable_pointclout",
        ),
        (
            ["--system", "vicom"],
            2,
            "error: --system/--host: unknown motioncapture type 'vicom' (did you mean 'vicon'?);",
        ),
        (
            ["--system", "nokov", "--timeout", "1"],
            1,
            "error: motioncapture nokov: this motioncapture build has no 'nokov'",
        ),
    ],
)
def test_watch_refuses_in_one_line(args, code, line):
    result = runner.invoke(app, ["mocap", "watch", *args])
    assert result.exit_code == code, result.output
    assert result.stdout == ""
    lines = [x for x in result.stderr.splitlines() if x.startswith("error")]
    assert len(lines) == 1 and lines[0].startswith(line), result.stderr


def test_watch_without_the_package_names_the_extra(monkeypatch):
    monkeypatch.setattr(motioncapture_source, "library_installed", lambda: False)
    result = runner.invoke(app, ["mocap", "watch", "--system", "mock", "--frames", "1"])
    assert result.exit_code == 1
    assert result.stderr.strip() == f"error: {MISSING_LIBRARY}"


def write(tmp_path: Path, mocap: str) -> Path:
    path = tmp_path / "m.yaml"
    path.write_text(MISSION.replace("MOCAP", mocap))
    return path


def test_fly_and_check_refuse_real_drones_on_mock_poses(tmp_path):
    path = write(tmp_path, "{kind: motioncapture, type: mock}")
    flown = runner.invoke(app, ["fly", str(path), "--no-console"])
    assert flown.exit_code == 2
    assert flown.stderr.strip() == (
        f"{path}:2: mocap.type: 'mock' serves fixed poses from its options, not the drones': it can only fly with "
        "--dry-run (which serves the simulated drones' poses, docs/mocap.md)"
    )
    checked = runner.invoke(app, ["check", str(path)])
    assert checked.exit_code == 0 and "preflight skipped: mocap.type: 'mock' serves fixed poses" in checked.stdout


def test_fly_without_the_package_is_one_line_before_anything_starts(tmp_path, monkeypatch):
    monkeypatch.setattr(motioncapture_source, "library_installed", lambda: False)
    path = write(tmp_path, "{kind: motioncapture, type: mock}")
    result = runner.invoke(app, ["fly", str(path), "--dry-run", "--no-console", "--log", str(tmp_path / "f.mcap")])
    assert result.exit_code == 1
    assert result.stderr.strip() == f"mocap: {MISSING_LIBRARY}"
    assert not (tmp_path / "f.mcap").exists()
    # Validating the mission needs no package.
    natnet = runner.invoke(app, ["check", str(path), "--no-preflight"])
    assert natnet.exit_code == 0, natnet.output


def test_an_unresolvable_optitrack_host_is_one_line_and_exit_2(tmp_path):
    path = write(tmp_path, "{kind: motioncapture, type: optitrack, hostname: no-such-host.invalid}")
    result = runner.invoke(app, ["fly", str(path), "--no-console"])
    assert result.exit_code == 2
    assert result.stderr.startswith(f"{path}:2: mocap.hostname: cannot resolve 'no-such-host.invalid' (")
    assert result.stderr.strip().endswith("expected the IP address or host name of the optitrack server")
