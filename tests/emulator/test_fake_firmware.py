"""The fake firmware at the packet level, on synthetic time (no threads, no radio, exact timings)."""

from __future__ import annotations

import errno
import math
import struct
from collections.abc import Callable

import pytest
from cflib.crazyflie.log import LogTocElement
from cflib.crazyflie.param import ParamTocElement
from cflib.utils.encoding import compress_quaternion

from rpf_fly.emulator.fake_firmware import (
    PROTOCOL_VERSION,
    REBOOT_BOOT_S,
    FakeFirmware,
    FirmwareSnapshot,
)
from rpf_fly.emulator.fake_planner import Trajectory
from rpf_fly.emulator.fake_vehicle import VehicleConfig
from rpf_fly.emulator.firmware_tables import LOG_TOC, PARAM_TOC
from rpf_fly.emulator.vehicle_figures import ACCEL_BIAS_M_S2, TRACK_TAU_S

DT = 0.01
READY_S = 0.15
"""Power-on to ready to fly: three supervisor updates at the firmware's 25 Hz (pre-flight checks passed, arming,
ready to fly: 0.12 s), with a tick to spare."""


def takeoff(height: float, duration: float) -> bytes:
    return struct.pack("<BBff?f", 7, 0, height, 0.0, True, duration)


def land(height: float, duration: float) -> bytes:
    return struct.pack("<BBff?f", 8, 0, height, 0.0, True, duration)


def go_to(x: float, y: float, z: float, yaw_rad: float, duration: float, linear: bool = False) -> bytes:
    return struct.pack("<BBBBfffff", 12, 0, 0, linear, x, y, z, yaw_rad, duration)


def position(x: float, y: float, z: float, yaw_deg: float = 0.0) -> bytes:
    return struct.pack("<Bffff", 7, x, y, z, yaw_deg)


class Sim:
    """A firmware on a synthetic clock stepped at 100 Hz. With `mocap` set (an offset in metres, (0, 0, 0) for
    none), every tick first sends an extpos of the true position plus that offset, as a 100 Hz mocap would."""

    def __init__(self, seed: int = 0, **config: object) -> None:
        self.t = 0.0
        self.fw = FakeFirmware(VehicleConfig(**config), seed=seed)  # type: ignore[arg-type]
        self.log_packets: list[tuple[float, bytes]] = []
        self.mocap: tuple[float, float, float] | None = None

    def send(self, port: int, channel: int, data: bytes) -> list[tuple[int, int, bytes]]:
        return self.fw.handle(port, channel, data, self.t)

    def run(self, seconds: float, each: Callable[[float], None] | None = None) -> None:
        end = self.t + seconds
        while self.t < end - 1e-9:
            self.t = round(self.t + DT, 6)
            if self.mocap is not None:
                pos = self.fw.vehicle.pos
                self.send(6, 0, struct.pack("<fff", *(p + o for p, o in zip(pos, self.mocap))))
            if each is not None:
                each(self.t)
            for _, _, payload in self.fw.step(self.t):
                self.log_packets.append((self.t, payload))

    def snap(self):
        return self.fw.snapshot()

    def hover(self, height: float = 0.5) -> None:
        """Arm (auto) and take off to `height`, then settle."""
        self.run(READY_S)
        assert self.send(8, 0, takeoff(height, 1.0))[0][2][3] == 0
        self.run(1.5)
        assert self.snap().position[2] == pytest.approx(height, abs=0.01)


def test_tocs_decode_with_cflib_and_have_stable_distinct_crcs() -> None:
    for toc, element_class in ((LOG_TOC, LogTocElement), (PARAM_TOC, ParamTocElement)):
        for entry in toc.entries:
            item = toc.item_reply(entry.ident)
            ident = struct.unpack("<H", item[1:3])[0]
            element = element_class(ident, item[3:])
            assert (element.ident, element.group, element.name, element.ctype) == (
                entry.ident,
                entry.group,
                entry.name,
                entry.ctype,
            )
        count, crc = struct.unpack("<HI", toc.info_reply()[1:])
        assert count == len(toc.entries) and crc == toc.crc
    assert LOG_TOC.crc != PARAM_TOC.crc
    needed = {
        "stateEstimate.x",
        "stateEstimate.vz",
        "pm.vbat",
        "pm.state",
        "supervisor.info",
        "kalman.varPZ",
        "radio.rssi",
    }
    assert needed <= set(LOG_TOC.by_name)
    assert LOG_TOC.by_name["pm.state"].ctype == "int8_t"
    assert LOG_TOC.by_name["supervisor.info"].ctype == "uint16_t"
    assert {
        "stabilizer.estimator",
        "commander.enHighLevel",
        "locSrv.extQuatStdDev",
        "locSrv.extPosStdDev",
        "kalman.resetEstimation",
    } <= set(PARAM_TOC.by_name)
    # what the backend's status log and reset_estimator use, with the firmware's types
    assert LOG_TOC.by_name["stateEstimate.yaw"].ctype == "float"
    for name in ("kalman.initialX", "kalman.initialY", "kalman.initialZ", "kalman.initialYaw"):
        assert PARAM_TOC.by_name[name].ctype == "float" and not PARAM_TOC.by_name[name].read_only
    assert PARAM_TOC.by_name["kalman.resetEstimation"].ctype == "uint8_t"
    # a second firmware has the very same tables (cflib's cache keys on the CRC)
    fw = FakeFirmware()
    assert fw.handle(5, 0, bytes([3]), 0.0)[0][2] == LOG_TOC.info_reply()


