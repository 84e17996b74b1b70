"""Contract: any cflib 0.1.34 program using Swarm, SyncCrazyflie, HighLevelCommander (with uploaded trajectories),
Commander, extpos, supervisor arming and emergency stop, SyncLogger/LogConfig, param set/get and the trajectory
memory works unchanged against ``fake://`` URIs for at least 10 drones.

The middle of the test is a plain user script (as in Bitcraze's swarm examples); only the URIs are fake, and the
assertions read the fake world afterwards."""

from __future__ import annotations

import itertools
import threading
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from cflib.crazyflie import Crazyflie
from cflib.crazyflie.log import LogConfig
from cflib.crazyflie.swarm import CachedCfFactory, Swarm
from cflib.crazyflie.syncCrazyflie import SyncCrazyflie
from cflib.crazyflie.syncLogger import SyncLogger

from rpf_fly.emulator.fake_world import FakeWorld


def test_plain_cflib_swarm_script_flies_ten_fake_drones(make_world: Callable[..., FakeWorld], toc_cache: Path) -> None:
    world = make_world(10)
    uris = [world.uri(a) for a in world.addresses]
    starts = {world.uri(a): world.snapshot(a).position for a in world.addresses}
    report: dict[str, dict[str, object]] = {uri: {} for uri in uris}
    address_of = {world.uri(a): a for a in world.addresses}

    def mocap(uri: str) -> tuple[float, float, float]:
        """The motion-capture system of this test: the true position."""
        return world.true_poses()[address_of[uri]][0]

    # ------------------------------------------ the user script ------------------------------------------
    def configure(scf: SyncCrazyflie) -> None:
        scf.wait_for_params()
        scf.cf.param.set_value("stabilizer.estimator", "2")
        scf.cf.param.set_value("commander.enHighLevel", "1")
        report[scf.cf.link_uri]["controller"] = scf.cf.param.get_value("stabilizer.controller")

    def read_state(scf: SyncCrazyflie) -> None:
        config = LogConfig(name="state", period_in_ms=100)
        for name in ("stateEstimate.x", "stateEstimate.y", "stateEstimate.z", "pm.vbat"):
            config.add_variable(name, "float")
        samples = []
        with SyncLogger(scf, config) as logger:
            for entry in logger:
                samples.append(entry)
                if len(samples) == 3:
                    break
        report[scf.cf.link_uri]["samples"] = samples

    def arm(scf: SyncCrazyflie) -> None:
        scf.cf.supervisor.send_arming_request(True)
        report[scf.cf.link_uri]["armed"] = scf.cf.supervisor.is_armed

    def take_off(scf: SyncCrazyflie) -> None:
        scf.cf.high_level_commander.takeoff(0.5, 1.0)
        time.sleep(1.3)

    def go_forward(scf: SyncCrazyflie) -> None:
        x, y, _ = starts[scf.cf.link_uri]
        scf.cf.high_level_commander.go_to(x + 0.3, y, 0.5, 0.0, 1.0)
        time.sleep(1.3)

    def stream_and_land(scf: SyncCrazyflie) -> None:
        cf = scf.cf
        x, y, _ = starts[cf.link_uri]
        for _ in range(30):  # 1.5 s at 20 Hz
            cf.extpos.send_extpos(*mocap(cf.link_uri))
            cf.commander.send_position_setpoint(x + 0.3, y + 0.3, 0.7, 0.0)
            time.sleep(0.05)
        report[cf.link_uri]["streamed_to"] = mocap(cf.link_uri)
        cf.commander.send_notify_setpoint_stop()
        cf.high_level_commander.land(0.0, 1.0)
        time.sleep(1.2)
        cf.high_level_commander.stop()

    factory = CachedCfFactory(rw_cache=str(toc_cache))
    with Swarm(uris, factory=factory) as swarm:
        swarm.parallel_safe(configure)
        swarm.parallel_safe(read_state)
        positions = swarm.get_estimated_positions()
        swarm.parallel_safe(arm)
        swarm.parallel_safe(take_off)
        after_takeoff = world.snapshots()
        swarm.parallel_safe(go_forward)
        after_go_to = world.snapshots()
        swarm.parallel_safe(stream_and_land)
        landed = world.snapshots()
        swarm.sequential(lambda scf: scf.cf.supervisor.send_emergency_stop() if scf.cf.link_uri == uris[0] else None)
        time.sleep(0.2)
    # -------------------------------------------- end of script --------------------------------------------

    assert len(uris) == 10
    for address, uri in zip(world.addresses, uris):
        x, y, _ = starts[uri]
        assert report[uri]["controller"] == "0" and report[uri]["armed"] is True
        _, data, _ = report[uri]["samples"][-1]  # type: ignore[index]
        assert (data["stateEstimate.x"], data["stateEstimate.y"], data["pm.vbat"]) == pytest.approx(
            (x, y, 4.15), abs=0.01
        )
        assert (positions[uri].x, positions[uri].y) == pytest.approx((x, y))
        assert after_takeoff[address].position == pytest.approx((x, y, 0.5), abs=0.02)
        assert after_takeoff[address].flying
        assert after_go_to[address].position == pytest.approx((x + 0.3, y, 0.5), abs=0.02)
        # 1.5 s of setpoints (0.36 m away, time constant 0.25 s) with the estimate fed by the mocap: settled
        assert report[uri]["streamed_to"] == pytest.approx((x + 0.3, y + 0.3, 0.7), abs=0.01)
        snap = landed[address]
        assert snap.params["stabilizer.estimator"] == 2 and snap.params["commander.enHighLevel"] == 1
        assert snap.position[2] == pytest.approx(0.0, abs=1e-6) and not snap.motors_on
        assert snap.packets_received[(6, 0)] == 30 and snap.packets_received[(7, 0)] == 30
        assert snap.packets_received[(7, 1)] == 1
    assert world.snapshot(world.addresses[0]).locked
    assert not any(world.snapshot(a).locked for a in world.addresses[1:])


