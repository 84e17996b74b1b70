"""The fault hooks of a dry run through the real paths: the NatNet client on loopback for the mocap faults, real
cflib over the fake radio for the radio and drone faults; each with the simulated drones in this process
(`FakeWorld`, `SimulatedBodies`) and in their own process (`WorldProcess`), through `DryRun`'s hooks by name.
The figures are those of docs/radio.md, "Fault hooks"."""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from cflib.crazyflie import Crazyflie
from cflib.crazyflie.log import LogConfig
from cflib.crazyflie.syncCrazyflie import SyncCrazyflie
from polling import wait_for

from rpf_fly.emulator.fake_firmware import REBOOT_BOOT_S
from rpf_fly.emulator.vehicle_figures import BLIND_DRIFT_MAX_M_S2
from rpf_fly.flight.dry_run import DryRun, StartFault
from rpf_fly.mission import parse_mission
from rpf_fly.mocap.frame import MocapFrame

MISSION = """\
name: faults-2
arena: {x: [-2.0, 2.0], y: [-2.0, 2.0], z: [0.0, 1.5]}
flight: {height: 0.5, speed: 0.5, rate_hz: 10, goal_tolerance: 0.1, takeoff_s: 1.0, land_s: 1.0, timeout_s: 30}
planner: {kind: apf, margin: 0}
mocap: {kind: sim, rate_hz: 100}
dry_run: {dynamics: first-order}
drones:
  - {name: cf1, uri: radio://0/80/2M/E7E7E7E701, start: [0.5, -0.5], goal: [1.0, -0.5]}
  - {name: cf2, uri: radio://0/80/2M/E7E7E7E702, start: [-0.5, 0.5], goal: [-1.0, 0.5]}
"""
"""The hooks' figures (docs/radio.md) are the first-order model's: its gust offset is worked out in closed form."""
START = {"cf1": (0.5, -0.5, 0.0), "cf2": (-0.5, 0.5, 0.0)}


@pytest.fixture(params=[False, True], ids=["in-process", "child-process"])
def rig(request: pytest.FixtureRequest, toc_cache: Path) -> Iterator[DryRun]:
    """A dry run of two drones on the ground at their starts, mocap over NatNet on loopback; a lossless radio
    (``radio_loss=None``), so each hook's figures are its own: the packet-loss test counts every lost attempt, and
    a burst would lower the link quality it expects back at 100 % (the hook over bursts: test_burst_loss.py)."""
    with DryRun(parse_mission(MISSION), process=request.param, cache_dir=toc_cache, radio_loss=None) as dry_run:
        yield dry_run


def frames(rig: DryRun, seconds: float) -> list[MocapFrame]:
    """Every frame the dry run's NatNet client delivers for ``seconds``."""
    out, deadline = [], time.monotonic() + seconds
    assert rig.mocap is not None
    while time.monotonic() < deadline:
        frame = rig.mocap.receive(0.05)
        if frame is not None:
            out.append(frame)
    return out


def connect(rig: DryRun, name: str, cache: Path, lost: list[str] | None = None) -> SyncCrazyflie:
    cf = Crazyflie(rw_cache=str(cache))
    if lost is not None:
        cf.connection_lost.add_callback(lambda _uri, message: lost.append(message))
    scf = SyncCrazyflie(rig.uris[name], cf=cf)
    scf.open_link()
    return scf


