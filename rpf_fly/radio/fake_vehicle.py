"""The simulated vehicle behind a fake Crazyflie: commander priorities, estimator, dynamics and battery.

One `Vehicle.step(now_s)` runs the firmware's stabilizer loop in the firmware's order (estimator, high-level
commander, commander, supervisor update, supervisor override, controller, motors), sub-stepped at 10 ms.

Dynamics (documented model, not physics):
- The controller acts on the *estimate* (true position + estimator error), as the real one does, so an external
  position that disagrees with the truth moves the true drone.
- Absolute position axes track the setpoint with a first-order lag of time constant `TRACK_TAU_S` (0.25 s), plus the
  setpoint's velocity feed-forward (high-level trajectories carry one, plain position setpoints do not). Velocity is
  limited per axis to the firmware's `posCtlPid.x/y/zVelMax` (1 m/s) times its 1.1 overhead.
- Velocity axes reach the commanded velocity with the same time constant. Disabled horizontal axes (level attitude:
  the watchdog's "level out", attitude-only setpoints) keep their velocity, decaying with `DRAG_TAU_S` (1 s).
- Yaw tracks like position (time constant `TRACK_TAU_S`) or integrates a yaw rate.
- Motors off (null setpoint, supervisor forbids flying, power off): free fall at 9.81 m/s^2 onto the floor (the
  initial z), then rest. On the floor a drone cannot slide.
- A crash (`Vehicle.crash`, called by the fake world on a contact): motors off at once and the horizontal velocity
  lost in the impact, so the drone drops where it hit (an inelastic impact: a Crazyflie that clips a pole or
  another drone does not sail on), then rests on the floor; its supervisor is crashed, tumbled and locked.

Estimator: estimate = truth + offset. Each external position (extpos, extpose) sets the offset so the estimate
equals the measurement at that instant; between measurements the estimate moves with the true motion (an ideal
IMU). With `positioning="extpos"` the estimate starts at the `kalman.initialX/Y/Z` parameters (0, 0, 0) until the
first measurement, and the position variance grows by 0.01 m^2/s while measurements are older than 0.5 s; with
`"onboard"` (a Lighthouse-like onboard system) it starts at the truth. `kalman.resetEstimation` sets the variance to
1 m^2, decaying to `locSrv.extPosStdDev`^2 with a 0.05 s time constant.

Battery: open-circuit voltage drains 0.0002 V/s with motors off and 0.0017 V/s with motors on (a 250 mAh
Crazyflie hovers about 7 minutes); `pm.vbat` sags 0.25 V under load. `pm.state` becomes low-power after 5 s below
`pm.lowVoltage` (3.2 V) and the firmware shuts down after 5 s low-power below `pm.criticalLowVoltage` (3.0 V):
motors off, radio silent.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, replace

from .fake_planner import HighLevelCommander
from .fake_setpoint import AxisMode, Setpoint, Vec3, null_setpoint, wrap_angle, yaw_from_quaternion
from .fake_supervisor import Supervisor, SupervisorStateName

logger = logging.getLogger(__name__)

GRAVITY_M_S2 = 9.81
TRACK_TAU_S = 0.25
DRAG_TAU_S = 1.0
SUBSTEP_S = 0.01
VEL_MAX_OVERHEAD = 1.1

PRIORITY_DISABLE = 0
PRIORITY_HIGH_LEVEL = 1
PRIORITY_CRTP = 2

BATTERY_DRAIN_IDLE_V_PER_S = 0.0002
BATTERY_DRAIN_FLYING_V_PER_S = 0.0017
BATTERY_SAG_V = 0.25
BATTERY_LOW_DURATION_S = 5.0

EXTPOS_STALE_S = 0.5
VARIANCE_GROWTH_M2_PER_S = 0.01
VARIANCE_AFTER_RESET_M2 = 1.0
VARIANCE_DECAY_TAU_S = 0.05


@dataclass(frozen=True)
class VehicleConfig:
    """Initial conditions and variant of one simulated drone."""

    position: Vec3 = (0.0, 0.0, 0.0)
    """Initial true position in metres; its z is the floor."""
    yaw_deg: float = 0.0
    initial_vbat_v: float = 4.15
    """Open-circuit battery voltage at power-on (4.2 full, 3.7 nominal); lower it to inject a low battery."""
    auto_arm: bool = True
    """Crazyflie 2.x default; False mirrors firmware built with CONFIG_MOTORS_REQUIRE_ARMING (Brushless, Bolt)."""
    positioning: str = "onboard"
    """"onboard" (estimate starts at the truth) or "extpos" (needs external positions, see module doc)."""

    def __post_init__(self) -> None:
        if self.positioning not in ("onboard", "extpos"):
            raise ValueError(f"positioning must be 'onboard' or 'extpos', not {self.positioning!r}")


class Battery:
    """Battery voltage and the firmware's power-management state."""

    def __init__(self, open_v: float, now_s: float) -> None:
        self.open_v = open_v
        self.vbat_v = open_v
        self.pm_state = 0
        self.shutdown = False
        self._above_low_s = now_s
        self._above_critical_s = now_s

    def step(self, now_s: float, dt_s: float, motors_on: bool, low_v: float, critical_v: float) -> None:
        rate = BATTERY_DRAIN_FLYING_V_PER_S if motors_on else BATTERY_DRAIN_IDLE_V_PER_S
        self.open_v = max(self.open_v - rate * dt_s, 2.5)
        self.vbat_v = self.open_v - (BATTERY_SAG_V if motors_on else 0.0)
        if self.vbat_v > low_v:
            self._above_low_s = now_s
        if self.vbat_v > critical_v:
            self._above_critical_s = now_s
        self.pm_state = 3 if now_s - self._above_low_s > BATTERY_LOW_DURATION_S else 0
        if self.pm_state == 3 and now_s - self._above_critical_s > BATTERY_LOW_DURATION_S and not self.shutdown:
            logger.warning("fake Crazyflie battery critically low (%.2f V): shutting down", self.vbat_v)
            self.shutdown = True
            self.pm_state = 4


