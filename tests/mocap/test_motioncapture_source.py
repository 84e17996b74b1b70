"""`MotioncaptureSource`: the real `motioncapture` library in a real child process, its frames over a pipe.

What must hold: the NatNet client's semantics (Z-up, validity, names), and that whatever the library does (crash,
hang, exception, missing) reaches the caller as no frames or one line, never as a dead caller.
"""

from __future__ import annotations

import os
import signal
import socket
import struct
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from rpf_fly.emulator.natnet_server import NatNetServer
from rpf_fly.mocap import motioncapture_source as source_module
from rpf_fly.mocap.motioncapture_options import MISSING_LIBRARY, WHEEL_TYPES
from rpf_fly.mocap.motioncapture_source import MotioncaptureSource, MotioncaptureUnavailable

MOCK = {"rigid_bodies": "cf1(1,2,3,1,0,0,0);cf2(-0.5,0.25,0.75,0.7071068,0,0,0.7071068)", "frequency": 200}


def gone(pid: int, within_s: float = 5.0) -> bool:
    """The process ``pid`` has exited (and been reaped, or is a zombie of a parent that is not us)."""
    deadline = time.monotonic() + within_s
    while time.monotonic() < deadline:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return True
        try:
            with open(f"/proc/{pid}/stat") as f:
                if f.read().split(")")[-1].split()[0] == "Z":
                    return True
        except OSError:
            return True
        time.sleep(0.02)
    return False


def poison_frame() -> bytes:
    """A NatNet 4.1 FRAMEOFDATA whose first marker set claims 178956970 markers: libmotioncapture 1.1 skips
    ``count * 12`` bytes without a bounds check and reads the next name 2 GiB past its buffer (our decoder refuses
    the count: it exceeds the payload)."""
    body = struct.pack("<iii", 999, 2, 64) + b"a\0" + struct.pack("<i", 178956970) + bytes(64)
    return struct.pack("<HH", 7, len(body)) + body


def test_mock_bodies_arrive_z_up_with_names_and_validity():
    with MotioncaptureSource("mock", options=MOCK, up_axis="y", bodies=["cf3"]) as source:
        frames = [source.receive(1.0) for _ in range(3)]
        now = time.monotonic()
        stats = source.stats
    assert all(f is not None for f in frames)
    numbers = [f.frame_number for f in frames]
    assert numbers == sorted(set(numbers)) and numbers[0] >= 1
    frame = frames[-1]
    assert frame.latency_s is None and frame.capture_time_s == frame.receive_time_s <= now
    assert sorted(frame.bodies) == ["cf1", "cf2", "cf3"]
    cf1, cf2, cf3 = (frame.bodies[n] for n in ("cf1", "cf2", "cf3"))
    # Y-up in, Z-up out, as the NatNet client converts: (x, y, z) -> (x, -z, y), (qx, qy, qz) -> (qx, -qz, qy).
    assert cf1.position == (1.0, -3.0, 2.0) and cf1.quaternion == (0.0, -0.0, 0.0, 1.0) and cf1.valid
    (q,) = struct.unpack("<f", struct.pack("<f", 0.7071068))  # the library's float32, exactly
    assert cf2.position == (-0.5, -0.75, 0.25) and cf2.quaternion == (0.0, -q, 0.0, q)
    # cf3 is expected but the library never reported it: untracked, at the origin (never flown on).
    assert not cf3.valid and cf3.position == (0.0, 0.0, 0.0)
    assert stats.packets == stats.frames + stats.messages + stats.dropped and stats.messages == 2  # STARTED, READY
    assert stats.dropped == stats.malformed == 0
    assert stats.delivered == 3 and stats.body_dropouts == 3


def test_a_body_the_library_stops_reporting_is_invalid_at_its_last_pose():
    """The library leaves untracked bodies out of a frame; the source reports them as NatNet does: invalid."""
    poses = {
        "cf1": ((0.5, 0.25, 1.0), (0.0, 0.0, 0.0, 1.0), True),
        "cf2": ((1.0, 1.0, 0.5), (0.0, 0.0, 0.0, 1.0), True),
    }
    with NatNetServer(lambda: poses, version="4.1", multicast=True, rate_hz=0, up_axis="z") as server:
        with MotioncaptureSource("optitrack", "127.0.0.1", {"port_command": server.command_port}) as source:
            server.send_frame()
            first = source.receive(2.0)
            poses["cf2"] = ((9.0, 9.0, 9.0), (0.0, 0.0, 0.0, 1.0), False)
            server.send_frame()
            second = source.receive(2.0)
    assert first is not None and second is not None
    assert first.bodies["cf2"].valid and first.bodies["cf2"].position == (1.0, 1.0, 0.5)
    assert second.bodies["cf1"].valid
    assert not second.bodies["cf2"].valid and second.bodies["cf2"].position == (1.0, 1.0, 0.5)


