"""One simulated Crazyflie flown the way the firmware flies it: the default PID cascade (cf_controller.py) on the
identified Crazyflie 2.1+ body (cf_body.py), with the high-level commander's plans (fake_planner.py).

Each `step(dt)` runs the firmware's 1 kHz stabilizer loop (`stabilizer.c:317-384`) tick by tick: the gyro sampled
and low-pass filtered (80 Hz, every tick), the state estimate refreshed every 10 ms (the Kalman filter predicts at
100 Hz, `estimator_kalman.c:119`; here the estimate is the true state then, without the filter's dynamics or noise),
the high-level commander at 100 Hz (`crtp_commander_high_level.c:345-406`), the controller, the power distribution,
then the body integrated over the 1 ms. Tick number k is at time k ms of the caller's clock, so every drone of one
world runs its 100 Hz and 500 Hz loops on the same ticks.

Setpoints: a streamed setpoint (`send_setpoint`, `send_position`) acts from the tick at or after the instant it is
sent until the next replaces it; it takes priority over the high-level commander and stops its plan (commander
priorities as fake_vehicle.py has them). `notify_setpoint_stop` hands control back to the high-level commander.
High-level commands (`takeoff`, `land`, `go_to`, `stop`) are planned by fake_planner.HighLevelCommander: a degree-7
rest-to-rest piece (`pptraj.c:148-178`, `planner.c:45-58`), take-off from the position copied from the estimate at
the last 100 Hz tick while idle, land and go_to from the running plan's position; the plan's position and velocity
go to the controller every 10 ms as an absolute setpoint whose velocity the position loop drops; after a landing
plan ends the commander sends the null setpoint (motors off). That planner starts a go_to from the running plan's
position at rest (the firmware also carries its velocity and acceleration, `planner.c:206-208`): a go_to sent
while a plan still moves starts more gently than on a real Crazyflie.

Not here (the simulated drone that embeds this adds them): the supervisor and its watchdogs, the estimator's errors,
the radio, the battery.
"""

from __future__ import annotations

import math
import struct
from typing import Any

from .cf_body import P250, CfBody, CfBodyParams, quaternion_to_rpy_deg
from .cf_controller import (
    ATTITUDE_EVERY,
    NULL_SETPOINT,
    POSITION_EVERY,
    THRUST_MAX_N,
    UINT16_MAX,
    CfGains,
    ControlSetpoint,
    Lpf2p,
    PidController,
    motor_thrust_n,
)
from .fake_planner import (
    COMMAND_GO_TO_2,
    COMMAND_LAND_2,
    COMMAND_STOP,
    COMMAND_TAKEOFF_2,
    HighLevelCommander,
    PlanState,
)
from .fake_setpoint import Setpoint

TICK_S = 0.001
PRIORITY_NONE = 0
PRIORITY_HIGH_LEVEL = 1
PRIORITY_CRTP = 2


