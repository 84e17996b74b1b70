"""`CflibBackend` over the fake radio (real cflib underneath)."""

from __future__ import annotations

import copy
import math
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from rpf_fly.emulator.fake_toc import value_size
from rpf_fly.emulator.fake_world import FakeDroneConfig, FakeWorld, RadioTiming
from rpf_fly.emulator.firmware_log import LOG_MAX_PAYLOAD
from rpf_fly.radio.backend import DroneBackend, PmState
from rpf_fly.radio.cflib_backend import CflibBackend
from rpf_fly.radio.cflib_telemetry import STATUS_VARIABLES, STATUS_VARIABLES_FLOAT, status_variables

MakeWorld = Callable[..., FakeWorld]


def address(index: int) -> int:
    return 0xE7E7E7E700 + index


def wait_for(condition: Callable[[], bool], timeout_s: float, poll_s: float = 0.02) -> bool:
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(poll_s)
    return True


def stream(seconds: float, send: Callable[[], object], period_s: float = 0.02) -> None:
    """Call `send` every `period_s` for `seconds`: a mocap (and setpoint) stream from the test thread."""
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        send()
        time.sleep(period_s)


@pytest.fixture
def backends() -> Iterator[Callable[..., CflibBackend]]:
    made: list[CflibBackend] = []

    def make(**kwargs: object) -> CflibBackend:
        backend = CflibBackend(**kwargs)  # type: ignore[arg-type]
        made.append(backend)
        return backend

    yield make
    for backend in made:
        backend.close()


def take_off_all(backend: CflibBackend, world: FakeWorld) -> None:
    """Every drone to 0.5 m with the high-level commander, and wait until the world has them there."""
    for name in backend.names():
        backend.takeoff(name, 0.5, 0.5)
    assert world.wait_until(lambda w: all(s.position[2] > 0.45 for s in w.snapshots().values()), 2.0)


def names_to_uris(world: FakeWorld) -> dict[str, str]:
    return {f"cf{i}": world.uri(a) for i, a in enumerate(world.addresses)}


def test_backend_implements_the_protocol() -> None:
    assert isinstance(CflibBackend(), DroneBackend)
    assert "reset_estimator" in dir(DroneBackend)


def test_status_block_fits_one_log_packet() -> None:
    for block in (STATUS_VARIABLES, STATUS_VARIABLES_FLOAT):
        assert sum(value_size(ctype) for _, ctype in block) <= LOG_MAX_PAYLOAD == 26
        assert ("stateEstimate.yaw", "float") in block


def test_the_controllers_target_is_in_the_telemetry_and_a_landing_holds_its_x_y(
    make_world: MakeWorld, toc_cache: Path, backends: Callable[..., CflibBackend]
) -> None:
    """The status block carries the firmware's controller target (`ctrltargetZ`, mm): the streamed setpoint while
    one streams, then the high-level landing's point, which keeps the x, y of the estimate when the land command
    arrived (the supervisor's tracking check of a landing reads it: docs/flight.md, *Tracking*). A firmware whose
    log TOC lacks the compressed groups gets the float block, without a target."""
    world = make_world(1)
    backend = backends(cache_dir=toc_cache)
    assert backend.connect(names_to_uris(world)) == {}
    take_off_all(backend, world)
    stream(1.5, lambda: backend.send_position_setpoint("cf0", 0.3, 0.1, 0.5, 0.0))
    assert wait_for(lambda: backend.state("cf0").target_m is not None, 1.0)
    assert backend.state("cf0").target_m == pytest.approx((0.3, 0.1, 0.5), abs=0.0015)
    backend.land("cf0", 0.0, 1.0)
    landed_at = time.monotonic()
    assert wait_for(lambda: (backend.state("cf0").estimate_stamp_s or 0.0) > landed_at + 0.3, 1.0)
    state = backend.state("cf0")
    assert state.target_m[:2] == pytest.approx(state.position_m[:2], abs=0.01)  # the estimate's x, y: it hovered
    assert state.target_m[:2] == pytest.approx((0.3, 0.1), abs=0.03)  # there
    assert 0.05 < state.target_m[2] < 0.45  # on the way down

    toc = copy.deepcopy(backend._drones["cf0"].scf.cf.log.toc)  # the real TOC cflib read from the firmware
    assert status_variables(toc) == STATUS_VARIABLES
    del toc.toc["ctrltargetZ"]  # a firmware without the compressed groups
    assert status_variables(toc) == STATUS_VARIABLES_FLOAT