def test_optitrack_without_a_host_reads_localhost_and_ctrl_c_does_not_stop_the_child():
    """The library's default host `localhost` is no IPv4 literal for its OptiTrack backend: it is resolved here.
    A Ctrl-C reaches the whole process group: the child ignores it, the drones keep their poses while landing."""
    poses = {"cf1": ((0.5, 0.25, 1.0), (0.0, 0.0, 0.0, 1.0), True)}
    with NatNetServer(lambda: poses, version="4.1", multicast=True, rate_hz=100, up_axis="z") as server:
        with MotioncaptureSource("optitrack", options={"port_command": server.command_port}) as source:
            assert source.config["hostname"] == "127.0.0.1" and source.config["interface_ip"] == "127.0.0.1"
            assert source.receive(2.0) is not None
            os.kill(source.pid, signal.SIGINT)
            time.sleep(0.2)
            while source.receive(0.0) is not None:
                pass
            frame = source.receive(1.0)
            assert frame is not None and frame.bodies["cf1"].position == (0.5, 0.25, 1.0)
            assert source.alive


def test_a_killed_child_is_no_frames_never_an_exception():
    with MotioncaptureSource("mock", options=MOCK) as source:
        assert source.receive(1.0) is not None
        pid = source.pid
        os.kill(pid, signal.SIGKILL)
        assert gone(pid)
        started = time.monotonic()
        frames = [source.receive(0.2) for _ in range(3)]
        waited = time.monotonic() - started
        assert source.failure == "killed by SIGKILL" and not source.alive
    # At most the frames queued before the kill, then None; and receive() kept its pace (a loop calling it does
    # not spin): three calls took three timeouts, give or take a queued frame.
    assert frames[-1] is None
    assert waited >= 0.35


def test_a_hung_child_delivers_nothing_within_the_timeout_and_close_still_ends_it():
    source = MotioncaptureSource("mock", options=MOCK)
    try:
        assert source.receive(1.0) is not None
        pid = source.pid
        os.kill(pid, signal.SIGSTOP)  # a library blocked forever in waitForNextFrame()
        time.sleep(0.05)
        while source.receive(0.0) is not None:  # what it sent before it stopped
            pass
        started = time.monotonic()
        assert source.receive(0.3) is None
        assert 0.25 <= time.monotonic() - started < 1.0
        assert source.alive  # nothing tells a hang from a quiet system: the flight's pose timeouts do
    finally:
        started = time.monotonic()
        source.close()
    assert time.monotonic() - started < 5.0
    assert gone(pid)


def test_the_library_segfaulting_on_a_frame_is_reported_not_inherited():
    """A real crash of libmotioncapture's C++ OptiTrack parser, mid-stream: one malformed datagram."""
    poses = {"cf1": ((0.5, 0.25, 1.0), (0.0, 0.0, 0.0, 1.0), True)}
    with NatNetServer(lambda: poses, version="4.1", multicast=True, rate_hz=100, up_axis="z") as server:
        with MotioncaptureSource("optitrack", "127.0.0.1", {"port_command": server.command_port}) as source:
            assert source.receive(2.0) is not None
            sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            sender.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton("127.0.0.1"))
            with sender:
                deadline = time.monotonic() + 5.0
                while source.alive and time.monotonic() < deadline:
                    sender.sendto(poison_frame(), ("239.255.42.99", server.data_port))
                    source.receive(0.02)
            assert source.failure == "killed by SIGSEGV"
            assert source.receive(0.05) is None