class Mocap:
    """Streams the dry run's mocap poses of one drone to its estimator as extpos at 50 Hz (what the flight loop
    does), until stopped."""

    def __init__(self, rig: DryRun, name: str, scf: SyncCrazyflie) -> None:
        self._stop = threading.Event()
        body = rig.bodies[name]

        def run() -> None:
            while not self._stop.wait(0.02):
                position = rig.poses()[body][0]
                scf.cf.extpos.send_extpos(*position)

        self._thread = threading.Thread(target=run, daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(2.0)


def hover(rig: DryRun, name: str, scf: SyncCrazyflie, height: float = 0.5) -> tuple[float, float, float]:
    """Take off with the high-level commander once the estimate has the mocap's position (the take-off keeps the
    estimated x, y), and settle; the hover position."""
    assert wait_for(lambda: math.dist(rig.snapshot(name).estimate, rig.snapshot(name).position) < 0.01, 2.0)
    time.sleep(0.05)  # the idle high-level commander takes the estimate at its next 10 ms tick
    scf.cf.high_level_commander.takeoff(height, 1.0)
    assert wait_for(lambda: rig.snapshot(name).position[2] > height - 0.02, 4.0)
    time.sleep(0.5)
    return rig.snapshot(name).position


# Mocap -----------------------------------------------------------------------------------------------------


def test_a_pose_jump_moves_the_served_pose_not_the_drone_and_ends(rig: DryRun) -> None:
    before = frames(rig, 0.2)[-1].bodies["cf1"]
    assert before.position == pytest.approx(START["cf1"], abs=1e-4) and before.valid
    rig.pose_jump("cf1", (0.3, -0.2, 0.1), 0.6)
    time.sleep(0.05)  # frames already on their way
    during = frames(rig, 0.4)
    assert len(during) > 20
    for frame in during:
        assert frame.bodies["cf1"].position == pytest.approx((0.8, -0.7, 0.1), abs=1e-4)
        assert frame.bodies["cf1"].valid  # a marker swap looks tracked
        assert frame.bodies["cf2"].position == pytest.approx(START["cf2"], abs=1e-4)
    assert rig.snapshot("cf1").position == pytest.approx(START["cf1"], abs=1e-6)  # the drone did not move
    time.sleep(0.25)
    after = frames(rig, 0.2)
    assert after and all(f.bodies["cf1"].position == pytest.approx(START["cf1"], abs=1e-4) for f in after)


def yaw_deg_of(quaternion: tuple[float, float, float, float]) -> float:
    qx, qy, qz, qw = quaternion
    return math.degrees(math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz)))


def test_an_orientation_flip_turns_the_served_orientation_not_the_drone_and_ends(rig: DryRun) -> None:
    before = frames(rig, 0.2)[-1].bodies["cf1"]
    assert yaw_deg_of(before.quaternion) == pytest.approx(0.0, abs=1e-3) and before.valid
    rig.orientation_flip("cf1", 90.0, 0.6)
    time.sleep(0.05)  # frames already on their way
    during = frames(rig, 0.4)
    assert len(during) > 20
    for frame in during:
        assert yaw_deg_of(frame.bodies["cf1"].quaternion) == pytest.approx(90.0, abs=1e-3)
        assert frame.bodies["cf1"].position == pytest.approx(START["cf1"], abs=1e-4)  # where it is
        assert frame.bodies["cf1"].valid  # a wrong fit looks tracked
        assert yaw_deg_of(frame.bodies["cf2"].quaternion) == pytest.approx(0.0, abs=1e-3)
    assert rig.snapshot("cf1").yaw_deg == pytest.approx(0.0, abs=1e-6)  # the drone did not turn
    time.sleep(0.25)
    after = frames(rig, 0.2)
    assert after and all(yaw_deg_of(f.bodies["cf1"].quaternion) == pytest.approx(0.0, abs=1e-3) for f in after)


def first_frame_showing(rig: DryRun, x: float, timeout_s: float) -> float:
    """Seconds until a frame shows cf1 beyond ``x`` (the step it made)."""
    start = time.monotonic()
    assert rig.mocap is not None
    while time.monotonic() - start < timeout_s:
        frame = rig.mocap.receive(0.05)
        if frame is not None and frame.bodies["cf1"].position[0] > x:
            return frame.receive_time_s - start
    raise AssertionError(f"no frame showed cf1 beyond x = {x} within {timeout_s} s")


def test_a_mocap_delay_serves_old_poses_at_the_frame_rate_then_ends(rig: DryRun) -> None:
    frames(rig, 0.2)
    rig.mocap_delay(0.25, 1.5)
    rig.world.disturb(rig.addresses["cf1"], (0.3, 0.0, 0.0))  # a step of the true pose (on the floor it stays)
    assert 0.2 < first_frame_showing(rig, 0.7, 1.0) < 0.33  # it shows a delay later ...
    steady = frames(rig, 0.5)
    assert len(steady) >= 40  # ... while frames keep coming at 100 Hz (latency, not a frame-rate drop)
    assert rig.snapshot("cf1").position[0] == pytest.approx(0.8, abs=1e-6)
    time.sleep(1.0)  # the delay is over
    rig.world.disturb(rig.addresses["cf1"], (0.3, 0.0, 0.0))
    assert first_frame_showing(rig, 1.0, 1.0) < 0.1


# Radio -----------------------------------------------------------------------------------------------------


