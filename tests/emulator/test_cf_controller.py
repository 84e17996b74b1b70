"""The firmware's PID cascade (rpf_fly/emulator/cf_controller.py), the cf2x_P250 body (cf_body.py), one drone
(cf_drone.py) and the batched swarm (cf_swarm.py), against the facts docs/dynamics.md cites."""

from __future__ import annotations

import math

import pytest

from rpf_fly.emulator.cf_body import P250, CfBody
from rpf_fly.emulator.cf_controller import (
    MODE_ABS,
    MODE_DISABLE,
    MODE_VELOCITY,
    NULL_SETPOINT,
    PARAM_NAMES,
    CfGains,
    ControlSetpoint,
    Lpf2p,
    Pid,
    PidController,
    legacy_power_distribution,
    motor_thrust_n,
    saturate_int16,
)
from rpf_fly.emulator.cf_drone import CfDrone
from rpf_fly.emulator.cf_swarm import CfSwarm
from rpf_fly.emulator.fake_setpoint import AxisMode, Setpoint

# The PID object (pid.c:58-157) ---------------------------------------------------------------------------------


def test_pid_derivative_acts_on_the_measurement_not_the_error() -> None:
    pid = Pid(kp=0.0, ki=0.0, kd=2.0, kff=0.0, dt=0.01)
    pid.reset(1.0)
    pid.desired = 5.0  # a setpoint jump: no derivative kick
    assert pid.update(1.0) == 0.0
    pid.desired = -3.0
    assert pid.update(1.0) == 0.0
    # the measurement rising by 0.1 in 10 ms: D = -kd x 0.1 / 0.01
    assert pid.update(1.1) == pytest.approx(-20.0)


def test_pid_integral_and_output_clamps() -> None:
    pid = Pid(kp=1.0, ki=4.0, kd=0.0, kff=0.0, dt=0.1, i_limit=0.5, output_limit=3.0)
    pid.desired = 2.0
    out = [pid.update(0.0) for _ in range(20)]
    assert pid.integ == 0.5  # error x dt = 0.2 a step, clamped at the integral limit
    assert out[0] == pytest.approx(2.0 + 4.0 * 0.2)  # P 2 + I 0.8: under the output limit
    assert out[-1] == 3.0  # P 2 + I 2, clamped
    pid.desired = -2.0
    assert pid.update(0.0) == pytest.approx(-2.0 + 4.0 * 0.3)  # the clamped integral unwinds at once


def test_pid_feed_forward_and_default_integral_limit() -> None:
    pid = Pid(kp=0.0, ki=1.0, kd=0.0, kff=0.5, dt=1.0)
    pid.desired = 4.0
    assert pid.update(0.0) == pytest.approx(4.0 + 2.0)
    for _ in range(3000):
        pid.update(-10.0)
    assert pid.integ == 5000.0  # DEFAULT_PID_INTEGRATION_LIMIT (pid.h:33)


def test_pid_yaw_error_and_derivative_wrap() -> None:
    pid = Pid(kp=1.0, ki=0.0, kd=1.0, kff=0.0, dt=1.0, is_yaw=True)
    pid.reset(179.0)
    pid.desired = -179.0
    # error -358 wraps to +2; the measurement stays, so no derivative
    assert pid.update(179.0) == pytest.approx(2.0)
    # the measurement crosses 180: a step of +2 degrees, not -358
    assert pid.update(-179.0) == pytest.approx(0.0 - 2.0)


def test_pid_reset() -> None:
    pid = Pid(kp=1.0, ki=1.0, kd=1.0, kff=0.0, dt=0.1)
    pid.desired = 1.0
    pid.update(0.0)
    pid.reset(0.3)
    assert (pid.integ, pid.error, pid.deriv, pid.prev_measured) == (0.0, 0.0, 0.0, 0.3)


