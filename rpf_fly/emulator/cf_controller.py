"""The Crazyflie firmware's default controller (`controllerPid`) with its power distribution and motor thrust, as
crazyflie-firmware 2026.08 (commit 2a18fc29) runs it on a Crazyflie 2.1 with the 2.1+ propellers.

Facts (file:line in that commit; short names as in docs/dynamics.md):
- Rates: the stabilizer loop ticks at 1 kHz, the attitude and rate PIDs run at 500 Hz, the position and velocity
  PIDs at 100 Hz (`stabilizer_types.h:371-374`); a task of rate R runs on the ticks whose number is a multiple of
  1000 / R (`stabilizer_types.h:377`). `PidController.tick` takes the tick number and does the same.
- The PID object (`pid.c:58-145`): P on the error, D on the change of the *measurement* (no derivative kick on a
  setpoint jump), integral += error x dt clamped to +/- iLimit (default 5000, `pid.h:33`; only the attitude and rate
  loops set their own, `attitude_pid_controller.c:118-131`), feed-forward kff x desired, then the output clamped to
  +/- outputLimit where it is not 0. A reset (`pid.c:151-157`) zeroes error, integral and derivative and sets the
  previous measurement. The D-term filters are off for the attitude and rate loops (`platform_defaults.h:100-113`);
  the position and velocity loops' filters act on their D term only, whose gains are 0 by default, so they are not
  modelled.
- Position loop (`position_controller_pid.c:193-234`): x, y in the body-yaw-aligned frame; an axis in absolute mode
  gets the position PID's output as its velocity setpoint, the setpoint's own velocity is used only for axes not in
  absolute mode (no feed-forward of a plan's velocity). Output limits xVelMax x 1.10, yVelMax x 1.10,
  max(zVelMax, 0.5) x 1.10 (`:196-200`).
- Velocity loop (`:236-267`): pitch = -PID(vx), roll = -PID(vy), PID outputs clamped at pLimit x 1.10 and rLimit x
  1.10, then the angles clamped at +/- rLimit, pLimit; thrust = PID(vz) x 1000 + thrustBase (vz output clamped at
  65535 / 2 / 1000), raised to thrustMin, clamped to 0..65535.
- The cascade (`controller_pid.c:74-180`): all PIDs reset when the setpoint's mode set changes from one tick to the
  next, the first setpoint included (`:43-50`, `:66-83`); yaw setpoint from the setpoint at 500 Hz (`:85-113`);
  position loop at 100 Hz (`:115-117`); at 500 Hz the raw thrust and roll/pitch of the setpoint where z or x/y are
  disabled (`:119-127`), the attitude PIDs, rate setpoints of rate modes (`:133-139`), the rate PIDs on the filtered
  gyro (x, -y, z) (`:142-143`), their outputs saturated to +/- 32767 and cast to int16
  (`attitude_pid_controller.c:46-55`, `:141-154`), the yaw command negated (`controller_pid.c:149`); every tick whose
  thrust is 0 zeroes the commands and resets all PIDs (`:161-179`). Attitude yaw uses the wrapped error
  (`pid.c:64-70`, `attitude_pid_controller.c:170`).
- The state the controller sees: roll, pitch, yaw in degrees with the legacy pitch sign (pitch = minus the
  right-handed pitch, `kalman_core.c:800-809`).
- Legacy power distribution (`power_distribution_quadrotor.c:84-93`): r, p = roll / 2, pitch / 2 (int16), motor 1 =
  T - r + p + yaw, 2 = T - r - p - yaw, 3 = T + r - p + yaw, 4 = T + r + p - yaw; a motor over 65535 lowers all four
  by the excess, and none goes below 0 (idle thrust 0 without arming: `:160-198`).
- Battery-compensated thrust (`motors.c:180-222`, `platform_defaults_cf2.h:67-75`): a motor command c is c / 65535 x
  0.12 N, and nothing under 0.0128 N (the motor voltage is chosen to make that thrust at any battery voltage).
  The firmware caps the compensated PWM (`stabilizer.c:208-219`, `:255-258`); the model caps the command, which is
  the same for a battery that gives 0.12 N at full duty.
- The gyro the rate loops see: a 2-pole low-pass at 80 Hz run at 1 kHz (`sensors_bmi088_bmp3xx.c:140`, `:546`;
  `filter.c:65-101`): `Lpf2p`.

Default gains and limits: `CfGains` (`platform_defaults_cf2.h:96-175`), each field carrying the firmware's parameter
name (`posCtlPid.xKp`, ...: the PARAM groups of `position_controller_pid.c:462-603` and
`attitude_pid_controller.c:318-450`). Arithmetic is double precision (the firmware's is float32).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

from .fake_setpoint import AxisMode, Setpoint

MODE_DISABLE = 0
MODE_ABS = 1
MODE_VELOCITY = 2
"""`stab_mode_t` (`stabilizer_types.h:246-248`)."""

MAIN_LOOP_HZ = 1000
ATTITUDE_HZ = 500
POSITION_HZ = 100
ATTITUDE_DT = 1.0 / ATTITUDE_HZ
POSITION_DT = 1.0 / POSITION_HZ
ATTITUDE_EVERY = MAIN_LOOP_HZ // ATTITUDE_HZ
POSITION_EVERY = MAIN_LOOP_HZ // POSITION_HZ

DEFAULT_INTEGRATION_LIMIT = 5000.0
"""`DEFAULT_PID_INTEGRATION_LIMIT` (`pid.h:33`)."""
RP_LIMIT_OVERHEAD = 1.10
VEL_MAX_OVERHEAD = 1.10
"""`rpLimitOverhead`, `velMaxOverhead` (`position_controller_pid.c:63`, `:68`)."""
THRUST_SCALE = 1000.0
"""`thrustScale` (`position_controller_pid.c:70`)."""
UINT16_MAX = 65535
INT16_MAX = 32767
THRUST_MAX_N = 0.12
THRUST_MIN_N = 0.012817578393224994
"""Per motor, 2.1+ propellers (`platform_defaults_cf2.h:73-74`)."""
GYRO_LPF_CUTOFF_HZ = 80.0
"""`GYRO_LPF_CUTOFF_FREQ` (`sensors_bmi088_bmp3xx.c:140`), run at 1 kHz (`:546`)."""

ROLL_RATE_INTEGRATION_LIMIT = 33.3
PITCH_RATE_INTEGRATION_LIMIT = 33.3
YAW_RATE_INTEGRATION_LIMIT = 166.7
ROLL_INTEGRATION_LIMIT = 20.0
PITCH_INTEGRATION_LIMIT = 20.0
YAW_INTEGRATION_LIMIT = 360.0
"""`PID_*_INTEGRATION_LIMIT` (`platform_defaults_cf2.h:100-130`), set by `attitude_pid_controller.c:118-131`."""


def _p(name: str, default: float, source: str):  # noqa: ANN202 - a dataclass field
    return field(default=default, metadata={"param": name, "source": source})


@dataclass
class CfGains:
    """The PID controller's gains and limits, defaults of a CF2 (`platform_defaults_cf2.h`); each field's metadata
    holds the firmware parameter that sets it (`params()` / `set_param()` use those names)."""

    pos_x_kp: float = _p("posCtlPid.xKp", 2.0, "platform_defaults_cf2.h:158")
    pos_x_ki: float = _p("posCtlPid.xKi", 0.0, "platform_defaults_cf2.h:159")
    pos_x_kd: float = _p("posCtlPid.xKd", 0.0, "platform_defaults_cf2.h:160")
    pos_x_kff: float = _p("posCtlPid.xKff", 0.0, "platform_defaults_cf2.h:161")
    pos_y_kp: float = _p("posCtlPid.yKp", 2.0, "platform_defaults_cf2.h:163")
    pos_y_ki: float = _p("posCtlPid.yKi", 0.0, "platform_defaults_cf2.h:164")
    pos_y_kd: float = _p("posCtlPid.yKd", 0.0, "platform_defaults_cf2.h:165")
    pos_y_kff: float = _p("posCtlPid.yKff", 0.0, "platform_defaults_cf2.h:166")
    pos_z_kp: float = _p("posCtlPid.zKp", 2.0, "platform_defaults_cf2.h:168")
    pos_z_ki: float = _p("posCtlPid.zKi", 0.5, "platform_defaults_cf2.h:169")
    pos_z_kd: float = _p("posCtlPid.zKd", 0.0, "platform_defaults_cf2.h:170")
    pos_z_kff: float = _p("posCtlPid.zKff", 0.0, "platform_defaults_cf2.h:171")
    thrust_base: float = _p("posCtlPid.thrustBase", 36000.0, "platform_defaults_cf2.h:154")
    thrust_min: float = _p("posCtlPid.thrustMin", 20000.0, "platform_defaults_cf2.h:156")
    r_limit: float = _p("posCtlPid.rLimit", 20.0, "platform_defaults_cf2.h:152")
    p_limit: float = _p("posCtlPid.pLimit", 20.0, "platform_defaults_cf2.h:153")
    x_vel_max: float = _p("posCtlPid.xVelMax", 1.0, "platform_defaults_cf2.h:173")
    y_vel_max: float = _p("posCtlPid.yVelMax", 1.0, "platform_defaults_cf2.h:174")
    z_vel_max: float = _p("posCtlPid.zVelMax", 1.0, "platform_defaults_cf2.h:175")
    vel_x_kp: float = _p("velCtlPid.vxKp", 25.0, "platform_defaults_cf2.h:132")
    vel_x_ki: float = _p("velCtlPid.vxKi", 1.0, "platform_defaults_cf2.h:133")
    vel_x_kd: float = _p("velCtlPid.vxKd", 0.0, "platform_defaults_cf2.h:134")
    vel_x_kff: float = _p("velCtlPid.vxKFF", 0.0, "platform_defaults_cf2.h:135")
    vel_y_kp: float = _p("velCtlPid.vyKp", 25.0, "platform_defaults_cf2.h:137")
    vel_y_ki: float = _p("velCtlPid.vyKi", 1.0, "platform_defaults_cf2.h:138")
    vel_y_kd: float = _p("velCtlPid.vyKd", 0.0, "platform_defaults_cf2.h:139")
    vel_y_kff: float = _p("velCtlPid.vyKFF", 0.0, "platform_defaults_cf2.h:140")
    vel_z_kp: float = _p("velCtlPid.vzKp", 25.0, "platform_defaults_cf2.h:142")
    vel_z_ki: float = _p("velCtlPid.vzKi", 15.0, "platform_defaults_cf2.h:143")
    vel_z_kd: float = _p("velCtlPid.vzKd", 0.0, "platform_defaults_cf2.h:144")
    vel_z_kff: float = _p("velCtlPid.vzKFF", 0.0, "platform_defaults_cf2.h:145")
    att_roll_kp: float = _p("pid_attitude.roll_kp", 6.0, "platform_defaults_cf2.h:114")
    att_roll_ki: float = _p("pid_attitude.roll_ki", 3.0, "platform_defaults_cf2.h:115")
    att_roll_kd: float = _p("pid_attitude.roll_kd", 0.0, "platform_defaults_cf2.h:116")
    att_roll_kff: float = _p("pid_attitude.roll_kff", 0.0, "platform_defaults_cf2.h:117")
    att_pitch_kp: float = _p("pid_attitude.pitch_kp", 6.0, "platform_defaults_cf2.h:120")
    att_pitch_ki: float = _p("pid_attitude.pitch_ki", 3.0, "platform_defaults_cf2.h:121")
    att_pitch_kd: float = _p("pid_attitude.pitch_kd", 0.0, "platform_defaults_cf2.h:122")
    att_pitch_kff: float = _p("pid_attitude.pitch_kff", 0.0, "platform_defaults_cf2.h:123")
    att_yaw_kp: float = _p("pid_attitude.yaw_kp", 6.0, "platform_defaults_cf2.h:126")
    att_yaw_ki: float = _p("pid_attitude.yaw_ki", 1.0, "platform_defaults_cf2.h:127")
    att_yaw_kd: float = _p("pid_attitude.yaw_kd", 0.35, "platform_defaults_cf2.h:128")
    att_yaw_kff: float = _p("pid_attitude.yaw_kff", 0.0, "platform_defaults_cf2.h:129")
    yaw_max_delta: float = _p("pid_attitude.yawMaxDelta", 0.0, "platform_defaults.h:118-120")
    rate_roll_kp: float = _p("pid_rate.roll_kp", 250.0, "platform_defaults_cf2.h:96")
    rate_roll_ki: float = _p("pid_rate.roll_ki", 500.0, "platform_defaults_cf2.h:97")
    rate_roll_kd: float = _p("pid_rate.roll_kd", 2.5, "platform_defaults_cf2.h:98")
    rate_roll_kff: float = _p("pid_rate.roll_kff", 0.0, "platform_defaults_cf2.h:99")
    rate_pitch_kp: float = _p("pid_rate.pitch_kp", 250.0, "platform_defaults_cf2.h:102")
    rate_pitch_ki: float = _p("pid_rate.pitch_ki", 500.0, "platform_defaults_cf2.h:103")
    rate_pitch_kd: float = _p("pid_rate.pitch_kd", 2.5, "platform_defaults_cf2.h:104")
    rate_pitch_kff: float = _p("pid_rate.pitch_kff", 0.0, "platform_defaults_cf2.h:105")
    rate_yaw_kp: float = _p("pid_rate.yaw_kp", 120.0, "platform_defaults_cf2.h:108")
    rate_yaw_ki: float = _p("pid_rate.yaw_ki", 16.7, "platform_defaults_cf2.h:109")
    rate_yaw_kd: float = _p("pid_rate.yaw_kd", 0.0, "platform_defaults_cf2.h:110")
    rate_yaw_kff: float = _p("pid_rate.yaw_kff", 0.0, "platform_defaults_cf2.h:111")

    def params(self) -> dict[str, float]:
        """Firmware parameter name -> value, e.g. ``{"posCtlPid.xKp": 2.0, ...}``."""
        return {f.metadata["param"]: float(getattr(self, f.name)) for f in fields(self)}

    def set_param(self, name: str, value: float) -> None:
        """Set one gain by its firmware parameter name (KeyError for a name the controller does not have)."""
        setattr(self, _FIELD_BY_PARAM[name], float(value))


_FIELD_BY_PARAM = {f.metadata["param"]: f.name for f in fields(CfGains)}
PARAM_NAMES = tuple(_FIELD_BY_PARAM)
"""Every parameter `CfGains` exposes, by its firmware name."""


class Pid:
    """The firmware's `PidObject` and `pidUpdate` / `pidReset` (`pid.c:58-157`), without the D filter (off or
    irrelevant in the PID controller's loops: module doc)."""

    __slots__ = (
        "kp",
        "ki",
        "kd",
        "kff",
        "i_limit",
        "output_limit",
        "dt",
        "is_yaw",
        "desired",
        "error",
        "prev_measured",
        "integ",
        "deriv",
        "out_p",
        "out_i",
        "out_d",
        "out_ff",
    )

    def __init__(
        self,
        kp: float,
        ki: float,
        kd: float,
        kff: float,
        dt: float,
        *,
        i_limit: float = DEFAULT_INTEGRATION_LIMIT,
        output_limit: float = 0.0,
        is_yaw: bool = False,
    ) -> None:
        self.kp, self.ki, self.kd, self.kff = kp, ki, kd, kff
        self.i_limit, self.output_limit, self.dt, self.is_yaw = i_limit, output_limit, dt, is_yaw
        self.desired = self.error = self.prev_measured = self.integ = self.deriv = 0.0
        self.out_p = self.out_i = self.out_d = self.out_ff = 0.0

    def update(self, measured: float) -> float:
        """`pidUpdate`: one step towards `desired` from `measured`."""
        error = self.desired - measured
        delta = self.prev_measured - measured
        if self.is_yaw:
            if error > 180.0:
                error -= 360.0
            elif error < -180.0:
                error += 360.0
            if delta > 180.0:
                delta -= 360.0
            elif delta < -180.0:
                delta += 360.0
        self.error = error
        self.out_p = self.kp * error
        self.deriv = delta / self.dt
        self.out_d = self.kd * self.deriv
        integ = self.integ + error * self.dt
        limit = self.i_limit
        if limit != 0.0:
            integ = -limit if integ < -limit else (limit if integ > limit else integ)
        self.integ = integ
        self.out_i = self.ki * integ
        self.out_ff = self.kff * self.desired
        output = self.out_p + self.out_d + self.out_i + self.out_ff
        limit = self.output_limit
        if limit != 0.0:
            output = -limit if output < -limit else (limit if output > limit else output)
        self.prev_measured = measured
        return output

    def reset(self, actual: float) -> None:
        """`pidReset`: error, integral and derivative to 0, the previous measurement to `actual`."""
        self.error = self.integ = self.deriv = 0.0
        self.prev_measured = actual