def test_connects_ten_drones_and_reports_preflight_state(
    make_world: MakeWorld, toc_cache: Path, backends: Callable[..., CflibBackend]
) -> None:
    world = make_world(10)
    backend = backends(cache_dir=toc_cache)
    start = time.monotonic()
    assert backend.connect(names_to_uris(world)) == {}
    assert time.monotonic() - start < 3.0
    assert backend.names() == tuple(f"cf{i}" for i in range(10))
    assert wait_for(lambda: all(s.link.latency_ms is not None for s in backend.states().values()), 2.0)
    for i, state in enumerate(backend.states().values()):
        assert state.link.up and state.link.error is None and state.link.quality_pct == pytest.approx(100.0)
        assert 0.0 < state.link.latency_ms < 50.0
        assert state.battery.voltage_v == pytest.approx(4.15, abs=0.01) and not state.battery.low
        assert state.supervisor.armed and state.supervisor.can_fly and not state.supervisor.flying
        assert not state.supervisor.locked and not state.supervisor.tumbled and not state.supervisor.crashed
        assert state.position_m == pytest.approx((0.5 * i, 0.0, 0.0))
        params = world.snapshot(address(i)).params
        assert params["stabilizer.estimator"] == 2 and params["commander.enHighLevel"] == 1
    stamp = backend.state("cf4").telemetry_stamp_s
    assert wait_for(lambda: backend.state("cf4").telemetry_stamp_s > stamp, 0.5)  # 10 Hz status


def test_one_drones_failure_does_not_block_the_others(
    make_world: MakeWorld, toc_cache: Path, backends: Callable[..., CflibBackend]
) -> None:
    world = make_world(3)
    drones = names_to_uris(world)
    drones["ghost"] = world.uri(address(9))
    backend = backends(cache_dir=toc_cache)
    start = time.monotonic()
    errors = backend.connect(drones)
    assert time.monotonic() - start < 3.0
    assert list(errors) == ["ghost"] and "Too many packets lost" in errors["ghost"]
    ghost = backend.state("ghost")
    assert not ghost.link.up and "Too many packets lost" in ghost.link.error and ghost.battery is None
    assert not backend.takeoff("ghost", 0.5, 1.0) and not backend.send_position_setpoint("ghost", 0, 0, 0.5, 0)
    assert backend.emergency_stop("ghost") == {"ghost": "emergency stop not delivered: link down"}
    assert all(backend.state(n).link.up for n in ("cf0", "cf1", "cf2"))
    assert backend.takeoff("cf1", 0.4, 0.5)
    assert world.wait_until(lambda w: w.snapshot(address(1)).position[2] > 0.35, 2.0)
    with pytest.raises(KeyError):
        backend.state("nobody")


def test_flight_cycle_with_arming_streaming_hand_over_and_landing(
    make_world: MakeWorld, toc_cache: Path, backends: Callable[..., CflibBackend]
) -> None:
    world = make_world({address(i): FakeDroneConfig.at(0.5 * i, 0.0, auto_arm=False) for i in range(2)})
    backend = backends(cache_dir=toc_cache)
    assert backend.connect(names_to_uris(world)) == {}
    assert not backend.state("cf0").supervisor.armed and backend.state("cf0").supervisor.can_be_armed
    backend.takeoff("cf0", 0.5, 0.5)  # not armed: the firmware refuses
    for name in backend.names():
        assert backend.arm(name)
    assert wait_for(lambda: all(s.supervisor.armed and s.supervisor.can_fly for s in backend.states().values()), 1.0)
    assert world.snapshot(address(0)).hl_commands_rejected == 1
    for name in backend.names():
        assert backend.takeoff(name, 0.5, 0.8)
    assert wait_for(
        lambda: all(s.supervisor.flying and abs(s.position_m[2] - 0.5) < 0.02 for s in backend.states().values()), 2.5
    )
    for _ in range(20):  # 1 s at 20 Hz
        for i, name in enumerate(backend.names()):
            assert backend.send_position_setpoint(name, 0.5 * i + 0.2, 0.1, 0.6, 30.0)
        time.sleep(0.05)
    for i, name in enumerate(backend.names()):
        assert backend.state(name).position_m == pytest.approx((0.5 * i + 0.2, 0.1, 0.6), abs=0.03)
    assert world.snapshot(address(0)).yaw_deg == pytest.approx(30.0, abs=2.0)  # yaw in degrees
    notified = {i: world.snapshot(address(i)).packets_received[(7, 1)] for i in range(2)}  # connect, take-offs
    for name in backend.names():
        assert backend.hand_over(name, hold_duration_s=0.5)
    time.sleep(2.3)  # past the 2 s watchdog: the high-level commander holds the drones
    for i in range(2):
        snap = world.snapshot(address(i))
        assert snap.supervisor_state == "Flying" and snap.hl_state == "FLYING"
        assert snap.position == pytest.approx((0.5 * i + 0.2, 0.1, 0.6), abs=0.02)
        assert snap.packets_received[(7, 1)] == notified[i] + 1  # exactly one notify-setpoint-stop at the hand-over
    for name in backend.names():
        assert backend.land(name, 0.0, 0.8)
    assert wait_for(lambda: all(abs(s.position_m[2]) < 0.01 for s in backend.states().values()), 2.0)
    assert not any(world.snapshot(address(i)).motors_on for i in range(2))
    assert backend.stop("cf0") and world.snapshot(address(0)).hl_state == "IDLE"


