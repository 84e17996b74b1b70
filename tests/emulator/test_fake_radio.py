"""The fake radio driven through the real cflib stack (Crazyflie, SyncCrazyflie, Swarm, SyncLogger): connection,
parameters, logging, watchdog, emergency stop and radio faults."""

from __future__ import annotations

import itertools
import threading
import time
from collections.abc import Callable
from pathlib import Path

import cflib.crtp
import pytest
from cflib.crazyflie import Crazyflie
from cflib.crazyflie.log import LogConfig
from cflib.crazyflie.swarm import CachedCfFactory, Swarm
from cflib.crazyflie.syncCrazyflie import SyncCrazyflie
from cflib.crazyflie.syncLogger import SyncLogger
from cflib.crtp.exceptions import WrongUriType

from rpf_fly.emulator import fake_radio
from rpf_fly.emulator.dongle_air import RadioTiming
from rpf_fly.emulator.fake_radio import FakeLink, FakeUri, parse_fake_uri
from rpf_fly.emulator.fake_world import FakeDroneConfig, FakeWorld, LinkFaults
from rpf_fly.emulator.host_lag import LINKS

MakeWorld = Callable[..., FakeWorld]


def address(index: int) -> int:
    """Radio address of drone `index` (as the `make_world` fixture numbers them)."""
    return 0xE7E7E7E700 + index


def fake_drivers() -> list[type]:
    return [c for c in cflib.crtp.CLASSES if isinstance(c, type) and issubclass(c, fake_radio.FakeRadioDriver)]


def open_in_thread(uri: str, timeout_s: float, cache: Path | None = None) -> tuple[bool, str, float]:
    """Open a SyncCrazyflie on a helper thread: (opened, error, seconds); a hang shows as a failure, not a hang."""
    result: dict[str, object] = {}

    def run() -> None:
        start = time.monotonic()
        scf = SyncCrazyflie(uri, cf=Crazyflie(rw_cache=str(cache) if cache else None))
        try:
            scf.open_link()
            result["ok"] = True
            scf.close_link()
        except Exception as exc:  # the failure is the result
            result["ok"], result["error"] = False, str(exc)
        result["seconds"] = time.monotonic() - start

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    thread.join(timeout_s)
    if thread.is_alive():
        return False, "hung", timeout_s
    return bool(result["ok"]), str(result.get("error", "")), float(result["seconds"])  # type: ignore[arg-type]


def test_parse_fake_uri() -> None:
    assert parse_fake_uri("fake://0/80/2M/E7E7E7E701") == FakeUri(0, 80, "2M", 0xE7E7E7E701)
    assert parse_fake_uri("fake://1") == FakeUri(1, 2, "2M", 0xE7E7E7E7E7)
    with pytest.raises(WrongUriType):
        parse_fake_uri("radio://0/80/2M/E7E7E7E701")
    with pytest.raises(ValueError):
        parse_fake_uri("fake://0/80/3M/E7E7E7E701")


def test_register_replaces_and_unregister_removes(make_world: MakeWorld) -> None:
    first, second = make_world(1), make_world(1)
    drivers = fake_drivers()
    assert len(drivers) == 1 and drivers[0].world is second
    assert drivers[0]().scan_interface(None) == [[second.uri(address(0)), ""]]
    fake_radio.unregister()
    assert fake_drivers() == []
    ok, error, _ = open_in_thread(first.uri(address(0)), 5.0)
    assert not ok and "No driver found" in error


def test_unknown_address_fails_to_connect_quickly(make_world: MakeWorld) -> None:
    world = make_world(1)
    ok, error, seconds = open_in_thread(world.uri(address(7)), 5.0)
    assert not ok and "Too many packets lost" in error and seconds < 2.0
    # a wrong channel is no answer either
    config = {address(0): FakeDroneConfig(channel=60)}
    world = make_world(config)
    ok, error, _ = open_in_thread(world.uri(address(0), channel=61), 5.0)
    assert not ok and "Too many packets lost" in error
    assert open_in_thread(world.uri(address(0), channel=60), 5.0)[0]


