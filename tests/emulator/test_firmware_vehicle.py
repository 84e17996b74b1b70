"""The simulated drone on the firmware model (`VehicleConfig.dynamics="firmware"`, fake_vehicle.py "Firmware
dynamics"): the firmware's PID cascade on the identified body, behind the vehicle's commander, supervisor, estimator,
battery and faults. At the packet level on synthetic time (test_fake_firmware.py's `Sim`); still air."""

from __future__ import annotations

import math
import struct
import threading
from collections.abc import Callable
from pathlib import Path

import pytest
from cflib.crazyflie import Crazyflie
from cflib.crazyflie.syncCrazyflie import SyncCrazyflie
from test_fake_firmware import READY_S, Sim, go_to, land, position, takeoff

from rpf_fly.emulator.cf_body import P250
from rpf_fly.emulator.cf_controller import PARAM_NAMES, CfGains
from rpf_fly.emulator.cf_drone import CfDrone
from rpf_fly.emulator.fake_firmware import REBOOT_BOOT_S
from rpf_fly.emulator.fake_toc import pack_value
from rpf_fly.emulator.fake_vehicle import Vehicle, VehicleConfig
from rpf_fly.emulator.fake_world import FakeDroneConfig, FakeWorld
from rpf_fly.emulator.firmware_tables import PARAM_TOC

MakeWorld = Callable[..., FakeWorld]
ADDRESS = 0xE7E7E7E700


def firmware_sim(**config: object) -> Sim:
    return Sim(dynamics="firmware", **config)


def set_param(sim: Sim, name: str, value: float) -> None:
    """A parameter write (CRTP 2:2) in the parameter's own type."""
    entry = PARAM_TOC.by_name[name]
    assert sim.send(2, 2, struct.pack("<H", entry.ident) + pack_value(entry.ctype, value))


def hover(sim: Sim, height: float = 0.5, seconds: float = 3.0) -> None:
    """Ready, then a high-level take-off to `height` in 1 s and `seconds` of flight (it settles a few cm high: the
    integrators wound up on the floor unwind slowly, docs/dynamics.md)."""
    sim.run(READY_S)
    assert sim.send(8, 0, takeoff(height, 1.0))[0][2][3] == 0
    sim.run(seconds)
    assert sim.snap().position[2] == pytest.approx(height, abs=0.06)


def test_first_order_stays_the_default_and_the_choice_is_checked() -> None:
    assert VehicleConfig().dynamics == "first_order" and Vehicle(VehicleConfig(), 0.0).body is None
    assert VehicleConfig(dynamics="first-order").dynamics == "first_order"  # the mission file's spelling
    assert Vehicle(VehicleConfig(dynamics="firmware"), 0.0).body is not None
    with pytest.raises(ValueError, match="dynamics must be"):
        VehicleConfig(dynamics="pid")


def test_it_flies_the_firmware_model_behind_the_commander() -> None:
    """With an onboard estimate (the truth) the simulated drone flies what `CfDrone` flies from the same calls, to a
    tenth of a millimetre:
    the high-level commander's take-off and go_to (the vehicle's own commander), then streamed setpoints through
    CRTP packets, each acting from the tick after it came."""
    sim = firmware_sim(position=(0.3, 0.0, 0.0))
    drone = CfDrone((0.3, 0.0, 0.0))
    worst = 0.0

    def both(seconds: float, stream: tuple[float, float, float] | None = None) -> None:
        nonlocal worst
        for _ in range(round(seconds / 0.01)):
            if stream is not None:
                sim.send(7, 0, position(*stream))
                drone.send_position(*stream)
            sim.run(0.01)
            drone.step(0.01)
            worst = max(worst, math.dist(sim.fw.vehicle.pos, drone.position))

    both(1.0)
    sim.send(8, 0, takeoff(0.5, 2.0))
    drone.takeoff(0.5, 2.0)
    both(4.0)
    sim.send(8, 0, go_to(0.8, 0.2, 0.5, 0.0, 2.0))
    drone.go_to(0.8, 0.2, 0.5, 2.0)
    both(3.0)
    both(3.0, stream=(1.0, 0.2, 0.7))
    assert drone.position == pytest.approx((1.0, 0.2, 0.7), abs=0.05)
    assert worst < 1e-4  # the packets carry float32 (0.2 is 0.200000003)


