"""The simulated drone's estimator (rpf_fly/emulator/fake_vehicle.py, "Estimator"): the Kalman-like estimate a
mocap drone's extpos feeds (a biased, noisy IMU between measurements), an onboard system's ideal one, and the
estimator divergence a test injects. Why apart: the estimate is what the controller flies on, and its errors are
the model's most measured figures (tests/emulator/test_blind_drift.py).

:class:`VehicleEstimator` is a part of :class:`~rpf_fly.emulator.fake_vehicle.Vehicle`: it reads and sets the vehicle's
attributes named in its body.
"""

from __future__ import annotations

import math
import random

from .fake_setpoint import Vec3, wrap_angle, yaw_from_quaternion
from .vehicle_figures import (
    ACCEL_BIAS_M_S2,
    ACCEL_NOISE_M_S2,
    ACCEL_PROCESS_NOISE,
    MAX_VARIANCE_M2,
    SUBSTEP_S,
    TILT_ERROR_M_S2,
    VARIANCE_AFTER_RESET_M2,
    VELOCITY_VARIANCE_AFTER_RESET,
)

_NOISE_PER_SUBSTEP = ACCEL_NOISE_M_S2 * SUBSTEP_S


class VehicleEstimator:
    """The estimate's state and its updates: measurements, the IMU's prediction, resets, divergence."""

    pos: list[float]
    vel: list[float]
    yaw: float
    kalman: bool
    _seed: int
    _rng: random.Random
    drift_accel: Vec3
    initial_estimate: Vec3
    initial_yaw: float
    ext_pos_std_dev: float
    offset: list[float]
    vel_error: list[float]
    yaw_offset: float
    p_pp: float
    p_pv: float
    p_vv: float
    divergence_velocity: Vec3 | None
    last_extpos_s: float | None
    _onboard_variance_m2: float

    def _draw_bias(self) -> Vec3:
        """A bias of norm `ACCEL_BIAS_M_S2` in a direction drawn from this drone's seed."""
        while True:
            x, y, z = (self._rng.gauss(0.0, 1.0) for _ in range(3))
            norm = math.sqrt(x * x + y * y + z * z)
            if norm > 1e-6:
                scale = ACCEL_BIAS_M_S2 / norm
                return (x * scale, y * scale, z * scale)

    def _draw_tilt(self) -> Vec3:
        """The horizontal acceleration of a roll/pitch error `TILT_ERROR_RAD` in a direction drawn from this drone's
        seed (its own stream: the IMU's noise is not disturbed)."""
        angle = random.Random(f"fake-tilt-{self._seed}").uniform(0.0, 2.0 * math.pi)
        return (TILT_ERROR_M_S2 * math.cos(angle), TILT_ERROR_M_S2 * math.sin(angle), 0.0)

    @property
    def estimate(self) -> Vec3:
        """Estimated position in metres."""
        return (self.pos[0] + self.offset[0], self.pos[1] + self.offset[1], self.pos[2] + self.offset[2])

    @property
    def estimate_velocity(self) -> Vec3:
        """Estimated velocity in m/s (world frame)."""
        return (self.vel[0] + self.vel_error[0], self.vel[1] + self.vel_error[1], self.vel[2] + self.vel_error[2])

    @property
    def estimate_yaw(self) -> float:
        """Estimated yaw in radians, wrapped."""
        return wrap_angle(self.yaw + self.yaw_offset)

    @property
    def variance_m2(self) -> float:
        """Position variance of one axis (`kalman.varPX/PY/PZ`), m^2."""
        return self.p_pp if self.kalman else self._onboard_variance_m2

    def diverge(self, rate_m_s: float) -> None:
        """From now on the estimator ignores external positions and its position estimate runs away at
        ``rate_m_s`` in a horizontal direction drawn from the drone's seed (fake_vehicle, "Estimator divergence").
        Until a new vehicle (reboot)."""
        angle = random.Random(f"fake-divergence-{self._seed}").uniform(0.0, 2.0 * math.pi)
        self.divergence_velocity = (rate_m_s * math.cos(angle), rate_m_s * math.sin(angle), 0.0)
        self.vel_error = list(self.divergence_velocity)

    def _run_away(self, dt: float) -> None:
        """A diverged estimator's step: the estimate moves with the truth (the IMU) plus the runaway; the
        estimated velocity carries the runaway, so the estimate looks still while the true drone drifts."""
        runaway = self.divergence_velocity or (0.0, 0.0, 0.0)
        offset = self.offset
        for axis in range(3):
            offset[axis] += runaway[axis] * dt
        self.vel_error = list(runaway)

    def external_position(self, position: Vec3, now_s: float) -> None:
        """An external position measurement (metres): a Kalman update of position and velocity (fake_vehicle).
        Ignored by a diverged estimator."""
        self.last_extpos_s = now_s
        if self.divergence_velocity is not None:
            return
        if not self.kalman:
            self.offset = [m - p for m, p in zip(position, self.pos)]
            return
        innovation_var = self.p_pp + self.ext_pos_std_dev**2
        k_pos, k_vel = self.p_pp / innovation_var, self.p_pv / innovation_var
        pos, offset, vel_error = self.pos, self.offset, self.vel_error
        for axis in range(3):
            innovation = position[axis] - pos[axis] - offset[axis]
            offset[axis] += k_pos * innovation
            vel_error[axis] += k_vel * innovation
        self.p_vv -= k_vel * self.p_pv
        self.p_pp *= 1.0 - k_pos
        self.p_pv *= 1.0 - k_pos

    def external_pose(self, position: Vec3, quaternion: tuple[float, float, float, float], now_s: float) -> None:
        """An external pose measurement (metres, quaternion qx, qy, qz, qw): position as `external_position`; the
        yaw estimate is set to the measured yaw."""
        self.external_position(position, now_s)
        if self.divergence_velocity is None:
            self.yaw_offset = wrap_angle(yaw_from_quaternion(*quaternion) - self.yaw)

    def reset_estimator(self) -> None:
        """`kalman.resetEstimation` (and power-on): the estimate restarts at `kalman.initialX/Y/Z` and
        `kalman.initialYaw`, at rest, with a large variance. An onboard system restarts at the truth."""
        if self.kalman:
            self.offset = [e - p for e, p in zip(self.initial_estimate, self.pos)]
            self.vel_error = [-v for v in self.vel]
            self.yaw_offset = wrap_angle(self.initial_yaw - self.yaw)
            self.p_pp, self.p_pv, self.p_vv = VARIANCE_AFTER_RESET_M2, 0.0, VELOCITY_VARIANCE_AFTER_RESET
        else:
            self.offset = [0.0, 0.0, 0.0]
            self.yaw_offset = 0.0
            self._onboard_variance_m2 = VARIANCE_AFTER_RESET_M2
        if self.divergence_velocity is not None:  # a reset restarts the estimate, not the broken filter
            self.vel_error = list(self.divergence_velocity)

    def _predict(self, dt: float, dv_x: float, dv_y: float) -> None:
        """Integrate the IMU over one sub-step: bias and noise enter the velocity error, which enters the position
        error; with a yaw error the true horizontal velocity change (dv) is integrated rotated (the IMU's body-frame
        acceleration turned into the world by the wrong yaw). The covariance grows with the filter's process
        noise."""
        vel_error, offset, bias = self.vel_error, self.offset, self.drift_accel
        if self.yaw_offset != 0.0:
            c, s = math.cos(self.yaw_offset), math.sin(self.yaw_offset)
            vel_error[0] += (c - 1.0) * dv_x - s * dv_y
            vel_error[1] += s * dv_x + (c - 1.0) * dv_y
        noise = _NOISE_PER_SUBSTEP if dt == SUBSTEP_S else ACCEL_NOISE_M_S2 * math.sqrt(SUBSTEP_S * dt)
        gauss = self._rng.gauss
        for axis in range(3):
            vel_error[axis] += bias[axis] * dt + noise * gauss(0.0, 1.0)
            offset[axis] += vel_error[axis] * dt
        p_vv = self.p_vv
        p_pp = self.p_pp + dt * (2.0 * self.p_pv + dt * p_vv)
        p_pv = self.p_pv + dt * p_vv
        p_vv += ACCEL_PROCESS_NOISE * dt
        if p_pp > MAX_VARIANCE_M2 or p_vv > MAX_VARIANCE_M2:  # bounded, as a long blind spell would not be
            p_pp, p_vv = min(p_pp, MAX_VARIANCE_M2), min(p_vv, MAX_VARIANCE_M2)
            p_pv = min(p_pv, math.sqrt(p_pp * p_vv))
        self.p_pp, self.p_pv, self.p_vv = p_pp, p_pv, p_vv