def test_ten_drones_connect_at_once_with_a_warm_toc_cache(make_world: MakeWorld, toc_cache: Path) -> None:
    world = make_world(10)
    uris = [world.uri(a) for a in world.addresses]
    start = time.monotonic()
    with Swarm(uris, factory=CachedCfFactory(rw_cache=str(toc_cache))) as swarm:
        connected_s = time.monotonic() - start
        swarm.parallel_safe(lambda scf: scf.wait_for_params())
        params_s = time.monotonic() - start
        positions = swarm.get_estimated_positions()
    assert connected_s < 3.0 and params_s < 4.0
    assert [positions[u].x for u in uris] == pytest.approx([0.5 * i for i in range(10)])
    snaps = world.snapshots()
    assert all(s.toc_item_requests == 0 for s in snaps.values())  # every TOC came from the cache
    assert all(s.packets_received[(2, 1)] == len(s.params) for s in snaps.values())  # one read per parameter


def test_toc_download_without_cache_fills_an_empty_cache(make_world: MakeWorld, tmp_path: Path) -> None:
    world = make_world(1)
    ok, _, _ = open_in_thread(world.uri(address(0)), 10.0, cache=tmp_path)
    assert ok and len(list(tmp_path.glob("*.json"))) == 2
    assert world.snapshot(address(0)).toc_item_requests > 40


def test_params_set_and_get(make_world: MakeWorld, toc_cache: Path) -> None:
    world = make_world(1)
    with SyncCrazyflie(world.uri(address(0)), cf=Crazyflie(rw_cache=str(toc_cache))) as scf:
        scf.wait_for_params()
        cf = scf.cf
        assert cf.param.get_value("stabilizer.estimator") == "0"
        assert float(cf.param.get_value("locSrv.extQuatStdDev")) == pytest.approx(4.5e-3)
        echoed = threading.Event()
        cf.param.add_update_callback(group="stabilizer", name="estimator", cb=lambda n, v: echoed.set())
        cf.param.set_value("stabilizer.estimator", 2)
        cf.param.set_value("locSrv.extQuatStdDev", 0.008)
        assert echoed.wait(2.0)
        assert world.wait_until(lambda w: w.snapshot(address(0)).params["locSrv.extQuatStdDev"] != 4.5e-3, 2.0)
        assert cf.param.get_value("stabilizer.estimator") == "2"
        assert world.snapshot(address(0)).params["locSrv.extQuatStdDev"] == pytest.approx(0.008)
        with pytest.raises(AttributeError):
            cf.param.set_value("firmware.revision0", 1)
        with pytest.raises(KeyError):
            cf.param.set_value("nosuch.param", 1)
        defaults: list[object] = []
        got = threading.Event()
        cf.param.get_default_value("pm.lowVoltage", lambda name, value: (defaults.append(value), got.set()))
        assert got.wait(2.0) and defaults[0] == pytest.approx(3.2)
        assert cf.param.toc.get_element_by_complete_name("pm.lowVoltage").is_persistent()


def test_sync_logger_at_10_hz(make_world: MakeWorld, toc_cache: Path) -> None:
    world = make_world({address(0): FakeDroneConfig.at(1.0, -2.0, yaw_deg=30.0)})
    config = LogConfig(name="pose", period_in_ms=100)
    for name in ("stateEstimate.x", "stateEstimate.y", "stateEstimate.z", "pm.vbat"):
        config.add_variable(name, "float")
    samples = []
    with (
        SyncCrazyflie(world.uri(address(0)), cf=Crazyflie(rw_cache=str(toc_cache))) as scf,
        SyncLogger(scf, config) as logger,
    ):
        for timestamp, data, _ in logger:
            samples.append((timestamp, data, time.monotonic()))
            if len(samples) == 6:
                break
    stamps = [s[0] for s in samples]
    assert all(b - a == pytest.approx(100, abs=11) for a, b in itertools.pairwise(stamps))
    assert (samples[-1][2] - samples[0][2]) == pytest.approx(0.5, abs=0.1)
    data = samples[-1][1]
    assert (data["stateEstimate.x"], data["stateEstimate.y"], data["stateEstimate.z"]) == pytest.approx((1, -2, 0))
    assert data["pm.vbat"] == pytest.approx(4.15, abs=0.01)


