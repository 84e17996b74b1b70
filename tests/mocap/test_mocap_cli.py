"""``rpf-fly mocap watch`` / ``emulate`` against the emulator over real sockets, every version and transport."""

from __future__ import annotations

import json
import socket
import subprocess
import sys

import pytest
from natnet_samples import VERSIONS
from typer.testing import CliRunner
from watch_summary import stop_after, summary_numbers

import rpf_fly.cli.mocap_cmd  # noqa: F401 - registers the `mocap` group on the app
from rpf_fly.cli import app
from rpf_fly.emulator.natnet_server import NatNetServer

TRANSPORTS = {"unicast": False, "multicast": True}
POSES = {
    "cf1": ((1.0, 2.0, 0.5), (0.0, 0.0, 0.0, 1.0), True),
    "cf2": ((-0.25, 0.75, 1.5), (0.0, 0.0, 0.5**0.5, 0.5**0.5), True),
    "cf3": ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0), False),
}
runner = CliRunner()


def watch_args(server: NatNetServer, multicast: bool, *extra: str) -> list[str]:
    args = ["mocap", "watch", "--natnet", "127.0.0.1", "--command-port", str(server.command_port), "--up-axis", "y"]
    return args + ([] if multicast else ["--unicast"]) + list(extra)


@pytest.mark.parametrize("transport", TRANSPORTS)
@pytest.mark.parametrize("version", VERSIONS, ids=lambda v: f"{v[0]}.{v[1]}")
def test_watch_prints_the_emulator_bodies(version, transport):
    multicast = TRANSPORTS[transport]
    with NatNetServer(lambda: POSES, version=version, multicast=multicast, rate_hz=200, up_axis="y") as server:
        result = runner.invoke(app, watch_args(server, multicast, "--frames", "3", "--rate", "0"))
    assert result.exit_code == 0, result.output
    lines = result.stdout.splitlines()
    assert "NatNet" in lines[0] and "printing every frame" in lines[0]  # the header
    assert lines[4].startswith("summary: 3 frames")
    for line in lines[1:4]:
        assert line.startswith("frame ")
        assert "cf1 (+1.000, +2.000, +0.500) ok" in line
        assert "cf2 (-0.250, +0.750, +1.500) ok" in line
        assert "cf3" in line and "LOST" in line


@pytest.mark.parametrize("transport", TRANSPORTS)
@pytest.mark.parametrize("version", VERSIONS, ids=lambda v: f"{v[0]}.{v[1]}")
def test_watch_json_lines(version, transport):
    multicast = TRANSPORTS[transport]
    with NatNetServer(lambda: POSES, version=version, multicast=multicast, rate_hz=200, up_axis="y") as server:
        result = runner.invoke(app, watch_args(server, multicast, "--frames", "4", "--json"))
    assert result.exit_code == 0, result.output
    objects = [json.loads(line) for line in result.stdout.splitlines()]
    assert len(objects) == 4
    numbers = [o["frame"] for o in objects]
    assert numbers == sorted(set(numbers))
    for obj in objects:
        assert set(obj) == {"frame", "timestamp", "bodies"}
        assert isinstance(obj["frame"], int) and isinstance(obj["timestamp"], float)
        assert sorted(obj["bodies"]) == ["cf1", "cf2", "cf3"]
        for name, body in obj["bodies"].items():
            assert set(body) == {"position", "quaternion", "valid"}
            position, quaternion, valid = POSES[name]
            assert body["valid"] is valid
            if valid:
                assert body["position"] == pytest.approx(position, abs=1e-6)
                assert body["quaternion"] == pytest.approx(quaternion, abs=1e-6)


def test_watch_fails_with_one_line_when_no_server_answers():
    silent = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    silent.bind(("127.0.0.1", 0))
    with silent:
        port = silent.getsockname()[1]
        result = runner.invoke(app, ["mocap", "watch", "--command-port", str(port), "--timeout", "0.5", "--unicast"])
    assert result.exit_code == 1
    assert result.stdout == ""
    assert result.stderr.strip().splitlines() == [f"error: no NatNet server answered at 127.0.0.1:{port} within 0.5 s"]


def test_watch_fails_when_the_server_answers_but_no_frames_come():
    with NatNetServer(lambda: POSES, rate_hz=0) as server:  # answers commands, never streams
        result = runner.invoke(app, watch_args(server, False, "--timeout", "0.5"))
    assert result.exit_code == 1
    assert len(result.stderr.strip().splitlines()) == 1
    assert "no frames arrived" in result.stderr