def test_streaming_then_land_hands_over_with_notify(
    make_world: MakeWorld, toc_cache: Path, backends: Callable[..., CflibBackend]
) -> None:
    world = make_world(1)
    backend = backends(cache_dir=toc_cache)
    assert backend.connect(names_to_uris(world)) == {}
    backend.takeoff("cf0", 0.5, 0.5)
    assert world.wait_until(lambda w: w.snapshot(address(0)).position[2] > 0.45, 2.0)
    for _ in range(6):
        backend.send_position_setpoint("cf0", 0.1, 0.0, 0.5, 0.0)
        time.sleep(0.05)
    notified = world.snapshot(address(0)).packets_received[(7, 1)]  # at connect and after the take-off
    assert backend.land("cf0", 0.0, 0.6)
    assert world.wait_until(lambda w: w.snapshot(address(0)).hl_state == "LANDING", 0.5)
    assert world.wait_until(lambda w: w.snapshot(address(0)).position[2] == 0.0, 1.5)
    snap = world.snapshot(address(0))
    assert snap.packets_received[(7, 1)] == notified + 1 and not snap.locked  # one at the landing
    assert snap.position[0] == pytest.approx(0.1, abs=0.05)  # landed where it was, not dropped


@pytest.mark.parametrize("command", ["land", "hand_over", "go_to"])
def test_the_hand_over_from_streaming_never_cuts_the_motors(
    make_world: MakeWorld, toc_cache: Path, backends: Callable[..., CflibBackend], command: str
) -> None:
    """Leaving the stream for the high-level commander: the firmware tick between the two packets finds the drone
    holding its last setpoint. A slow radio (15 ms a transaction) puts one or two ticks between them every time; with
    notify-setpoint-stop sent first those ticks were motors-off (the idle high-level commander)."""
    world = make_world(1, timing=RadioTiming(transaction_s=0.015))
    backend = backends(cache_dir=toc_cache)
    assert backend.connect(names_to_uris(world)) == {}
    backend.takeoff("cf0", 0.5, 0.5)
    assert world.wait_until(lambda w: w.snapshot(address(0)).position[2] > 0.45, 3.0)
    for _ in range(10):
        backend.send_position_setpoint("cf0", 0.0, 0.0, 0.5, 0.0)
        time.sleep(0.03)
    world.truth_samples()  # from here on
    if command == "land":
        assert backend.land("cf0", 0.0, 1.0)
    elif command == "hand_over":
        assert backend.hand_over("cf0", 1.0)
    else:
        assert backend.go_to("cf0", (0.0, 0.0, 0.5), 0.0, 1.0)
    time.sleep(0.3)
    samples = world.truth_samples()
    assert len(samples) > 20
    motors = [drones[address(0)][2] for _, drones in samples]
    heights = [drones[address(0)][0][2] for _, drones in samples]
    assert all(motors), f"motors off in {motors.count(False)} of {len(motors)} steps of the hand-over"
    assert min(heights) > (0.3 if command == "land" else 0.45)  # 0.3 s into a 1 s landing from 0.5 m
    assert world.snapshot(address(0)).hl_state == ("LANDING" if command == "land" else "FLYING")