def lpf2p_coefficients(sample_hz: float, cutoff_hz: float) -> tuple[float, float, float, float, float]:
    """`lpf2pSetCutoffFreq` (`filter.c:74-86`): b0, b1, b2, a1, a2 of the 2-pole Butterworth low-pass."""
    ohm = math.tan(math.pi / (sample_hz / cutoff_hz))
    c = 1.0 + 2.0 * math.cos(math.pi / 4.0) * ohm + ohm * ohm
    b0 = ohm * ohm / c
    return b0, 2.0 * b0, b0, 2.0 * (ohm * ohm - 1.0) / c, (1.0 - 2.0 * math.cos(math.pi / 4.0) * ohm + ohm * ohm) / c


class Lpf2p:
    """`lpf2pApply` (`filter.c:88-101`) on three axes at once (the gyro's x, y, z)."""

    __slots__ = ("b0", "b1", "b2", "a1", "a2", "d1", "d2")

    def __init__(self, sample_hz: float = MAIN_LOOP_HZ, cutoff_hz: float = GYRO_LPF_CUTOFF_HZ) -> None:
        self.b0, self.b1, self.b2, self.a1, self.a2 = lpf2p_coefficients(sample_hz, cutoff_hz)
        self.d1 = [0.0, 0.0, 0.0]
        self.d2 = [0.0, 0.0, 0.0]

    def apply(self, x: float, y: float, z: float) -> tuple[float, float, float]:
        b0, b1, b2, a1, a2, d1, d2 = self.b0, self.b1, self.b2, self.a1, self.a2, self.d1, self.d2
        out = []
        for i, sample in enumerate((x, y, z)):
            d0 = sample - d1[i] * a1 - d2[i] * a2
            out.append(d0 * b0 + d1[i] * b1 + d2[i] * b2)
            d2[i] = d1[i]
            d1[i] = d0
        return out[0], out[1], out[2]

    def settle(self, x: float, y: float, z: float) -> None:
        """Put the filter in the steady state of a constant input (a drone that has been still a while)."""
        for i, sample in enumerate((x, y, z)):
            self.d1[i] = self.d2[i] = sample / (1.0 + self.a1 + self.a2)