def test_link_platform_and_memory_answers() -> None:
    fw = FakeFirmware()
    assert fw.handle(15, 1, bytes([0]), 0.0)[0][2][:18] == b"Bitcraze Crazyflie"
    ping = struct.pack("<Bd", 0, 123.5)
    assert fw.handle(15, 0, ping, 0.0) == [(15, 0, ping)]
    assert fw.handle(13, 1, bytes([0]), 0.0) == [(13, 1, bytes([0, PROTOCOL_VERSION]))]
    assert fw.handle(4, 0, bytes([1]), 0.0) == [(4, 0, bytes([1, 5]))]  # the memories of a deckless CF2.1
    assert fw.handle(5, 1, bytes([5]), 0.0) == [(5, 1, bytes([5, 0, 0]))]


def test_param_read_write_and_misc() -> None:
    fw = FakeFirmware()
    ident = PARAM_TOC.by_name["stabilizer.estimator"].ident
    head = struct.pack("<H", ident)
    assert fw.handle(2, 1, head, 0.0) == [(2, 1, head + b"\0" + bytes([0]))]
    assert fw.handle(2, 2, head + bytes([2]), 0.0) == [(2, 2, head + bytes([2]))]
    assert fw.handle(2, 1, head, 0.0)[0][2][3] == 2
    read_only = struct.pack("<H", PARAM_TOC.by_name["firmware.revision0"].ident)
    assert fw.handle(2, 2, read_only + bytes(4), 0.0) == []
    unknown = struct.pack("<H", len(PARAM_TOC))
    assert fw.handle(2, 1, unknown, 0.0) == [(2, 1, unknown + bytes([errno.ENOENT]))]
    persistent = PARAM_TOC.by_name["pm.lowVoltage"]
    assert persistent.persistent
    reply = fw.handle(2, 3, struct.pack("<BH", 7, persistent.ident), 0.0)[0][2]
    assert reply[3:] == bytes([0, 1])  # extended type v2: status ok, persistent
    default = fw.handle(2, 3, struct.pack("<BH", 8, persistent.ident), 0.0)[0][2]
    assert struct.unpack("<f", default[4:])[0] == pytest.approx(3.2)
    by_name = b"\0stabilizer\0estimator\0" + bytes([0x08, 1])
    assert fw.handle(2, 3, by_name, 0.0)[0][2][-1] == 0
    assert fw.snapshot().params["stabilizer.estimator"] == 1


def test_log_blocks_create_start_data_stop_delete() -> None:
    sim = Sim(position=(1.0, 2.0, 0.0))
    ids = [LOG_TOC.by_name[n].ident for n in ("stateEstimate.x", "pm.state")]
    create = bytes([6, 1, 0x07, *struct.pack("<H", ids[0]), 0x04, *struct.pack("<H", ids[1])])
    assert sim.send(5, 1, create) == [(5, 1, bytes([6, 1, 0]))]
    assert sim.send(5, 1, create)[0][2][2] == errno.EEXIST
    assert sim.send(5, 1, bytes([3, 9, 10]))[0][2][2] == errno.ENOENT
    assert sim.send(5, 1, bytes([3, 1, 2]))[0][2] == bytes([3, 1, 0])  # every 20 ms
    sim.run(1.0)
    assert 49 <= len(sim.log_packets) <= 51
    stamp_ms = int.from_bytes(sim.log_packets[-1][1][1:4], "little")
    assert stamp_ms == pytest.approx(1000, abs=20)
    x, pm_state = struct.unpack("<fb", sim.log_packets[-1][1][4:])
    assert (x, pm_state) == (pytest.approx(1.0), 0)
    assert sim.send(5, 1, bytes([4, 1]))[0][2] == bytes([4, 1, 0])
    sim.log_packets.clear()
    sim.run(0.2)
    assert sim.log_packets == []
    assert sim.send(5, 1, bytes([2, 1]))[0][2] == bytes([2, 1, 0])
    too_big = bytes([6, 2]) + b"".join(bytes([0x07, *struct.pack("<H", ids[0])]) for _ in range(7))
    assert sim.send(5, 1, too_big)[0][2][2] == errno.E2BIG


def test_takeoff_reaches_height_in_duration_and_is_refused_when_flying() -> None:
    sim = Sim(position=(1.0, -1.0, 0.0))
    sim.run(READY_S)
    assert sim.snap().supervisor_state == "Ready to fly"  # auto-arming
    command = takeoff(0.8, 2.0)
    assert sim.send(8, 0, command) == [(8, 0, command[:3] + bytes([0]))]  # firmware answer: 3 bytes + errno
    sim.run(1.0)
    assert 0.3 < sim.snap().position[2] < 0.5  # mid-way along the smooth trajectory
    sim.run(1.2)
    snap = sim.snap()
    assert snap.position == pytest.approx((1.0, -1.0, 0.8), abs=0.01)
    assert snap.flying and snap.supervisor_bits & 0x0310 == 0x0310  # flying, HL active, trajectory finished
    assert sim.send(8, 0, takeoff(1.0, 1.0))[0][2][3] == 1  # the firmware refuses a take-off when not idle