def test_gyro_filter_is_the_firmware_two_pole_low_pass() -> None:
    f = Lpf2p()
    ohm = math.tan(math.pi * 80.0 / 1000.0)
    c = 1.0 + math.sqrt(2.0) * ohm + ohm * ohm
    assert f.b0 == pytest.approx(ohm * ohm / c)
    assert f.a1 == pytest.approx(2.0 * (ohm * ohm - 1.0) / c)
    out = [f.apply(1.0, -2.0, 0.5) for _ in range(200)]
    assert out[-1] == pytest.approx((1.0, -2.0, 0.5))  # unity DC gain
    assert out[0][0] < 0.1  # two poles at 80 Hz: a step takes a few ms


# Mixer and motors (power_distribution_quadrotor.c:84-198, motors.c:180-222) --------------------------------------


def test_legacy_mixer_formulas() -> None:
    thrust, roll, pitch, yaw = 40000.0, 1001, -601, 50
    r, p = 500, -300  # half of roll and pitch, truncated towards zero (int16)
    assert legacy_power_distribution(thrust, roll, pitch, yaw) == (
        thrust - r + p + yaw,
        thrust - r - p - yaw,
        thrust + r - p + yaw,
        thrust + r + p - yaw,
    )


def test_mixer_lowers_all_motors_by_the_excess_and_floors_at_zero() -> None:
    m = legacy_power_distribution(64000.0, 4000, 0, 0)  # motors 3 and 4 at 66000: 465 over
    assert m == (62000 - 465, 62000 - 465, 65535, 65535)
    assert legacy_power_distribution(1000.0, 6000, 0, 0) == (0, 0, 4000, 4000)


def test_battery_compensated_thrust() -> None:
    assert motor_thrust_n(65535) == pytest.approx(0.12)
    assert motor_thrust_n(32767.5) == pytest.approx(0.06)
    assert motor_thrust_n(6990) == 0.0  # 0.0128 N (a command of 7000) is the least a motor makes
    assert motor_thrust_n(7100) > 0.0
    hover = P250.hover_thrust_n / 0.12 * 65535
    assert hover == pytest.approx(42600, abs=50)  # "Hovering a 31.8 g drone takes about 42 600 per motor"


def test_saturate_int16() -> None:
    assert saturate_int16(40000.7) == 32767
    assert saturate_int16(-40000.0) == -32767
    assert saturate_int16(-12.9) == -12


# Body (drone-models cf2x_P250) ---------------------------------------------------------------------------------


def test_rotor_speed_at_hover_and_time_constants() -> None:
    assert P250.hover_rpm == pytest.approx(23200, rel=0.01)
    for up in (True, False):
        body = CfBody((0.0, 0.0, 5.0))
        body.spin_at(P250.hover_thrust_n)
        target = P250.hover_rpm * (1.01 if up else 0.99)
        body.rotor_cmd_rpm = [target] * 4
        start, t = body.rotor_rpm[0], 0.0
        while abs(body.rotor_rpm[0] - target) > abs(target - start) * math.exp(-1.0):
            body.step(0.0005)
            t += 0.0005
        assert t == pytest.approx(0.11 if up else 0.10, abs=0.006)  # README: about 0.11 s up, 0.10 s down


def test_body_hovers_at_hover_thrust_and_falls_without() -> None:
    body = CfBody((0.0, 0.0, 1.0))
    body.on_floor = False
    body.spin_at(P250.hover_thrust_n)
    for _ in range(1000):
        body.step(0.001)
    assert body.pos[2] == pytest.approx(1.0, abs=1e-9)
    body.command_thrusts([0.0] * 4)
    for _ in range(300):
        body.step(0.001)
    assert body.pos[2] < 0.9
    for _ in range(2000):
        body.step(0.001)
    assert body.pos == [0.0, 0.0, 0.0] and body.vel == [0.0, 0.0, 0.0]  # on the floor: no penetration, no slide


def test_roll_torque_sign_matches_the_firmware_convention() -> None:
    """A positive roll command speeds up motors 3 and 4 (left): the body rolls right-handed about x, and the legacy
    pitch command (motors 1 and 4, front, faster) pitches the nose up (negative right-handed pitch)."""
    for roll, pitch, axis, sign in ((2000, 0, 0, 1.0), (0, 2000, 1, -1.0)):
        body = CfBody((0.0, 0.0, 1.0))
        body.on_floor = False
        m = legacy_power_distribution(42600.0, roll, pitch, 0)
        body.spin_at(P250.hover_thrust_n)
        body.command_thrusts([motor_thrust_n(c) for c in m])
        for _ in range(50):
            body.step(0.001)
        assert body.omega[axis] * sign > 0.0