@dataclass(slots=True)
class ControlSetpoint:
    """The parts of the firmware's `setpoint_t` the PID controller reads: modes (0 disable, 1 absolute, 2 velocity),
    position (m), velocity (m/s), attitude (deg; roll, pitch in the legacy convention), attitude rates (deg/s) and
    the raw thrust of the modes that do not control z."""

    mode_x: int = MODE_DISABLE
    mode_y: int = MODE_DISABLE
    mode_z: int = MODE_DISABLE
    mode_roll: int = MODE_DISABLE
    mode_pitch: int = MODE_DISABLE
    mode_yaw: int = MODE_DISABLE
    x: float = 0.0
    y: float = 0.0
    z: float = 0.0
    vx: float = 0.0
    vy: float = 0.0
    vz: float = 0.0
    roll: float = 0.0
    pitch: float = 0.0
    yaw: float = 0.0
    roll_rate: float = 0.0
    pitch_rate: float = 0.0
    yaw_rate: float = 0.0
    thrust: float = 0.0

    @property
    def modes(self) -> tuple[int, int, int, int, int, int]:
        """The mode set `setpointModeChanged` compares (`controller_pid.c:66-72`; the quaternion mode is never
        set here)."""
        return (self.mode_x, self.mode_y, self.mode_z, self.mode_roll, self.mode_pitch, self.mode_yaw)

    @classmethod
    def position(cls, x: float, y: float, z: float, yaw_deg: float = 0.0) -> ControlSetpoint:
        """cflib's `send_position_setpoint` as the firmware decodes it (`crtp_commander_generic.c:506-522`, the
        setpoint zeroed first, `:553`): x, y, z and yaw absolute, velocity 0."""
        return cls(MODE_ABS, MODE_ABS, MODE_ABS, MODE_DISABLE, MODE_DISABLE, MODE_ABS, x, y, z, yaw=yaw_deg)

    @classmethod
    def from_setpoint(cls, sp: Setpoint) -> ControlSetpoint:
        """The emulator's `Setpoint` (fake_setpoint.py) as the firmware's `setpoint_t`."""
        mode = {AxisMode.DISABLE: MODE_DISABLE, AxisMode.ABS: MODE_ABS, AxisMode.VELOCITY: MODE_VELOCITY}
        out = cls(
            mode[sp.modes[0]],
            mode[sp.modes[1]],
            mode[sp.modes[2]],
            mode[sp.attitude_mode],
            mode[sp.attitude_mode],
            mode[sp.yaw_mode],
            sp.position[0],
            sp.position[1],
            sp.position[2],
            sp.velocity[0],
            sp.velocity[1],
            sp.velocity[2],
            thrust=float(sp.thrust),
        )
        if sp.attitude_mode is AxisMode.ABS:
            out.roll, out.pitch = sp.attitude_deg
        elif sp.attitude_mode is AxisMode.VELOCITY:
            out.roll_rate, out.pitch_rate = sp.attitude_deg
        if sp.yaw_mode is AxisMode.ABS:
            out.yaw = sp.yaw_deg
        elif sp.yaw_mode is AxisMode.VELOCITY:
            out.yaw_rate = sp.yaw_rate_deg_s
        return out