def test_watchdog_through_cflib_while_high_level_hover_is_unaffected(make_world: MakeWorld, toc_cache: Path) -> None:
    world = make_world(2)
    streamer, hoverer = address(0), address(1)
    cache = str(toc_cache)
    with (
        SyncCrazyflie(world.uri(streamer), cf=Crazyflie(rw_cache=cache)) as scf,
        SyncCrazyflie(world.uri(hoverer), cf=Crazyflie(rw_cache=cache)) as other_scf,
    ):
        for cf in (scf.cf, other_scf.cf):
            cf.high_level_commander.takeoff(0.5, 0.6)
        assert world.wait_until(lambda w: all(abs(s.position[2] - 0.5) < 0.02 for s in w.snapshots().values()), 3.0)
        for _ in range(10):  # 20 Hz for 0.5 s, then silence
            scf.cf.commander.send_position_setpoint(0.2, 0.0, 0.5, 0.0)
            time.sleep(0.05)
        assert world.wait_until(lambda w: w.snapshot(streamer).locked, 3.0)
        snap = world.snapshot(streamer)
        last = snap.last_crtp_setpoint_s
        # at the supervisor's first 25 Hz update past each window (up to 40 ms), give or take the thread's 30 ms
        assert 0.5 < snap.entered("Warning, level out") - last < 0.57
        assert 2.0 < snap.entered("Exception, free fall") - last < 2.07
        assert snap.entered("Locked") - snap.entered("Exception, free fall") == pytest.approx(0.04, abs=0.03)
        assert world.wait_until(lambda w: w.snapshot(streamer).position[2] == 0.0, 1.0)
        assert scf.cf.supervisor.is_locked and not scf.cf.supervisor.is_flying
        other = world.snapshot(hoverer)  # no setpoint for 2.5 s either, but the high-level commander flies it
        assert other.supervisor_state == "Flying" and other.position[2] == pytest.approx(0.5, abs=0.02)
        other_scf.cf.high_level_commander.land(0.0, 0.5)
        assert world.wait_until(lambda w: w.snapshot(hoverer).position[2] == 0.0, 2.0)


def test_emergency_stop_latches_through_cflib(make_world: MakeWorld, toc_cache: Path) -> None:
    world = make_world(1)
    with SyncCrazyflie(world.uri(address(0)), cf=Crazyflie(rw_cache=str(toc_cache))) as scf:
        cf = scf.cf
        cf.high_level_commander.takeoff(0.5, 0.5)
        assert world.wait_until(lambda w: w.snapshot(address(0)).position[2] > 0.45, 2.0)
        cf.supervisor.send_emergency_stop()
        assert world.wait_until(lambda w: w.snapshot(address(0)).position[2] == 0.0, 1.0)
        assert cf.supervisor.is_locked and not cf.supervisor.is_flying
        cf.supervisor.send_arming_request(True)
        cf.high_level_commander.takeoff(0.5, 0.5)
        for _ in range(10):
            cf.commander.send_position_setpoint(0.0, 0.0, 0.5, 0.0)
            time.sleep(0.05)
        snap = world.snapshot(address(0))
        assert snap.locked and snap.position[2] == 0.0 and not snap.motors_on and snap.hl_commands_rejected >= 1


def test_link_drop_fault_is_reported_and_the_others_continue(make_world: MakeWorld, toc_cache: Path) -> None:
    drop_at = 1.5
    configs = {address(i): FakeDroneConfig.at(0.5 * i, 0.0) for i in range(3)}
    configs[address(1)] = FakeDroneConfig.at(0.5, 0.0, faults=LinkFaults(drop_link_at_s=drop_at))
    world = make_world(configs)
    lost: dict[str, tuple[str, float]] = {}
    samples: dict[str, int] = {}
    uris = [world.uri(a) for a in configs]
    with Swarm(uris, factory=CachedCfFactory(rw_cache=str(toc_cache))) as swarm:
        assert world.time_s() < drop_at - 0.5, "connecting took too long for this test"

        def watch(scf: SyncCrazyflie) -> None:
            uri = scf.cf.link_uri
            scf.cf.connection_lost.add_callback(lambda u, msg: lost.setdefault(u, (msg, world.time_s())))
            config = LogConfig(name="z", period_in_ms=100)
            config.add_variable("stateEstimate.z", "float")
            config.data_received_cb.add_callback(lambda *a: samples.__setitem__(uri, samples.get(uri, 0) + 1))
            scf.cf.log.add_config(config)
            config.start()

        swarm.parallel_safe(watch)
        assert world.wait_until(lambda w: uris[1] in lost, drop_at + 2.0)
        message, when = lost[uris[1]]
        assert message == "Too many packets lost" and drop_at < when < drop_at + 0.5
        before = dict(samples)
        time.sleep(0.35)
        assert samples[uris[0]] - before[uris[0]] >= 2 and samples[uris[2]] - before[uris[2]] >= 2
        assert samples[uris[1]] == before[uris[1]]
        assert set(lost) == {uris[1]}


