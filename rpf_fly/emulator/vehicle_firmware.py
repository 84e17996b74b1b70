"""The simulated drone on the "firmware" dynamics (rpf_fly/emulator/fake_vehicle.py, "Firmware dynamics"): the
identified Crazyflie 2.1+ body (cf_body.py) flown by the firmware's PID cascade (cf_controller.py) at its 1 kHz
ticks, with the commander's selection, the supervisor's override and the estimate it sees at its 100 Hz ticks.
Why apart: the second of the vehicle's two dynamics, with a state of its own; the first-order model never runs it.

:class:`VehicleFirmware` is a part of :class:`~rpf_fly.emulator.fake_vehicle.Vehicle`: it reads and sets the vehicle's
attributes named in its body.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING

from .cf_body import CfBody, quaternion_to_rpy_deg
from .cf_controller import (
    ATTITUDE_EVERY,
    NULL_SETPOINT,
    PARAM_NAMES,
    POSITION_EVERY,
    CfGains,
    ControlSetpoint,
    Lpf2p,
    PidController,
    motor_thrust_n,
)
from .fake_planner import HighLevelCommander
from .fake_setpoint import Setpoint, Vec3, null_setpoint
from .fake_supervisor import Supervisor
from .vehicle_figures import PRIORITY_HIGH_LEVEL, TURBULENCE_MIN_HEIGHT_M, VARIANCE_DECAY_TAU_S

if TYPE_CHECKING:
    from .fake_vehicle import Battery, VehicleConfig

TICK_S = 0.001
"""The firmware's stabilizer tick (1 kHz): the step of the "firmware" dynamics."""
CONTROLLER_PARAMS = frozenset(PARAM_NAMES)
"""The controller's parameters by firmware name (`posCtlPid.xKp`, ...: cf_controller.CfGains)."""

_STILL_ROTORS = [0.0, 0.0, 0.0, 0.0]
_NO_FORCE = (0.0, 0.0, 0.0)