def test_packet_loss_lowers_link_quality_and_loses_acks_then_recovers(rig: DryRun, toc_cache: Path) -> None:
    quality: list[tuple[float, float]] = []
    lost: list[str] = []
    scf = connect(rig, "cf1", toc_cache, lost)
    address = rig.addresses["cf1"]
    try:
        scf.cf.link_statistics.link_quality_updated.add_callback(lambda q: quality.append((time.monotonic(), q)))
        time.sleep(1.2)
        assert quality[-1][1] == pytest.approx(100.0)
        before = rig.world.radio_counters(address)
        start = time.monotonic()
        rig.packet_loss("cf1", 0.8, 2.0)  # 2 s: the link's packets of a loaded machine still fill cflib's window
        time.sleep(2.0)
        during = rig.world.radio_counters(address)
        worst = min(q for t, q in quality if t > start)
        assert worst < 92.0  # 80 % of attempts lost: 1.2 retries an ack on average (quality 88)
        assert during.lost_transactions - before.lost_transactions > 20  # 41 % of transactions lost ...
        assert during.lost_attempts - before.lost_attempts > 100
        assert not lost and scf.cf.is_connected()  # ... never 100 in a row
        time.sleep(0.3)
        ended = rig.world.radio_counters(address)
        time.sleep(1.2)
        assert rig.world.radio_counters(address).lost_attempts == ended.lost_attempts  # the fault expired
        assert quality[-1][1] == pytest.approx(100.0)
    finally:
        scf.close_link()


# Drone -----------------------------------------------------------------------------------------------------


def test_a_gust_pushes_a_hovering_drone_off_by_the_documented_amount_and_it_comes_back(
    rig: DryRun, toc_cache: Path
) -> None:
    scf = connect(rig, "cf1", toc_cache)
    mocap = Mocap(rig, "cf1", scf)
    try:
        x0, y0, z0 = hover(rig, "cf1", scf)
        rig.gust("cf1", (1.5, 0.0, 0.0), 2.5)
        time.sleep(2.2)
        snap = rig.snapshot("cf1")
        assert snap.gust_m_s2 == (1.5, 0.0, 0.0)
        assert snap.position[0] - x0 == pytest.approx(0.176, abs=0.015)  # 0.1175 m per m/s^2, 97 % after 2 s
        assert snap.position[1:] == pytest.approx((y0, z0), abs=0.01)
        assert math.dist(snap.estimate, snap.position) < 0.01  # the estimate follows the push (IMU + extpos)
        time.sleep(2.3)
        snap = rig.snapshot("cf1")
        assert snap.gust_m_s2 == (0.0, 0.0, 0.0) and snap.position == pytest.approx((x0, y0, z0), abs=0.015)
    finally:
        mocap.stop()
        scf.close_link()


def test_estimator_divergence_drifts_the_true_drone_opposite_to_its_estimate(rig: DryRun, toc_cache: Path) -> None:
    scf = connect(rig, "cf1", toc_cache)
    mocap = Mocap(rig, "cf1", scf)
    estimates: list[tuple[float, float, float]] = []
    config = LogConfig(name="estimate", period_in_ms=100)
    for axis in "xyz":
        config.add_variable(f"stateEstimate.{axis}", "float")
    config.data_received_cb.add_callback(
        lambda _t, data, _c: estimates.append(tuple(data[f"stateEstimate.{a}"] for a in "xyz"))
    )
    try:
        scf.cf.log.add_config(config)
        config.start()
        start = hover(rig, "cf1", scf)
        rig.estimator_divergence("cf1", 0.2)
        time.sleep(0.6)  # past the controller's lag
        one, t_one = rig.snapshot("cf1"), time.monotonic()
        time.sleep(1.5)
        two, t_two = rig.snapshot("cf1"), time.monotonic()
        assert two.estimator_diverging
        drift = (two.position[0] - one.position[0], two.position[1] - one.position[1])
        assert math.hypot(*drift) / (t_two - t_one) == pytest.approx(0.2, abs=0.03)  # the true drone at 0.2 m/s
        runaway = (two.estimate[0] - two.position[0], two.estimate[1] - two.position[1])
        cosine = (drift[0] * runaway[0] + drift[1] * runaway[1]) / (math.hypot(*drift) * math.hypot(*runaway))
        assert cosine < -0.98  # ... opposite to where its estimate ran
        assert math.dist(two.estimate, start) < 0.08  # while the estimate holds the setpoint (extpos ignored)
        telemetry = estimates[-1]  # the diverged estimate is what cflib receives
        assert math.dist(telemetry, two.estimate) < 0.05 and math.dist(telemetry, two.position) > 0.3
    finally:
        mocap.stop()
        scf.close_link()


