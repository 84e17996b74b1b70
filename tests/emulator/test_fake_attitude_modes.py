"""The fake Crazyflie's attitude modes (RPYT, z-distance, manual, CPPM) through real cflib: its thrust lock, a raw
thrust that climbs or sinks instead of holding a height, and roll and pitch that accelerate the drone the way the
firmware signs them (rpf_fly/emulator/fake_setpoint.py, fake_vehicle.py "Attitude modes"). Modelled as "level,
hold the height" for any thrust above zero, a script that would fly a real drone into the ceiling or across the
room would hover in place in a dry run."""

from __future__ import annotations

import math
import struct
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from cflib.crazyflie import Crazyflie
from cflib.crazyflie.syncCrazyflie import SyncCrazyflie

from rpf_fly.emulator.fake_setpoint import TYPE_CPPM_EMU, AxisMode, decode_generic, decode_rpyt
from rpf_fly.emulator.fake_world import FakeWorld
from rpf_fly.emulator.vehicle_figures import GRAVITY_M_S2, HOVER_THRUST


def address(index: int) -> int:
    """Radio address of drone `index` (as the `make_world` fixture numbers them)."""
    return 0xE7E7E7E700 + index


def stream(send: Callable[[], None], seconds: float, rate_hz: float = 50.0) -> None:
    """Send one setpoint every 1 / rate_hz for `seconds`, as a user script's loop does."""
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        send()
        time.sleep(1.0 / rate_hz)


def test_rpyt_thrust_is_locked_until_a_zero_thrust_packet(
    make_world: Callable[..., FakeWorld], toc_cache: Path
) -> None:
    world = make_world(1)
    with SyncCrazyflie(world.uri(address(0)), cf=Crazyflie(rw_cache=str(toc_cache))) as scf:
        stream(lambda: scf.cf.commander.send_setpoint(0.0, 0.0, 0.0, 45000), 0.6)
        locked = world.snapshot(address(0))
        scf.cf.commander.send_setpoint(0.0, 0.0, 0.0, 0)  # "unlock startup thrust protection"
        stream(lambda: scf.cf.commander.send_setpoint(0.0, 0.0, 0.0, 45000), 0.5)
        unlocked = world.snapshot(address(0))
        scf.cf.commander.send_stop_setpoint()
    assert not locked.motors_on and locked.position[2] == 0.0
    assert unlocked.motors_on and unlocked.position[2] > 0.15


def test_an_rpyt_thrust_over_the_hover_thrust_climbs_and_under_it_sinks(
    make_world: Callable[..., FakeWorld], toc_cache: Path
) -> None:
    """No height is held in RPYT: 45000 (1.25 x the hover thrust) climbs ever faster, 30000 comes down."""
    world = make_world(1)
    heights: list[tuple[float, float]] = []
    with SyncCrazyflie(world.uri(address(0)), cf=Crazyflie(rw_cache=str(toc_cache))) as scf:
        cf = scf.cf
        cf.commander.send_setpoint(0.0, 0.0, 0.0, 0)
        start = time.monotonic()

        def climb() -> None:
            cf.commander.send_setpoint(0.0, 0.0, 0.0, 45000)
            heights.append((time.monotonic() - start, world.snapshot(address(0)).position[2]))

        stream(climb, 0.8)
        top = world.snapshot(address(0)).position[2]
        stream(lambda: cf.commander.send_setpoint(0.0, 0.0, 0.0, 30000), 1.0)
        later = world.snapshot(address(0))
        cf.commander.send_stop_setpoint()
    assert top > 0.4  # 1.25 g of lift: 2.45 m/s^2 upwards (less drag): about 0.6 m in 0.8 s
    # it accelerates: the second half of the climb covers more height than the first
    half = [z for t, z in heights if t <= 0.4][-1]
    assert top - half > half
    assert later.velocity[2] < 0.0  # 30000 < 36000: 1.6 m/s^2 downwards, it stopped climbing and sinks