def test_packet_loss_still_connects_with_lower_link_quality(make_world: MakeWorld, toc_cache: Path) -> None:
    configs = {
        address(0): FakeDroneConfig(),
        address(1): FakeDroneConfig(faults=LinkFaults(packet_loss=0.4)),
        address(2): FakeDroneConfig(faults=LinkFaults(packet_loss=1.0)),
    }
    world = make_world(configs)
    quality: dict[int, list[float]] = {0: [], 1: []}
    for index in (0, 1):
        with SyncCrazyflie(world.uri(address(index)), cf=Crazyflie(rw_cache=str(toc_cache))) as scf:
            scf.cf.link_statistics.link_quality_updated.add_callback(quality[index].append)
            scf.wait_for_params()
            assert scf.cf.param.get_value("pm.lowVoltage") is not None
            time.sleep(0.3)
    assert quality[0][-1] == pytest.approx(100.0)
    assert 60.0 < quality[1][-1] < 99.0
    ok, error, seconds = open_in_thread(world.uri(address(2)), 5.0)
    assert not ok and "Too many packets lost" in error and seconds < 2.0


def test_latency_fault_shows_in_cflib_latency(make_world: MakeWorld, toc_cache: Path) -> None:
    world = make_world({address(0): FakeDroneConfig(faults=LinkFaults(latency_s=0.02))})
    latencies: list[float] = []
    with SyncCrazyflie(world.uri(address(0)), cf=Crazyflie(rw_cache=str(toc_cache))) as scf:
        scf.cf.link_statistics.latency_updated.add_callback(latencies.append)
        deadline = time.monotonic() + 3.0
        while len(latencies) < 3 and time.monotonic() < deadline:
            time.sleep(0.05)
    assert len(latencies) >= 3 and 40.0 <= latencies[-1] < 80.0


def test_closing_a_cflib_link_in_flight_cuts_the_motors(make_world: MakeWorld, toc_cache: Path) -> None:
    world = make_world(1)
    with SyncCrazyflie(world.uri(address(0)), cf=Crazyflie(rw_cache=str(toc_cache))) as scf:
        scf.cf.high_level_commander.takeoff(0.5, 0.5)
        assert world.wait_until(lambda w: w.snapshot(address(0)).position[2] > 0.45, 2.0)
    assert world.wait_until(lambda w: w.snapshot(address(0)).position[2] == 0.0, 1.0)
    assert world.snapshot(address(0)).setpoint_source == "crtp-rpyt"


def test_world_exposes_true_poses(make_world: MakeWorld) -> None:
    world: FakeWorld = make_world({address(0): FakeDroneConfig.at(1.0, 2.0, 0.1, yaw_deg=90.0)})
    position, quaternion = world.true_poses()[address(0)]
    assert position == (1.0, 2.0, 0.1)
    assert quaternion == pytest.approx((0.0, 0.0, 2**-0.5, 2**-0.5))


def test_links_on_one_dongle_share_its_air_time(make_world: MakeWorld) -> None:
    timing = RadioTiming(transaction_s=0.01)  # 100 transactions/s per dongle
    shared, separate = make_world(3, timing=timing), make_world(3, timing=timing)
    links = [FakeLink(shared, parse_fake_uri(shared.uri(a, devid=0)), None, None) for a in shared.addresses]
    links += [
        FakeLink(separate, parse_fake_uri(separate.uri(a, devid=i)), None, None)
        for i, a in enumerate(separate.addresses)
    ]
    try:
        time.sleep(0.1)
        before = [w.drone(a).transactions for w in (shared, separate) for a in w.addresses]
        time.sleep(0.5)
        after = [w.drone(a).transactions for w in (shared, separate) for a in w.addresses]
    finally:
        for link in links:
            link.close()
    counts = [b - a for a, b in zip(before, after)]
    assert sum(counts[:3]) <= 0.5 / 0.01 + 3  # three links polling through one dongle
    assert sum(counts[3:]) >= 2 * sum(counts[:3])  # one dongle each