NULL_SETPOINT = ControlSetpoint()
"""All modes disabled, thrust 0: motors off."""


def cap_angle(angle: float) -> float:
    """`capAngle` (`controller_pid.c:52-64`)."""
    while angle > 180.0:
        angle -= 360.0
    while angle < -180.0:
        angle += 360.0
    return angle


def saturate_int16(value: float) -> int:
    """`saturateSignedInt16` (`attitude_pid_controller.c:46-55`): to +/- 32767, truncated to an integer."""
    if value > INT16_MAX:
        return INT16_MAX
    if value < -INT16_MAX:
        return -INT16_MAX
    return int(value)


def legacy_power_distribution(thrust: float, roll: int, pitch: int, yaw: int) -> tuple[int, int, int, int]:
    """`powerDistributionLegacy` then `powerDistributionCap` (`power_distribution_quadrotor.c:84-93`, `:160-198`):
    the four motor commands, each 0..65535."""
    r = int(roll / 2.0)
    p = int(pitch / 2.0)
    m1 = int(thrust - r + p + yaw)
    m2 = int(thrust - r - p - yaw)
    m3 = int(thrust + r - p + yaw)
    m4 = int(thrust + r + p - yaw)
    excess = max(m1, m2, m3, m4) - UINT16_MAX
    if excess > 0:
        m1, m2, m3, m4 = m1 - excess, m2 - excess, m3 - excess, m4 - excess
    return max(m1, 0), max(m2, 0), max(m3, 0), max(m4, 0)


