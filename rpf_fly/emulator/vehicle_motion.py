"""How the simulated drone's body moves on the first-order model (rpf_fly/emulator/fake_vehicle.py, "Dynamics"):
the controller's lags on the estimate, the attitude modes, the gust's disturbance velocity, the turbulence's random
push, free fall and the floor. Why apart: the documented model of the body, apart from the flight stack that
decides what it is asked to do.

:class:`VehicleMotion` is a part of :class:`~rpf_fly.emulator.fake_vehicle.Vehicle`: it reads and sets the vehicle's
attributes named in its body.
"""

from __future__ import annotations

import math
import random
from typing import TYPE_CHECKING

from .fake_setpoint import AxisMode, Setpoint, Vec3, wrap_angle
from .vehicle_figures import (
    ATTITUDE_TAU_S,
    DRAG_TAU_S,
    GRAVITY_M_S2,
    GUST_RESPONSE_TAU_S,
    HOVER_THRUST,
    MAX_TILT_DEG,
    TRACK_TAU_S,
    TURBULENCE_TAU_S,
    TURBULENCE_Z_SHARE,
    VEL_MAX_OVERHEAD,
)

if TYPE_CHECKING:
    from .fake_vehicle import VehicleConfig


class VehicleMotion:
    """The first-order body: its move per sub-step, the attitude modes, gusts and turbulence."""

    config: VehicleConfig
    pos: list[float]
    vel: list[float]
    yaw: float
    floor_z: float
    yaw_offset: float
    vel_error: list[float]
    xy_vel_max: float
    z_vel_max: float
    attitude_deg: list[float]
    _gust_vel: list[float]
    _turbulence: list[float]
    _turbulence_rng: random.Random

    if TYPE_CHECKING:  # the estimator's (VehicleEstimator), read here

        @property
        def estimate(self) -> Vec3: ...

        @property
        def estimate_yaw(self) -> float: ...

    def _turbulent(self, dt: float, push: Vec3 | None) -> Vec3:
        """Advance the random push one step (an Ornstein-Uhlenbeck process per axis, exact over ``dt``) and add it
        to ``push``."""
        keep = math.exp(-dt / TURBULENCE_TAU_S)
        spread = math.sqrt(1.0 - keep * keep)
        sigma = self.config.turbulence_m_s2 or 0.0  # resolved to a float by VehicleConfig
        gauss, turbulence = self._turbulence_rng.gauss, self._turbulence
        for axis in range(3):
            scale = sigma if axis < 2 else sigma * TURBULENCE_Z_SHARE
            turbulence[axis] = turbulence[axis] * keep + scale * spread * gauss(0.0, 1.0)
        if push is None:
            return (turbulence[0], turbulence[1], turbulence[2])
        return (push[0] + turbulence[0], push[1] + turbulence[1], push[2] + turbulence[2])

    def _move(self, dt: float, sp: Setpoint, *, motors_on: bool, push: Vec3 | None = None) -> None:
        """Advance the true body by `dt`. The controller works on the estimate: positions and velocities are the
        estimated ones, and the horizontal velocity it commands in its (estimated) frame is realised through the
        true attitude, i.e. rotated by the yaw error (true minus estimated yaw). `push`: a gust's acceleration
        (fake_vehicle), fought by the controlled axes, taken whole by the others."""
        pos, vel, gust = self.pos, self.vel, self._gust_vel
        if not motors_on:
            gust[0] = gust[1] = gust[2] = 0.0
            self.attitude_deg[0] = self.attitude_deg[1] = 0.0
            if pos[2] <= self.floor_z and vel[2] <= 0.0:
                pos[2], vel[:] = self.floor_z, [0.0, 0.0, 0.0]
                return
            vel[2] -= GRAVITY_M_S2 * dt
            if push is not None:
                for axis in range(3):
                    vel[axis] += push[axis] * dt
        else:
            est, vel_error = self.estimate, self.vel_error
            gain = 1.0 - math.exp(-dt / TRACK_TAU_S)
            modes = sp.modes
            # per controlled axis the velocity the controller commands (position axes) or aims at (velocity axes),
            # in the world as it believes it to be
            wanted = [0.0, 0.0, 0.0]
            for axis in range(3):
                limit = (self.xy_vel_max if axis < 2 else max(self.z_vel_max, 0.5)) * VEL_MAX_OVERHEAD
                mode = modes[axis]
                if mode is AxisMode.ABS:
                    command = sp.velocity[axis] + (sp.position[axis] - est[axis]) / TRACK_TAU_S
                    wanted[axis] = min(max(command, -limit), limit)
                elif mode is AxisMode.VELOCITY:
                    wanted[axis] = min(max(sp.velocity[axis], -limit), limit) - vel_error[axis]
            if self.yaw_offset != 0.0:
                c, s = math.cos(self.yaw_offset), math.sin(self.yaw_offset)  # rotation by true - estimated yaw
                wanted[0], wanted[1] = c * wanted[0] + s * wanted[1], c * wanted[1] - s * wanted[0]
            thrust_accel = self._attitude_step(dt, sp)
            if push is None and not (gust[0] or gust[1] or gust[2]):
                drag = math.exp(-dt / DRAG_TAU_S)
                for axis in range(3):
                    mode = modes[axis]
                    if mode is AxisMode.ABS:
                        vel[axis] = wanted[axis]
                    elif mode is AxisMode.VELOCITY:
                        vel[axis] += (wanted[axis] - vel[axis]) * gain
                    else:
                        vel[axis] = vel[axis] * drag + thrust_accel[axis] * dt
            else:
                self._move_in_gust(dt, modes, wanted, gain, push, thrust_accel)
            if sp.yaw_mode is AxisMode.ABS:
                self.yaw += wrap_angle(math.radians(sp.yaw_deg) - self.estimate_yaw) * gain
            elif sp.yaw_mode is AxisMode.VELOCITY:
                self.yaw += math.radians(sp.yaw_rate_deg_s) * dt
            self.yaw = wrap_angle(self.yaw)
            if pos[2] <= self.floor_z and vel[2] <= 0.0:
                vel[:] = [0.0, 0.0, 0.0]  # no lift off the floor: it stands on its feet, it cannot slide
                return
        for axis in range(3):
            pos[axis] += vel[axis] * dt
        if pos[2] <= self.floor_z:
            pos[2] = self.floor_z
            if vel[2] <= 0.0:
                vel[:] = [0.0, 0.0, 0.0]

    def _move_in_gust(
        self,
        dt: float,
        modes: tuple[AxisMode, AxisMode, AxisMode],
        wanted: list[float],
        gain: float,
        push: Vec3 | None,
        thrust_accel: Vec3,
    ) -> None:
        """The controlled velocities of `_move` with a gust (or what is left of one): on controlled axes the true
        velocity is the controller's plus the disturbance velocity d, d' = push - d / `GUST_RESPONSE_TAU_S`
        (integrated exactly over the step); uncontrolled axes take the push whole, with the thrust's acceleration
        (`_attitude_step`)."""
        vel, gust = self.vel, self._gust_vel
        decay = math.exp(-dt / GUST_RESPONSE_TAU_S)
        drag = math.exp(-dt / DRAG_TAU_S)
        for axis in range(3):
            a = push[axis] if push is not None else 0.0
            mode = modes[axis]
            if mode is AxisMode.ABS or mode is AxisMode.VELOCITY:
                controlled = wanted[axis] if mode is AxisMode.ABS else vel[axis] - gust[axis]
                if mode is AxisMode.VELOCITY:
                    controlled += (wanted[axis] - controlled) * gain
                d = gust[axis] * decay + a * GUST_RESPONSE_TAU_S * (1.0 - decay)
                gust[axis] = d if abs(d) > 1e-9 or a else 0.0
                vel[axis] = controlled + gust[axis]
            else:
                gust[axis] = 0.0
                vel[axis] = vel[axis] * drag + (a + thrust_accel[axis]) * dt

    def _attitude_step(self, dt: float, sp: Setpoint) -> Vec3:
        """Roll and pitch follow the setpoint's attitude (fake_vehicle, "Attitude modes"); returns the world-frame
        acceleration the thrust gives the axes the controller does not hold: horizontally its tilt (the specific
        force that holds the height, or the raw thrust's), vertically the raw thrust's lift less gravity (0 where
        the height is controlled)."""
        att = self.attitude_deg
        if sp.attitude_mode is AxisMode.DISABLE:
            att[0] = att[1] = 0.0
            return (0.0, 0.0, 0.0)
        keep = math.exp(-dt / ATTITUDE_TAU_S)
        for i in range(2):
            if sp.attitude_mode is AxisMode.ABS:
                target = min(max(sp.attitude_deg[i], -MAX_TILT_DEG), MAX_TILT_DEG)
                att[i] = target + (att[i] - target) * keep
            else:
                att[i] = min(max(att[i] + sp.attitude_deg[i] * dt, -MAX_TILT_DEG), MAX_TILT_DEG)
        roll, pitch = math.radians(att[0]), math.radians(-att[1])  # right-handed pitch: nose down is positive
        up = math.cos(roll) * math.cos(pitch)
        if sp.modes[2] is AxisMode.DISABLE:
            force = GRAVITY_M_S2 * sp.thrust / HOVER_THRUST if sp.commands_thrust else 0.0
            vertical = force * up - GRAVITY_M_S2
            if vertical <= 0.0 and self.pos[2] <= self.floor_z and self.vel[2] <= 0.0:
                return (0.0, 0.0, 0.0)  # too little lift to leave the floor: it stands (and cannot slide)
        else:  # the height controller asks for what holds the height, up to full thrust
            force = min(GRAVITY_M_S2 / max(up, 1e-6), GRAVITY_M_S2 * 65535 / HOVER_THRUST)
            vertical = 0.0
        c, s = math.cos(self.yaw), math.sin(self.yaw)  # the attitude loop holds the TRUE body (its IMU)
        forward, left = math.sin(pitch) * math.cos(roll), -math.sin(roll)
        return (force * (c * forward - s * left), force * (s * forward + c * left), vertical)