def test_the_truth_reaches_the_outside_world() -> None:
    sim = firmware_sim()
    hover(sim)
    sim.send(8, 0, go_to(0.5, 0.0, 0.5, 0.0, 1.0))
    sim.run(0.7)
    snap, v = sim.snap(), sim.fw.vehicle
    assert snap.position == tuple(v.body.pos) and snap.velocity == tuple(v.body.vel) and snap.velocity[0] > 0.2
    assert snap.motors_on and snap.flying
    pitch = math.degrees(math.asin(2.0 * (v.body.quat[3] * v.body.quat[1] - v.body.quat[2] * v.body.quat[0])))
    assert v.attitude_deg[1] == pytest.approx(-pitch, abs=0.5) and abs(v.attitude_deg[1]) > 2.0  # legacy sign


def test_the_controller_acts_on_the_estimate() -> None:
    """An extpos drone: a diverging estimator runs the estimate away and the controller holds the estimate on its
    setpoint, so the true drone drifts the other way at that speed; a wrong yaw estimate turns its commands."""
    sim = firmware_sim(position=(0.5, -0.5, 0.0), positioning="extpos")
    sim.mocap = (0.0, 0.0, 0.0)
    hover(sim)
    held = sim.snap()
    sim.fw.estimator_divergence(0.2)
    sim.run(2.0)
    one = sim.snap()
    sim.run(1.0)
    two = sim.snap()
    runaway = [e - p for e, p in zip(two.estimate, two.position)]
    drift = [b - a for a, b in zip(one.position, two.position)]
    assert math.hypot(drift[0], drift[1]) == pytest.approx(0.2, abs=0.01)
    assert drift[0] * runaway[0] + drift[1] * runaway[1] < -0.95 * 0.2 * math.hypot(runaway[0], runaway[1])
    assert math.dist(two.estimate, held.position) < 0.05

    def fly_with_yaw_error(error_deg: float) -> tuple[float, float]:
        sim = firmware_sim(positioning="extpos", yaw_deg=error_deg)
        sim.mocap = (0.0, 0.0, 0.0)
        hover(sim)
        sideways = 0.0

        def each(t: float) -> None:
            nonlocal sideways
            sim.send(7, 0, position(0.5, 0.0, 0.5))
            sideways = max(sideways, abs(sim.fw.vehicle.pos[1]))

        sim.run(3.0, each)
        return math.dist(sim.snap().position[:2], (0.5, 0.0)), sideways

    off, sideways = fly_with_yaw_error(5.0)  # bent, then there (held 5 degrees off: the attitude loop's yaw)
    assert off < 0.02 and 0.005 < sideways < 0.05
    off, _ = fly_with_yaw_error(120.0)  # the fly-away
    assert off > 1.0


def test_a_gust_is_an_external_force_the_cascade_fights() -> None:
    """1.5 m/s^2 on a hovering drone: the body feels mass x accel; the velocity loop's P term holds it about
    0.117 m per m/s^2 downwind (docs/dynamics.md), its integrator slowly less; it comes back when the gust ends."""
    sim = firmware_sim(position=(0.0, 0.0, 0.0), positioning="extpos")
    sim.mocap = (0.0, 0.0, 0.0)
    hover(sim)
    x0 = sim.snap().position[0]
    sim.fw.gust((1.5, 0.0, 0.0), 3.0, sim.t)
    sim.run(0.05)
    assert sim.fw.vehicle.body.external_force == pytest.approx((P250.mass * 1.5, 0.0, 0.0))
    sim.run(2.5)
    assert 0.12 < sim.snap().position[0] - x0 < 0.19
    sim.run(3.0)
    assert sim.fw.vehicle.body.external_force == (0.0, 0.0, 0.0)
    assert abs(sim.snap().position[0] - x0) < 0.03