def test_smooth_and_linear_trajectories() -> None:
    smooth = Trajectory(0.0, 2.0, (0.0, 0.0, 0.0), (2.0, 0.0, 1.0), 0.0, 1.0)
    assert smooth.evaluate(1.0)[0] == pytest.approx((1.0, 0.0, 0.5))
    assert smooth.evaluate(0.0)[1] == (0.0, 0.0, 0.0) and smooth.evaluate(2.0)[1] == pytest.approx((0, 0, 0))
    linear = Trajectory(0.0, 2.0, (0.0, 0.0, 0.0), (2.0, 0.0, 0.0), 0.0, 0.0, linear=True)
    assert linear.evaluate(0.5)[0][0] == pytest.approx(0.5) and linear.evaluate(0.5)[1][0] == pytest.approx(1.0)


def test_go_to_then_land_stops_motors() -> None:
    sim = Sim()
    sim.hover(0.5)
    sim.send(8, 0, go_to(1.0, 0.5, 0.7, math.pi / 2, 1.0))
    sim.run(1.0)
    # a 1 m smooth go-to in 1 s peaks at 2.2 m/s in x: the drone is held to the firmware's 1.1 m/s and lags
    assert 0.5 < sim.snap().position[0] < 0.95
    sim.run(0.6)
    snap = sim.snap()
    assert snap.position == pytest.approx((1.0, 0.5, 0.7), abs=0.02)
    assert snap.yaw_deg == pytest.approx(90.0, abs=2.0)
    sim.send(8, 0, land(0.0, 1.0))
    sim.run(1.1)
    snap = sim.snap()
    assert snap.position[2] == pytest.approx(0.0, abs=1e-6) and not snap.motors_on
    assert snap.hl_state == "IDLE"


def test_position_setpoints_track_with_first_order_lag() -> None:
    sim = Sim()
    sim.hover(0.5)
    sim.run(0.5, lambda t: sim.send(7, 0, position(0.1, 0.0, 0.5)))
    # 0.1 m step, time constant 0.25 s: after 0.5 s, 1 - e^-2 of the way
    assert sim.snap().position[0] == pytest.approx(0.1 * (1 - math.exp(-0.5 / TRACK_TAU_S)), abs=0.004)
    assert sim.snap().hl_state == "IDLE"  # streaming stopped the high-level plan


def test_turbulence_makes_a_hovering_drone_wander_as_a_real_one_does() -> None:
    """The documented figures (fake_vehicle, "Turbulence"): a mocap drone hovering on a fixed position setpoint
    wanders 1.2 cm (standard deviation) on each horizontal axis, 0.5 cm vertically, up to 4-5 cm at its worst in a
    minute; each drone its own. A still body (0) holds
    its setpoint exactly. A real Crazyflie under mocap is never that still: the dry run must not be kinder."""
    import statistics

    shipped = 0.15  # fake_vehicle.TURBULENCE_M_S2 (set to 0 for this directory by conftest.py)
    tracks = []
    for seed in range(3):
        sim = Sim(seed=seed, positioning="extpos", turbulence_m_s2=shipped)
        sim.mocap = (0.0, 0.0, 0.0)
        sim.hover(0.5)
        xs, ys, zs = [], [], []

        def record(t: float) -> None:
            sim.send(7, 0, position(0.0, 0.0, 0.5))
            x, y, z = sim.fw.vehicle.pos
            xs.append(x), ys.append(y), zs.append(z)

        sim.run(60.0, record)
        assert 0.008 < statistics.pstdev(xs) < 0.018 and 0.008 < statistics.pstdev(ys) < 0.018
        assert 0.002 < statistics.pstdev(zs) < 0.009
        assert 0.025 < max(math.hypot(x, y) for x, y in zip(xs, ys)) < 0.07
        tracks.append(xs[:100])
    assert tracks[0] != tracks[1]  # each drone its own turbulence
    still = Sim(positioning="extpos")  # this directory's default: still air
    still.mocap = (0.0, 0.0, 0.0)
    still.hover(0.5)
    still.run(5.0, lambda t: still.send(7, 0, position(0.0, 0.0, 0.5)))
    assert math.hypot(*still.snap().position[:2]) < 1e-3  # the IMU noise through the estimate: tens of micrometres


def test_watchdog_levels_out_after_half_a_second_and_cuts_after_two() -> None:
    sim = Sim()
    sim.hover(0.6)
    sim.run(0.5, lambda t: sim.send(7, 0, position(t * 0.4, 0.0, 0.6)))  # moving at 0.4 m/s
    last = sim.snap().last_crtp_setpoint_s
    sim.run(0.45)
    assert sim.snap().supervisor_state == "Flying"
    sim.run(0.1)
    snap = sim.snap()
    assert snap.supervisor_state == "Warning, level out" and snap.control_source == "level-out"
    assert 0.5 < snap.entered("Warning, level out") - last <= 0.54 + 1e-6  # the first 25 Hz update past 0.5 s
    assert snap.position[2] == pytest.approx(0.6, abs=0.02) and snap.velocity[0] > 0.1  # drifts, keeps height
    sim.run(1.3)
    snap = sim.snap()
    assert snap.motors_on and snap.position[2] == pytest.approx(0.6, abs=0.02)
    assert abs(snap.velocity[0]) < 0.4 * math.exp(-1.0)  # horizontal speed decays (level attitude)
    sim.run(0.2)
    snap = sim.snap()
    assert 2.0 < snap.entered("Exception, free fall") - last <= 2.04 + 1e-6  # the first update past 2 s ...
    assert snap.entered("Locked") - snap.entered("Exception, free fall") == pytest.approx(0.04)  # ... locked the next
    assert snap.locked and not snap.flying and snap.supervisor_bits & 0x0050 == 0x0040
    sim.run(0.5)
    assert sim.snap().position[2] == 0.0  # fell to the floor
    sim.send(7, 0, position(0.0, 0.0, 0.5))
    sim.run(1.0)
    assert sim.snap().position[2] == 0.0 and sim.snap().locked