def open_fails(rig: DryRun, name: str, cache: Path) -> str:
    """The error of a connection attempt that must fail (on a helper thread: a hang shows as a failure)."""
    result: list[str] = []

    def run() -> None:
        scf = SyncCrazyflie(rig.uris[name], cf=Crazyflie(rw_cache=str(cache)))
        try:
            scf.open_link()
            result.append("connected")
            scf.close_link()
        except Exception as exc:  # noqa: BLE001 - the failure is the result
            result.append(str(exc))

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    thread.join(1.0)
    return result[0] if result else "hung"


def test_a_reboot_in_flight_falls_fails_the_link_and_a_new_connection_finds_a_fresh_drone(
    rig: DryRun, toc_cache: Path
) -> None:
    lost: list[str] = []
    scf = connect(rig, "cf1", toc_cache, lost)
    mocap = Mocap(rig, "cf1", scf)
    try:
        scf.cf.param.set_value("stabilizer.estimator", 2)
        x0, y0, _ = hover(rig, "cf1", scf)
        rig.reboot("cf1")
        rebooted = time.monotonic()
        snap = rig.snapshot("cf1")
        assert not snap.motors_on and snap.booting and not snap.powered
        assert wait_for(lambda: bool(lost), 1.0) and lost[0] == "Too many packets lost"  # cflib's own error
        mocap.stop()
        assert wait_for(lambda: rig.snapshot("cf1").position[2] == 0.0, 1.0)  # fell (0.32 s from 0.5 m)
        assert time.monotonic() - rebooted < 0.8
        assert rig.snapshot("cf1").position[:2] == pytest.approx((x0, y0), abs=0.01)  # straight down
        assert "Too many packets lost" in open_fails(rig, "cf1", toc_cache)  # silent while it boots
    finally:
        mocap.stop()
        scf.close_link()
    assert wait_for(lambda: not rig.snapshot("cf1").booting, REBOOT_BOOT_S + 0.5)
    booted = time.monotonic()
    assert booted - rebooted > REBOOT_BOOT_S - 0.1
    fresh = connect(rig, "cf1", toc_cache)
    try:
        assert fresh.cf.param.get_value("stabilizer.estimator") == "0"  # default parameters again
        assert wait_for(lambda: rig.snapshot("cf1").supervisor_state == "Ready to fly", 0.5)  # (auto-)armed anew
        snap = rig.snapshot("cf1")
        assert snap.boots == 1 and snap.powered and not snap.motors_on and not snap.flying
        assert snap.transitions[0].old.value == "Pre-flight checks not passed"  # a fresh supervisor
        assert snap.position == pytest.approx((x0, y0, 0.0), abs=0.01)  # on the floor where it fell
        # the estimator restarted at kalman.initial* and has dead-reckoned since, without mocap (fake_vehicle.py)
        blind_s = time.monotonic() - booted + 0.1  # the wait above polls
        assert math.dist(snap.estimate, (0.0, 0.0, 0.0)) < 0.01 + 0.5 * BLIND_DRIFT_MAX_M_S2 * blind_s**2, blind_s
    finally:
        fresh.close_link()


# At power-on -----------------------------------------------------------------------------------------------


@pytest.mark.parametrize("process", [False, True], ids=["in-process", "child-process"])
def test_start_faults_turn_and_move_a_drone_before_power_on(process: bool, toc_cache: Path) -> None:
    faults = {"cf1": StartFault(yaw_deg=120.0, offset_m=(0.2, -0.1))}
    with DryRun(parse_mission(MISSION), start_faults=faults, process=process, cache_dir=toc_cache) as rig:
        snap = rig.snapshot("cf1")
        assert snap.position == pytest.approx((0.7, -0.6, 0.0)) and snap.yaw_deg == pytest.approx(120.0)
        assert snap.estimate_yaw_deg == pytest.approx(0.0)  # kalman.initialYaw, as a real Crazyflie
        body = frames(rig, 0.2)[-1].bodies["cf1"]
        assert body.position == pytest.approx((0.7, -0.6, 0.0), abs=1e-4)
        assert 2.0 * math.degrees(math.atan2(body.quaternion[2], body.quaternion[3])) == pytest.approx(120.0, abs=0.1)
        assert rig.snapshot("cf2").position == pytest.approx(START["cf2"])
    with pytest.raises(ValueError, match="cf9"):
        DryRun(parse_mission(MISSION), start_faults={"cf9": StartFault(yaw_deg=10.0)})
