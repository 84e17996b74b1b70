"""The simulated vehicle behind a fake Crazyflie: commander priorities, estimator, dynamics and battery.

One `Vehicle.step(now_s)` runs the firmware's stabilizer loop in the firmware's order (estimator, high-level
commander, commander, supervisor update, supervisor override, controller, motors), sub-stepped at 10 ms (the
"firmware" dynamics: in the firmware's 1 ms ticks, "Firmware dynamics" below).

Supervisor rate: the supervisor updates at the firmware's 25 Hz (RATE_SUPERVISOR, `stabilizer_types.h` line 375;
`supervisor.c` line 589), in the first sub-step (100 Hz tick) that reaches each multiple of 40 ms of the caller's
clock (the world's time: the drones of one world update together). Every other sub-step reads the state the last
update left: whether the high-level commander may run and the motors may turn, and the override (level out, motors
off), as the firmware's loop does between updates (`stabilizer.c` lines 332, 354, 360). So a watchdog or timeout
acts at the first update past it, up to 40 ms after the instant (rpf_fly/emulator/fake_supervisor.py). A crash acts
at once.

Rule: a simulated Crazyflie is never kinder than a real one. Where the model simplifies, it does not simplify away
a failure a real drone has (the yaw fly-away, drift without mocap).

Dynamics (documented model, not physics; the default `VehicleConfig.dynamics`, "first_order"):
- The controller acts on the *estimate* (position, velocity, yaw), as the real one does, so an external position
  that disagrees with the truth moves the true drone.
- Absolute position axes track the setpoint with a first-order lag of time constant `TRACK_TAU_S` (0.25 s), plus the
  setpoint's velocity feed-forward (high-level trajectories carry one, plain position setpoints do not). Velocity is
  limited per axis to the firmware's `posCtlPid.x/y/zVelMax` (1 m/s) times its 1.1 overhead.
- Each tick's loop runs at the start of the `SUBSTEP_S` interval it then flies (the instant its estimate is of): the
  high-level commander evaluates its plan there, so a trajectory is tracked with its own velocity as feed-forward
  over each interval (within 2.2 mm of the polynomial at 0.9 m/s: `tests/emulator/test_fake_trajectory.py`), and a
  plan that begins inside an interval is flown from the interval's start (up to 10 ms early, a lead that decays
  with `TRACK_TAU_S`).
- Velocity axes bring the *estimated* velocity to the commanded one with the same time constant. Disabled horizontal
  axes keep their velocity, decaying with `DRAG_TAU_S` (1 s), plus what the attitude gives them (below).
- Attitude modes (RPYT, z-distance, alt-hold, manual, CPPM: fake_setpoint.py; the watchdog's "level out" is a level
  attitude): roll and pitch follow the command with the attitude loop's time constant `ATTITUDE_TAU_S` (1/6 s;
  rates integrate), bounded at `MAX_TILT_DEG`, in the TRUE body frame (the attitude loop runs on the IMU, so a yaw
  estimate error does not turn it). The thrust tilted with them accelerates the free horizontal axes: where the
  height is controlled (z-distance, alt-hold, level out) by the specific force that holds the height, g / cos(tilt)
  (g tan(tilt) sideways: 1.73 m/s^2 at 10 degrees), up to full thrust; where it is not (RPYT, manual, CPPM) by the
  raw thrust's, g x thrust / `HOVER_THRUST`, which also lifts the drone against gravity: 45000 climbs at 2.45 m/s^2,
  30000 sinks; nothing holds a height. Vertical drag as horizontal (`DRAG_TAU_S`). A thrust that cannot lift it
  leaves the drone standing (it cannot slide). Not modelled: the height lost at a tilt past what full thrust holds
  (57 degrees), the thrust lost to a sagging battery beyond the firmware's compensation. Until 2026-12-02 any
  thrust above zero was "level, hold the height" and roll and pitch were ignored: kinder than a real drone.
- The controller works in its estimated frame: the horizontal velocity it commands (position axes) or aims at
  (velocity axes) is realised through the true attitude, i.e. rotated by the yaw error (true minus estimated yaw)
  in the true world. A small error bends the path (5 degrees: 1.6 cm sideways on a 0.5 m move); beyond 90 degrees
  the position loop is unstable and the drone spirals away from its setpoint at up to the velocity limit (120
  degrees: 2.7 m off after 3 s), the classic fly-away of a drone whose yaw estimate is wrong.
- Yaw tracks a yaw setpoint on the *estimated* yaw (time constant `TRACK_TAU_S`) or integrates a yaw rate; the
  estimate turns with the truth (an ideal gyro), so the yaw error stays what it was.
- Motors off (null setpoint, supervisor forbids flying, power off): free fall at 9.81 m/s^2 onto the floor (the
  initial z), then rest. On the floor a drone cannot slide, with its motors on either: a body on the floor whose
  controller asks for no lift (a position setpoint at floor height, too little RPYT thrust) stands where it is
  (until 2026-12-03 a setpoint on the floor 0.5 m away slid it there at flying speed; a real one scrapes or tips).
- A crash (`Vehicle.crash`, called by the fake world on a contact): motors off at once and the horizontal velocity
  lost in the impact, so the drone drops where it hit (an inelastic impact: a Crazyflie that clips a pole or
  another drone does not sail on), then rests on the floor; its supervisor is crashed, tumbled and locked.

Firmware dynamics (`VehicleConfig.dynamics="firmware"`; "first_order", the model above, is the default until the
stack's figures tuned on it are re-derived): the body is the identified Crazyflie 2.1+ rigid body and rotors
(cf_body.py) flown by the firmware's default PID cascade (cf_controller.py), at the firmware's 1 kHz ticks on the
caller's clock (tick k at k ms, the 100 Hz loops on the ticks whose number, counted from 1, is a multiple of 10:
`CfDrone`'s phase, so the drones of one world tick together). Docs/dynamics.md has the model's facts; here what
the vehicle gives it:
- The controller acts on what the firmware's acts on: the setpoint the commander selects (a streamed CRTP setpoint
  in its modes, from the tick after it came; the high-level commander's plan, this vehicle's `hl`, at the 100 Hz
  ticks, its velocity dropped by the position loop in absolute mode; the null setpoint of an idle commander), with
  the supervisor's override (level out: x, y off, level attitude, yaw rate 0; the mode change resets every PID, so
  the height sags from thrustBase as a Crazyflie's does; null where flying is not allowed), and the motors run only
  while the supervisor allows them (`stabilizer.c`: motorsStop otherwise).
- The state it sees, refreshed at each 100 Hz tick, is the estimate's: this module's position and velocity
  estimate (extpos or onboard, with their errors, drift and divergence as above), the true roll and pitch (the
  estimate's tilt error stays in the drift figures, as for the first-order model) and the estimated yaw. So a yaw
  estimate that is wrong turns the controller's frame and flies away, as above, and a diverged estimate drags the
  true drone.
- A gust (and the turbulence) is an external force on the body, mass x acceleration; the cascade fights it (a
  steady push of a m/s^2 holds it about 0.117 a m downwind through the velocity loop's P term, docs/dynamics.md; the
  velocity integrator then takes it back over tens of seconds).
- On the floor the body stands level on its feet: it neither slides nor tips (its x, y and its roll and pitch stay
  as they were while it rests; the rest rule of cf_body.py); a body at rest with its rotors still is not stepped.
- A crash stops the rotors at once (the impact) and the body drops where it hit; a power cut (reboot, flat battery)
  cuts the motors' command and the rotors coast down; a reboot's new stack flies the same dynamics.
- The controller's gains and limits are the firmware's parameters (`posCtlPid.xKp`, `velCtlPid.vzKi`,
  `pid_attitude.roll_kp`, `pid_rate.yaw_kd`, `posCtlPid.thrustBase`, ...: `CONTROLLER_PARAMS`), written through
  the parameter port (`set_controller_param`), acting at once.
Cost: about 125 us of CPU per drone per 10 ms (the model's 10 ticks), against 15 us for the first-order model: a
40-drone world steps in 5 ms of each 10 ms (tools/bench_vehicle.py's hover, docs/dynamics.md).

Estimator with `positioning="extpos"` (a mocap drone; the Kalman estimator fed by CRTP 6:0 / 6:1):
- Yaw: the estimate starts at `kalman.initialYaw` (radians, 0) at power-on and on `kalman.resetEstimation`, not at
  the true yaw. Position-only extpos never corrects it; extpose sets it to the measured yaw.
- Position: the estimate starts at `kalman.initialX/Y/Z` (0, 0, 0) at power-on and on reset, at rest, with variance
  `VARIANCE_AFTER_RESET_M2` (1 m^2; velocity 0.01 (m/s)^2). Initial values written later act at the next reset.
  Writing `kalman.resetEstimation` non-zero resets at once and the flag reads 0 again.
- Between measurements the estimate integrates a biased, noisy IMU through a slightly wrong attitude: each drone
  has a constant accelerometer bias of norm `ACCEL_BIAS_M_S2` (0.196 m/s^2, the BMI088's typical zero-g offset of
  20 mg; direction drawn from the drone's seed), a constant roll/pitch error of its attitude estimate,
  `TILT_ERROR_RAD` (0.01 rad, the Kalman estimator's own roll/pitch standard deviation), which makes up a
  horizontal acceleration of g sin(0.01) = 0.098 m/s^2 (direction drawn from the seed), and white noise of
  `ACCEL_NOISE_M_S2` (0.1 m/s^2) per 10 ms. Bias and tilt error add to a constant acceleration error of 0.098 to
  0.294 m/s^2 (`BLIND_DRIFT_MAX_M_S2`) by drone; it and the noise enter the velocity error, which enters the
  position error. With a yaw error the true horizontal acceleration is integrated rotated by it (the IMU's
  body-frame reading turned into the world by the wrong yaw). The estimate drifts on the ground too, as a real one
  does.
- Each extpos or extpose is a Kalman update of a position-velocity filter, one covariance shared by the three axes:
  predicted with the filter's process noise (velocity variance + `ACCEL_PROCESS_NOISE` = 1 (m/s)^2 a second),
  gains k_pos = P_pp / (P_pp + s^2) and k_vel = P_pv / (P_pp + s^2) with s = `locSrv.extPosStdDev` (0.01 m). After
  a reset or a blind spell P_pp is large and the next measurement is taken almost whole.
- Measured (tests/emulator/test_fake_firmware.py, `test_imu_drift_without_extpos_and_the_kalman_pull_back`, and
  tests/emulator/test_blind_drift.py; 200 seeds, hovering): with extpos at 50 Hz the estimate stays within 0.6 mm
  of the truth, its velocity within 0.021 m/s (the filter has no bias state: it lags the acceleration error);
  1 s without extpos it is 4.7-17.5 cm off (median 12.8), 2 s without 19-64 cm (median 48), and the first extpos
  after that brings it back within 1.1 mm. The controller holds the *estimate* on its setpoint, so the true drone
  drifts the other way.
- `kalman.varPX/PY/PZ` is P_pp.
With `"onboard"` (a Lighthouse-like onboard system that observes position and yaw): the estimate is the truth; an
extpos sets a position offset that then moves with the truth (extpose also a yaw offset); a reset clears the
offsets and sets the variance to 1 m^2, decaying to `locSrv.extPosStdDev`^2 with a 0.05 s time constant.
Not modelled: gyro drift of the yaw estimate, the tilt error's growth with the gyro's drift (it is constant here),
outlier rejection, the weight of `locSrv.extQuatStdDev` (an extpose sets the yaw whole).

Faults a test injects while the drone flies (each as a real Crazyflie would suffer it):
- Gust (`Vehicle.gust`): an external acceleration on the true body for a while. The position controller fights it
  through a velocity loop of time constant `GUST_RESPONSE_TAU_S` (0.47 s): the push builds a disturbance velocity
  d (d' = a - d / 0.47 s) on top of the commanded one, so a steady gust of a m/s^2 holds the drone
  a * 0.25 s * 0.47 s = 0.1175 s^2 * a off its setpoint downwind (1.5 m/s^2: 17.6 cm, 97 % of it after 2 s), and
  it comes back as the gust ends (the same two time constants). The figure is the firmware's default gains worked
  out (position Kp 2 /s, velocity Kp 25 deg per m/s: 0.117 m per m/s^2); the integrators that would slowly remove
  the offset (velocity Ki, tens of seconds) are not modelled. The commanded velocity stays limited to 1.1 m/s, so
  a gust over 1.1 / 0.47 = 2.3 m/s^2 blows the drone away downwind (a real one holds up to about 3.5 m/s^2, its
  20-degree tilt limit). Level attitude (watchdog level-out) and free fall do not fight: the gust just accelerates
  the body. On the floor a drone cannot slide. The IMU feels the push, so the estimate follows the true motion
  (and extpos keeps it on the truth).
- Estimator divergence (`Vehicle.diverge`): the estimate stops taking extpos/extpose and runs away from the truth
  at a constant horizontal velocity (direction drawn from the drone's seed); its estimated velocity and variance
  stay plausible (the filter believes itself). The controller holds the *estimate* on the setpoint, so the true
  drone drifts the opposite way at that rate while telemetry looks fine. A `kalman.resetEstimation` restarts the
  estimate at `kalman.initial*` but does not cure it; only a reboot (a new vehicle) does.
- Power cut (`Vehicle.cut_power`, a brown-out or reboot): motors off at once, free fall, nothing answered.

Turbulence (a real drone never holds still): a flying body (motors on, off the floor) is pushed by a random
acceleration, an Ornstein-Uhlenbeck process per axis of standard deviation `TURBULENCE_M_S2` (0.15 m/s^2) on each
horizontal axis and 0.4 of it vertically, correlation time `TURBULENCE_TAU_S` (0.5 s): its own propwash, the
room's air, the other drones' downwash, controller and motor imperfections. It enters through the gust path (the
controller fights it; the IMU feels it, so extpos keeps the estimate on the truth), which makes a hovering drone
wander 1.2 cm (standard deviation) on each horizontal axis and 0.5 cm vertically, about 1.7 cm in the plane, and up
to 4-5 cm at the worst moments of a minute. The figure is an assumption, set so that the dry run's tracking error
is that of a real Crazyflie under mocap as this project states it (2-5 cm: issue #11, `flight/supervisor.py`),
not kinder: until 2026-12-02 the simulated drone tracked its setpoints within 1.3 cm of the supervisor's model,
and the supervisor's tracking warning (5 cm) had been set on that. Each drone draws its own (seeded) turbulence;
`VehicleConfig.turbulence_m_s2` = 0 turns it off for the emulator's precision tests.

Battery: open-circuit voltage drains 0.0002 V/s with motors off and 0.0017 V/s with motors on (a 250 mAh
Crazyflie hovers about 7 minutes); `pm.vbat` sags 0.25 V under load. `pm.state` becomes low-power after 5 s below
`pm.lowVoltage` (3.2 V) and the firmware shuts down after 5 s low-power below `pm.criticalLowVoltage` (3.0 V):
motors off, radio silent.
"""