def test_high_level_hover_is_not_subject_to_the_watchdog() -> None:
    sim = Sim()
    sim.hover(0.5)
    sim.run(10.0)
    snap = sim.snap()
    assert snap.supervisor_state == "Flying" and snap.position[2] == pytest.approx(0.5, abs=0.01)


def test_notify_setpoint_stop_hands_over_to_the_high_level_commander() -> None:
    sim = Sim()
    sim.hover(0.5)
    sim.run(0.5, lambda t: sim.send(7, 0, position(0.3, 0.0, 0.5)))
    sim.send(7, 1, struct.pack("<BI", 0, 100))
    sim.send(8, 0, go_to(0.3, 0.0, 0.5, 0.0, 0.5))
    sim.run(3.0)  # well past the watchdog: the high-level commander holds the drone
    snap = sim.snap()
    assert snap.supervisor_state == "Flying" and snap.position == pytest.approx((0.3, 0.0, 0.5), abs=0.02)


def test_notify_setpoint_stop_without_a_plan_cuts_the_motors() -> None:
    # firmware 2026.08: remain_valid_ms is ignored; the idle high-level commander asks for motors off
    sim = Sim()
    sim.hover(0.5)
    sim.run(0.3, lambda t: sim.send(7, 0, position(0.0, 0.0, 0.5)))
    sim.send(7, 1, struct.pack("<BI", 0, 1000))
    sim.run(0.05)
    assert not sim.snap().motors_on
    sim.run(0.5)
    assert sim.snap().position[2] == 0.0


def test_emergency_stop_latches_until_reboot() -> None:
    sim = Sim()
    sim.hover(0.5)
    assert sim.send(9, 1, bytes([0x03])) == []
    sim.run(0.5)
    snap = sim.snap()
    assert snap.locked and snap.emergency_stop_latched and snap.position[2] == 0.0 and not snap.motors_on
    assert sim.send(9, 1, bytes([0x01, 1]))[0][2] == bytes([0x81, 0, 0])  # arming refused
    assert sim.send(8, 0, takeoff(0.5, 1.0))[0][2][3] == errno.EBUSY
    sim.run(1.0, lambda t: sim.send(7, 0, position(0.0, 0.0, 0.5)))
    assert sim.snap().position[2] == 0.0 and sim.snap().locked
    sim.fw.reboot(sim.t)
    sim.run(REBOOT_BOOT_S)  # radio silent while it boots
    sim.hover(0.4)


def test_legacy_localization_emergency_stop_and_rpyt_zero_thrust() -> None:
    sim = Sim()
    sim.hover(0.5)
    sim.send(3, 0, struct.pack("<fffH", 0.0, 0.0, 0.0, 0))  # what cflib's close_link sends
    sim.run(0.05)
    assert not sim.snap().motors_on
    other = Sim()
    other.hover(0.5)
    other.send(6, 1, bytes([3]))
    other.run(0.1)
    assert other.snap().locked


def test_supervisor_state_query_and_arming_when_required() -> None:
    sim = Sim(auto_arm=False)
    sim.run(0.1)
    bits = struct.unpack("<H", sim.send(9, 0, bytes([0x0C]))[0][2][1:])[0]
    assert bits & 0x0F == 0x01  # can be armed, not armed, not auto-armed, cannot fly
    assert sim.send(8, 0, takeoff(0.5, 1.0))[0][2][3] == errno.EBUSY
    assert sim.send(9, 1, bytes([0x01, 1]))[0][2] == bytes([0x81, 1, 1])
    sim.run(READY_S)
    assert sim.send(9, 0, bytes([0x02]))[0][2] == bytes([0x82, 1])  # "is armed" query
    assert sim.snap().supervisor_state == "Ready to fly"
    assert sim.send(8, 0, takeoff(0.5, 1.0))[0][2][3] == 0
    sim.run(1.2)
    sim.send(8, 0, land(0.0, 1.0))
    sim.run(1.1 + 2.0 + 3.2)  # landing, flying hysteresis, landing timeout
    snap = sim.snap()
    assert not snap.armed and snap.supervisor_state == "Pre-flight checks passed"