def test_link_loss_is_surfaced_per_drone(
    make_world: MakeWorld, toc_cache: Path, backends: Callable[..., CflibBackend]
) -> None:
    world = make_world(3)
    backend = backends(cache_dir=toc_cache)
    lost: list[tuple[str, str, float]] = []
    event = threading.Event()
    backend.add_link_lost_callback(lambda name, reason: (lost.append((name, reason, time.monotonic())), event.set()))
    assert backend.connect(names_to_uris(world)) == {}
    take_off_all(backend, world)
    dropped_at = time.monotonic()
    world.drop_link(address(1))
    assert event.wait(2.0)
    assert [(name, reason) for name, reason, _ in lost] == [("cf1", "Too many packets lost")]
    assert lost[0][2] - dropped_at < 1.0
    state = backend.state("cf1")
    assert not state.link.up and "Too many packets lost" in state.link.error and state.link.lost_at_s is not None
    assert not backend.send_position_setpoint("cf1", 0.0, 0.0, 0.5, 0.0) and not backend.land("cf1")
    stamps = {n: backend.state(n).telemetry_stamp_s for n in ("cf0", "cf2")}
    assert wait_for(lambda: all(backend.state(n).telemetry_stamp_s > stamps[n] for n in stamps), 0.5)
    assert backend.land("cf0", 0.0, 0.5) and backend.land("cf2", 0.0, 0.5)
    assert world.wait_until(
        lambda w: w.snapshot(address(0)).position[2] == 0.0 and w.snapshot(address(2)).position[2] == 0.0, 2.0
    )
    assert world.snapshot(address(1)).flying  # the lost drone hovers on under its high-level commander
    time.sleep(0.2)
    assert len(lost) == 1


def test_emergency_stop_one_then_all(
    make_world: MakeWorld, toc_cache: Path, backends: Callable[..., CflibBackend]
) -> None:
    world = make_world(3)
    backend = backends(cache_dir=toc_cache)
    assert backend.connect(names_to_uris(world)) == {}
    take_off_all(backend, world)
    assert backend.emergency_stop("cf1") == {}
    assert wait_for(lambda: backend.state("cf1").supervisor.locked, 1.0)
    assert world.wait_until(lambda w: w.snapshot(address(1)).position[2] == 0.0, 1.0)
    assert world.snapshot(address(0)).flying and world.snapshot(address(2)).flying
    assert backend.emergency_stop() == {}
    assert wait_for(
        lambda: all(s.supervisor.locked and not s.supervisor.flying for s in backend.states().values()), 1.0
    )
    # every drone down (a fall from 0.5 m takes about 0.3 s, more on a loaded machine's clock): then nothing that
    # follows the stop may spin a motor up again
    assert world.wait_until(
        lambda w: all(s.position[2] == 0.0 and not s.motors_on for s in w.snapshots().values()), 2.0
    )
    backend.takeoff("cf0", 0.5, 0.5)
    backend.send_position_setpoint("cf2", 0.0, 0.0, 0.5, 0.0)
    time.sleep(0.3)
    assert all(s.position[2] == 0.0 and not s.motors_on for s in world.snapshots().values())