class Vehicle:
    """One simulated Crazyflie's flight stack and body. Not thread-safe: `FakeFirmware` serialises calls."""

    def __init__(self, config: VehicleConfig, now_s: float) -> None:
        self.config = config
        self.pos: list[float] = [float(v) for v in config.position]
        self.vel: list[float] = [0.0, 0.0, 0.0]
        self.yaw = math.radians(config.yaw_deg)
        self.floor_z = float(config.position[2])
        self.initial_estimate: Vec3 = (0.0, 0.0, 0.0)
        self.offset: list[float] = self._reset_offset()
        self.yaw_offset = 0.0
        self.supervisor = Supervisor(auto_arm=config.auto_arm)
        self.hl = HighLevelCommander(self.estimate, self.yaw)
        self.priority = PRIORITY_DISABLE
        self.setpoint: Setpoint = null_setpoint(-math.inf)
        self.control_setpoint: Setpoint = self.setpoint
        self.battery = Battery(config.initial_vbat_v, now_s)
        self.xy_vel_max = 1.0
        self.z_vel_max = 1.0
        self.low_voltage_v = 3.2
        self.critical_voltage_v = 3.0
        self.ext_pos_std_dev = 0.01
        self.param_emergency_stop = False
        self.variance_m2 = self.ext_pos_std_dev**2
        self.last_extpos_s: float | None = None
        self.last_crtp_setpoint_s: float | None = None
        self.thrusting = False
        self.motors_on = False
        self.crash_s: float | None = None
        """Time of the crash (seconds on the caller's clock), None if the drone never crashed."""
        self.crash_reason: str | None = None
        self._last_s = now_s

    # Estimator ------------------------------------------------------------------------------------------------

    def _reset_offset(self) -> list[float]:
        if self.config.positioning == "extpos":
            return [e - p for e, p in zip(self.initial_estimate, self.pos)]
        return [0.0, 0.0, 0.0]

    @property
    def estimate(self) -> Vec3:
        """Estimated position in metres."""
        return (self.pos[0] + self.offset[0], self.pos[1] + self.offset[1], self.pos[2] + self.offset[2])

    @property
    def estimate_yaw(self) -> float:
        """Estimated yaw in radians, wrapped."""
        return wrap_angle(self.yaw + self.yaw_offset)

    @property
    def powered(self) -> bool:
        return not self.battery.shutdown

    def external_position(self, position: Vec3, now_s: float) -> None:
        """An external position measurement (metres)."""
        self.offset = [m - p for m, p in zip(position, self.pos)]
        self.last_extpos_s = now_s

    def external_pose(self, position: Vec3, quaternion: tuple[float, float, float, float], now_s: float) -> None:
        """An external pose measurement (metres, quaternion qx, qy, qz, qw)."""
        self.external_position(position, now_s)
        self.yaw_offset = wrap_angle(yaw_from_quaternion(*quaternion) - self.yaw)

    def reset_estimator(self) -> None:
        """`kalman.resetEstimation`: restart the estimate and its variance."""
        self.offset = self._reset_offset()
        self.yaw_offset = 0.0
        self.variance_m2 = VARIANCE_AFTER_RESET_M2

    # Commander ------------------------------------------------------------------------------------------------

    def _commander_set(self, setpoint: Setpoint, priority: int, now_s: float) -> bool:
        if priority < self.priority:
            return False
        self.setpoint = replace(setpoint, timestamp_s=now_s)
        self.priority = priority
        if priority > PRIORITY_HIGH_LEVEL:
            self.hl.stop()
        return True

    def crtp_setpoint(self, setpoint: Setpoint, now_s: float) -> None:
        """A streamed (low-level) setpoint: preempts the high-level commander, feeds the watchdog."""
        self.last_crtp_setpoint_s = now_s
        self._commander_set(setpoint, PRIORITY_CRTP, now_s)

    def notify_setpoint_stop(self, remain_valid_ms: int) -> None:
        """Relax the priority so the high-level commander takes over at its next tick.

        Firmware 2026.08 ignores `remain_valid_ms` ("an artifact of the old pull-based high-level commander"): if
        no high-level plan follows, the idle high-level commander asks for motors off at once."""
        del remain_valid_ms
        self.hl.tell_state(self.estimate, (self.vel[0], self.vel[1], self.vel[2]), self.estimate_yaw)
        self.priority = PRIORITY_HIGH_LEVEL

    # Contact --------------------------------------------------------------------------------------------------

    @property
    def airborne(self) -> bool:
        """Above the floor or motors on: only such a drone can hit something (two drones resting on the floor
        cannot collide)."""
        return self.motors_on or self.pos[2] > self.floor_z + 1e-6

    def crash(self, now_s: float, reason: str, at: Vec3 | None = None) -> bool:
        """The drone hit something at `now_s` (at true position `at`, where it touched; None: where it is): motors
        off now, the impact takes its horizontal velocity, it falls to the floor and its supervisor locks (crashed,
        tumbled). The first crash is the one recorded; returns True if this one was it."""
        if at is not None:
            self.pos[:] = [float(at[0]), float(at[1]), max(float(at[2]), self.floor_z)]
        self.motors_on = self.thrusting = False
        self.vel[0] = self.vel[1] = 0.0
        self.vel[2] = min(self.vel[2], 0.0)
        self.control_setpoint = null_setpoint(now_s, "crash")
        self.supervisor.crash(now_s)
        if self.crash_s is not None:
            return False
        self.crash_s, self.crash_reason = now_s, reason
        logger.debug("fake Crazyflie crashed at %.3f s (%s): motors off, locked", now_s, reason)
        return True

    # Stabilizer loop ------------------------------------------------------------------------------------------

    def step(self, now_s: float) -> None:
        """Advance to `now_s` (seconds) in sub-steps of at most `SUBSTEP_S`."""
        remaining = now_s - self._last_s
        t = self._last_s
        while remaining > 1e-9:
            dt = min(SUBSTEP_S, remaining)
            t += dt
            remaining -= dt
            self._tick(t, dt)
        self._last_s = max(self._last_s, now_s)

    def _tick(self, now_s: float, dt: float) -> None:
        if not self.powered:
            self.control_setpoint = null_setpoint(now_s, "power-off")
            self.motors_on = self.thrusting = False
            self._move(dt, self.control_setpoint, motors_on=False)
            return
        can_fly = self.supervisor.motors_allowed
        self.hl.block(not can_fly)
        if can_fly:
            velocity = (self.vel[0], self.vel[1], self.vel[2])
            hl_setpoint = self.hl.get_setpoint(now_s, self.estimate, velocity, self.estimate_yaw)
            if hl_setpoint is not None:
                self._commander_set(hl_setpoint, PRIORITY_HIGH_LEVEL, now_s)
        setpoint = self.setpoint if can_fly else null_setpoint(0.0)
        self.supervisor.update(
            now_s,
            thrust_over_idle=self.thrusting,
            setpoint_age_s=now_s - setpoint.timestamp_s,
            param_emergency_stop=self.param_emergency_stop,
        )
        setpoint = self._override(setpoint)
        self.control_setpoint = setpoint
        self.motors_on = self.supervisor.motors_allowed and setpoint.commands_thrust
        self._move(dt, setpoint, motors_on=self.motors_on)
        self.thrusting = self.motors_on
        self.battery.step(now_s, dt, self.motors_on, self.low_voltage_v, self.critical_voltage_v)
        self._update_variance(now_s, dt)

    def _override(self, setpoint: Setpoint) -> Setpoint:
        state = self.supervisor.state
        if state is SupervisorStateName.WARNING_LEVEL_OUT:
            return Setpoint(
                modes=(AxisMode.DISABLE, AxisMode.DISABLE, setpoint.modes[2]),
                position=setpoint.position,
                velocity=setpoint.velocity,
                yaw_mode=AxisMode.VELOCITY,
                yaw_rate_deg_s=0.0,
                thrust=setpoint.thrust,
                timestamp_s=setpoint.timestamp_s,
                source="level-out",
            )
        if state in (SupervisorStateName.READY_TO_FLY, SupervisorStateName.LANDED, SupervisorStateName.FLYING):
            return setpoint
        return null_setpoint(setpoint.timestamp_s, "supervisor")

    def _move(self, dt: float, sp: Setpoint, *, motors_on: bool) -> None:
        pos, vel = self.pos, self.vel
        if not motors_on:
            if pos[2] <= self.floor_z and vel[2] <= 0.0:
                pos[2], vel[:] = self.floor_z, [0.0, 0.0, 0.0]
                return
            vel[2] -= GRAVITY_M_S2 * dt
        else:
            est = self.estimate
            gain = 1.0 - math.exp(-dt / TRACK_TAU_S)
            for axis in range(3):
                limit = (self.xy_vel_max if axis < 2 else max(self.z_vel_max, 0.5)) * VEL_MAX_OVERHEAD
                mode = sp.modes[axis]
                if mode is AxisMode.ABS:
                    wanted = sp.velocity[axis] + (sp.position[axis] - est[axis]) / TRACK_TAU_S
                    vel[axis] = min(max(wanted, -limit), limit)
                elif mode is AxisMode.VELOCITY:
                    target = min(max(sp.velocity[axis], -limit), limit)
                    vel[axis] += (target - vel[axis]) * gain
                elif axis < 2:
                    vel[axis] *= math.exp(-dt / DRAG_TAU_S)
                else:
                    vel[axis] *= 1.0 - gain
            if sp.yaw_mode is AxisMode.ABS:
                self.yaw += wrap_angle(math.radians(sp.yaw_deg) - self.estimate_yaw) * gain
            elif sp.yaw_mode is AxisMode.VELOCITY:
                self.yaw += math.radians(sp.yaw_rate_deg_s) * dt
            self.yaw = wrap_angle(self.yaw)
        for axis in range(3):
            pos[axis] += vel[axis] * dt
        if pos[2] <= self.floor_z:
            pos[2] = self.floor_z
            if vel[2] <= 0.0:
                vel[:] = [0.0, 0.0, 0.0]

    def _update_variance(self, now_s: float, dt: float) -> None:
        floor = self.ext_pos_std_dev**2
        stale = self.config.positioning == "extpos" and (
            self.last_extpos_s is None or now_s - self.last_extpos_s > EXTPOS_STALE_S
        )
        if stale:
            self.variance_m2 += VARIANCE_GROWTH_M2_PER_S * dt
        else:
            self.variance_m2 = floor + (self.variance_m2 - floor) * math.exp(-dt / VARIANCE_DECAY_TAU_S)