def test_external_position_moves_the_estimate_and_the_controller_follows_it() -> None:
    sim = Sim(position=(1.0, 1.0, 0.0), positioning="extpos")
    sim.run(0.1)
    # kalman.initialX/Y/Z until mocap arrives (the IMU's drift in 0.1 s: at most 1.5 mm, 0.5 x 0.294 m/s^2 x 0.01 s^2)
    assert sim.snap().estimate == pytest.approx((0.0, 0.0, 0.0), abs=2e-3)
    assert sim.snap().variance_m2 > 1e-3
    sim.send(6, 0, struct.pack("<fff", 1.0, 1.0, 0.0))
    assert sim.snap().estimate == pytest.approx((1.0, 1.0, 0.0), abs=1e-3)  # large variance: taken almost whole
    sim.mocap = (0.0, 0.0, 0.0)
    sim.hover(0.5)
    # the mocap says the drone is 0.1 m further in x than it is: the true drone settles 0.1 m short
    sim.mocap = (0.1, 0.0, 0.0)
    sim.run(1.0)
    assert sim.snap().position[0] == pytest.approx(0.9, abs=0.01)
    assert sim.snap().variance_m2 < 1e-3
    quat = (0.0, 0.0, math.sin(math.pi / 8), math.cos(math.pi / 8))  # yaw 45 degrees
    sim.send(6, 1, struct.pack("<Bfffffff", 8, 0.9, 1.0, 0.5, *quat))
    assert math.degrees(sim.fw.vehicle.estimate_yaw) == pytest.approx(45.0, abs=1e-3)


def test_kalman_reset_raises_then_settles_the_variance() -> None:
    sim = Sim()
    sim.run(0.1)
    ident = struct.pack("<H", PARAM_TOC.by_name["kalman.resetEstimation"].ident)
    sim.send(2, 2, ident + bytes([1]))
    assert sim.snap().variance_m2 == pytest.approx(1.0, abs=0.01)
    assert sim.snap().params["kalman.resetEstimation"] == 0
    sim.run(0.5)
    assert sim.snap().variance_m2 < 2e-4


def test_low_battery_state_and_critical_shutdown() -> None:
    sim = Sim(initial_vbat_v=3.40)
    sim.hover(0.5)  # 0.25 V sag under load: 3.15 V < 3.2 V
    assert sim.snap().vbat_v == pytest.approx(3.15, abs=0.01) and sim.snap().pm_state == 0
    sim.run(5.0)
    assert sim.snap().pm_state == 3
    other = Sim(initial_vbat_v=3.20)
    other.hover(0.5)  # 2.95 V under load, below both thresholds since the take-off
    other.run(3.0)
    assert other.snap().pm_state == 0 and other.snap().powered
    other.run(1.0)  # both 5 s timers expire together: low power and, at once, critical shutdown
    snap = other.snap()
    assert not snap.powered and snap.pm_state == 4
    other.run(0.5)
    assert other.snap().position[2] == 0.0
    assert other.send(15, 1, bytes([0])) == []  # a dead drone answers nothing


def test_battery_drains_faster_in_flight() -> None:
    idle, flying = Sim(), Sim()
    flying.hover(0.5)
    idle.run(flying.t)
    start_idle, start_flying = idle.fw.vehicle.battery.open_v, flying.fw.vehicle.battery.open_v
    idle.run(10.0)
    flying.run(10.0)
    assert start_idle - idle.fw.vehicle.battery.open_v == pytest.approx(0.002, rel=0.01)
    assert start_flying - flying.fw.vehicle.battery.open_v == pytest.approx(0.017, rel=0.01)


def test_other_setpoint_types() -> None:
    sim = Sim()
    sim.hover(0.5)
    sim.run(1.0, lambda t: sim.send(7, 0, struct.pack("<Bffff", 8, 0.2, 0.0, 0.0, 0.0)))  # velocity world
    assert sim.snap().velocity[0] == pytest.approx(0.2, abs=0.01)
    x = sim.snap().position[0]
    sim.run(1.0, lambda t: sim.send(7, 0, struct.pack("<Bffff", 10, 0.0, 0.0, 0.0, 0.7)))  # hover: vx, vy, z
    assert sim.snap().position[2] == pytest.approx(0.7, abs=0.02) and sim.snap().position[0] - x < 0.1
    full = struct.pack(
        "<BhhhhhhhhhIhhh", 6, 300, -200, 600, 0, 0, 0, 0, 0, 0, compress_quaternion([0.0, 0.0, 0.0, 1.0]), 0, 0, 0
    )
    sim.run(1.5, lambda t: sim.send(7, 0, full))
    assert sim.snap().position == pytest.approx((0.3, -0.2, 0.6), abs=0.01)
    sim.send(7, 0, bytes([0]))  # stop setpoint: motors off; nothing refreshes it, so the watchdog locks
    sim.run(0.6)
    assert sim.snap().position[2] == 0.0 and not sim.snap().motors_on
    sim.run(1.5)
    assert sim.snap().locked


def set_param(sim: Sim, name: str, value: float) -> None:
    entry = PARAM_TOC.by_name[name]
    payload = struct.pack("<H", entry.ident) + (
        struct.pack("<f", value) if entry.ctype == "float" else bytes([int(value)])
    )
    assert sim.send(2, 2, payload) == [(2, 2, payload)]