from __future__ import annotations

import logging
import math
import random
from dataclasses import dataclass, replace

from .cf_body import CfBody, quaternion_to_rpy_deg
from .cf_controller import ATTITUDE_EVERY, NULL_SETPOINT, PARAM_NAMES, POSITION_EVERY, CfGains, ControlSetpoint, \
    Lpf2p, PidController, motor_thrust_n
from .fake_planner import HighLevelCommander
from .fake_setpoint import AxisMode, Setpoint, Vec3, null_setpoint, wrap_angle, yaw_from_quaternion
from .fake_supervisor import UPDATE_PERIOD_S, Supervisor, SupervisorStateName

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
_NOISE_PER_SUBSTEP = ACCEL_NOISE_M_S2 * SUBSTEP_S
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
"""Time constant with which the controller's velocity loop cancels a velocity an external push builds up (module
doc): with `TRACK_TAU_S` it sets the steady offset of a gust, 0.1175 m per m/s^2. From the firmware's default
position and velocity gains (2 /s and 25 degrees of tilt per m/s: 1 / (2 * 25 * g * pi / 180) = 0.117 m per
m/s^2)."""
TURBULENCE_M_S2 = 0.15
"""Standard deviation of the random push on a flying body, each horizontal axis (m/s^2; module doc, "Turbulence")."""
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
DYNAMICS = ("first_order", "firmware")
"""`VehicleConfig.dynamics`: the documented first-order model above, or the firmware's PID cascade on the identified
body (module doc, "Firmware dynamics")."""
TICK_S = 0.001
"""The firmware's stabilizer tick (1 kHz): the step of the "firmware" dynamics."""
CONTROLLER_PARAMS = frozenset(PARAM_NAMES)
"""The controller's parameters by firmware name (`posCtlPid.xKp`, ...: cf_controller.CfGains)."""