@pytest.mark.parametrize(("pitch_deg", "roll_deg"), [(10.0, 0.0), (0.0, 10.0)])
def test_roll_and_pitch_accelerate_the_drone_as_the_firmware_signs_them(
    make_world: Callable[..., FakeWorld], toc_cache: Path, pitch_deg: float, roll_deg: float
) -> None:
    """z-distance carries the firmware's own angles (a positive pitch flies backwards, a positive roll to the
    right: -x, -y); cflib's RPYT negates the pitch it is given (a positive pitch flies forwards). 10 degrees of tilt
    is g tan(10) = 1.73 m/s^2 sideways: decimetres in 0.8 s where the old model stood still (0.3 m/s gained is the
    tilt held for a fifth of a second)."""
    world = make_world(1)
    with SyncCrazyflie(world.uri(address(0)), cf=Crazyflie(rw_cache=str(toc_cache))) as scf:
        cf = scf.cf
        cf.high_level_commander.takeoff(0.5, 1.0)
        time.sleep(1.3)
        before = world.snapshot(address(0))
        tilted_s = 0.8  # the tilt takes about 0.2 s to build, longer behind a loaded host's late packets
        stream(lambda: cf.commander.send_zdistance_setpoint(roll_deg, pitch_deg, 0.0, 0.5), tilted_s)
        after_zdistance = world.snapshot(address(0))
        stream(lambda: cf.commander.send_zdistance_setpoint(0.0, 0.0, 0.0, 0.5), 0.3)  # level
        middle = world.snapshot(address(0))
        thrust = int(HOVER_THRUST / math.cos(math.radians(10.0)))
        cf.commander.send_setpoint(0.0, 0.0, 0.0, 0)
        stream(lambda: cf.commander.send_setpoint(roll_deg, pitch_deg, 0.0, thrust), tilted_s)
        after_rpyt = world.snapshot(address(0))
        cf.commander.send_stop_setpoint()
    axis = 0 if pitch_deg else 1
    moved = after_zdistance.position[axis] - before.position[axis]
    sped_zdistance = after_zdistance.velocity[axis] - before.velocity[axis]
    sped_rpyt = after_rpyt.velocity[axis] - middle.velocity[axis]
    assert sped_zdistance < -0.3 and moved < -0.05, (sped_zdistance, moved)  # backwards (pitch), right (roll)
    assert abs(after_zdistance.position[2] - 0.5) < 0.05  # z-distance holds the height while it tilts
    if pitch_deg:
        assert sped_rpyt > 0.3, sped_rpyt  # cflib's send_setpoint negates the pitch: forwards
    else:
        assert sped_rpyt < -0.3, sped_rpyt  # roll is not negated: to the right again
    # a tilt of 10 degrees for the window's simulated time with the attitude loop's lag: under what an instant tilt
    # gives over it (0.8 s: 1.38 m/s and 0.55 m)
    tilt_accel = GRAVITY_M_S2 * math.tan(math.radians(10.0))
    span = after_zdistance.time_s - before.time_s
    assert abs(sped_zdistance) < tilt_accel * span and abs(moved) < 0.5 * tilt_accel * span**2, (span, moved)


def test_rpyt_decoding_follows_the_firmware() -> None:
    packet = struct.pack("<fffH", 1.0, -2.0, 30.0, 45000)
    setpoint, locked = decode_rpyt(packet, 0.0, thrust_locked=True)
    assert setpoint is not None and locked and setpoint.thrust == 0 and not setpoint.commands_thrust
    _, locked = decode_rpyt(struct.pack("<fffH", 0.0, 0.0, 0.0, 0), 0.0, thrust_locked=True)
    assert not locked
    setpoint, locked = decode_rpyt(struct.pack("<fffH", 0.0, 0.0, 0.0, 65000), 0.0, thrust_locked=False)
    assert setpoint is not None and setpoint.thrust == 60000 and not locked  # clipped to MAX_THRUST
    setpoint, _ = decode_rpyt(struct.pack("<fffH", 0.0, 0.0, 0.0, 999), 0.0, thrust_locked=False)
    assert setpoint is not None and setpoint.thrust == 0  # under MIN_THRUST
    setpoint, _ = decode_rpyt(packet, 0.0, thrust_locked=False)
    assert setpoint is not None and setpoint.attitude_mode is AxisMode.ABS and setpoint.attitude_deg == (1.0, -2.0)
    assert setpoint.yaw_rate_deg_s == 30.0 and setpoint.modes[2] is AxisMode.DISABLE


def test_cppm_emulation_decodes_channels_into_angles_and_thrust() -> None:
    # roll stick full right (2000), pitch centred, yaw centred, thrust at half; no aux channel: self-levelling
    body = struct.pack("<BHHHH", 0, 2000, 1500, 1500, 1500)
    setpoint = decode_generic(bytes([TYPE_CPPM_EMU]) + body, 0.0, 0.0)
    assert setpoint is not None and setpoint.attitude_mode is AxisMode.ABS
    assert setpoint.attitude_deg == (-50.0, 0.0) and setpoint.thrust == 32767
    # aux channel 0 low: rate mode
    body = struct.pack("<BHHHHH", 1, 1500, 1000, 1500, 1000, 1000)
    setpoint = decode_generic(bytes([TYPE_CPPM_EMU]) + body, 0.0, 0.0)
    assert setpoint is not None and setpoint.attitude_mode is AxisMode.VELOCITY
    assert setpoint.attitude_deg == (0.0, 720.0) and setpoint.thrust == 0 and not setpoint.commands_thrust