def test_midpoint_and_rk4_agree() -> None:
    flights = []
    for integrator in ("midpoint", "rk4"):
        drone = CfDrone.hovering((0.0, 0.0, 1.0), settle_s=2.0, integrator=integrator)
        drone.send_position(0.5, 0.2, 1.1)
        track = []
        for _ in range(300):
            drone.step(0.01)
            track.append((drone.position, drone.tilt_deg))
        flights.append(track)
    pos_err = max(max(abs(a - b) for a, b in zip(p, q)) for (p, _), (q, _) in zip(*flights))
    tilt_err = max(abs(a - b) for (_, a), (_, b) in zip(*flights))
    assert pos_err < 5e-5 and tilt_err < 0.01, (pos_err, tilt_err)


# Controller ----------------------------------------------------------------------------------------------------


def test_gains_carry_the_firmware_parameter_names() -> None:
    gains = CfGains()
    params = gains.params()
    for name, value in (
        ("posCtlPid.xKp", 2.0),
        ("posCtlPid.zKi", 0.5),
        ("velCtlPid.vxKp", 25.0),
        ("velCtlPid.vzKi", 15.0),
        ("pid_attitude.roll_kp", 6.0),
        ("pid_attitude.yaw_kd", 0.35),
        ("pid_rate.roll_kp", 250.0),
        ("pid_rate.roll_kd", 2.5),
        ("pid_rate.yaw_ki", 16.7),
        ("posCtlPid.xVelMax", 1.0),
        ("posCtlPid.zVelMax", 1.0),
        ("posCtlPid.thrustBase", 36000.0),
        ("posCtlPid.thrustMin", 20000.0),
        ("posCtlPid.rLimit", 20.0),
        ("posCtlPid.pLimit", 20.0),
    ):
        assert params[name] == value
    assert set(PARAM_NAMES) == set(params)
    assert all(name.split(".")[0] in ("posCtlPid", "velCtlPid", "pid_attitude", "pid_rate") for name in params)
    gains.set_param("posCtlPid.xVelMax", 0.5)
    assert gains.x_vel_max == 0.5
    with pytest.raises(KeyError):
        gains.set_param("posCtlPid.noSuch", 1.0)


def test_a_lower_velocity_limit_slows_a_step() -> None:
    drone = CfDrone.hovering((0.0, 0.0, 1.0), settle_s=2.0)
    drone.set_param("posCtlPid.xVelMax", 0.4)
    drone.send_position(1.0, 0.0, 1.0)
    peak = 0.0
    for _ in range(200):
        drone.step(0.01)
        peak = max(peak, drone.velocity[0])
    assert 0.4 < peak < 0.4 * 1.1 * 1.05  # the position loop's output clamp, xVelMax x 1.10