def test_streamed_setpoints_are_followed_by_the_estimate(make_world: Callable[..., FakeWorld], toc_cache: Path) -> None:
    world = make_world(1)
    uri = world.uri(world.addresses[0])
    estimates: list[tuple[float, float]] = []
    with SyncCrazyflie(uri, cf=Crazyflie(rw_cache=str(toc_cache))) as scf:
        cf = scf.cf
        config = LogConfig(name="x", period_in_ms=50)
        config.add_variable("stateEstimate.x", "float")
        config.add_variable("stateEstimate.z", "float")
        cf.log.add_config(config)
        config.data_received_cb.add_callback(
            lambda ts, data, conf: estimates.append((data["stateEstimate.x"], data["stateEstimate.z"]))
        )
        config.start()
        cf.high_level_commander.takeoff(0.5, 0.6)
        time.sleep(0.8)
        for step in range(20):  # 1 s at 20 Hz, moving the setpoint at 0.4 m/s
            cf.commander.send_position_setpoint(0.02 * (step + 1), 0.0, 0.5, 0.0)
            time.sleep(0.05)
        cf.commander.send_notify_setpoint_stop()
        cf.high_level_commander.land(0.0, 0.5)
        time.sleep(0.7)
        config.stop()
    xs = [x for x, _ in estimates]
    assert max(xs) == pytest.approx(0.4 - 0.4 * 0.25, abs=0.04)  # a ramp lags by speed x time constant
    assert all(b >= a - 1e-6 for a, b in itertools.pairwise(xs))
    assert estimates[-1][1] == pytest.approx(0.0, abs=0.01)


def test_register_without_a_world_serves_any_unchanged_cflib_program(toc_cache: Path) -> None:
    """``fake_radio.register()`` with no argument: drones appear on their first connection, on the floor, on a
    0.5 m grid in the order they connect, or where the URI's query says; a plain script flies them."""
    from rpf_fly.emulator import fake_radio

    driver = fake_radio.register()
    try:
        uris = ["fake://0/80/2M/E7E7E7E701", "fake://0/80/2M/E7E7E7E702", "fake://0/80/2M/E7E7E7E703?x=0.5&y=1.5"]
        # ------------------------------------------ the user script ------------------------------------------
        with (
            SyncCrazyflie(uris[0], cf=Crazyflie(rw_cache=str(toc_cache))) as a,
            SyncCrazyflie(uris[1], cf=Crazyflie(rw_cache=str(toc_cache))) as b,
            SyncCrazyflie(uris[2], cf=Crazyflie(rw_cache=str(toc_cache))) as c,
        ):
            for scf in (a, b, c):
                scf.cf.high_level_commander.takeoff(0.4, 1.0)
            time.sleep(1.6)
            heights = {
                scf.cf.link_uri: driver.world.snapshot(int(scf.cf.link_uri.split("/")[5][:10], 16)).position
                for scf in (a, b, c)
            }
            for scf in (a, b, c):
                scf.cf.high_level_commander.land(0.0, 1.0)
            time.sleep(1.5)
        # -----------------------------------------------------------------------------------------------------
        world = driver.world
        assert world.snapshot(0xE7E7E7E701).position[:2] == (0.0, 0.0)
        assert world.snapshot(0xE7E7E7E702).position[:2] == pytest.approx((0.5, 0.0), abs=0.02)
        assert world.snapshot(0xE7E7E7E703).position[:2] == pytest.approx((0.5, 1.5), abs=0.02)
        assert all(p[2] == pytest.approx(0.4, abs=0.05) for p in heights.values()), heights
        assert all(world.snapshot(a).position[2] < 0.02 for a in (0xE7E7E7E701, 0xE7E7E7E702, 0xE7E7E7E703))
        assert world.snapshot(0xE7E7E7E701).estimate == pytest.approx(world.snapshot(0xE7E7E7E701).position, abs=0.05)
    finally:
        driver.world.close()
        fake_radio.unregister()