def test_extpose_configures_and_feeds_the_estimator(
    make_world: MakeWorld, toc_cache: Path, backends: Callable[..., CflibBackend]
) -> None:
    world = make_world({address(0): FakeDroneConfig.at(1.0, 1.0, positioning="extpos")})
    backend = backends(cache_dir=toc_cache, use_extpose=True, ext_quat_std_dev=0.01, ext_pos_std_dev=0.002)
    assert backend.connect(names_to_uris(world)) == {}
    params = world.snapshot(address(0)).params
    assert params["locSrv.extQuatStdDev"] == pytest.approx(0.01) and params["locSrv.extPosStdDev"] == pytest.approx(
        0.002
    )
    # no mocap yet: the estimate started at kalman.initialX/Y/Z (0, 0, 0) and drifts with the IMU, far from the truth
    assert math.dist(backend.state("cf0").position_m, (1.0, 1.0, 0.0)) > 0.5
    assert backend.state("cf0").extpos_sent_s is None  # nothing fed it yet
    yaw = math.radians(45.0)
    quaternion = (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))
    stream(0.5, lambda: backend.send_extpose("cf0", (1.0, 1.0, 0.0), quaternion))
    assert world.snapshot(address(0)).estimate == pytest.approx((1.0, 1.0, 0.0), abs=1e-3)
    assert world.snapshot(address(0)).estimate_yaw_deg == pytest.approx(45.0, abs=1e-3)
    assert wait_for(lambda: backend.state("cf0").position_m == pytest.approx((1.0, 1.0, 0.0), abs=2e-3), 1.0)
    stream(0.5, lambda: backend.send_extpos("cf0", (1.2, 1.0, 0.0)))
    assert world.snapshot(address(0)).estimate == pytest.approx((1.2, 1.0, 0.0), abs=2e-3)
    sent = backend.state("cf0").extpos_sent_s  # its outbox handed them to its link: the estimate check's feed
    assert sent is not None and time.monotonic() - 0.3 < sent <= time.monotonic()
    assert world.snapshot(address(0)).estimate_yaw_deg == pytest.approx(45.0, abs=1e-3)  # extpos leaves yaw alone


def test_reset_estimators_and_low_battery(
    make_world: MakeWorld, toc_cache: Path, backends: Callable[..., CflibBackend]
) -> None:
    world = make_world({address(0): FakeDroneConfig(), address(1): FakeDroneConfig.at(0.5, 0.0, initial_vbat_v=3.1)})
    backend = backends(cache_dir=toc_cache, reset_estimators=True)
    start = time.monotonic()
    assert backend.connect(names_to_uris(world)) == {}
    assert 4.5 < time.monotonic() - start < 9.0  # ten samples at 2 Hz
    for i in range(2):
        snap = world.snapshot(address(i))
        assert snap.variance_m2 < 1e-3 and snap.params["kalman.resetEstimation"] == 0
    # the low drone has been below 3.2 V for more than 5 s (1 s boot + connect + reset)
    assert wait_for(lambda: backend.battery("cf1").pm_state is PmState.LOW_POWER, 1.0)
    assert backend.battery("cf1").low and backend.battery("cf1").voltage_v == pytest.approx(3.1, abs=0.01)
    assert not backend.battery("cf0").low


# The estimator: yaw and drift (fake_vehicle's model, the firmware's behaviour) --------------------------------

FACING_DEG = 120.0
"""True yaw of the drones below: powered on facing away from +x, where the yaw estimate starts (initialYaw 0)."""
GOAL = (0.3, 0.0, 0.5)
"""Position setpoint of the drones below (they stand at the origin)."""


def mocap_drone(world: FakeWorld, backend: CflibBackend, *, extpose: bool = False) -> Callable[[], object]:
    """A function that sends cf0 its true pose, as a mocap would: extpos (position only) or extpose."""

    def send() -> object:
        position, quaternion = world.true_poses()[address(0)]
        if extpose:
            return backend.send_extpose("cf0", position, quaternion)
        return backend.send_extpos("cf0", position)

    return send


def fly_to_goal(world: FakeWorld, backend: CflibBackend, mocap: Callable[[], object], seconds: float) -> float:
    """Stream the mocap and position setpoints to `GOAL` (yaw `FACING_DEG`) at 50 Hz for `seconds`; the largest
    distance between the estimate and the truth in the last second (metres). Not earlier: while the drone moves
    at 1 m/s an extpos that spent 10 ms on the (loaded) radio is a centimetre old, as a real mocap's would be."""
    worst = 0.0
    settled_from = time.monotonic() + seconds - 1.0

    def tick() -> None:
        nonlocal worst
        mocap()
        backend.send_position_setpoint("cf0", *GOAL, FACING_DEG)
        if time.monotonic() >= settled_from:
            snap = world.snapshot(address(0))
            worst = max(worst, math.dist(snap.estimate, snap.position))

    stream(seconds, tick)
    return worst


def facing_world(make_world: MakeWorld) -> FakeWorld:
    return make_world({address(0): FakeDroneConfig.at(0.0, 0.0, yaw_deg=FACING_DEG, positioning="extpos")})