class CfDrone:
    """One Crazyflie: controller, body, gyro filter, high-level commander (module doc). Deterministic: the same
    calls give the same flight."""

    def __init__(
        self,
        position: tuple[float, float, float] = (0.0, 0.0, 0.0),
        yaw_deg: float = 0.0,
        *,
        t_s: float = 0.0,
        gains: CfGains | None = None,
        body_params: CfBodyParams = P250,
        integrator: str = "midpoint",
        estimate_every_ticks: int = POSITION_EVERY,
        step_offset: int = 1,
    ) -> None:
        self.body = CfBody(
            position,
            math.radians(yaw_deg),
            params=body_params,
            integrator=integrator,
            floor_z=min(0.0, float(position[2])),
        )
        self.controller = PidController(gains)
        self.gyro_filter = Lpf2p()
        self.tick_count = round(t_s / TICK_S)
        """The next tick's number; it runs at `tick_count` ms."""
        self.step_offset = step_offset
        """The firmware's tick number (`stabilizerStep`) is the tick's time in ms plus this: the counter starts at 1
        (`stabilizer.c:306`) on the loop's first tick, at time 0, so the 100 Hz loops run at 9, 19, ... ms."""
        self.estimate_every_ticks = estimate_every_ticks
        self.state = self._true_state()
        """What the controller sees: x, y, z, vx, vy, vz, roll, pitch (legacy sign), yaw (m, m/s, deg)."""
        self.setpoint: ControlSetpoint = NULL_SETPOINT
        self.priority = PRIORITY_NONE
        x, y, z = self.body.pos
        self.hl = HighLevelCommander((x, y, z), math.radians(yaw_deg))
        self.motor_commands = (0, 0, 0, 0)

    @classmethod
    def hovering(
        cls,
        position: tuple[float, float, float],
        yaw_deg: float = 0.0,
        *,
        t_s: float = 0.0,
        settle_s: float = 10.0,
        **kwargs: Any,
    ) -> CfDrone:
        """A drone that has hovered at `position` under streamed position setpoints for `settle_s` before `t_s`:
        rotors at hover speed and the vertical-velocity integrator carrying the thrust thrustBase lacks, then
        flown `settle_s` so every loop settles (the state of a drone that has hovered a while)."""
        drone = cls(position, yaw_deg, t_s=t_s - settle_s, **kwargs)
        drone.body.floor_z = min(0.0, drone.body.floor_z)
        drone.body.on_floor = False
        p = drone.body.params
        drone.body.spin_at(p.hover_thrust_n)
        hover_command = p.hover_thrust_n / THRUST_MAX_N * UINT16_MAX
        c = drone.controller
        sp = ControlSetpoint.position(position[0], position[1], position[2], yaw_deg)
        c.previous_modes = sp.modes
        c.reinitialize(drone.state)
        c.pid_vz.integ = (hover_command - c.gains.thrust_base) / (1000.0 * c.gains.vel_z_ki)
        c.actuator_thrust = c.thrust = hover_command
        c.attitude_desired[2] = yaw_deg
        drone.send_setpoint(sp)
        drone.step(settle_s)
        return drone

    # Commands ---------------------------------------------------------------------------------------------------

    @property
    def time_s(self) -> float:
        return self.tick_count * TICK_S

    def send_setpoint(self, setpoint: ControlSetpoint | Setpoint) -> None:
        """A streamed (CRTP) setpoint: acts from the next tick, preempts the high-level commander."""
        if isinstance(setpoint, Setpoint):
            setpoint = ControlSetpoint.from_setpoint(setpoint)
        self.setpoint = setpoint
        self.priority = PRIORITY_CRTP
        self.hl.stop()

    def send_position(self, x: float, y: float, z: float, yaw_deg: float = 0.0) -> None:
        """cflib `send_position_setpoint`."""
        self.send_setpoint(ControlSetpoint.position(x, y, z, yaw_deg))

    def notify_setpoint_stop(self) -> None:
        """cflib `send_notify_setpoint_stop`: the high-level commander takes over from its next tick."""
        x, y, z, vx, vy, vz, _, _, yaw = self.state
        self.hl.tell_state((x, y, z), (vx, vy, vz), math.radians(yaw))
        self.priority = PRIORITY_HIGH_LEVEL

    def _hl(self, command: int, body: bytes) -> int:
        answer = self.hl.handle(bytes([command]) + body, self.time_s)
        return answer[3] if len(answer) > 3 else 0

    def takeoff(self, height_m: float, duration_s: float, yaw_deg: float = 0.0) -> int:
        """cflib `HighLevelCommander.takeoff` (takeoff2, absolute height); returns the firmware's answer (0: ok)."""
        return self._hl(COMMAND_TAKEOFF_2, struct.pack("<Bff?f", 0, height_m, math.radians(yaw_deg), False, duration_s))

    def land(self, height_m: float, duration_s: float, yaw_deg: float = 0.0) -> int:
        """cflib `HighLevelCommander.land` (land2)."""
        return self._hl(COMMAND_LAND_2, struct.pack("<Bff?f", 0, height_m, math.radians(yaw_deg), False, duration_s))

    def go_to(
        self,
        x: float,
        y: float,
        z: float,
        duration_s: float,
        yaw_deg: float = 0.0,
        *,
        relative: bool = False,
        linear: bool = False,
    ) -> int:
        """cflib `HighLevelCommander.go_to` (go_to2)."""
        return self._hl(
            COMMAND_GO_TO_2, struct.pack("<BBBfffff", 0, relative, linear, x, y, z, math.radians(yaw_deg), duration_s)
        )

    def stop(self) -> int:
        """cflib `HighLevelCommander.stop`: the plan ends, the commander asks for motors off."""
        return self._hl(COMMAND_STOP, bytes([0]))

    def plan_position(self, t_s: float) -> tuple[float, float, float] | None:
        """The high-level plan's position at `t_s` (its goal once it has ended); None before any plan (or where it
        does not evaluate)."""
        if self.hl.trajectory is None:
            return None
        evaluated = self.hl.trajectory.evaluate(t_s)
        return None if evaluated is None else evaluated[0]

    # Simulation -------------------------------------------------------------------------------------------------

    def step(self, dt_s: float) -> None:
        """Advance by `dt_s` (rounded to whole 1 ms ticks)."""
        for _ in range(round(dt_s / TICK_S)):
            self._tick()

    def _true_state(self) -> tuple[float, ...]:
        b = self.body
        roll, pitch, yaw = quaternion_to_rpy_deg(*b.quat)
        return (b.pos[0], b.pos[1], b.pos[2], b.vel[0], b.vel[1], b.vel[2], roll, -pitch, yaw)

    def _tick(self) -> None:
        k = self.tick_count + self.step_offset
        body = self.body
        o = body.omega
        gyro = self.gyro_filter.apply(math.degrees(o[0]), math.degrees(o[1]), math.degrees(o[2]))
        if k % self.estimate_every_ticks == 0:
            self.state = self._true_state()
        if k % POSITION_EVERY == 0 and self.priority <= PRIORITY_HIGH_LEVEL:
            x, y, z, vx, vy, vz, _, _, yaw = self.state
            hl_setpoint = self.hl.get_setpoint(self.tick_count * TICK_S, (x, y, z), (vx, vy, vz), math.radians(yaw))
            if hl_setpoint is not None:
                self.setpoint = ControlSetpoint.from_setpoint(hl_setpoint)
                self.priority = PRIORITY_HIGH_LEVEL
        c = self.controller
        c.tick(k, self.setpoint, self.state, gyro)
        if k % ATTITUDE_EVERY == 0 or c.thrust != self._last_thrust:
            motors = c.motors()
            if motors != self.motor_commands:
                self.motor_commands = motors
                body.command_thrusts([motor_thrust_n(m) for m in motors])
        self._last_thrust = c.thrust
        body.step(TICK_S)
        self.tick_count += 1

    _last_thrust = math.nan
    """The thrust of the last tick (NaN before the first: the first tick sets the motors)."""

    # Outputs ----------------------------------------------------------------------------------------------------

    @property
    def position(self) -> tuple[float, float, float]:
        p = self.body.pos
        return (p[0], p[1], p[2])

    @property
    def velocity(self) -> tuple[float, float, float]:
        v = self.body.vel
        return (v[0], v[1], v[2])

    @property
    def quaternion(self) -> tuple[float, float, float, float]:
        """Attitude, x, y, z, w (body to world)."""
        q = self.body.quat
        return (q[0], q[1], q[2], q[3])

    @property
    def rpy_deg(self) -> tuple[float, float, float]:
        """Roll, pitch, yaw (deg, right-handed: a positive pitch accelerates along +x)."""
        return self.body.rpy_deg()

    @property
    def tilt_deg(self) -> float:
        return self.body.tilt_deg

    @property
    def motors_on(self) -> bool:
        """Some motor is commanded a thrust it makes (over `THRUST_MIN`)."""
        return any(motor_thrust_n(m) > 0.0 for m in self.motor_commands)

    @property
    def flying(self) -> bool:
        """The high-level commander's plan is running (taking off, flying, landing)."""
        return self.hl.state in (PlanState.FLYING, PlanState.LANDING)

    @property
    def external_force(self) -> tuple[float, float, float]:
        """A force on the body (N, world frame) while set: a gust. (0, 0, 0) for still air."""
        return self.body.external_force

    @external_force.setter
    def external_force(self, force: tuple[float, float, float]) -> None:
        self.body.external_force = (float(force[0]), float(force[1]), float(force[2]))

    def params(self) -> dict[str, float]:
        """The controller's parameters by firmware name (`posCtlPid.xKp`, ...)."""
        return self.controller.params()

    def set_param(self, name: str, value: float) -> None:
        self.controller.set_param(name, value)