def _state(x: float = 0.0, y: float = 0.0, z: float = 1.0) -> tuple[float, ...]:
    return (x, y, z, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


def test_absolute_mode_drops_the_setpoint_velocity() -> None:
    """position_controller_pid.c:211-231: in absolute mode the velocity setpoint is the position PID's output."""
    thrusts = []
    for vx in (0.0, 0.8):
        c = PidController()
        sp = ControlSetpoint(MODE_ABS, MODE_ABS, MODE_ABS, MODE_DISABLE, MODE_DISABLE, MODE_ABS, 0.3, 0.0, 1.0, vx=vx)
        c.tick(10, sp, _state(), (0.0, 0.0, 0.0))
        thrusts.append((c.attitude_desired[1], c.pid_vx.desired))
    assert thrusts[0] == thrusts[1]
    assert thrusts[0][1] == pytest.approx(0.6)  # kp 2 x 0.3 m
    # velocity mode uses it
    c = PidController()
    sp = ControlSetpoint(MODE_VELOCITY, MODE_VELOCITY, MODE_ABS, MODE_DISABLE, MODE_DISABLE, MODE_ABS, z=1.0, vx=0.8)
    c.tick(10, sp, _state(), (0.0, 0.0, 0.0))
    assert c.pid_vx.desired == 0.8
    assert c.attitude_desired[1] == pytest.approx(-min(25.0 * 0.8, 20.0))  # pitch = -PID(vx), clamped at 20 deg


def test_position_loop_clamps_and_thrust_limits() -> None:
    c = PidController()
    sp = ControlSetpoint.position(5.0, 0.0, 9.0)
    c.tick(10, sp, _state(), (0.0, 0.0, 0.0))
    assert c.pid_vx.desired == pytest.approx(1.1)  # xVelMax 1 x 1.10
    assert c.pid_vz.desired == pytest.approx(1.1)
    assert c.actuator_thrust == pytest.approx(36000 + 1000 * (25.0 * 1.1 + 15.0 * 1.1 * 0.01))
    assert c.attitude_desired[1] == -20.0  # pitch for +x, clamped at pLimit
    c = PidController()
    c.tick(10, ControlSetpoint.position(0.0, 0.0, -5.0), _state(), (0.0, 0.0, 0.0))
    assert c.actuator_thrust == 20000.0  # raised to thrustMin


def test_resets_on_a_mode_change_and_on_zero_thrust() -> None:
    c = PidController()
    sp = ControlSetpoint.position(0.0, 0.0, 1.5)
    for step in range(1, 200):
        c.tick(step, sp, _state(), (0.0, 0.0, 0.0))
    assert c.pid_vz.integ != 0.0 and c.pid_z.integ != 0.0
    same_modes = ControlSetpoint.position(0.1, 0.0, 1.5)
    c.tick(200, same_modes, _state(), (0.0, 0.0, 0.0))
    assert c.pid_vz.integ != 0.0  # the same mode set: no reset
    hover = ControlSetpoint(MODE_VELOCITY, MODE_VELOCITY, MODE_ABS, MODE_DISABLE, MODE_DISABLE, MODE_VELOCITY, z=1.5)
    c.tick(201, hover, _state(), (0.0, 0.0, 0.0))
    assert c.pid_vz.integ == 0.0 and c.pid_z.integ == 0.0  # reset, then the tick's own update (not a 10 ms tick)
    c.tick(210, hover, _state(), (0.0, 0.0, 0.0))
    assert c.pid_vz.integ != 0.0
    c.tick(212, NULL_SETPOINT, _state(), (10.0, 0.0, 0.0))
    assert c.thrust == 0.0 and (c.roll, c.pitch, c.yaw) == (0, 0, 0)
    assert c.pid_vz.integ == 0.0 and c.pid_roll_rate.integ == 0.0


def test_setpoint_conversion() -> None:
    sp = Setpoint(
        (AxisMode.DISABLE, AxisMode.DISABLE, AxisMode.ABS),
        (0.0, 0.0, 0.7),
        yaw_mode=AxisMode.VELOCITY,
        yaw_rate_deg_s=30.0,
        attitude_mode=AxisMode.ABS,
        attitude_deg=(5.0, -3.0),
    )
    c = ControlSetpoint.from_setpoint(sp)
    assert c.modes == (MODE_DISABLE, MODE_DISABLE, MODE_ABS, MODE_ABS, MODE_ABS, MODE_VELOCITY)
    assert (c.z, c.roll, c.pitch, c.yaw_rate) == (0.7, 5.0, -3.0, 30.0)


# One drone -----------------------------------------------------------------------------------------------------


def test_a_fresh_controller_sags_then_recovers() -> None:
    """README, start states: a freshly reset controller starts at 36 000 and sags about 8 cm in half a second."""
    drone = CfDrone((0.0, 0.0, 1.0))
    drone.body.on_floor = False
    drone.body.floor_z = 0.0
    drone.body.spin_at(P250.hover_thrust_n)
    drone.send_position(0.0, 0.0, 1.0)
    low = 1.0
    for _ in range(100):
        drone.step(0.01)
        low = min(low, drone.position[2])
    assert 0.05 < 1.0 - low < 0.12


def test_floor_take_off_lands_and_stops_the_motors() -> None:
    drone = CfDrone((0.3, -0.2, 0.0), t_s=-1.0)
    drone.step(1.0)
    assert not drone.motors_on and drone.position == (0.3, -0.2, 0.0)
    assert drone.takeoff(0.5, 2.0) == 0
    drone.step(0.5)
    assert drone.motors_on and drone.position[2] == 0.0  # 36 000 does not lift it: the integrators build up
    drone.step(4.5)
    assert drone.position[2] == pytest.approx(0.5, abs=0.06)
    assert drone.land(0.0, 2.0) == 0
    drone.step(2.1)
    assert not drone.motors_on  # the landing plan ended: the null setpoint
    drone.step(1.0)
    assert drone.position[2] == 0.0 and drone.velocity == (0.0, 0.0, 0.0)
    assert math.hypot(drone.position[0] - 0.3, drone.position[1] + 0.2) < 0.01


def test_gust_pushes_and_the_controller_fights_back() -> None:
    drone = CfDrone.hovering((0.0, 0.0, 1.0), settle_s=2.0)
    force = 0.02  # N along +x: tan(tilt) = 0.02 / (0.0318 x 9.81), 3.7 degrees to hold it
    drone.external_force = (force, 0.0, 0.0)
    drone.step(3.0)
    tilt = math.degrees(math.atan(force / (P250.mass * P250.gravity)))
    # the velocity loop holds the tilt with a velocity error of tilt / 25 deg per m/s, the position loop that
    # with an offset of it / kp 2 (the velocity integrator, ki 1, takes tens of seconds to remove it)
    offset = tilt / 25.0 / 2.0
    assert drone.position[0] == pytest.approx(offset, rel=0.3)
    assert drone.tilt_deg == pytest.approx(tilt, rel=0.15)
    drone.external_force = (0.0, 0.0, 0.0)
    drone.step(4.0)
    assert abs(drone.position[0]) < 0.02


def test_a_drone_is_deterministic() -> None:
    runs = []
    for _ in range(2):
        drone = CfDrone.hovering((0.0, 0.0, 1.0), settle_s=1.0)
        drone.send_position(0.4, -0.3, 1.2, 30.0)
        drone.step(2.0)
        runs.append((drone.position, drone.quaternion, drone.velocity))
    assert runs[0] == runs[1]
    q = runs[0][1]
    assert math.sqrt(sum(c * c for c in q)) == pytest.approx(1.0)
    assert math.degrees(2.0 * math.atan2(q[2], q[3])) == pytest.approx(30.0, abs=1.0)  # it turned to yaw 30


# The swarm -----------------------------------------------------------------------------------------------------


def test_the_swarm_flies_each_drone_as_one_drone_flies() -> None:
    drones = [CfDrone.hovering((0.0, 0.0, 1.0), settle_s=1.0), CfDrone((1.0, 0.0, 0.0), t_s=-1.0)]
    drones[1].step(1.0)
    swarm = CfSwarm.hovering([(0.0, 0.0, 1.0), (1.0, 0.0, 1.0)], settle_s=1.0)
    floor = CfSwarm([(1.0, 0.0, 0.0)], t_s=-1.0)
    floor.step(1.0)
    views = [swarm.drone(0), floor.drone(0)]
    for d in (drones[0], views[0]):
        d.send_position(0.5, 0.3, 1.2, 20.0)
        d.external_force = (0.0, 0.005, 0.0)
    for d in (drones[1], views[1]):
        d.takeoff(0.6, 1.5)
    for step in range(400):
        if step == 250:
            for d in (drones[1], views[1]):
                d.go_to(1.4, 0.2, 0.8, 1.0)
        for d in drones:
            d.step(0.01)
        swarm.step(0.01)
        floor.step(0.01)
        for one, many in zip(drones, views):
            assert max(abs(a - b) for a, b in zip(one.position, many.position)) < 1e-9
            assert max(abs(a - b) for a, b in zip(one.quaternion, many.quaternion)) < 1e-9
            assert one.motor_commands == many.motor_commands
    # the other drone of the swarm hovered on, untouched
    assert swarm.drone(1).position == pytest.approx((1.0, 0.0, 1.0), abs=1e-3)