def test_plain_cflib_swarm_script_uploads_and_flies_trajectories(
    make_world: Callable[..., FakeWorld], toc_cache: Path
) -> None:
    """Contract: the trajectory part of cflib (trajectory memory upload with `write_data_sync`, `define_trajectory`,
    `start_trajectory` relative) works unchanged for 10 drones, as in cflib's autonomous_sequence_high_level
    example. The figure is this test's own (`trajectory_shapes.figure_eight`), given as the rows of coefficients a
    user script carries."""
    from cflib.crazyflie.mem import MemoryElement, Poly4D
    from trajectory_shapes import figure_eight, reference

    world = make_world(10)
    uris = [world.uri(a) for a in world.addresses]
    address_of = {world.uri(a): a for a in world.addresses}
    # duration, x^0..x^7, y^0..y^7, z^0..z^7, yaw^0..yaw^7 (the layout of cflib's example tables)
    figure8 = [[p.duration, *p.polys[0], *p.polys[1], *p.polys[2], *p.polys[3]] for p in figure_eight(height=0.0)]
    uploaded: dict[str, float] = {}
    samples: list[dict[int, object]] = []
    stop_sampling = threading.Event()

    def sample() -> None:
        while not stop_sampling.is_set():
            samples.append(world.snapshots())
            time.sleep(0.05)

    # ------------------------------------------ the user script ------------------------------------------
    def upload_trajectory(scf: SyncCrazyflie) -> None:
        cf = scf.cf
        trajectory_mem = cf.mem.get_mems(MemoryElement.TYPE_TRAJ)[0]
        trajectory_mem.trajectory = []
        total_duration = 0.0
        for row in figure8:
            duration = row[0]
            x = Poly4D.Poly(row[1:9])
            y = Poly4D.Poly(row[9:17])
            z = Poly4D.Poly(row[17:25])
            yaw = Poly4D.Poly(row[25:33])
            trajectory_mem.trajectory.append(Poly4D(duration, x, y, z, yaw))
            total_duration += duration
        if not trajectory_mem.write_data_sync():
            raise RuntimeError("upload failed")
        cf.high_level_commander.define_trajectory(1, 0, len(trajectory_mem.trajectory))
        uploaded[cf.link_uri] = total_duration

    def take_off(scf: SyncCrazyflie) -> None:
        scf.cf.supervisor.send_arming_request(True)
        scf.cf.high_level_commander.takeoff(0.5, 1.0)
        time.sleep(1.3)

    def fly_figure(scf: SyncCrazyflie) -> None:
        scf.cf.high_level_commander.start_trajectory(1, 1.0, relative_position=True)
        time.sleep(uploaded[scf.cf.link_uri] + 0.2)

    def land(scf: SyncCrazyflie) -> None:
        scf.cf.high_level_commander.land(0.0, 1.0)
        time.sleep(1.2)
        scf.cf.high_level_commander.stop()

    sampler = threading.Thread(target=sample, daemon=True)
    with Swarm(uris, factory=CachedCfFactory(rw_cache=str(toc_cache))) as swarm:
        swarm.parallel_safe(upload_trajectory)
        swarm.parallel_safe(take_off)
        sampler.start()
        swarm.parallel_safe(fly_figure)
        stop_sampling.set()
        swarm.parallel_safe(land)
    # -------------------------------------------- end of script --------------------------------------------
    sampler.join()
    pieces = figure_eight(height=0.0)
    duration = sum(p.duration for p in pieces)
    assert sorted(uploaded) == sorted(uris) and all(v == pytest.approx(duration) for v in uploaded.values())
    for uri in uris:
        address = address_of[uri]
        x0, y0 = 0.5 * (address - world.addresses[0]), 0.0
        snaps = [s[address] for s in samples]
        plan_start = snaps[-1].hl_plan_start_s  # type: ignore[attr-defined]
        flown = [s for s in snaps if s.hl_plan_start_s == plan_start]  # type: ignore[attr-defined]
        assert len(flown) > 0.7 * duration / 0.05
        for snap in flown:
            t = snap.time_s - plan_start  # type: ignore[attr-defined]
            # a sample of the step that took the command, before its start: the plan holds its start point (a
            # loaded host sampled one 0.22 s before it)
            x, y, z = reference(pieces, max(t, 0.0))[0]
            assert snap.position == pytest.approx((x0 + x, y0 + y, 0.5 + z), abs=0.01), (uri, t)  # type: ignore[attr-defined]
        landed = world.snapshot(address)
        assert landed.position[2] == pytest.approx(0.0, abs=1e-6) and not landed.crashed
        assert landed.packets_received[(4, 2)] == 44  # 8 pieces of 132 bytes, 24 bytes a packet