class VehicleFirmware:
    """The body, controller and 1 kHz ticks of the "firmware" dynamics."""

    config: VehicleConfig
    pos: list[float]
    vel: list[float]
    yaw: float
    floor_z: float
    gains: CfGains
    body: CfBody | None
    controller: PidController | None
    kalman: bool
    divergence_velocity: Vec3 | None
    ext_pos_std_dev: float
    _onboard_variance_m2: float
    supervisor: Supervisor
    _supervisor_slot: int
    hl: HighLevelCommander
    setpoint: Setpoint
    control_setpoint: Setpoint
    battery: Battery
    xy_vel_max: float
    z_vel_max: float
    low_voltage_v: float
    critical_voltage_v: float
    param_emergency_stop: bool
    thrusting: bool
    motors_on: bool
    attitude_deg: list[float]
    gust_accel: Vec3
    gust_until_s: float
    _turbulence: list[float]
    _last_s: float
    _commander_set: Callable[[Setpoint, int, float], bool]
    _override: Callable[[Setpoint], Setpoint]
    _predict: Callable[[float, float, float], None]
    _run_away: Callable[[float], None]
    _supervisor_lattice: Callable[[float], int]
    _turbulent: Callable[[float, Vec3 | None], Vec3]

    if TYPE_CHECKING:  # the estimator's (VehicleEstimator) and the vehicle's, read here

        @property
        def estimate(self) -> Vec3: ...

        @property
        def estimate_velocity(self) -> Vec3: ...

        @property
        def estimate_yaw(self) -> float: ...

        @property
        def powered(self) -> bool: ...

    def _init_firmware_dynamics(self, now_s: float) -> None:
        """The "firmware" dynamics' state (fake_vehicle, "Firmware dynamics"): body, controller, gyro filter, the
        1 kHz tick counter on the caller's clock."""
        self.body = CfBody(self.pos, self.yaw, floor_z=self.floor_z)
        self.pos, self.vel = self.body.pos, self.body.vel
        self.controller = PidController(self.gains)
        self._gyro_filter = Lpf2p()
        self._tick_ms = math.ceil(now_s / TICK_S - 1e-6)
        """The next tick's number: it runs at `_tick_ms` ms of the caller's clock and flies the body to the next."""
        self._slot_s = (self._tick_ms - POSITION_EVERY) * TICK_S
        """The time of the last 100 Hz tick (the estimator's, high-level commander's and position loop's)."""
        self._slot_vel = (0.0, 0.0)
        """The true horizontal velocity at the last 100 Hz tick (the IMU's velocity change since: `_predict`)."""
        self._control: ControlSetpoint = NULL_SETPOINT
        """The controller's setpoint (the commander's selection, overridden by the supervisor)."""
        self._control_idle = True
        """`_control` is the null setpoint's (all modes off, no thrust): motors off."""
        self._control_of: Setpoint | None = None
        """The `Setpoint` `_control` was made from."""
        self._selected_from: Setpoint | None = None
        """The commander's setpoint when the control was last selected."""
        self._motors_allowed = False
        """The supervisor's verdict at the last selection (`stabilizer.c`: motors run only when allowed)."""
        self._state: tuple[float, ...] = (0.0,) * 9
        """What the controller sees: the estimate (x, y, z, vx, vy, vz), true roll, pitch (legacy sign) and the
        estimated yaw, degrees; refreshed every 10 ms."""
        self._last_thrust = math.nan
        self.motor_commands = (0, 0, 0, 0)

    def set_controller_param(self, name: str, value: float) -> None:
        """A controller parameter written (`posCtlPid.xKp`, ...; KeyError for another name): it acts at once, as
        the firmware's PID objects read their gains each update."""
        gains = self.gains
        if self.controller is not None:
            self.controller.set_param(name, value)
        else:
            gains.set_param(name, value)
        self.xy_vel_max = min(gains.x_vel_max, gains.y_vel_max)
        self.z_vel_max = gains.z_vel_max

    def _stop_motors(self) -> None:
        """Motors off now (power cut, crash): no command reaches them until the next selection allows it."""
        self._motors_allowed = False
        self._control = NULL_SETPOINT
        self._control_of = None
        self._control_idle = True
        self.motor_commands = (0, 0, 0, 0)
        assert self.body is not None
        self.body.command_thrusts((0.0, 0.0, 0.0, 0.0))

    def _select(self, setpoint: Setpoint) -> None:
        """The controller's setpoint from the commander's (`setpoint`, already null where flying is not allowed):
        the supervisor's override on its current state, and whether the motors may run."""
        setpoint = self._override(setpoint)
        self.control_setpoint = setpoint
        if setpoint is not self._control_of:
            control = self._control = ControlSetpoint.from_setpoint(setpoint)
            self._control_of = setpoint
            self._control_idle = control.thrust == 0.0 and control.modes == NULL_SETPOINT.modes
        self._motors_allowed = self.powered and self.supervisor.motors_allowed

    def _update_motors_on(self) -> None:
        self.motors_on = self.thrusting = self._motors_allowed and any(
            motor_thrust_n(m) > 0.0 for m in self.motor_commands
        )

    def _step_firmware(self, now_s: float) -> None:
        """Fly the 1 ms ticks up to `now_s` (fake_vehicle, "Firmware dynamics")."""
        end = math.floor(now_s / TICK_S + 1e-6)
        body, controller, gyro_filter = self.body, self.controller, self._gyro_filter
        assert body is not None and controller is not None
        if self._tick_ms < end and self.setpoint is not self._selected_from and self.powered:
            # a streamed setpoint that came since the last tick acts from this one (commanderGetSetpoint each tick)
            self._selected_from = self.setpoint
            self._select(self.setpoint if self.supervisor.motors_allowed else null_setpoint(0.0))
        degrees = math.degrees
        while self._tick_ms < end:
            k = self._tick_ms + 1  # the firmware's tick counter starts at 1 on the loop's first tick (CfDrone)
            o = body.omega
            gyro = gyro_filter.apply(degrees(o[0]), degrees(o[1]), degrees(o[2]))
            if k % POSITION_EVERY == 0:
                self._firmware_slot(self._tick_ms * TICK_S)
            control = self._control
            if self._motors_allowed and not self._control_idle:
                controller.tick(k, control, self._state, gyro)
                if k % ATTITUDE_EVERY == 0 or controller.thrust != self._last_thrust:
                    motors = controller.motors()
                    if motors != self.motor_commands:
                        self.motor_commands = motors
                        body.command_thrusts([motor_thrust_n(m) for m in motors])
                self._last_thrust = controller.thrust
            else:
                # the null setpoint (or motors not allowed, which the override makes null): the controller's output
                # is 0 and it resets on the state every tick, which changes every 10 ms: ticked then, and until
                # its mode set and thrust are the null's
                if k % POSITION_EVERY == 0 or controller.thrust != 0.0 or controller.previous_modes != control.modes:
                    controller.tick(k, control, self._state, gyro)
                    self._last_thrust = controller.thrust
                if self.motor_commands != (0, 0, 0, 0):
                    self.motor_commands = (0, 0, 0, 0)
                    body.command_thrusts((0.0, 0.0, 0.0, 0.0))
            if not (
                body.on_floor
                and body.rotor_rpm == _STILL_ROTORS
                and body.rotor_cmd_rpm == _STILL_ROTORS
                and body.external_force == _NO_FORCE
            ):  # at rest on the floor with rotors still, nothing moves
                x, y, was_on_floor = body.pos[0], body.pos[1], body.on_floor
                body.step(TICK_S)
                if body.on_floor:  # it stands on its feet: level, and it can neither slide nor tip
                    body.pos[0], body.pos[1] = x, y
                    qz, qw = body.quat[2], body.quat[3]
                    if not was_on_floor or body.quat[0] or body.quat[1]:
                        norm = math.hypot(qz, qw)
                        body.quat = [0.0, 0.0, qz / norm, qw / norm]
            self._tick_ms += 1
        self.pos, self.vel = body.pos, body.vel
        self._update_motors_on()
        self._last_s = max(self._last_s, now_s)

    def _firmware_slot(self, t: float) -> None:
        """The 100 Hz part of the tick at `t`: the interval since the last one closed (battery, estimator), the
        truth's attitude read, the push of gusts and turbulence set, then the high-level commander, the
        commander's selection, the supervisor (at its 25 Hz) and its override, and the estimate the controller
        sees for the next 10 ms."""
        body = self.body
        assert body is not None
        self.pos, self.vel = body.pos, body.vel  # the body's lists of now (each step makes new ones)
        dt = t - self._slot_s
        self._slot_s = t
        self._update_motors_on()
        vel = body.vel
        if dt > 0.0:
            self.battery.step(t, dt, self.motors_on, self.low_voltage_v, self.critical_voltage_v)
            if self.divergence_velocity is not None:
                self._run_away(dt)
            elif self.kalman:
                self._predict(dt, vel[0] - self._slot_vel[0], vel[1] - self._slot_vel[1])
            else:
                floor = self.ext_pos_std_dev**2
                self._onboard_variance_m2 = floor + (self._onboard_variance_m2 - floor) * math.exp(
                    -dt / VARIANCE_DECAY_TAU_S
                )
        self._slot_vel = (vel[0], vel[1])
        roll, pitch, yaw = quaternion_to_rpy_deg(*body.quat)
        self.yaw = math.radians(yaw)
        self.attitude_deg[0], self.attitude_deg[1] = roll, -pitch
        push = self.gust_accel if t <= self.gust_until_s else None
        if self.config.turbulence_m_s2 and self.motors_on and body.pos[2] > self.floor_z + TURBULENCE_MIN_HEIGHT_M:
            push = self._turbulent(POSITION_EVERY * TICK_S, push)
        elif self._turbulence[0] or self._turbulence[1] or self._turbulence[2]:
            self._turbulence = [0.0, 0.0, 0.0]
        mass = body.params.mass
        body.external_force = _NO_FORCE if push is None else (mass * push[0], mass * push[1], mass * push[2])
        if not self.powered:
            self.control_setpoint = null_setpoint(t, "power-off")
            self._stop_motors()
            return
        can_fly = self.supervisor.motors_allowed
        self.hl.block(not can_fly)
        if can_fly:
            hl_setpoint = self.hl.get_setpoint(t, self.estimate, self.estimate_velocity, self.estimate_yaw)
            if hl_setpoint is not None:
                self._commander_set(hl_setpoint, PRIORITY_HIGH_LEVEL, t)
        setpoint = self.setpoint if can_fly else null_setpoint(0.0)
        slot = self._supervisor_lattice(t)
        if slot > self._supervisor_slot:
            self._supervisor_slot = slot
            self.supervisor.update(
                t,
                thrust_over_idle=self.thrusting,
                setpoint_age_s=t - setpoint.timestamp_s,
                param_emergency_stop=self.param_emergency_stop,
            )
        self._selected_from = self.setpoint
        self._select(setpoint)
        est, est_vel = self.estimate, self.estimate_velocity
        self._state = (
            est[0],
            est[1],
            est[2],
            est_vel[0],
            est_vel[1],
            est_vel[2],
            roll,
            -pitch,
            math.degrees(self.estimate_yaw),
        )