def test_yaw_error_with_position_only_extpos_flies_off(
    make_world: MakeWorld, toc_cache: Path, backends: Callable[..., CflibBackend]
) -> None:
    world = facing_world(make_world)
    backend = backends(cache_dir=toc_cache)
    assert backend.connect(names_to_uris(world)) == {}
    mocap = mocap_drone(world, backend)
    stream(0.3, mocap)
    snap = world.snapshot(address(0))
    assert math.dist(snap.estimate, snap.position) < 0.01  # the position estimate is right...
    assert snap.estimate_yaw_deg == pytest.approx(0.0, abs=0.5) and snap.yaw_deg == pytest.approx(FACING_DEG)
    fly_to_goal(world, backend, mocap, 3.0)
    snap = world.snapshot(address(0))
    # ...but the controller pushes 120 degrees off: the drone spirals away from its setpoint (the classic fly-away)
    assert math.dist(snap.position, GOAL) > 0.5
    assert snap.supervisor_state == "Flying"


def test_reset_estimator_to_the_mocap_pose_cures_the_yaw_error(
    make_world: MakeWorld, toc_cache: Path, backends: Callable[..., CflibBackend]
) -> None:
    world = facing_world(make_world)
    backend = backends(cache_dir=toc_cache)
    assert backend.connect(names_to_uris(world)) == {}
    mocap = mocap_drone(world, backend)
    stream(0.3, mocap)
    assert world.snapshot(address(0)).estimate_yaw_deg == pytest.approx(0.0, abs=0.5)  # 120 degrees off
    position, _ = world.true_poses()[address(0)]
    start = time.monotonic()
    assert backend.reset_estimator("cf0", position, math.radians(FACING_DEG))
    assert time.monotonic() - start < 2.0  # five confirmed writes (ms), no 5 s wait for the variance
    params = world.snapshot(address(0)).params
    assert params["kalman.initialYaw"] == pytest.approx(math.radians(FACING_DEG), rel=1e-6)
    assert (params["kalman.initialX"], params["kalman.initialY"], params["kalman.initialZ"]) == pytest.approx(
        position, abs=1e-6
    )
    assert params["kalman.resetEstimation"] == 0  # the firmware clears the trigger when it resets
    assert world.snapshot(address(0)).estimate_yaw_deg == pytest.approx(FACING_DEG, abs=1e-3)
    worst = fly_to_goal(world, backend, mocap, 3.0)
    snap = world.snapshot(address(0))
    assert snap.position == pytest.approx(GOAL, abs=0.02), snap
    assert worst < 0.01


def test_extpose_corrects_the_yaw_estimate_and_the_drone_tracks(
    make_world: MakeWorld, toc_cache: Path, backends: Callable[..., CflibBackend]
) -> None:
    world = facing_world(make_world)
    backend = backends(cache_dir=toc_cache, use_extpose=True)
    assert backend.connect(names_to_uris(world)) == {}
    assert world.snapshot(address(0)).estimate_yaw_deg == pytest.approx(0.0, abs=0.5)
    mocap = mocap_drone(world, backend, extpose=True)
    stream(0.3, mocap)
    assert world.snapshot(address(0)).estimate_yaw_deg == pytest.approx(FACING_DEG, abs=1e-3)
    worst = fly_to_goal(world, backend, mocap, 3.0)
    snap = world.snapshot(address(0))
    assert snap.position == pytest.approx(GOAL, abs=0.02), snap
    assert worst < 0.01


def test_drone_state_yaw_is_the_estimate_in_degrees(
    make_world: MakeWorld, toc_cache: Path, backends: Callable[..., CflibBackend]
) -> None:
    world = facing_world(make_world)
    backend = backends(cache_dir=toc_cache)
    assert backend.connect(names_to_uris(world)) == {}
    assert backend.state("cf0").yaw_deg == pytest.approx(0.0, abs=0.5)  # initialYaw, not the true 120 degrees
    assert backend.reset_estimator("cf0", (0.0, 0.0, 0.0), math.radians(-45.0))
    assert wait_for(lambda: backend.state("cf0").yaw_deg == pytest.approx(-45.0, abs=0.01), 1.0)
    assert world.snapshot(address(0)).yaw_deg == pytest.approx(FACING_DEG)  # the truth did not move
    assert not backend.reset_estimator("cf0", (math.nan, 0.0, 0.0), 0.0)  # refused, nothing sent