def test_the_library_is_never_imported_into_the_callers_process():
    code = textwrap.dedent("""
        import sys
        from rpf_fly.mocap.motioncapture_source import MotioncaptureSource
        with MotioncaptureSource("mock", options={"rigid_bodies": "cf1(0,0,0,1,0,0,0)"}) as s:
            assert s.receive(2.0) is not None
        print("motioncapture" in sys.modules)
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True)
    assert out.stdout.strip() == "False"


def test_the_child_leaves_when_its_parent_is_killed():
    code = textwrap.dedent("""
        import sys, time
        from rpf_fly.mocap.motioncapture_source import MotioncaptureSource
        s = MotioncaptureSource("mock", options={"rigid_bodies": "cf1(0,0,0,1,0,0,0)"})
        print(s.pid, flush=True)
        time.sleep(60)
    """)
    parent = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    try:
        child = int(parent.stdout.readline())
        os.kill(child, 0)
        parent.kill()
        parent.wait(5)
        assert gone(child), "the library's process outlived the flight"
    finally:
        parent.kill()
        parent.stdout.close()


def test_connect_gives_up_in_one_line_when_nothing_answers():
    silent = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    silent.bind(("127.0.0.1", 0))
    with silent:
        with pytest.raises(MotioncaptureUnavailable) as info:
            MotioncaptureSource(
                "optitrack", "127.0.0.1", {"port_command": silent.getsockname()[1]}, connect_timeout_s=0.5
            )
    assert str(info.value) == (
        "motioncapture optitrack at 127.0.0.1: no answer within 0.5 s (is the system "
        "streaming, and this host on its network?)"
    )


def test_a_crash_while_connecting_is_one_line():
    """libmotioncapture 1.1 segfaults on a NatNet 4.2 MODELDEF with two rigid bodies (docs/mocap.md)."""
    poses = {f"cf{i}": ((0.1 * i, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0), True) for i in (1, 2)}
    with NatNetServer(lambda: poses, version="4.2", multicast=True, rate_hz=50) as server:
        with pytest.raises(MotioncaptureUnavailable) as info:
            MotioncaptureSource("optitrack", "127.0.0.1", {"port_command": server.command_port})
    assert str(info.value).startswith(
        "motioncapture optitrack at 127.0.0.1: the library's process died while connecting (killed by SIGSEGV)"
    )
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("system", ["nokov", "fzmotion", "motionanalysis", "optitrack_closed_source"])
def test_a_type_this_build_lacks_is_one_line_naming_the_wheels_types(system):
    with pytest.raises(MotioncaptureUnavailable) as info:
        MotioncaptureSource(system, connect_timeout_s=2.0)
    where = f"motioncapture {system}" + (" at 127.0.0.1" if system == "optitrack_closed_source" else "")
    assert str(info.value) == (
        f"{where}: this motioncapture build has no {system!r} (the PyPI wheel of 1.1 has "
        f"{', '.join(WHEEL_TYPES)}): RuntimeError: Unknown motion capture type!"
    )


def test_the_wheel_has_the_types_the_table_says():
    """Each wheel type is known to the installed library: it fails to connect, but not as an unknown type."""
    for system in ("qualisys", "vicon"):
        with pytest.raises(MotioncaptureUnavailable) as info:
            MotioncaptureSource(system, "127.0.0.1", connect_timeout_s=1.0)
        assert "Unknown motion capture type" not in str(info.value), info.value


def test_a_missing_package_is_one_line_naming_the_extra(monkeypatch):
    monkeypatch.setattr(source_module, "library_installed", lambda: False)
    with pytest.raises(MotioncaptureUnavailable) as info:
        MotioncaptureSource("mock")
    assert str(info.value) == MISSING_LIBRARY
    assert "pip install 'rpf_fly[motioncapture]'" in MISSING_LIBRARY


def test_a_package_that_fails_to_import_in_the_child_is_the_same_line(tmp_path, monkeypatch):
    (tmp_path / "motioncapture.py").write_text("raise ImportError('no motioncapture here')\n")
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(tmp_path), *sys.path]))
    with pytest.raises(MotioncaptureUnavailable) as info:
        MotioncaptureSource("mock")
    assert str(info.value) == MISSING_LIBRARY


def test_the_extra_is_installed_where_the_tests_run():
    """The motioncapture tests need the real package: CI installs the extra, so a missing wheel fails here, loudly,
    with the reason, instead of as a skip."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        installed = version("motioncapture")
    except PackageNotFoundError:
        pytest.fail("the motioncapture package is missing: pip install -e '.[dev,train,live,motioncapture]'")
    assert installed == "1.1"
    assert source_module.library_installed()


def test_ci_and_the_readme_install_the_extra():
    root = Path(__file__).resolve().parents[2]
    assert '-e ".[dev,train,live,motioncapture]"' in (root / ".ci" / "run").read_text()
    assert 'pip install -e ".[dev,train,live,motioncapture]" && python -m pytest' in (root / "README.md").read_text()
    assert 'motioncapture = ["motioncapture==1.1"]' in (root / "pyproject.toml").read_text()
