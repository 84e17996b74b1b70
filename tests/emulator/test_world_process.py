"""Simulated drones in a process of their own (the dry run's default): real cflib in this process reaches them
through the fake radio over UDP, the fault hooks go over the control connection, and the child never outlives its
parent or a Ctrl-C."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
from cflib.crazyflie import Crazyflie
from cflib.crazyflie.syncCrazyflie import SyncCrazyflie
from polling import wait_for

from rpf_fly.emulator import fake_radio
from rpf_fly.emulator.fake_world import FakeDroneConfig
from rpf_fly.emulator.remote_world import RemoteWorld
from rpf_fly.emulator.world_process import WorldProcess
from rpf_fly.mission.model import CircleObstacle

A1, A2 = 0xE7E7E7E701, 0xE7E7E7E702


def uri(address: int) -> str:
    return f"fake://0/80/2M/{address:010X}"


@pytest.fixture
def child():  # type: ignore[no-untyped-def]
    drones = {A1: FakeDroneConfig.at(0.0, 0.0), A2: FakeDroneConfig.at(1.0, 0.5, initial_vbat_v=3.5)}
    process = WorldProcess(drones, {A1: "cf1", A2: "cf2"}, natnet=None)
    fake_radio.register(RemoteWorld(process.radio, process.addresses))
    yield process
    fake_radio.unregister()
    process.close()


def test_cflib_flies_a_drone_of_the_child_process(child, tmp_path: Path) -> None:
    with SyncCrazyflie(uri(A1), cf=Crazyflie(rw_cache=str(tmp_path))) as scf:
        cf = scf.cf
        assert cf.param.get_value("stabilizer.estimator") is not None  # TOC and parameters over the UDP radio
        cf.high_level_commander.takeoff(0.5, 1.0)
        assert wait_for(lambda: child.snapshot(A1).position[2] > 0.45, 5.0)
        cf.high_level_commander.land(0.0, 1.0)
        assert wait_for(lambda: child.snapshot(A1).position[2] < 0.02, 5.0)
    assert child.snapshot(A2).position[:2] == pytest.approx((1.0, 0.5))  # the other drone never moved
    assert child.snapshot(A1).toc_item_requests > 0


def test_obstacles_and_truth_reach_across_the_processes(tmp_path: Path) -> None:
    """The mission's obstacles go to the child's world with its settings (a drone flown into one crashes there);
    the child's truth samples, one per world step stamped with its ``time.monotonic()``, come back in batches."""
    process = WorldProcess(
        {A1: FakeDroneConfig.at(0.0, 0.0), A2: FakeDroneConfig.at(0.0, 1.0)},
        {A1: "cf1", A2: "cf2"},
        natnet=None,
        obstacles=[CircleObstacle((1.0, 0.0), 0.1)],
    )
    fake_radio.register(RemoteWorld(process.radio, process.addresses))
    try:
        process.truth_samples()
        with SyncCrazyflie(uri(A1), cf=Crazyflie(rw_cache=str(tmp_path))) as scf:
            scf.cf.high_level_commander.takeoff(0.5, 1.0)
            assert wait_for(lambda: process.snapshot(A1).position[2] > 0.48, 5.0)
            scf.cf.high_level_commander.go_to(2.0, 0.0, 0.5, 0.0, 2.0)
            assert wait_for(lambda: process.snapshot(A1).crashed, 5.0)
            time.sleep(0.5)
        snap = process.snapshot(A1)
        assert snap.crash_reason == "obstacle" and snap.locked and snap.position[2] == 0.0
        samples = process.truth_samples() + process.truth_samples()  # the second call brings only what is new
        stamps = [t for t, _ in samples]
        assert stamps == sorted(stamps) and stamps[-1] <= time.monotonic() and len(samples) > 200
        periods = sorted(b - a for a, b in zip(stamps, stamps[1:]))
        assert periods[len(periods) // 2] == pytest.approx(0.01, abs=0.002)  # every world step
        assert all(set(states) == {A1, A2} for _, states in samples)
        flying = [s[A1] for _, s in samples if s[A1][2]]
        assert flying and all(not crashed for _, _, _, crashed, _ in flying)
        position, yaw, motors, crashed, estimate = samples[-1][1][A1]
        assert crashed and not motors and position == snap.position and estimate == pytest.approx(position)
        assert samples[-1][1][A2] == ((0.0, 1.0, 0.0), 0.0, False, False, (0.0, 1.0, 0.0))  # the other stayed put
    finally:
        fake_radio.unregister()
        process.close()


def test_a_dropped_link_fails_cflib_with_its_usual_error(child, tmp_path: Path) -> None:
    errors: list[str] = []
    cf = Crazyflie(rw_cache=str(tmp_path))
    cf.connection_lost.add_callback(lambda _uri, message: errors.append(message))
    with SyncCrazyflie(uri(A2), cf=cf):
        child.drop_link(A2)
        assert wait_for(lambda: bool(errors), 5.0)
    assert errors[0] == "Too many packets lost"


def test_unknown_address_fails_to_connect(child, tmp_path: Path) -> None:
    scf = SyncCrazyflie(uri(0xE7E7E7E7AA), cf=Crazyflie(rw_cache=str(tmp_path)))
    with pytest.raises(Exception, match="Too many packets lost"):
        scf.open_link()


def test_hooks_and_bad_calls_over_the_control_connection(child) -> None:
    poses = child.poses()
    assert set(poses) == {"cf1", "cf2"} and poses["cf2"][0][:2] == pytest.approx((1.0, 0.5)) and poses["cf2"][2]
    child.hide("cf2", 5.0)
    assert child.poses()["cf2"][2] is False and child.poses()["cf1"][2] is True
    child.blackout(5.0)
    assert not any(tracked for _, _, tracked in child.poses().values())
    with pytest.raises(RuntimeError, match="snapshot failed: KeyError"):
        child.snapshot(0xE7E7E7E7AA)
    assert child.snapshot(A2).vbat_v < 3.6  # the child stays up after a bad call (cf2 has a low battery)


def test_the_child_ignores_sigint(child) -> None:
    os.kill(child._process.pid, signal.SIGINT)  # noqa: SLF001 - what a Ctrl-C in a terminal does to the group
    time.sleep(0.3)
    assert child._process.poll() is None  # noqa: SLF001
    assert set(child.poses()) == {"cf1", "cf2"}


def test_the_child_exits_when_its_parent_is_killed() -> None:
    parent = subprocess.Popen(
        [
            sys.executable,
            "-c",
            textwrap.dedent("""
        import sys, time
        from rpf_fly.emulator.fake_world import FakeDroneConfig
        from rpf_fly.emulator.world_process import WorldProcess
        process = WorldProcess({0xE7E7E7E701: FakeDroneConfig.at(0.0, 0.0)}, {0xE7E7E7E701: "cf1"})
        print(process._process.pid, flush=True)
        time.sleep(60)
    """),
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        pid = int(parent.stdout.readline())  # type: ignore[union-attr]
        os.kill(parent.pid, signal.SIGKILL)
        parent.wait(5)
        assert wait_for(lambda: not _alive(pid), 10.0), "the simulated drones outlived their parent"
    finally:
        if parent.poll() is None:
            parent.kill()


HOVERING_PARENT = """
import sys, time
from cflib.crazyflie import Crazyflie
from cflib.crazyflie.syncCrazyflie import SyncCrazyflie
from rpf_fly.emulator import fake_radio
from rpf_fly.emulator.fake_world import FakeDroneConfig
from rpf_fly.emulator.remote_world import RemoteWorld
from rpf_fly.emulator.world_process import WorldProcess
A1 = 0xE7E7E7E701
process = WorldProcess({A1: FakeDroneConfig.at(0.0, 0.0)}, {A1: "cf1"}, natnet=None, names={A1: "cf1"},
                       exit_report=sys.argv[1], orphan_cap_s=float(sys.argv[2]))
fake_radio.register(RemoteWorld(process.radio, process.addresses))
scf = SyncCrazyflie("fake://0/80/2M/E7E7E7E701", cf=Crazyflie(rw_cache=sys.argv[3]))
scf.open_link()
scf.cf.high_level_commander.takeoff(0.5, 1.0)  # a high-level plan: no setpoint watchdog
while process.snapshot(A1).position[2] < 0.45:
    time.sleep(0.05)
print(process.pid, flush=True)
time.sleep(60)
"""


def test_an_orphan_whose_drone_hovers_on_a_high_level_plan_exits_at_its_cap(tmp_path: Path) -> None:
    """The firmware's high-level commander has no watchdog: a drone that took off with it hovers on after its
    ground station died. The orphaned child must not linger for that: it reports the hovering drone at its cap and
    exits."""
    report = tmp_path / "exit.json"
    cap_s = 2.0
    parent = subprocess.Popen(
        [sys.executable, "-c", HOVERING_PARENT, str(report), str(cap_s), str(tmp_path)],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        pid = int(parent.stdout.readline())  # type: ignore[union-attr]
        os.kill(parent.pid, signal.SIGKILL)
        killed = time.monotonic()
        parent.wait(5)
        assert wait_for(lambda: not _alive(pid), cap_s + 3.0), "the orphaned simulated drones outlived their cap"
        gone = time.monotonic() - killed
    finally:
        if parent.poll() is None:
            parent.kill()
    assert cap_s <= gone < cap_s + 1.5
    data = json.loads(report.read_text())
    assert data["capped"] and not data["all_down"] and data["cap_s"] == cap_s and data["elapsed_s"] >= cap_s
    drone = data["drones"]["cf1"]
    assert drone["motors_on"] and not drone["at_rest"] and drone["motors_off_after_s"] is None
    assert abs(drone["z"] - 0.5) < 0.02 and drone["control_source"] == "high-level"
    assert drone["supervisor_state"] == "Flying" and not drone["locked"]


FORKING_PARENT = """
import os, sys, time
from rpf_fly.emulator.fake_world import FakeDroneConfig
from rpf_fly.emulator.world_process import WorldProcess
process = WorldProcess({0xE7E7E7E701: FakeDroneConfig.at(0.0, 0.0)}, {0xE7E7E7E701: "cf1"}, natnet=None,
                       exit_report=sys.argv[1])
holder = os.fork()
if holder == 0:  # inherits the control connection: the parent's death does not close it
    time.sleep(30)
    os._exit(0)
print(process.pid, holder, flush=True)
time.sleep(60)
"""


def test_an_orphan_notices_its_parent_is_gone_when_the_connection_stays_open(tmp_path: Path) -> None:
    """A helper the flight's process forked holds the control connection open after the parent was killed: the
    child notices by its parent pid instead, reports the drones (on the floor: at once) and exits."""
    report = tmp_path / "exit.json"
    parent = subprocess.Popen([sys.executable, "-c", FORKING_PARENT, str(report)], stdout=subprocess.PIPE, text=True)
    holder = 0
    try:
        pid, holder = map(int, parent.stdout.readline().split())  # type: ignore[union-attr]
        os.kill(parent.pid, signal.SIGKILL)
        parent.wait(5)
        assert wait_for(lambda: not _alive(pid), 3.0), "the orphan did not notice its parent was gone"
        assert _alive(holder)  # the connection was still open
    finally:
        if parent.poll() is None:
            parent.kill()
        if holder:
            os.kill(holder, signal.SIGKILL)
    data = json.loads(report.read_text())
    assert data["detected_by"] == "the parent process is gone (the child was re-parented)"
    assert data["all_down"] and data["elapsed_s"] < 0.1
    drone = data["drones"]["E7E7E7E701"]  # no names given: by address
    assert drone["at_rest"] and drone["motors_off_after_s"] == 0.0 and drone["at_rest_after_s"] == 0.0


def _alive(pid: int) -> bool:
    try:
        finished, _ = os.waitpid(pid, os.WNOHANG)  # not our child: raises ChildProcessError
    except ChildProcessError:
        finished = 0
    if finished:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return Path(f"/proc/{pid}/stat").exists() and Path(f"/proc/{pid}/stat").read_text().split()[2] != "Z"


def test_killed_simulated_drones_fail_the_links_at_once(child, tmp_path: Path) -> None:
    """Link loss, the dry-run way: the drones' process dies; cflib reports the usual error within a second."""
    errors: list[tuple[float, str]] = []
    cf = Crazyflie(rw_cache=str(tmp_path))
    cf.connection_lost.add_callback(lambda _uri, message: errors.append((time.monotonic(), message)))
    with SyncCrazyflie(uri(A1), cf=cf):
        killed = time.monotonic()
        child._process.kill()  # noqa: SLF001
        assert wait_for(lambda: bool(errors), 5.0)
    when, message = errors[0]
    assert message == "Too many packets lost" and when - killed < 1.5  # a transaction in flight waits out 0.5 s