def test_reset_estimator_on_a_lost_link_returns_false(
    make_world: MakeWorld, toc_cache: Path, backends: Callable[..., CflibBackend]
) -> None:
    world = make_world(2)
    backend = backends(cache_dir=toc_cache, param_timeout_s=0.3)
    assert backend.connect(names_to_uris(world)) == {}
    world.drop_link(address(1))
    assert wait_for(lambda: not backend.state("cf1").link.up, 2.0)
    assert not backend.reset_estimator("cf1", (0.5, 0.0, 0.0), 0.0)
    assert backend.reset_estimator("cf0", (0.0, 0.0, 0.0), 0.0)


def test_estimate_drifts_without_extpos_and_recovers_when_it_resumes(
    make_world: MakeWorld, toc_cache: Path, backends: Callable[..., CflibBackend]
) -> None:
    world = make_world({address(0): FakeDroneConfig.at(0.0, 0.0, positioning="extpos")})
    backend = backends(cache_dir=toc_cache)
    assert backend.connect(names_to_uris(world)) == {}
    mocap = mocap_drone(world, backend)
    hover = (0.0, 0.0, 0.5)
    stream(0.3, mocap)

    def tick() -> None:
        mocap()
        backend.send_position_setpoint("cf0", *hover, 0.0)

    stream(2.0, tick)
    snap = world.snapshot(address(0))
    assert snap.position == pytest.approx(hover, abs=0.01) and math.dist(snap.estimate, snap.position) < 0.01
    blind_from = time.monotonic()
    while time.monotonic() - blind_from < 1.0:  # the mocap stops; setpoints go on
        backend.send_position_setpoint("cf0", *hover, 0.0)
        time.sleep(0.02)
    snap = world.snapshot(address(0))
    blind_s = time.monotonic() - blind_from
    drift = math.dist(snap.estimate, snap.position)
    # fake_vehicle.py: 0.5 a t^2, a this drone's acceleration error (0.098-0.294 m/s^2: the BMI088's zero-g offset and
    # the attitude estimate's tilt error), plus the velocity error it went blind with and the IMU's noise
    accel = math.hypot(*world.firmware(address(0)).vehicle.drift_accel)
    assert 0.02 < drift < 0.5 * accel * blind_s**2 + 0.03 * blind_s + 0.05, (drift, accel, blind_s)
    stream(0.5, tick)  # the first extpos brings the estimate back; the drone then flies back to its setpoint
    snap = world.snapshot(address(0))
    assert math.dist(snap.estimate, snap.position) < 0.01 and snap.position == pytest.approx(hover, abs=0.01)


def test_a_dying_link_holds_back_no_other_drone(
    make_world: MakeWorld, toc_cache: Path, backends: Callable[..., CflibBackend]
) -> None:
    """One link dies in flight: cflib's send to it blocks (its driver's queue stays full while the radio retries,
    until cflib gives up on the link), but each drone's commands go out from a thread of its own, so the caller
    never waits and the other drones' setpoints keep flowing. With one thread sending for all, the stream of every
    drone stopped for as long as the dead link's send blocked (0.4-0.6 s in the fault campaign; here 100 lost
    attempts, each 1 ms plus its turn on a dongle of 2 ms transactions shared by three links)."""
    world = make_world(3, timing=RadioTiming(transaction_s=0.002))
    backend = backends(cache_dir=toc_cache)
    assert backend.connect(names_to_uris(world)) == {}
    take_off_all(backend, world)
    slowest = [0.0]

    def send_all() -> None:
        for i, name in enumerate(backend.names()):
            t0 = time.monotonic()
            backend.send_position_setpoint(name, 0.5 * i, 0.0, 0.5, 0.0)
            slowest[0] = max(slowest[0], time.monotonic() - t0)

    stream(0.3, send_all, 0.01)
    before = {i: world.snapshot(address(i)).packets_received.get((7, 0), 0) for i in (0, 2)}
    slowest[0] = 0.0
    world.drop_link(address(1))
    stream(0.6, send_all, 0.01)  # cflib declares the link lost after about 0.4-0.6 s of failed retries
    received = {i: world.snapshot(address(i)).packets_received.get((7, 0), 0) - before[i] for i in (0, 2)}
    assert slowest[0] < 0.1, f"a send blocked its caller for {slowest[0]:.3f} s"
    assert all(n >= 30 for n in received.values()), f"setpoints received in 0.6 s at 100 Hz: {received}"
    assert backend.land("cf0", 0.0, 0.5) and backend.land("cf2", 0.0, 0.5)
    assert world.wait_until(
        lambda w: w.snapshot(address(0)).position[2] == 0.0 and w.snapshot(address(2)).position[2] == 0.0, 2.0
    )