def test_yaw_estimate_starts_at_initial_yaw_and_only_extpose_corrects_it() -> None:
    sim = Sim(position=(1.0, 0.0, 0.0), yaw_deg=120.0, positioning="extpos")
    sim.run(0.1)
    assert sim.snap().estimate_yaw_deg == pytest.approx(0.0) and sim.snap().yaw_deg == pytest.approx(120.0)
    sim.mocap = (0.0, 0.0, 0.0)
    sim.run(1.0)  # position-only extpos: the position converges, the yaw estimate does not
    assert sim.snap().estimate == pytest.approx((1.0, 0.0, 0.0), abs=1e-3)
    assert sim.snap().estimate_yaw_deg == pytest.approx(0.0)
    set_param(sim, "kalman.initialYaw", math.radians(-30.0))
    set_param(sim, "kalman.initialX", 2.0)
    assert sim.snap().estimate_yaw_deg == pytest.approx(0.0)  # initial values act at the next reset
    set_param(sim, "kalman.resetEstimation", 1)
    snap = sim.snap()
    assert snap.estimate_yaw_deg == pytest.approx(-30.0, abs=1e-4) and snap.estimate == pytest.approx((2.0, 0.0, 0.0))
    assert snap.variance_m2 == pytest.approx(1.0) and snap.params["kalman.resetEstimation"] == 0
    sim.run(0.02)  # the large variance takes the next extpos almost whole
    assert sim.snap().estimate == pytest.approx((1.0, 0.0, 0.0), abs=1e-3) and sim.snap().variance_m2 < 1e-3
    quat = (0.0, 0.0, math.sin(math.radians(60.0)), math.cos(math.radians(60.0)))  # yaw 120 degrees
    sim.send(6, 1, struct.pack("<Bfffffff", 8, 1.0, 0.0, 0.0, *quat))
    assert sim.snap().estimate_yaw_deg == pytest.approx(120.0, abs=1e-3)
    sim.fw.reboot(sim.t)  # power-cycle: default parameters, the estimate starts at yaw 0 again
    sim.run(REBOOT_BOOT_S)
    assert sim.fw.snapshot().estimate_yaw_deg == pytest.approx(0.0) and sim.fw.snapshot().yaw_deg == pytest.approx(120)


def fly_with_yaw_error(yaw_error_deg: float, seconds: float = 3.0) -> tuple[FirmwareSnapshot, float]:
    """A mocap (extpos) drone whose true yaw is `yaw_error_deg` off its estimate flies from the origin to
    (0.5, 0, 0.5) under position setpoints; its last snapshot and its largest sideways (y) excursion."""
    sim = Sim(positioning="extpos", yaw_deg=yaw_error_deg)
    sim.mocap = (0.0, 0.0, 0.0)
    sideways = 0.0

    def each(t: float) -> None:
        nonlocal sideways
        sim.send(7, 0, position(0.5, 0.0, 0.5, 0.0))
        sideways = max(sideways, abs(sim.fw.vehicle.pos[1]))

    sim.run(seconds, each)
    return sim.snap(), sideways


def test_the_position_controller_acts_in_the_estimated_frame() -> None:
    snap, sideways = fly_with_yaw_error(0.0)
    assert snap.position == pytest.approx((0.5, 0.0, 0.5), abs=1e-3) and sideways < 1e-3
    snap, sideways = fly_with_yaw_error(5.0)  # a small error bends the path, then it arrives
    assert snap.position == pytest.approx((0.5, 0.0, 0.5), abs=1e-3) and 0.005 < sideways < 0.03
    assert snap.estimate_yaw_deg == pytest.approx(0.0) and snap.yaw_deg == pytest.approx(5.0)  # yaw 0 held estimated
    snap, sideways = fly_with_yaw_error(120.0)  # the classic fly-away
    assert math.dist(snap.position, (0.5, 0.0, 0.5)) > 1.0 and math.dist(snap.estimate, snap.position) < 0.01


def test_imu_drift_without_extpos_and_the_kalman_pull_back() -> None:
    """The figures of docs/radio.md ("Estimator"), over ten drones (seeds): hovering under position setpoints with
    a 50 Hz mocap, then 1 s and 2 s without it, then the mocap again."""
    biases = set()
    for seed in range(10):
        sim = Sim(seed=seed, positioning="extpos")
        sim.mocap = (0.0, 0.0, 0.0)
        sim.hover(0.5)
        sim.mocap = None
        ticks = iter(range(10**6))
        worst = 0.0

        def streamed(t: float) -> None:
            nonlocal worst
            sim.send(7, 0, position(0.0, 0.0, 0.5))
            if next(ticks) % 2 == 0:
                sim.send(6, 0, struct.pack("<fff", *sim.fw.vehicle.pos))
            worst = max(worst, math.dist(sim.fw.vehicle.estimate, sim.fw.vehicle.pos))

        def error() -> float:
            return math.dist(sim.snap().estimate, sim.snap().position)

        sim.run(2.0, streamed)
        assert worst < 1e-3  # 50 Hz extpos: within a millimetre (0.2-0.6 mm measured)
        sim.run(1.0, lambda t: sim.send(7, 0, position(0.0, 0.0, 0.5)))
        assert 0.04 < error() < 0.19  # 1 s blind: 4.7-17.5 cm measured over 200 seeds
        sim.run(1.0, lambda t: sim.send(7, 0, position(0.0, 0.0, 0.5)))
        assert 0.17 < error() < 0.68  # 2 s blind: 19-64 cm measured over 200 seeds
        sim.run(0.05, streamed)
        assert error() < 1.5e-3  # the variance grew while blind: the first extpos is taken almost whole (<1.1 mm)
        biases.add(sim.fw.vehicle.accel_bias)
        assert math.hypot(*sim.fw.vehicle.accel_bias) == pytest.approx(ACCEL_BIAS_M_S2)
    assert len(biases) == 10  # each drone its own


# Fault hooks (docs/radio.md, "Fault hooks"): the figures, on synthetic time ------------------------------------