def motor_thrust_n(command: float) -> float:
    """The thrust (N) a battery-compensated motor makes for a command of 0..65535 (`motors.c:198-202`): command /
    65535 x 0.12 N, 0 under 0.0128 N."""
    thrust = command / UINT16_MAX * THRUST_MAX_N
    return thrust if thrust >= THRUST_MIN_N else 0.0


class PidController:
    """`controllerPid` with its position, velocity, attitude and rate PIDs (module doc). Feed it one stabilizer tick
    at a time (`tick`); it keeps the firmware's static state between ticks."""

    def __init__(self, gains: CfGains | None = None) -> None:
        self.gains = gains if gains is not None else CfGains()
        g = self.gains
        self.pid_x = Pid(g.pos_x_kp, g.pos_x_ki, g.pos_x_kd, g.pos_x_kff, POSITION_DT)
        self.pid_y = Pid(g.pos_y_kp, g.pos_y_ki, g.pos_y_kd, g.pos_y_kff, POSITION_DT)
        self.pid_z = Pid(g.pos_z_kp, g.pos_z_ki, g.pos_z_kd, g.pos_z_kff, POSITION_DT)
        self.pid_vx = Pid(g.vel_x_kp, g.vel_x_ki, g.vel_x_kd, g.vel_x_kff, POSITION_DT)
        self.pid_vy = Pid(g.vel_y_kp, g.vel_y_ki, g.vel_y_kd, g.vel_y_kff, POSITION_DT)
        self.pid_vz = Pid(g.vel_z_kp, g.vel_z_ki, g.vel_z_kd, g.vel_z_kff, POSITION_DT)
        self.pid_roll = Pid(0, 0, 0, 0, ATTITUDE_DT, i_limit=ROLL_INTEGRATION_LIMIT)
        self.pid_pitch = Pid(0, 0, 0, 0, ATTITUDE_DT, i_limit=PITCH_INTEGRATION_LIMIT)
        self.pid_yaw = Pid(0, 0, 0, 0, ATTITUDE_DT, i_limit=YAW_INTEGRATION_LIMIT, is_yaw=True)
        self.pid_roll_rate = Pid(0, 0, 0, 0, ATTITUDE_DT, i_limit=ROLL_RATE_INTEGRATION_LIMIT)
        self.pid_pitch_rate = Pid(0, 0, 0, 0, ATTITUDE_DT, i_limit=PITCH_RATE_INTEGRATION_LIMIT)
        self.pid_yaw_rate = Pid(0, 0, 0, 0, ATTITUDE_DT, i_limit=YAW_RATE_INTEGRATION_LIMIT)
        self.apply_gains()
        self.previous_modes = NULL_SETPOINT.modes
        """`setpointModeChanged`'s static (zero-initialised: the first non-null setpoint resets)."""
        self.attitude_desired = [0.0, 0.0, 0.0]
        """roll, pitch, yaw (deg, legacy pitch)."""
        self.rate_desired = [0.0, 0.0, 0.0]
        self.actuator_thrust = 0.0
        self.thrust = 0.0
        self.roll = self.pitch = self.yaw = 0
        """The control outputs (`control_t`): thrust (float) and the int16 roll, pitch, yaw commands."""

    def apply_gains(self) -> None:
        """Copy `gains` into the PID objects (what writing a parameter does on the firmware)."""
        g = self.gains
        for pid, prefix in (
            (self.pid_x, "pos_x"),
            (self.pid_y, "pos_y"),
            (self.pid_z, "pos_z"),
            (self.pid_vx, "vel_x"),
            (self.pid_vy, "vel_y"),
            (self.pid_vz, "vel_z"),
            (self.pid_roll, "att_roll"),
            (self.pid_pitch, "att_pitch"),
            (self.pid_yaw, "att_yaw"),
            (self.pid_roll_rate, "rate_roll"),
            (self.pid_pitch_rate, "rate_pitch"),
            (self.pid_yaw_rate, "rate_yaw"),
        ):
            pid.kp = getattr(g, prefix + "_kp")
            pid.ki = getattr(g, prefix + "_ki")
            pid.kd = getattr(g, prefix + "_kd")
            pid.kff = getattr(g, prefix + "_kff")

    def params(self) -> dict[str, float]:
        return self.gains.params()

    def set_param(self, name: str, value: float) -> None:
        self.gains.set_param(name, value)
        self.apply_gains()

    def reinitialize(self, state: tuple[float, ...]) -> None:
        """`controllerPidReinitialize` (`controller_pid.c:43-50`): every PID reset on the state."""
        x, y, z, _, _, _, roll, pitch, yaw = state
        self.pid_x.reset(x)
        self.pid_y.reset(y)
        self.pid_z.reset(z)
        self.pid_vx.reset(0.0)
        self.pid_vy.reset(0.0)
        self.pid_vz.reset(0.0)
        self.pid_roll.reset(roll)
        self.pid_pitch.reset(pitch)
        self.pid_yaw.reset(yaw)
        self.pid_roll_rate.reset(0.0)
        self.pid_pitch_rate.reset(0.0)
        self.pid_yaw_rate.reset(0.0)
        self.attitude_desired[0] = roll
        self.attitude_desired[1] = pitch

    def tick(self, step: int, sp: ControlSetpoint, state: tuple[float, ...], gyro: tuple[float, float, float]) -> None:
        """One stabilizer tick number `step`: `state` is (x, y, z, vx, vy, vz, roll, pitch, yaw) as the estimator
        gives it (m, m/s, deg with the legacy pitch), `gyro` the filtered body rates (deg/s, x, y, z). Updates
        `thrust`, `roll`, `pitch`, `yaw`."""
        modes = sp.modes
        if modes != self.previous_modes:
            self.reinitialize(state)
        self.previous_modes = modes
        attitude_tick = step % ATTITUDE_EVERY == 0
        att = self.attitude_desired
        if attitude_tick:
            if sp.mode_yaw == MODE_VELOCITY:
                att[2] = cap_angle(att[2] + sp.yaw_rate * ATTITUDE_DT)
                max_delta = self.gains.yaw_max_delta
                if max_delta != 0.0:
                    delta = cap_angle(att[2] - state[8])
                    if delta > max_delta:
                        att[2] = state[8] + max_delta
                    elif delta < -max_delta:
                        att[2] = state[8] - max_delta
            elif sp.mode_yaw == MODE_ABS:
                att[2] = sp.yaw
            att[2] = cap_angle(att[2])
        if step % POSITION_EVERY == 0:
            self._position_controller(sp, state)
        if attitude_tick:
            if sp.mode_z == MODE_DISABLE:
                self.actuator_thrust = sp.thrust
            if sp.mode_x == MODE_DISABLE or sp.mode_y == MODE_DISABLE:
                att[0] = sp.roll
                att[1] = sp.pitch
            rate = self.rate_desired
            pid = self.pid_roll
            pid.desired = att[0]
            rate[0] = pid.update(state[6])
            pid = self.pid_pitch
            pid.desired = att[1]
            rate[1] = pid.update(state[7])
            pid = self.pid_yaw
            pid.desired = att[2]
            rate[2] = pid.update(state[8])
            if sp.mode_roll == MODE_VELOCITY:
                rate[0] = sp.roll_rate
            if sp.mode_pitch == MODE_VELOCITY:
                rate[1] = sp.pitch_rate
            pid = self.pid_roll_rate
            pid.desired = rate[0]
            self.roll = saturate_int16(pid.update(gyro[0]))
            pid = self.pid_pitch_rate
            pid.desired = rate[1]
            self.pitch = saturate_int16(pid.update(-gyro[1]))
            pid = self.pid_yaw_rate
            pid.desired = rate[2]
            self.yaw = -saturate_int16(pid.update(gyro[2]))
        self.thrust = self.actuator_thrust
        if self.thrust == 0.0:
            self.roll = self.pitch = self.yaw = 0
            self.reinitialize(state)
            att[2] = state[8]

    def _position_controller(self, sp: ControlSetpoint, state: tuple[float, ...]) -> None:
        """`positionController` and `velocityController` (`position_controller_pid.c:193-267`)."""
        g = self.gains
        x, y, z, vx, vy, vz, _, _, yaw = state
        self.pid_x.output_limit = g.x_vel_max * VEL_MAX_OVERHEAD
        self.pid_y.output_limit = g.y_vel_max * VEL_MAX_OVERHEAD
        self.pid_z.output_limit = max(g.z_vel_max, 0.5) * VEL_MAX_OVERHEAD
        cosyaw = math.cos(math.radians(yaw))
        sinyaw = math.sin(math.radians(yaw))
        vsx, vsy, vsz = sp.vx, sp.vy, sp.vz
        if sp.mode_x == MODE_ABS:
            self.pid_x.desired = sp.x * cosyaw + sp.y * sinyaw
            vsx = self.pid_x.update(x * cosyaw + y * sinyaw)
        else:
            vsx = sp.vx * cosyaw + sp.vy * sinyaw
        if sp.mode_y == MODE_ABS:
            self.pid_y.desired = -sp.x * sinyaw + sp.y * cosyaw
            vsy = self.pid_y.update(-x * sinyaw + y * cosyaw)
        else:
            vsy = sp.vy * cosyaw - sp.vx * sinyaw
        if sp.mode_z == MODE_ABS:
            self.pid_z.desired = sp.z
            vsz = self.pid_z.update(z)
        # velocityController
        r_limit, p_limit = g.r_limit, g.p_limit
        self.pid_vx.output_limit = p_limit * RP_LIMIT_OVERHEAD
        self.pid_vy.output_limit = r_limit * RP_LIMIT_OVERHEAD
        self.pid_vz.output_limit = UINT16_MAX / 2 / THRUST_SCALE
        self.pid_vx.desired = vsx
        pitch = -self.pid_vx.update(vx * cosyaw + vy * sinyaw)
        self.pid_vy.desired = vsy
        roll = -self.pid_vy.update(-vx * sinyaw + vy * cosyaw)
        att = self.attitude_desired
        att[0] = min(max(roll, -r_limit), r_limit)
        att[1] = min(max(pitch, -p_limit), p_limit)
        self.pid_vz.desired = vsz
        thrust = self.pid_vz.update(vz) * THRUST_SCALE + g.thrust_base
        if thrust < g.thrust_min:
            thrust = g.thrust_min
        self.actuator_thrust = min(max(thrust, 0.0), float(UINT16_MAX))

    def motors(self) -> tuple[int, int, int, int]:
        """This tick's motor commands (legacy power distribution and cap)."""
        return legacy_power_distribution(self.thrust, self.roll, self.pitch, self.yaw)