def test_the_supervisor_gates_the_motors_and_the_watchdog_levels_out() -> None:
    """Streamed setpoints that stop: after 0.5 s the supervisor levels out (x, y disabled, level attitude; the mode
    change resets every PID, so the height sags from thrustBase, as the firmware's does), after 2 s it cuts the
    motors and the drone falls to the floor; an emergency stop cuts them at once."""
    sim = firmware_sim()
    hover(sim, 0.6)
    sim.run(0.5, lambda t: sim.send(7, 0, position(0.0, 0.0, 0.6)))
    sim.run(0.6)
    snap = sim.snap()
    assert snap.supervisor_state == "Warning, level out" and snap.control_source == "level-out" and snap.motors_on
    assert sim.fw.vehicle._control.mode_x == 0 and sim.fw.vehicle._control.mode_roll == 1
    sim.run(1.0)
    assert abs(sim.fw.vehicle.attitude_deg[0]) < 1.0 and abs(sim.fw.vehicle.attitude_deg[1]) < 1.0
    assert 0.4 < sim.snap().position[2] < 0.7
    sim.run(0.6)
    snap = sim.snap()
    assert snap.locked and not snap.motors_on and sim.fw.vehicle.motor_commands == (0, 0, 0, 0)
    sim.run(1.0)
    assert sim.snap().position[2] == 0.0 and sim.fw.vehicle.body.on_floor

    stopped = firmware_sim()
    hover(stopped)
    stopped.send(6, 1, bytes([3]))  # emergency stop
    stopped.run(0.05)
    assert not stopped.snap().motors_on and stopped.fw.vehicle.motor_commands == (0, 0, 0, 0)
    stopped.run(1.0)
    assert stopped.snap().position[2] == 0.0


def test_a_crash_drops_it_where_it_hit_and_a_reboot_keeps_the_model() -> None:
    sim = firmware_sim(position=(0.3, 0.2, 0.0), positioning="extpos")
    sim.mocap = (0.0, 0.0, 0.0)
    hover(sim)
    sim.send(8, 0, go_to(0.8, 0.2, 0.5, 0.0, 1.0))
    sim.run(0.5)
    hit = sim.snap().position
    assert sim.fw.crash(sim.t, "obstacle")
    v = sim.fw.vehicle
    assert v.body.rotor_rpm == [0.0] * 4 and not v.motors_on
    sim.run(0.6)
    snap = sim.snap()
    assert snap.position[2] == 0.0 and math.dist(snap.position[:2], hit[:2]) < 0.02 and snap.locked
    sim.fw.reboot(sim.t)
    sim.run(REBOOT_BOOT_S + 0.05)
    assert sim.fw.vehicle.config.dynamics == "firmware" and sim.fw.vehicle.body is not None
    hover(sim, 0.4)  # the fresh stack flies the model again


def test_on_the_floor_it_neither_slides_nor_tips() -> None:
    sim = firmware_sim(position=(0.2, 0.1, 0.0))
    sim.run(READY_S)
    sim.fw.gust((2.0, 1.0, 0.0), 1.0, sim.t)
    sim.run(1.0, lambda t: sim.send(7, 0, position(0.2, 0.1, 0.0)))  # motors on, no lift
    snap = sim.snap()
    assert snap.position == (0.2, 0.1, 0.0) and sim.fw.vehicle.body.tilt_deg == 0.0


def test_landing_stops_the_motors_and_the_battery_drains_in_flight() -> None:
    sim = firmware_sim()
    idle = firmware_sim()
    hover(sim)
    idle.run(READY_S + 3.0)
    assert sim.snap().vbat_v < idle.snap().vbat_v - 0.2  # the sag under load, and more drain
    sim.send(8, 0, land(0.0, 2.0))
    sim.run(3.0)
    snap = sim.snap()
    assert snap.position[2] == 0.0 and not snap.motors_on and snap.hl_state == "IDLE"


def test_the_gains_are_firmware_parameters_that_act_at_once() -> None:
    """Every controller parameter under its firmware name and type (floats, thrustBase and thrustMin uint16; all
    persistent), its default the firmware's; written, the controller has it at once."""
    defaults = CfGains().params()
    assert set(PARAM_NAMES) <= set(PARAM_TOC.by_name)
    for name in PARAM_NAMES:
        entry = PARAM_TOC.by_name[name]
        assert entry.persistent and not entry.read_only
        assert entry.ctype == ("uint16_t" if name in ("posCtlPid.thrustBase", "posCtlPid.thrustMin") else "float")
    assert {
        "posCtlPid.xKp",
        "posCtlPid.zKi",
        "velCtlPid.vzKi",
        "pid_attitude.yawMaxDelta",
        "pid_rate.yaw_kff",
        "posCtlPid.xVelMax",
        "posCtlPid.thrustBase",
    } <= set(PARAM_NAMES)
    sim = firmware_sim()
    assert sim.snap().params["posCtlPid.thrustBase"] == defaults["posCtlPid.thrustBase"] == 36000
    set_param(sim, "posCtlPid.xKp", 1.0)
    set_param(sim, "pid_rate.roll_kd", 2.0)
    set_param(sim, "posCtlPid.thrustBase", 38000)
    c = sim.fw.vehicle.controller
    assert c.pid_x.kp == 1.0 and c.pid_roll_rate.kd == 2.0 and c.gains.thrust_base == 38000
    assert sim.snap().params["posCtlPid.xKp"] == 1.0