def test_no_setpoint_reaches_a_drone_after_its_landing(
    make_world: MakeWorld, toc_cache: Path, backends: Callable[..., CflibBackend]
) -> None:
    """A slow radio (15 ms a transaction) and setpoints queued faster than it carries them: the newest setpoint
    wins, and the landing queued after them drops the one still waiting, so the drone lands (a setpoint after the
    land would take the priority back and hold it in the air)."""
    world = make_world(1, timing=RadioTiming(transaction_s=0.015))
    backend = backends(cache_dir=toc_cache)
    assert backend.connect(names_to_uris(world)) == {}
    backend.takeoff("cf0", 0.5, 0.5)
    assert world.wait_until(lambda w: w.snapshot(address(0)).position[2] > 0.45, 3.0)
    for _ in range(200):  # 1 ms apart: at most one in fifteen goes out
        backend.send_position_setpoint("cf0", 0.1, 0.0, 0.5, 0.0)
        time.sleep(0.001)
    assert backend.land("cf0", 0.0, 1.0)
    assert backend.wait_sent(timeout_s=2.0)
    setpoints = world.snapshot(address(0)).packets_received.get((7, 0), 0)
    assert setpoints < 100, f"{setpoints} of 200 setpoints sent over a radio carrying 1 in 15"
    assert backend.radio_counts()["cf0"].superseded == 200 - setpoints  # each one not sent is counted
    assert world.wait_until(lambda w: w.snapshot(address(0)).hl_state == "LANDING", 0.5)
    time.sleep(0.3)
    snap = world.snapshot(address(0))
    assert snap.packets_received.get((7, 0), 0) == setpoints and snap.hl_state == "LANDING"
    assert world.wait_until(lambda w: w.snapshot(address(0)).position[2] == 0.0, 2.0)


def test_setpoint_latency_is_measured_to_cflibs_hand_over(
    make_world: MakeWorld, toc_cache: Path, backends: Callable[..., CflibBackend]
) -> None:
    world = make_world(1)
    backend = backends(cache_dir=toc_cache)
    assert backend.connect(names_to_uris(world)) == {}
    origin = time.monotonic() - 0.25  # a frame received 250 ms ago
    assert backend.send_position_setpoint("cf0", 0.0, 0.0, 0.0, 0.0, origin_s=origin)
    assert backend.send_position_setpoint("cf0", 0.0, 0.0, 0.0, 0.0)  # no origin: not measured
    assert backend.wait_sent(timeout_s=1.0)
    latencies = backend.take_setpoint_latencies()
    assert len(latencies) <= 1 and all(0.25 <= v < 1.0 for v in latencies)
    assert backend.take_setpoint_latencies() == []
    backend.stop("cf0")


def test_an_emergency_stop_waits_for_no_blocked_link(
    make_world: MakeWorld, toc_cache: Path, backends: Callable[..., CflibBackend]
) -> None:
    """cf1's link dies while the pool's thread is inside a send to it (holding cflib's send lock): an emergency
    stop of cf0 and cf1 with a short wait returns at once, cf0 stops, cf1's stop is reported as still being sent,
    and nothing queued afterwards goes out to the stopped drones."""
    world = make_world(2, timing=RadioTiming(transaction_s=0.002))
    backend = backends(cache_dir=toc_cache)
    assert backend.connect(names_to_uris(world)) == {}
    take_off_all(backend, world)
    world.drop_link(address(1))
    stream(0.1, lambda: backend.send_position_setpoint("cf1", 0.5, 0.0, 0.5, 0.0), 0.005)  # fills its driver queue
    t0 = time.monotonic()
    errors = backend.emergency_stop(["cf0", "cf1"], wait_s=0.05)
    took = time.monotonic() - t0
    assert took < 0.3, f"the emergency stop held its caller {took:.3f} s"
    assert "cf0" not in errors and "cf1" in errors, errors
    assert wait_for(lambda: backend.state("cf0").supervisor.locked, 1.0)
    assert not backend.send_position_setpoint("cf0", 0.0, 0.0, 0.5, 0.0) and not backend.land("cf0")