def gust_offsets(accel_m_s2: float, seconds: float = 3.0) -> tuple[list[float], float, FirmwareSnapshot]:
    """A mocap (extpos) drone hovering at the origin under the high-level commander, pushed along +x: its x every
    0.5 s of the gust, the largest estimate error meanwhile, and its snapshot at the end of the gust."""
    sim = Sim(positioning="extpos")
    sim.mocap = (0.0, 0.0, 0.0)
    sim.hover(0.5)
    sim.fw.gust((accel_m_s2, 0.0, 0.0), seconds, sim.t)
    xs, worst = [], 0.0

    def each(t: float) -> None:
        nonlocal worst
        worst = max(worst, math.dist(sim.fw.vehicle.pos, sim.fw.vehicle.estimate))

    for _ in range(round(seconds / 0.5)):
        sim.run(0.5, each)
        xs.append(sim.snap().position[0])
    return xs, worst, sim.snap()


def test_a_gust_holds_the_drone_off_its_setpoint_by_the_documented_amount_and_it_comes_back() -> None:
    xs, worst, snap = gust_offsets(1.5)
    assert xs[3] == pytest.approx(0.171, abs=0.003)  # 97 % of the steady offset after 2 s
    assert xs[-1] == pytest.approx(0.1175 * 1.5, abs=0.003)  # steady: 0.1175 m per m/s^2 (17.6 cm)
    assert snap.gust_m_s2 == (1.5, 0.0, 0.0) and snap.position[1:] == pytest.approx((0.0, 0.5), abs=1e-3)
    assert worst < 1e-3  # the IMU feels the push: with extpos the estimate stays on the truth
    assert gust_offsets(0.75)[0][-1] == pytest.approx(xs[-1] / 2, abs=0.003)  # it grows with the gust
    # beyond 1.1 m/s / 0.47 s = 2.3 m/s^2 the velocity-limited controller cannot hold: blown away
    assert gust_offsets(3.0)[0][-1] > 0.6
    sim = Sim()
    sim.hover(0.5)
    sim.fw.gust((0.0, -1.5, 0.0), 1.0, sim.t)
    sim.run(1.0, lambda t: sim.send(7, 0, position(0.0, 0.0, 0.5)))  # streamed setpoints fight it alike
    assert -0.16 < sim.snap().position[1] < -0.12
    sim.run(0.5, lambda t: sim.send(7, 0, position(0.0, 0.0, 0.5)))
    assert sim.snap().gust_m_s2 == (0.0, 0.0, 0.0) and -0.10 < sim.snap().position[1] < -0.07  # coming back
    sim.run(1.5, lambda t: sim.send(7, 0, position(0.0, 0.0, 0.5)))
    assert abs(sim.snap().position[1]) < 0.005
    grounded = Sim(position=(1.0, 1.0, 0.0))
    grounded.run(0.1)
    grounded.fw.gust((5.0, 0.0, 0.0), 1.0, grounded.t)
    grounded.run(1.0)
    assert grounded.snap().position == (1.0, 1.0, 0.0)  # on the floor a drone cannot slide


def test_estimator_divergence_drifts_the_true_drone_the_other_way_until_reboot() -> None:
    sim = Sim(position=(0.5, -0.5, 0.0), positioning="extpos")
    sim.mocap = (0.0, 0.0, 0.0)  # extpos at 100 Hz throughout: the diverged estimator ignores it
    sim.hover(0.5)
    hover = sim.snap()
    sim.fw.estimator_divergence(0.2)
    sim.run(1.0)
    one = sim.snap()
    sim.run(1.0)
    two = sim.snap()
    assert two.estimator_diverging and two.variance_m2 == pytest.approx(hover.variance_m2)  # it looks fine
    runaway = [e - p for e, p in zip(two.estimate, two.position)]
    assert math.hypot(runaway[0], runaway[1]) == pytest.approx(0.4, abs=0.005) and abs(runaway[2]) < 1e-3
    drift = [b - a for a, b in zip(one.position, two.position)]
    assert math.hypot(drift[0], drift[1]) == pytest.approx(0.2, abs=0.005)  # the true drone: 0.2 m/s ...
    assert drift[0] * runaway[0] + drift[1] * runaway[1] < -0.99 * 0.2 * 0.4  # ... the other way
    assert math.dist(two.estimate, hover.position) < 0.06  # the estimate sits near the setpoint (lagging 5 cm)
    set_param(sim, "kalman.resetEstimation", 1)
    sim.run(0.5)
    assert sim.snap().estimator_diverging  # a reset does not mend it
    other = Sim(seed=1, positioning="extpos")
    other.fw.estimator_divergence(0.2)
    other.run(1.0)
    direction = [e - p for e, p in zip(other.snap().estimate, other.snap().position)]
    assert abs(direction[0] * runaway[1] - direction[1] * runaway[0]) > 0.01  # each drone its own direction
    sim.fw.reboot(sim.t)
    sim.run(REBOOT_BOOT_S + 0.05)
    snap = sim.snap()
    assert not snap.estimator_diverging and snap.boots == 1
    assert math.dist(snap.estimate, snap.position) < 1e-3  # a fresh estimator takes the extpos again