def test_a_velocity_limit_written_limits_the_flight() -> None:
    sim = firmware_sim()
    set_param(sim, "posCtlPid.xVelMax", 0.3)
    hover(sim)
    fastest = 0.0

    def each(t: float) -> None:
        nonlocal fastest
        sim.send(7, 0, position(1.0, 0.0, 0.5))
        fastest = max(fastest, sim.fw.vehicle.vel[0])

    sim.run(2.0, each)
    assert 0.3 < fastest < 0.3 * 1.1 + 0.02  # xVelMax x the 1.1 overhead, and a little the loop lets through
    first_order = Sim()
    set_param(first_order, "posCtlPid.xVelMax", 0.3)
    assert first_order.fw.vehicle.xy_vel_max == pytest.approx(0.3)  # the first-order model keeps its limit too


def test_it_runs_the_firmwares_1_ms_ticks_on_the_callers_clock() -> None:
    """10 ticks for 10 ms, none for less than a tick; a packet between steps acts from the next tick."""
    sim = firmware_sim()
    v = sim.fw.vehicle
    start = v._tick_ms
    sim.run(0.25)
    assert v._tick_ms - start == 250
    sim.fw.step(sim.t + 0.0004)  # less than a tick: nothing
    assert v._tick_ms - start == 250
    assert sim.send(6, 0, struct.pack("<fff", 0.0, 0.0, 0.0)) == []


def test_the_gains_through_cflib(make_world: MakeWorld, toc_cache: Path) -> None:
    """Read and written through real cflib (`cf.param`), in their firmware types; a write acts on the flying
    model's controller at once, and a velocity limit written caps the flight that follows."""
    world = make_world({ADDRESS: FakeDroneConfig.at(0.0, 0.0, dynamics="firmware")}).start()
    with SyncCrazyflie(world.uri(ADDRESS), cf=Crazyflie(rw_cache=str(toc_cache))) as scf:
        scf.wait_for_params()
        cf = scf.cf
        toc = cf.param.toc
        assert float(cf.param.get_value("posCtlPid.xKp")) == 2.0
        assert float(cf.param.get_value("velCtlPid.vzKi")) == 15.0
        assert float(cf.param.get_value("pid_rate.roll_kd")) == 2.5
        assert int(cf.param.get_value("posCtlPid.thrustBase")) == 36000
        assert toc.get_element_by_complete_name("posCtlPid.thrustBase").pytype == "<H"
        assert toc.get_element_by_complete_name("posCtlPid.xVelMax").pytype == "<f"
        assert toc.get_element_by_complete_name("pid_attitude.yawMaxDelta").is_persistent()
        controller = world.firmware(ADDRESS).vehicle.controller
        echoed = threading.Event()
        cf.param.add_update_callback(group="posCtlPid", name="xVelMax", cb=lambda n, v: echoed.set())
        cf.param.set_value("posCtlPid.zKp", 3.0)
        cf.param.set_value("posCtlPid.thrustBase", 37000)
        cf.param.set_value("posCtlPid.xVelMax", 0.3)
        assert echoed.wait(2.0)
        assert controller.pid_z.kp == 3.0 and controller.gains.thrust_base == 37000
        assert controller.gains.x_vel_max == pytest.approx(0.3)
        assert cf.param.get_value("posCtlPid.thrustBase") == "37000"
        cf.param.set_value("posCtlPid.zKp", 2.0)
        cf.param.set_value("posCtlPid.thrustBase", 36000)
        cf.high_level_commander.takeoff(0.5, 1.0)
        assert world.wait_until(lambda w: w.snapshot(ADDRESS).position[2] > 0.45, 5.0)
        fastest = 0.0

        def fastest_x(w: object) -> bool:
            nonlocal fastest
            snap = world.snapshot(ADDRESS)
            fastest = max(fastest, snap.velocity[0])
            return snap.position[0] > 0.9

        cf.high_level_commander.go_to(1.0, 0.0, 0.5, 0.0, 1.0)
        assert world.wait_until(fastest_x, 8.0, poll_s=0.005)
        assert 0.25 < fastest < 0.3 * 1.1 + 0.02  # the 1 m go_to in 1 s flies at the written limit (x 1.1)
        cf.high_level_commander.land(0.0, 1.0)
        assert world.wait_until(lambda w: not w.snapshot(ADDRESS).motors_on, 5.0)
