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

Dynamics (documented model, not physics; `VehicleConfig.dynamics` "first_order", its default, a dry run's
`dry_run.dynamics: first-order`):
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
  (57 degrees), the thrust lost to a sagging battery beyond the firmware's compensation.
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
  (a real one scrapes or tips; it does not slide to a setpoint on the floor at flying speed).
- A crash (`Vehicle.crash`, called by the fake world on a contact): motors off at once and the horizontal velocity
  lost in the impact, so the drone drops where it hit (an inelastic impact: a Crazyflie that clips a pole or
  another drone does not sail on), then rests on the floor; its supervisor is crashed, tumbled and locked.

Firmware dynamics (`VehicleConfig.dynamics="firmware"`, what a dry run flies unless its mission says
`dry_run.dynamics: first-order`): the body is the identified Crazyflie 2.1+ rigid body and rotors
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
is that of a real Crazyflie under mocap as this project states it (2-5 cm: `flight/supervisor.py`), not kinder:
a tracking warning set on drones that hold their setpoints to the millimetre would sound on healthy real ones.
Each drone draws its own (seeded) turbulence; `VehicleConfig.turbulence_m_s2` = 0 turns it off for the emulator's
precision tests.

Battery: open-circuit voltage drains 0.0002 V/s with motors off and 0.0017 V/s with motors on (a 250 mAh
Crazyflie hovers about 7 minutes); `pm.vbat` sags 0.25 V under load. `pm.state` becomes low-power after 5 s below
`pm.lowVoltage` (3.2 V) and the firmware shuts down after 5 s low-power below `pm.criticalLowVoltage` (3.0 V):
motors off, radio silent.

Parts: the figures above, with their sources, are in vehicle_figures.py; `Vehicle` is made of the estimator
(vehicle_estimator.py), the first-order body (vehicle_motion.py) and the "firmware" dynamics (vehicle_firmware.py);
this module keeps the configuration, the battery, the commander's priorities, contact and the stabilizer loop.
"""

from __future__ import annotations

import logging
import math
import random
from dataclasses import dataclass, replace

from .cf_body import CfBody
from .cf_controller import CfGains, PidController
from .fake_planner import HighLevelCommander
from .fake_setpoint import AxisMode, Setpoint, Vec3, null_setpoint
from .fake_supervisor import UPDATE_PERIOD_S, Supervisor, SupervisorStateName
from .vehicle_estimator import VehicleEstimator
from .vehicle_figures import (
    BATTERY_DRAIN_FLYING_V_PER_S,
    BATTERY_DRAIN_IDLE_V_PER_S,
    BATTERY_LOW_DURATION_S,
    BATTERY_SAG_V,
    PRIORITY_CRTP,
    PRIORITY_DISABLE,
    PRIORITY_HIGH_LEVEL,
    SUBSTEP_S,
    TURBULENCE_M_S2,
    TURBULENCE_MIN_HEIGHT_M,
    VARIANCE_DECAY_TAU_S,
)
from .vehicle_firmware import VehicleFirmware
from .vehicle_motion import VehicleMotion

logger = logging.getLogger(__name__)
DYNAMICS = ("first_order", "firmware")
"""`VehicleConfig.dynamics`: the documented first-order model above, or the firmware's PID cascade on the identified
body (module doc, "Firmware dynamics")."""


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
        turbulence = TURBULENCE_M_S2 if self.turbulence_m_s2 is None else self.turbulence_m_s2
        object.__setattr__(self, "turbulence_m_s2", turbulence)  # resolved here: a child process gets it
        if not turbulence >= 0.0:
            raise ValueError(f"turbulence_m_s2 must be >= 0, not {turbulence}")


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


class Vehicle(VehicleEstimator, VehicleMotion, VehicleFirmware):
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
        self.drift_accel: Vec3 = (
            self.accel_bias[0] + self.tilt_accel[0],
            self.accel_bias[1] + self.tilt_accel[1],
            self.accel_bias[2] + self.tilt_accel[2],
        )
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
        self.supervisor = Supervisor(
            auto_arm=config.auto_arm, tumbled=config.upside_down, spinup_fails=config.motor_fault
        )
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
                -dt / VARIANCE_DECAY_TAU_S
            )

    @staticmethod
    def _supervisor_lattice(now_s: float) -> int:
        """The index of the last supervisor update instant at or before ``now_s``: the multiples of
        `UPDATE_PERIOD_S` (40 ms) of the caller's clock (module doc, "Supervisor rate")."""
        return math.floor(now_s / UPDATE_PERIOD_S + 1e-6)

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