def test_a_reboot_in_flight_cuts_the_motors_falls_is_silent_then_boots_fresh_on_the_floor() -> None:
    sim = Sim(position=(0.3, 0.2, 0.0), positioning="extpos")
    sim.mocap = (0.0, 0.0, 0.0)
    sim.hover(0.5)
    set_param(sim, "stabilizer.estimator", 2)
    ident = LOG_TOC.by_name["stateEstimate.z"].ident
    assert sim.send(5, 1, bytes([6, 1, 0x07, *struct.pack("<H", ident)]))[0][2][2] == 0
    sim.send(8, 0, go_to(0.6, 0.2, 0.5, 0.0, 1.0))
    sim.run(1.5)
    sim.mocap = None
    sim.fw.reboot(sim.t)
    snap = sim.snap()
    assert not snap.motors_on and not snap.powered and snap.booting and snap.boots == 0
    assert sim.send(15, 0, b"ping") == []  # radio silent
    sim.run(0.1)
    assert 0.40 < sim.snap().position[2] < 0.46  # falling: 4.9 cm in 0.1 s
    sim.run(0.25)
    assert sim.snap().position == pytest.approx((0.6, 0.2, 0.0), abs=1e-3)  # on the floor where it fell (0.32 s)
    sim.run(REBOOT_BOOT_S - 0.4)
    assert sim.snap().booting and sim.send(15, 0, b"ping") == []
    sim.run(0.1)
    snap = sim.snap()
    assert snap.powered and not snap.booting and snap.boots == 1 and not snap.motors_on
    assert sim.send(15, 0, b"ping") == [(15, 0, b"ping")]
    assert snap.params["stabilizer.estimator"] == 0 and snap.log_blocks == {}  # default parameters, no blocks
    assert snap.estimate == pytest.approx((0.0, 0.0, 0.0), abs=0.01)  # kalman.initialX/Y/Z = 0, no mocap yet
    assert snap.position == pytest.approx((0.6, 0.2, 0.0), abs=1e-3)
    sim.run(READY_S)  # the fresh supervisor's three updates at 25 Hz
    snap = sim.snap()
    assert all(t.time_s > sim.t - 0.2 - READY_S for t in snap.transitions) and snap.supervisor_state == "Ready to fly"
    sim.mocap = (0.0, 0.0, 0.0)
    sim.hover(0.4)  # a fresh drone flies
    falling = Sim()
    falling.hover(0.5)
    falling.fw.reboot(falling.t, boot_s=0.1)
    falling.run(0.2)
    assert falling.snap().booting and falling.snap().position[2] > 0.0  # still falling: it boots where it lands
    falling.run(0.2)
    assert not falling.snap().booting and falling.snap().position[2] == 0.0


def test_persistent_parameters_are_stored_survive_a_reboot_and_clear() -> None:
    """paramPersistentStore / GetState / Clear of param_logic.c: the state answer is [4, id, stored, default
    (, stored value)]; stored values are applied at boot."""
    sim = Sim()
    effect = PARAM_TOC.by_name["ring.effect"]
    assert effect.persistent and effect.ctype == "uint8_t"
    ident = struct.pack("<H", effect.ident)
    assert sim.send(2, 3, bytes([4]) + ident)[0][2][3:] == bytes([0, 6])  # not stored, default 6
    sim.send(2, 2, ident + bytes([10]))
    assert sim.send(2, 3, bytes([3]) + ident)[0][2][3] == 0
    assert sim.send(2, 3, bytes([4]) + ident)[0][2][3:] == bytes([1, 6, 10])  # stored 10, default still 6
    sim.send(2, 2, ident + bytes([12]))
    sim.fw.reboot(sim.t)
    sim.run(2.0)
    assert sim.snap().boots == 1 and sim.snap().params["ring.effect"] == 10  # the stored value, not 12 or 6
    assert sim.send(2, 3, bytes([5]) + ident)[0][2][3] == 0
    assert sim.send(2, 3, bytes([4]) + ident)[0][2][3:] == bytes([0, 6])
    not_persistent = struct.pack("<H", PARAM_TOC.by_name["stabilizer.estimator"].ident)
    assert sim.send(2, 3, bytes([3]) + not_persistent)[0][2][3] == errno.ENOENT
    # the parameters of the default build's deck drivers are there, saying no deck is attached
    for name in ("deck.bcFlow2", "deck.bcLighthouse4", "deck.bcLoco", "deck.bcLedRing", "deck.bcAI"):
        assert PARAM_TOC.by_name[name].read_only and sim.snap().params[name] == 0
    assert sim.snap().params["cpu.flash"] == 1024 and PARAM_TOC.by_name["cpu.flash"].ctype == "uint16_t"
    assert {"kalman.stateX", "kalman.stateY", "kalman.stateZ"} <= set(LOG_TOC.by_name)


def test_a_drone_on_the_floor_with_its_motors_on_does_not_slide_to_a_setpoint_at_floor_height() -> None:
    """A position setpoint on the floor 0.5 m away, streamed to a drone standing there with its motors on: the
    height controller asks for no lift, so the body stands on its feet (a real one scrapes or tips, it does not
    glide to the setpoint at flying speed). A setpoint above the floor still lifts it and takes it there."""
    sim = Sim(position=(1.0, 1.0, 0.0))
    sim.run(READY_S)
    sim.run(1.0, lambda t: sim.send(7, 0, position(1.5, 1.0, 0.0)))
    standing = sim.snap()
    assert standing.motors_on and standing.position == pytest.approx((1.0, 1.0, 0.0), abs=1e-9)
    sim.run(2.0, lambda t: sim.send(7, 0, position(1.5, 1.0, 0.3)))
    assert sim.snap().position == pytest.approx((1.5, 1.0, 0.3), abs=0.02)