@dataclass(frozen=True)
class VehicleConfig:
    """Initial conditions and variant of one simulated drone."""

    position: Vec3 = (0.0, 0.0, 0.0)
    """Initial true position in metres; its z is the floor."""
    yaw_deg: float = 0.0
    """Initial true yaw in degrees. With "extpos" the yaw estimate starts at `kalman.initialYaw` (0) whatever this
    is, so a drone set up facing away from +x has that yaw error (see the module doc)."""
    initial_vbat_v: float = 4.15
    """Open-circuit battery voltage at power-on (4.2 full, 3.7 nominal); lower it to inject a low battery."""
    auto_arm: bool = True
    """Crazyflie 2.x default; False mirrors firmware built with CONFIG_MOTORS_REQUIRE_ARMING (Brushless, Bolt)."""
    positioning: str = "onboard"
    """"onboard" (an onboard system observing position and yaw: the estimate is the truth) or "extpos" (a mocap
    drone: a Kalman-like estimate from extpos/extpose and a biased IMU, see the module doc)."""
    upside_down: bool = False
    """It lies on its back at power-on: the supervisor's tumble check keeps the pre-flight checks from passing, so
    it reports tumbled and refuses to arm (supervisor_state_machine.c)."""
    motor_fault: bool = False
    """A motor that does not spin up: the arming RPM check (Brushless firmware) never passes, so arming ends after
    2 s back in pre-flight checks not passed and the drone never gets ready to fly."""
    turbulence_m_s2: float | None = None
    """The random push on the flying body (module doc, "Turbulence"); None: `TURBULENCE_M_S2` as it is when the
    config is made; 0 for a body that tracks its setpoints exactly (the emulator's tests of its own figures)."""
    dynamics: str = "first_order"
    """How the body flies: "first_order" (the documented lags of the module doc, "Dynamics") or "firmware" (the
    firmware's default PID cascade on the identified Crazyflie 2.1+ body, module doc "Firmware dynamics");
    "first-order" (the mission file's spelling) is taken for "first_order"."""
    stored_params: tuple[tuple[str, float], ...] = ()
    """Persistent parameters stored in the drone's EEPROM at power-on, by firmware name (a vehicle profile's gains,
    rpf_fly/calibrate/profile.py): applied at boot as the firmware applies stored values (`FakeFirmware`), and kept
    through a reboot."""

    def __post_init__(self) -> None:
        if self.dynamics == "first-order":
            object.__setattr__(self, "dynamics", "first_order")
        if self.dynamics not in DYNAMICS:
            raise ValueError(f"dynamics must be 'first_order' or 'firmware', not {self.dynamics!r}")
        if self.positioning not in ("onboard", "extpos"):
            raise ValueError(f"positioning must be 'onboard' or 'extpos', not {self.positioning!r}")
        if self.turbulence_m_s2 is None:
            object.__setattr__(self, "turbulence_m_s2", TURBULENCE_M_S2)  # resolved here: a child process gets it
        if not self.turbulence_m_s2 >= 0.0:
            raise ValueError(f"turbulence_m_s2 must be >= 0, not {self.turbulence_m_s2}")


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
    """One simulated Crazyflie's flight stack and body. Not thread-safe: `FakeFirmware` serialises calls.

    Estimator state (see the module docstring): `offset` and `vel_error` are the estimate's errors (estimate minus
    truth) in position and velocity, `yaw_offset` its yaw error; `p_pp`, `p_pv`, `p_vv` the filter's covariance
    of one axis (the same for all three: they are measured together and modelled alike)."""

    def __init__(self, config: VehicleConfig, now_s: float, seed: int = 0) -> None:
        self.config = config
        self.pos: list[float] = [float(v) for v in config.position]
        self.vel: list[float] = [0.0, 0.0, 0.0]
        self.yaw = math.radians(config.yaw_deg)
        self.floor_z = float(config.position[2])
        self.gains = CfGains()
        """The position controller's gains and limits by firmware parameter (`set_controller_param`): all of them
        act on the "firmware" dynamics, the velocity limits (`posCtlPid.x/y/zVelMax`) on the first-order one too."""
        self.body: CfBody | None = None
        """The identified rigid body and rotors of the "firmware" dynamics (None for "first_order"); `pos` and
        `vel` are its own lists (the same objects), so whoever moves the one moves the other."""
        self.controller: PidController | None = None
        if config.dynamics == "firmware":
            self._init_firmware_dynamics(now_s)
        self.kalman = config.positioning == "extpos"
        """True when the estimate is the mocap-fed filter; False for "onboard" (an ideal onboard system)."""
        self._seed = seed
        self._rng = random.Random(f"fake-imu-{seed}")
        self.accel_bias: Vec3 = self._draw_bias() if self.kalman else (0.0, 0.0, 0.0)
        """The accelerometer's constant bias in m/s^2 (world frame; norm `ACCEL_BIAS_M_S2`), per drone."""
        self.tilt_accel: Vec3 = self._draw_tilt() if self.kalman else (0.0, 0.0, 0.0)
        """The horizontal acceleration (m/s^2, world frame; norm `TILT_ERROR_M_S2`) the attitude estimate's tilt
        error makes up, per drone."""
        self.drift_accel: Vec3 = (self.accel_bias[0] + self.tilt_accel[0], self.accel_bias[1] + self.tilt_accel[1],
                                  self.accel_bias[2] + self.tilt_accel[2])
        """The estimate's constant acceleration error while blind: bias plus tilt error (norm at most
        `BLIND_DRIFT_MAX_M_S2`)."""
        self.initial_estimate: Vec3 = (0.0, 0.0, 0.0)
        """`kalman.initialX/Y/Z`, metres."""
        self.initial_yaw = 0.0
        """`kalman.initialYaw`, radians."""
        self.ext_pos_std_dev = 0.01
        self.offset: list[float] = [0.0, 0.0, 0.0]
        self.vel_error: list[float] = [0.0, 0.0, 0.0]
        self.yaw_offset = 0.0
        self.p_pp = self.p_pv = self.p_vv = 0.0
        self.divergence_velocity: Vec3 | None = None
        """While the estimator diverges: the velocity (m/s) at which the estimate runs away from the truth."""
        self._onboard_variance_m2 = self.ext_pos_std_dev**2
        self.reset_estimator()
        self._onboard_variance_m2 = self.ext_pos_std_dev**2  # an onboard system is settled at power-on
        self.supervisor = Supervisor(auto_arm=config.auto_arm, tumbled=config.upside_down,
                                     spinup_fails=config.motor_fault)
        self._supervisor_slot = self._supervisor_lattice(now_s)
        """The last lattice point (in `UPDATE_PERIOD_S`) at which the supervisor updated (`_tick`)."""
        self.hl = HighLevelCommander(self.estimate, self.estimate_yaw)
        self.priority = PRIORITY_DISABLE
        self.setpoint: Setpoint = null_setpoint(-math.inf)
        self.control_setpoint: Setpoint = self.setpoint
        self.battery = Battery(config.initial_vbat_v, now_s)
        self.xy_vel_max = 1.0
        self.z_vel_max = 1.0
        self.low_voltage_v = 3.2
        self.critical_voltage_v = 3.0
        self.param_emergency_stop = False
        self.last_extpos_s: float | None = None
        self.last_crtp_setpoint_s: float | None = None
        self.thrusting = False
        self.motors_on = False
        self.rpyt_thrust_locked = True
        """`crtp_commander_rpyt.c`'s thrust lock: set at power-on, lifted by an RPYT packet with thrust 0."""
        self.attitude_deg = [0.0, 0.0]
        """True roll and pitch (degrees, the firmware's legacy convention: fake_setpoint.py) in the attitude modes;
        level while the horizontal axes are controlled (their tilt is not modelled, only its effect)."""
        self.crash_s: float | None = None
        """Time of the crash (seconds on the caller's clock), None if the drone never crashed."""
        self.crash_reason: str | None = None
        self.power_cut = False
        """True after `cut_power` (a brown-out, a reboot): the stack is dead until a new vehicle replaces it."""
        self.gust_accel: Vec3 = (0.0, 0.0, 0.0)
        """External acceleration on the true body (m/s^2, world frame) until `gust_until_s`."""
        self.gust_until_s = -math.inf
        self._gust_vel = [0.0, 0.0, 0.0]
        """The velocity the gust has built up and the controller has not cancelled yet (m/s)."""
        self._turbulence = [0.0, 0.0, 0.0]
        """The random push now (m/s^2, world frame; module doc, "Turbulence")."""
        self._turbulence_rng = random.Random(f"fake-turbulence-{seed}")
        self._last_s = now_s

    def _init_firmware_dynamics(self, now_s: float) -> None:
        """The "firmware" dynamics' state (module doc, "Firmware dynamics"): body, controller, gyro filter, the
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

    # Estimator ------------------------------------------------------------------------------------------------

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

    @property
    def powered(self) -> bool:
        return not self.battery.shutdown and not self.power_cut

    def cut_power(self) -> None:
        """Power lost now (brown-out, reset button): the motors stop at once and the drone falls; nothing of this
        stack runs again (the firmware boots a new one)."""
        self.power_cut = True
        self.motors_on = self.thrusting = False
        if self.body is not None:  # the motors lose their power: the rotors coast down
            self._stop_motors()

    def gust(self, accel_m_s2: Vec3, until_s: float) -> None:
        """Push the true body with ``accel_m_s2`` (m/s^2, world frame) until ``until_s`` (module doc, "Gust");
        replaces a gust still blowing."""
        self.gust_accel = (float(accel_m_s2[0]), float(accel_m_s2[1]), float(accel_m_s2[2]))
        self.gust_until_s = until_s

    def diverge(self, rate_m_s: float) -> None:
        """From now on the estimator ignores external positions and its position estimate runs away at
        ``rate_m_s`` in a horizontal direction drawn from the drone's seed (module doc, "Estimator divergence").
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
        """An external position measurement (metres): a Kalman update of position and velocity (module doc).
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
        self.hl.tell_state(self.estimate, self.estimate_velocity, self.estimate_yaw)
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
        if self.body is not None:  # the propellers stop in the impact; the body drops as it is
            self._stop_motors()
            self.body.rotor_rpm = [0.0, 0.0, 0.0, 0.0]
            self.body.omega = [0.0, 0.0, 0.0]
        self.supervisor.crash(now_s)
        if self.crash_s is not None:
            return False
        self.crash_s, self.crash_reason = now_s, reason
        logger.debug("fake Crazyflie crashed at %.3f s (%s): motors off, locked", now_s, reason)
        return True

    # Stabilizer loop ------------------------------------------------------------------------------------------

    def step(self, now_s: float) -> None:
        """Advance to `now_s` (seconds) in sub-steps of at most `SUBSTEP_S` (the "firmware" dynamics: in the
        firmware's 1 ms ticks)."""
        if self.body is not None:
            self._step_firmware(now_s)
            return
        remaining = now_s - self._last_s
        t = self._last_s
        while remaining > 1e-9:
            dt = min(SUBSTEP_S, remaining)
            t += dt
            remaining -= dt
            self._tick(t, dt)
        self._last_s = max(self._last_s, now_s)

    def _tick(self, now_s: float, dt: float) -> None:
        push = self.gust_accel if now_s <= self.gust_until_s else None
        if self.config.turbulence_m_s2 and self.motors_on and self.pos[2] > self.floor_z + TURBULENCE_MIN_HEIGHT_M:
            push = self._turbulent(dt, push)
        elif self._turbulence[0] or self._turbulence[1] or self._turbulence[2]:
            self._turbulence = [0.0, 0.0, 0.0]  # on the floor, or falling: no propwash to stir it
        if not self.powered:
            self.control_setpoint = null_setpoint(now_s, "power-off")
            self.motors_on = self.thrusting = False
            self._move(dt, self.control_setpoint, motors_on=False, push=push)
            return
        can_fly = self.supervisor.motors_allowed
        self.hl.block(not can_fly)
        if can_fly:
            # the loop of this tick runs at the start of the interval it controls (the estimate is of that time)
            hl_setpoint = self.hl.get_setpoint(now_s - dt, self.estimate, self.estimate_velocity, self.estimate_yaw)
            if hl_setpoint is not None:
                self._commander_set(hl_setpoint, PRIORITY_HIGH_LEVEL, now_s)
        setpoint = self.setpoint if can_fly else null_setpoint(0.0)
        slot = self._supervisor_lattice(now_s)
        if slot > self._supervisor_slot:  # 25 Hz, as the firmware's; between updates its last decision stands
            self._supervisor_slot = slot
            self.supervisor.update(
                now_s,
                thrust_over_idle=self.thrusting,
                setpoint_age_s=now_s - setpoint.timestamp_s,
                param_emergency_stop=self.param_emergency_stop,
            )
        setpoint = self._override(setpoint)
        self.control_setpoint = setpoint
        self.motors_on = self.supervisor.motors_allowed and setpoint.commands_thrust
        vx, vy = self.vel[0], self.vel[1]
        self._move(dt, setpoint, motors_on=self.motors_on, push=push)
        self.thrusting = self.motors_on
        self.battery.step(now_s, dt, self.motors_on, self.low_voltage_v, self.critical_voltage_v)
        if self.divergence_velocity is not None:
            self._run_away(dt)
        elif self.kalman:
            self._predict(dt, self.vel[0] - vx, self.vel[1] - vy)
        else:
            floor = self.ext_pos_std_dev**2
            self._onboard_variance_m2 = floor + (self._onboard_variance_m2 - floor) * math.exp(
                -dt / VARIANCE_DECAY_TAU_S)

    @staticmethod
    def _supervisor_lattice(now_s: float) -> int:
        """The index of the last supervisor update instant at or before ``now_s``: the multiples of
        `UPDATE_PERIOD_S` (40 ms) of the caller's clock (module doc, "Supervisor rate")."""
        return math.floor(now_s / UPDATE_PERIOD_S + 1e-6)

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

    def _override(self, setpoint: Setpoint) -> Setpoint:
        state = self.supervisor.state
        if state is SupervisorStateName.WARNING_LEVEL_OUT:
            return Setpoint(
                modes=(AxisMode.DISABLE, AxisMode.DISABLE, setpoint.modes[2]),
                position=setpoint.position,
                velocity=setpoint.velocity,
                yaw_mode=AxisMode.VELOCITY,
                yaw_rate_deg_s=0.0,
                thrust=setpoint.thrust,  # the height as it was: held, or the raw thrust kept
                attitude_mode=AxisMode.ABS,
                attitude_deg=(0.0, 0.0),
                timestamp_s=setpoint.timestamp_s,
                source="level-out",
            )
        if state in (SupervisorStateName.READY_TO_FLY, SupervisorStateName.LANDED, SupervisorStateName.FLYING):
            return setpoint
        return null_setpoint(setpoint.timestamp_s, "supervisor")

    def _move(self, dt: float, sp: Setpoint, *, motors_on: bool, push: Vec3 | None = None) -> None:
        """Advance the true body by `dt`. The controller works on the estimate: positions and velocities are the
        estimated ones, and the horizontal velocity it commands in its (estimated) frame is realised through the
        true attitude, i.e. rotated by the yaw error (true minus estimated yaw). `push`: a gust's acceleration
        (module doc), fought by the controlled axes, taken whole by the others."""
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

    def _move_in_gust(self, dt: float, modes: tuple[AxisMode, AxisMode, AxisMode], wanted: list[float],
                      gain: float, push: Vec3 | None, thrust_accel: Vec3) -> None:
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
        """Roll and pitch follow the setpoint's attitude (module doc, "Attitude modes"); returns the world-frame
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

    # Firmware dynamics ------------------------------------------------------------------------------------------

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
            motor_thrust_n(m) > 0.0 for m in self.motor_commands)

    def _step_firmware(self, now_s: float) -> None:
        """Fly the 1 ms ticks up to `now_s` (module doc, "Firmware dynamics")."""
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
            if not (body.on_floor and body.rotor_rpm == _STILL_ROTORS and body.rotor_cmd_rpm == _STILL_ROTORS
                    and body.external_force == _NO_FORCE):  # at rest on the floor with rotors still, nothing moves
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
                    -dt / VARIANCE_DECAY_TAU_S)
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
            self.supervisor.update(t, thrust_over_idle=self.thrusting, setpoint_age_s=t - setpoint.timestamp_s,
                                   param_emergency_stop=self.param_emergency_stop)
        self._selected_from = self.setpoint
        self._select(setpoint)
        est, est_vel = self.estimate, self.estimate_velocity
        self._state = (est[0], est[1], est[2], est_vel[0], est_vel[1], est_vel[2], roll, -pitch,
                       math.degrees(self.estimate_yaw))


_STILL_ROTORS = [0.0, 0.0, 0.0, 0.0]
_NO_FORCE = (0.0, 0.0, 0.0)