def test_emulate_then_watch():
    command = [sys.executable, "-c", "import rpf_fly.cli.mocap_cmd; from rpf_fly.cli import app; app()"]
    args = ["mocap", "emulate", "--version", "4.2", "--unicast", "--bodies", "2", "--rate", "100"]
    args += ["--command-port", "0", "--data-port", "0", "--duration", "20"]
    emulator = subprocess.Popen(command + args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        banner = emulator.stdout.readline()
        assert banner.startswith("NatNet emulator: bitstream 4.2, unicast"), banner + emulator.stderr.read()
        port = banner.split("command port ")[1].split(",")[0]
        result = runner.invoke(
            app, ["mocap", "watch", "--command-port", port, "--unicast", "--frames", "5", "--json", "--up-axis", "z"]
        )
        assert result.exit_code == 0, result.output
        objects = [json.loads(line) for line in result.stdout.splitlines()]
        assert len(objects) == 5
        for obj in objects:
            assert sorted(obj["bodies"]) == ["cf1", "cf2"]
            for body in obj["bodies"].values():
                x, y, z = body["position"]
                assert body["valid"] and 0.4 < z < 0.8  # flying circles at 0.5 m and 0.6 m
                assert 0.9 < (x * x + y * y) ** 0.5 < 1.3
    finally:
        emulator.terminate()
        emulator.wait(timeout=10)


def test_emulate_rejects_unknown_versions():
    result = runner.invoke(app, ["mocap", "emulate", "--version", "2.9", "--duration", "0.1"])
    assert result.exit_code != 0
    assert "2.9" in result.output


def test_the_summary_tells_the_frames_span_from_the_watchs_duration():
    """The stream stops after 1 s of a 3 s watch: the summary gives the frames, the 1 s they span and the rate over
    it (200 Hz), and the watch's 3 s apart (not 200 frames "in 3 s, 200 Hz")."""
    with NatNetServer(lambda: POSES, version=(4, 1), multicast=False, rate_hz=200, up_axis="y") as server:
        timer = stop_after(server, 1.0)
        result = runner.invoke(app, watch_args(server, False, "--duration", "3", "--timeout", "5", "--rate", "1"))
        timer.join()
    assert result.exit_code == 0, result.output
    head, _ = summary_of(result.stdout)
    frames, span, rate, watched = summary_numbers(head)
    assert 0.5 < span < 1.4 and 2.9 < watched < 3.6, head
    assert 100 < rate < 250 and abs((frames - 1) / rate - span) < 0.06, head  # the rate is over the span


def summary_of(text: str) -> tuple[str, dict[str, float]]:
    """The summary's head line and each body's valid %."""
    lines = text.splitlines()
    start = next(i for i, line in enumerate(lines) if "summary: " in line)
    lines[start] = lines[start][lines[start].index("summary: ") :]  # after a terminal's cursor codes
    valid = {}
    for line in lines[start + 1 :]:
        name, rest = line.strip().split(": valid ")
        valid[name] = float(rest.split("%")[0])
    return lines[start], valid


def test_watch_piped_prints_a_header_at_most_rate_lines_a_second_and_a_summary():
    with NatNetServer(lambda: POSES, version=(4, 1), multicast=False, rate_hz=200, up_axis="y") as server:
        result = runner.invoke(app, watch_args(server, False, "--duration", "1.5", "--rate", "4"))
    assert result.exit_code == 0, result.output
    lines = result.stdout.splitlines()
    assert lines[0].startswith("NatNet") or "NatNet 4.1" in lines[0]
    assert "3 rigid bodies (cf1, cf2, cf3)" in lines[0] and "at most 4 lines a second" in lines[0]
    frame_lines = [line for line in lines if line.startswith("frame ")]
    assert 4 <= len(frame_lines) <= 8  # 1.5 s at 4 lines a second, not 300 lines at 200 Hz
    head, valid = summary_of(result.stdout)
    frames = int(head.split()[1])
    assert frames > 150 and " Hz (first to last); watched " in head and "missed" in head
    assert valid == {"cf1": 100.0, "cf2": 100.0, "cf3": 0.0}


def test_watch_json_keeps_every_frame_on_stdout_and_the_summary_on_stderr():
    with NatNetServer(lambda: POSES, version=(4, 1), multicast=False, rate_hz=200, up_axis="y") as server:
        result = runner.invoke(app, watch_args(server, False, "--duration", "0.5", "--json"))
    assert result.exit_code == 0, result.output
    objects = [json.loads(line) for line in result.stdout.splitlines()]
    head, valid = summary_of(result.stderr)
    assert len(objects) == int(head.split()[1]) > 50
    assert valid["cf3"] == 0.0


def test_watch_on_a_terminal_redraws_one_table():
    with NatNetServer(lambda: POSES, version=(4, 1), multicast=False, rate_hz=200, up_axis="y") as server:
        result = runner.invoke(
            app, watch_args(server, False, "--duration", "1.0"), env={"TTY_COMPATIBLE": "1", "COLUMNS": "120"}
        )
    assert result.exit_code == 0, result.output
    out = result.stdout
    assert "\x1b[" in out  # cursor control: the table is redrawn in place
    assert not [line for line in out.splitlines() if line.startswith("frame ")]  # no line per frame
    assert "valid %" in out and "cf3" in out
    head, valid = summary_of(out)
    assert valid["cf1"] == 100.0


def test_watch_stops_on_ctrl_c_with_the_summary():
    import signal
    import time

    command = [sys.executable, "-m", "rpf_fly", "mocap", "watch"]
    with NatNetServer(lambda: POSES, version=(4, 1), multicast=False, rate_hz=100, up_axis="y") as server:
        proc = subprocess.Popen(
            command + watch_args(server, False)[2:], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
        )
        try:
            header = proc.stdout.readline()
            assert "rigid bodies" in header, header + proc.stderr.read()
            time.sleep(1.0)
            proc.send_signal(signal.SIGINT)
            out, err = proc.communicate(timeout=30)
        finally:
            proc.kill()
    assert proc.returncode == 0, err
    assert "Traceback" not in err
    head, valid = summary_of(out)
    assert int(head.split()[1]) > 50 and valid["cf2"] == 100.0


# -- the up axis: watch says which it assumed, and hints at the other when the bodies look streamed with it --------

ON_THE_FLOOR = {
    "cf1": ((0.5, -0.999, 0.03), (0.0, 0.0, 0.0, 1.0), True),
    "cf2": ((-1.0, 1.0, 0.03), (0.0, 0.0, 0.0, 1.0), True),
}
"""Two drones on the floor (Z-up world), one of them at y -0.999."""


def up_axis_watch(streams: str, poses: dict, *args: str):  # type: ignore[no-untyped-def]
    with NatNetServer(lambda: poses, version=(4, 1), multicast=False, rate_hz=100, up_axis=streams) as server:
        return runner.invoke(
            app,
            [
                "mocap",
                "watch",
                "--command-port",
                str(server.command_port),
                "--unicast",
                "--duration",
                "1.5",
                "--rate",
                "2",
                *args,
            ],
        )


def test_a_y_up_stream_watched_as_z_up_says_what_it_assumed_and_how_to_change_it():
    result = up_axis_watch("y", ON_THE_FLOOR)  # the watch's default --up-axis z
    assert result.exit_code == 0, result.output
    lines = result.stdout.splitlines()
    assert "assuming Z-up (--up-axis z; NatNet does not say which Motive streams), shown Z-up" in lines[0]
    assert "cf2 (-1.000, +0.030, -1.000) ok" in lines[1]  # its depth shown as z, below the floor
    hint = (
        "hint: cf2 is at z -1.000 m, below the floor: the stream looks Y-up (Motive's default), not the Z-up "
        "assumed (--up-axis z): watch with --up-axis y, and fly with mocap.up_axis: y"
    )
    assert lines.count(hint) == 2 and lines[-1] == hint  # once the first second is in, and after the summary


def test_a_z_up_stream_watched_as_y_up_hints_at_z():
    result = up_axis_watch("z", ON_THE_FLOOR, "--up-axis", "y")
    assert result.exit_code == 0, result.output
    assert "assuming Y-up (--up-axis y;" in result.stdout.splitlines()[0]
    assert result.stdout.splitlines()[-1] == (
        "hint: cf1 is at z -0.999 m, below the floor: the stream looks Z-up, not the Y-up assumed (--up-axis y): "
        "watch with --up-axis z, and fly with mocap.up_axis: z"
    )
    # bodies at rest, all at y near 0 and one high: their height is in y (said if they stand on the floor)
    result = up_axis_watch(
        "z",
        {"cf1": ((1.0, 2.0, 0.03), (0.0, 0.0, 0.0, 1.0), True), "cf2": ((0.0, 0.5, 0.03), (0.0, 0.0, 0.0, 1.0), True)},
        "--up-axis",
        "y",
        "--json",
    )
    assert result.exit_code == 0, result.output
    assert result.stderr.splitlines()[-1] == (
        "hint: every body at rest has y within 0.1 m of 0 while cf1 is at z +2.000 m: if they stand on the floor, "
        "the stream looks Z-up, not the Y-up assumed (--up-axis y): watch with --up-axis z, and fly with "
        "mocap.up_axis: z"
    )
    assert all(line.startswith("{") for line in result.stdout.splitlines())  # the JSON lines stay JSON


def test_the_right_up_axis_gives_no_hint():
    result = up_axis_watch("y", ON_THE_FLOOR, "--up-axis", "y")
    assert result.exit_code == 0, result.output
    assert "hint" not in result.stdout and "cf1 (+0.500, -0.999, +0.030) ok" in result.stdout


def test_the_header_counts_lines_in_the_singular_and_the_plural():
    from rpf_fly.cli.mocap_cmd import printing

    assert printing(1) == "at most 1 line a second (--rate)"
    assert printing(2) == "at most 2 lines a second (--rate)" and printing(0.5) == "at most 0.5 lines a second (--rate)"
    assert printing(0) == "every frame"
    with NatNetServer(lambda: POSES, version=(4, 1), multicast=False, rate_hz=100, up_axis="y") as server:
        result = runner.invoke(app, watch_args(server, False, "--frames", "2", "--rate", "1"))
    assert result.exit_code == 0, result.output
    assert result.stdout.splitlines()[0].endswith("; printing at most 1 line a second (--rate)")