def test_a_dongle_is_held_for_the_air_time_only_not_for_a_slow_drone_answer(
    make_world: MakeWorld, toc_cache: Path
) -> None:
    """Two cflib links on one dongle (1 ms of air a transaction); one drone's answer takes 4 ms (as a loaded world
    process's round trip can): the other link keeps the dongle's air to itself meanwhile, so it gets its 150 extpos
    through while the slow one gets about one in five. Held for the whole round trip instead, the dongle would
    alternate and both links crawl at the slow one's pace."""
    world = make_world(2, timing=RadioTiming(transaction_s=0.001))
    slow, fast = address(0), address(1)
    got: dict[int, list[float]] = {slow: [], fast: []}

    def observer(drone: int, delay_s: float) -> Callable[[int, int, bytes, float], None]:
        def seen(port: int, channel: int, payload: bytes, stamp: float) -> None:
            if port == 6:
                got[drone].append(stamp)
            if delay_s:
                time.sleep(delay_s)  # the drone's answer is late; the radio's air is not busy meanwhile

        return seen

    cache = str(toc_cache)
    with (
        SyncCrazyflie(world.uri(slow), cf=Crazyflie(rw_cache=cache)) as slow_scf,
        SyncCrazyflie(world.uri(fast), cf=Crazyflie(rw_cache=cache)) as fast_scf,
    ):
        world.add_packet_observer(slow, observer(slow, 0.004))
        world.add_packet_observer(fast, observer(fast, 0.0))
        air = world.dongle(0)
        before = air.transactions
        senders = [
            threading.Thread(target=lambda cf=scf.cf: [cf.extpos.send_extpos(0.0, 0.0, 0.0) for _ in range(150)])
            for scf in (slow_scf, fast_scf)
        ]  # one sender each: a full link holds its sender back
        for sender in senders:
            sender.start()
        assert world.wait_until(lambda w: len(got[fast]) >= 150, 10.0)
        slow_then = len(got[slow])
        assert world.wait_until(lambda w: len(got[slow]) >= 150, 10.0)  # the slow one is not starved either
        slots = air.transactions - before
        for sender in senders:
            sender.join(5.0)
    assert slow_then < 0.6 * 150, f"the slow drone got {slow_then} of 150 while the fast one got all of its own"
    assert slow_then >= 5  # both links took turns from the start (first come, first served)
    assert slots >= 300  # every packet took a slot of the dongle's air (polls too)


def test_a_transaction_the_host_held_counts_as_time_behind(make_world: MakeWorld, toc_cache: Path) -> None:
    """A drone's answer 0.15 s late (a world process or link thread the host did not run) holds that link's
    transaction past its air slot: the process's links (`host_lag.LINKS`) count it as time behind, which the flight's
    ``host`` warning says, even when the world's own steps and the flight loop were on time."""
    world = make_world(1, timing=RadioTiming(transaction_s=0.001))
    held = {"left": 1}

    def seen(port: int, channel: int, payload: bytes, stamp: float) -> None:
        if port == 6 and held["left"]:
            held["left"] -= 1
            time.sleep(0.15)

    with SyncCrazyflie(world.uri(address(0)), cf=Crazyflie(rw_cache=str(toc_cache))) as scf:
        before = LINKS.snapshot()
        world.add_packet_observer(address(0), seen)
        scf.cf.extpos.send_extpos(0.0, 0.0, 0.0)
        assert world.wait_until(lambda w: LINKS.snapshot().late_runs > before.late_runs, 5.0)
        after = LINKS.snapshot()
    assert after.late_runs > before.late_runs
    assert after.max_late_s >= 0.14
    assert after.behind_s - before.behind_s >= 0.14


def test_a_link_holds_two_packets_at_most_and_then_holds_back_its_sender(
    make_world: MakeWorld, toc_cache: Path
) -> None:
    """cflib's radio driver queues one packet a link (and its radio thread sends one): a sender faster than the
    radio (here 10 ms of air a transaction) is held in ``send_packet`` instead of building a queue of stale
    packets. After each send returns, the firmware has every extpos but the last two at most (the drone gets a
    packet when its air slot starts, so usually all but the last one)."""
    world = make_world(1, timing=RadioTiming(transaction_s=0.01))
    got: list[float] = []
    world.add_packet_observer(address(0), lambda port, ch, payload, stamp: got.append(port) if port == 6 else None)
    behind = []
    with SyncCrazyflie(world.uri(address(0)), cf=Crazyflie(rw_cache=str(toc_cache))) as scf:
        for accepted in range(1, 31):
            scf.cf.extpos.send_extpos(0.0, 0.0, 0.0)
            behind.append(accepted - len(got))
        assert world.wait_until(lambda w: len(got) == 30, 5.0)
    assert max(behind) <= fake_radio.DRIVER_PACKETS, behind  # an unbounded queue: 29 behind at the end
    assert max(behind) >= 1  # the sender did get ahead of the radio: it was held back, not lock-stepped
