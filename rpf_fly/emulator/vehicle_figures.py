"""The simulated Crazyflie's figures (rpf_fly/emulator/fake_vehicle.py describes the model that uses them): the
lags and limits of its dynamics, the commander's priorities, its battery, its IMU and estimator, the gust response,
the turbulence and the thrust, each with its source. Why apart: the vehicle's parts, the fake firmware and the
tests read the same figures, and the figures are the model's claims, to be checked against a real Crazyflie.
"""

from __future__ import annotations

import math

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

ACCEL_BIAS_M_S2 = 0.196
"""Norm of each drone's constant accelerometer bias (seeded direction, world frame): the Crazyflie 2.1's IMU, the
Bosch BMI088, has a typical zero-g offset of 20 mg (BMI088 data sheet, BST-BMI088-DS001, section 1.1, the
accelerometer's specification table, row "Zero-g offset" Off_acc: typ. +-20 mg), 20e-3 x 9.81 = 0.196 m/s^2. The
firmware scales the accelerometer at rest but takes no offset off it (`sensors_bmi088_bmp3xx.c` lines 322, 337-339),
and its Kalman estimator has no bias state (`kalman_core.h` line 64), so the offset is integrated while it is
blind."""
TILT_ERROR_RAD = 0.01
"""Each drone's constant error of the estimated roll/pitch (seeded horizontal direction): the Kalman estimator's own
roll/pitch standard deviation after a reset, `stdDevInitialAttitude_rollpitch` = 0.01 rad, 0.57 degrees
(`kalman_core_params_defaults.h` line 68, "roughly flat"). Flying, the estimator takes only the body-z acceleration
and subtracts gravity through its attitude (`kalman_core.c` lines 506-541), so a tilt error of the estimate is a
horizontal acceleration the drone does not have: g sin(1 degree) = 0.17 m/s^2 per degree."""
TILT_ERROR_M_S2 = GRAVITY_M_S2 * math.sin(TILT_ERROR_RAD)
"""The horizontal acceleration error of `TILT_ERROR_RAD`: 0.098 m/s^2."""
BLIND_DRIFT_MAX_M_S2 = ACCEL_BIAS_M_S2 + TILT_ERROR_M_S2
"""The largest constant acceleration error of a blind estimate (bias and tilt error in line): 0.294 m/s^2, 0.147 m
after 1 s and 0.59 m after 2 s (0.5 a t^2), before the noise (`ACCEL_NOISE_M_S2`) and the velocity error the
estimate had when it went blind."""
ACCEL_NOISE_M_S2 = 0.1
"""Standard deviation of the accelerometer noise over one 10 ms sub-step."""
ACCEL_PROCESS_NOISE = 1.0
"""The filter's process noise: its velocity variance grows by this many (m/s)^2 a second."""
VARIANCE_AFTER_RESET_M2 = 1.0
"""Position variance after a reset (and at power-on), m^2: the first external position is taken almost whole."""
VELOCITY_VARIANCE_AFTER_RESET = 0.01
"""Velocity variance after a reset, (m/s)^2: the drone is assumed at rest."""
MAX_VARIANCE_M2 = 100.0
"""Bound of the filter's variances (m^2 and (m/s)^2)."""
VARIANCE_DECAY_TAU_S = 0.05
"""Onboard positioning: time constant of the variance settling after a reset."""
GUST_RESPONSE_TAU_S = 0.47
"""Time constant with which the controller's velocity loop cancels a velocity an external push builds up
(fake_vehicle, "Gust"): with `TRACK_TAU_S` it sets the steady offset of a gust, 0.1175 m per m/s^2. From the
firmware's default position and velocity gains (2 /s and 25 degrees of tilt per m/s: 1 / (2 * 25 * g * pi / 180)
= 0.117 m per m/s^2)."""
TURBULENCE_M_S2 = 0.15
"""Standard deviation of the random push on a flying body, each horizontal axis (m/s^2; fake_vehicle, "Turbulence")."""
TURBULENCE_TAU_S = 0.5
"""Correlation time of that push (s)."""
TURBULENCE_Z_SHARE = 0.4
"""The vertical push's share of the horizontal one."""
TURBULENCE_MIN_HEIGHT_M = 0.02
"""Above the floor by this much a body with its motors on is flying (below it, it stands: it cannot slide)."""
HOVER_THRUST = 36000
"""The integer thrust that holds a Crazyflie 2.1 in the air (`PID_VEL_THRUST_BASE`, platform_defaults_cf2.h). The
firmware's battery compensation makes the thrust linear in newtons (thrust / 65535 x 0.12 N a motor), so the
thrust's specific force is g x thrust / `HOVER_THRUST`: 1.67 g at the RPYT maximum (60000), 1.82 g at 65535."""
ATTITUDE_TAU_S = 1.0 / 6.0
"""Time constant with which roll and pitch follow an attitude command: the attitude loop's gain (`PID_ROLL_KP`,
`PID_PITCH_KP` = 6 /s) over a rate loop fast enough to be ideal."""
MAX_TILT_DEG = 80.0
"""The model's bound on roll and pitch (rate modes integrate; a real drone past this flips)."""
