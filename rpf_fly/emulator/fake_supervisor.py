"""The fake Crazyflie's supervisor: arming, flying detection, commander watchdog, emergency stop and locking.

It mirrors the state machine of crazyflie-firmware 2026.08 (`supervisor.c`, `supervisor_state_machine.c`) with the
conditions this simulation can produce: armed, is-flying, commander watchdog warning (setpoint older than 0.5 s) and
timeout (older than 2 s), emergency stop, pre-flight timeout (30 s armed without flying), landing timeout (3 s
after landing), a crash (a contact found by the fake world, :meth:`Supervisor.crash`), a drone lying tumbled at
power-on (``tumbled=True``: the tumble check blocks the pre-flight checks, so arming is refused) and a motor that
fails the arming spin-up check (``spinup_fails=True``: the RPM check of firmware built with
CONFIG_MOTORS_ESC_PROTOCOL_DSHOT_BIDIRECTIONAL, the Brushless; arming ends after ARMING_SPINUP_TIMEOUT_MS = 2 s back
in pre-flight checks not passed). Not simulated: tumble detection from attitude in flight (the simulation has
none), deck faults, the in-flight motors-not-responding check; good motors pass the arming spin-up at once.

Key behaviours kept from the firmware:
- Flying + watchdog warning -> "warning, level out"; flying or levelled out + watchdog timeout -> free fall ->
  locked. Locked has no way out but a reboot.
- An emergency stop (supervisor command, legacy localization command, expired emergency-stop watchdog or the
  `stabilizer.stop` parameter) sends every state but "landed" to free fall -> locked; "landed" gets there through
  reset.
- A crash (contact with another drone or an obstacle) sends every state to free fall -> locked at once, and sets
  the tumbled and crashed bits for good. The firmware's crash handling lets a drone that is upright again recover
  (supervisor command 0x02); a drone that hit something may have broken propellers, so this one stays locked until
  reboot (the project rule: a simulated Crazyflie is never kinder than a real one).
- Motors may run only in ready-to-fly, flying, warning-level-out and landed.
- Disarming in flight resets (motors off). Entering any state outside arming/ready/flying/level-out/landed disarms.
- Auto-arming (the Crazyflie 2.x default) re-arms whenever pre-flight checks pass.

Rate: the firmware updates its supervisor at RATE_SUPERVISOR = 25 Hz (`stabilizer_types.h` line 375; line 377's
RATE_DO_EXECUTE gates it on the 1 kHz stabilizer step, `supervisor.c` line 589), so one update in every 40 steps of
the stabilizer loop (`stabilizer.c` line 347); between updates the loop reads the state the last update left
(`supervisorCanFly`, line 332; `supervisorOverrideSetpoint`, line 354; `supervisorAreMotorsAllowedToRun`, line 360).
The owning vehicle calls :meth:`Supervisor.update` at that rate (`UPDATE_PERIOD_S`, on the lattice of its clock:
rpf_fly/emulator/fake_vehicle.py), so every window here (watchdog 0.5 s and 2 s, emergency-stop watchdog 1 s,
pre-flight, landing and spin-up timeouts, the is-flying hysteresis) takes effect at the first update past it, up to
40 ms late, as on the firmware. The commands (arming, emergency stop, the watchdog's feed) are latched and read at
the next update; a crash (:meth:`Supervisor.crash`) acts at once.

Times are seconds on the caller's clock.
"""

from __future__ import annotations

import enum
import logging
from collections import deque
from dataclasses import dataclass

logger = logging.getLogger(__name__)

WDT_WARNING_S = 0.5
"""Setpoint age after which a flying drone levels out (COMMANDER_WDT_TIMEOUT_STABILIZE)."""
WDT_TIMEOUT_S = 2.0
"""Setpoint age after which a flying drone cuts its motors and locks (COMMANDER_WDT_TIMEOUT_SHUTDOWN)."""
IS_FLYING_HYSTERESIS_S = 2.0
"""The drone counts as flying until this long after the thrust last exceeded idle."""
PREFLIGHT_TIMEOUT_S = 30.0
"""Armed (ready to fly) this long without flying -> disarmed."""
LANDING_TIMEOUT_S = 3.0
"""Landed this long -> reset (disarmed)."""
ARMING_SPINUP_TIMEOUT_S = 2.0
"""Arming this long without the motors' RPM check passing -> back to pre-flight checks not passed
(ARMING_SPINUP_TIMEOUT_MS, platform_defaults.h)."""
EMERGENCY_STOP_WATCHDOG_S = 1.0
"""Once an emergency-stop watchdog notification was received, silence this long triggers an emergency stop (an
update at or past the notification plus 1000 ms: `supervisor.c` line 366)."""
UPDATE_PERIOD_S = 0.04
"""The supervisor updates once every this many seconds: RATE_SUPERVISOR, 25 Hz (`stabilizer_types.h` line 375)."""


class SupervisorStateName(enum.Enum):
    """Supervisor states, named as in the firmware."""

    PRE_FLIGHT_CHECKS_NOT_PASSED = "Pre-flight checks not passed"
    PRE_FLIGHT_CHECKS_PASSED = "Pre-flight checks passed"
    ARMING = "Arming"
    READY_TO_FLY = "Ready to fly"
    FLYING = "Flying"
    LANDED = "Landed"
    RESET = "Reset"
    WARNING_LEVEL_OUT = "Warning, level out"
    EXCEPTION_FREE_FALL = "Exception, free fall"
    LOCKED = "Locked"


S = SupervisorStateName

_MOTORS_ALLOWED = frozenset({S.READY_TO_FLY, S.FLYING, S.WARNING_LEVEL_OUT, S.LANDED})
_KEEPS_ARMING = frozenset({S.ARMING, S.READY_TO_FLY, S.FLYING, S.WARNING_LEVEL_OUT, S.LANDED})


@dataclass(frozen=True)
class Conditions:
    """Inputs of one supervisor update."""

    armed: bool
    is_flying: bool
    wdt_warning: bool
    wdt_timeout: bool
    emergency_stop: bool
    crashed: bool
    preflight_timeout: bool
    landing_timeout: bool
    tumbled: bool = False
    spinup_timeout: bool = False
    rpm_at_arming_valid: bool = True


@dataclass(frozen=True)
class Transition:
    """One state change, for logs and test assertions."""

    time_s: float
    old: SupervisorStateName
    new: SupervisorStateName


class Supervisor:
    """State machine of one drone's supervisor. Not thread-safe: the owning vehicle serialises calls."""

    def __init__(self, *, auto_arm: bool, tumbled: bool = False, spinup_fails: bool = False) -> None:
        self.auto_arm = auto_arm
        self.spinup_fails = spinup_fails
        """A motor does not spin up: the arming RPM check never passes."""
        self.state = S.PRE_FLIGHT_CHECKS_NOT_PASSED
        self.armed = False
        self.emergency_stop_requested = False
        """Latched by an emergency-stop command until reboot."""
        self.crashed = False
        """Latched by :meth:`crash` until reboot (with :attr:`tumbled`)."""
        self.tumbled = tumbled
        """The drone lies tumbled: put down on its back (power-on), or knocked over by a crash (:meth:`crash`)."""
        self._latest_thrust_s: float | None = None
        self._latest_arming_s = 0.0
        self._arming_entered_s: float | None = None
        self._latest_landing_s: float | None = None
        self._estop_watchdog_s: float | None = None
        self.transitions: deque[Transition] = deque(maxlen=64)

    # Commands -------------------------------------------------------------------------------------------------

    def request_arming(self, do_arm: bool) -> bool:
        """Arm or disarm; arming succeeds only when pre-flight checks have passed. Returns success."""
        if do_arm == self.armed:
            return True
        if do_arm and self.state is not S.PRE_FLIGHT_CHECKS_PASSED:
            return False
        self.armed = do_arm
        return True

    def request_emergency_stop(self) -> None:
        """Latch an emergency stop."""
        self.emergency_stop_requested = True

    def crash(self, now_s: float) -> None:
        """The drone hit something: free fall at once (motors off this instant, not at the next update), then
        locked; the crashed and tumbled bits stay set until reboot."""
        self.crashed = self.tumbled = True
        if self.state not in (S.EXCEPTION_FREE_FALL, S.LOCKED):
            self._enter(now_s, S.EXCEPTION_FREE_FALL)

    def notify_emergency_stop_watchdog(self, now_s: float) -> None:
        """Feed (and from the first call on, arm) the emergency-stop watchdog."""
        self._estop_watchdog_s = now_s

    # Queries --------------------------------------------------------------------------------------------------

    @property
    def motors_allowed(self) -> bool:
        """True in the states where the motors may run (the firmware's `supervisorCanFly`)."""
        return self.state in _MOTORS_ALLOWED

    @property
    def is_flying(self) -> bool:
        """True in flying and warning-level-out."""
        return self.state in (S.FLYING, S.WARNING_LEVEL_OUT)

    @property
    def is_locked(self) -> bool:
        return self.state is S.LOCKED

    def info_bits(self, hl_bits: int) -> int:
        """The `supervisor.info` bitfield; `hl_bits` are the high-level commander's bits 8-10."""
        bits = 0
        if self.state is S.PRE_FLIGHT_CHECKS_PASSED:
            bits |= 0x0001
        if self.armed:
            bits |= 0x0002
        if self.auto_arm:
            bits |= 0x0004
        if self.motors_allowed:
            bits |= 0x0008
        if self.is_flying:
            bits |= 0x0010
        if self.tumbled:
            bits |= 0x0020
        if self.is_locked:
            bits |= 0x0040
        if self.crashed:
            bits |= 0x0080
        return bits | (hl_bits & 0x0700)

    # Update ---------------------------------------------------------------------------------------------------

    def conditions(
        self, now_s: float, *, thrust_over_idle: bool, setpoint_age_s: float, param_emergency_stop: bool
    ) -> Conditions:
        """Evaluate the conditions for one update (records the thrust time as a side effect)."""
        if thrust_over_idle:
            self._latest_thrust_s = now_s
        is_flying = self._latest_thrust_s is not None and now_s - self._latest_thrust_s < IS_FLYING_HYSTERESIS_S
        estop = self.emergency_stop_requested or param_emergency_stop
        if self._estop_watchdog_s is not None and now_s >= self._estop_watchdog_s + EMERGENCY_STOP_WATCHDOG_S - 1e-9:
            estop = True
        return Conditions(
            armed=self.armed,
            is_flying=is_flying,
            wdt_warning=setpoint_age_s > WDT_WARNING_S,
            wdt_timeout=setpoint_age_s > WDT_TIMEOUT_S,
            emergency_stop=estop,
            crashed=self.crashed,
            preflight_timeout=self.state is S.READY_TO_FLY and now_s - self._latest_arming_s > PREFLIGHT_TIMEOUT_S,
            landing_timeout=self._latest_landing_s is not None and now_s - self._latest_landing_s > LANDING_TIMEOUT_S,
            tumbled=self.tumbled,
            spinup_timeout=self.state is S.ARMING
            and self._arming_entered_s is not None
            and now_s - self._arming_entered_s > ARMING_SPINUP_TIMEOUT_S,
            rpm_at_arming_valid=not self.spinup_fails,
        )

    def update(
        self, now_s: float, *, thrust_over_idle: bool, setpoint_age_s: float, param_emergency_stop: bool = False
    ) -> None:
        """One supervisor update (the owner calls it every `UPDATE_PERIOD_S`): at most one state transition, then
        its side effects."""
        c = self.conditions(
            now_s,
            thrust_over_idle=thrust_over_idle,
            setpoint_age_s=setpoint_age_s,
            param_emergency_stop=param_emergency_stop,
        )
        new = _next_state(self.state, c)
        if new is not self.state:
            self._enter(now_s, new)

    def _enter(self, now_s: float, new: SupervisorStateName) -> None:
        """Change state and apply the side effects of entering ``new``."""
        old, self.state = self.state, new
        self.transitions.append(Transition(now_s, old, new))
        logger.debug("supervisor %s -> %s at %.3f s", old.value, new.value, now_s)
        if new is S.READY_TO_FLY:
            self._latest_arming_s = now_s
        self._arming_entered_s = now_s if new is S.ARMING else None
        if new is S.LANDED:
            self._latest_landing_s = now_s
        if new is S.LOCKED:
            logger.info("fake Crazyflie locked at %.3f s: reboot required", now_s)
        if new not in _KEEPS_ARMING:
            self.request_arming(False)
        if self.auto_arm and new is S.PRE_FLIGHT_CHECKS_PASSED:
            self.request_arming(True)


def _next_state(state: SupervisorStateName, c: Conditions) -> SupervisorStateName:
    """The firmware's transition table, first matching transition wins (a crash overrides every state)."""
    if c.crashed and state not in (S.EXCEPTION_FREE_FALL, S.LOCKED):
        return S.EXCEPTION_FREE_FALL
    if state is S.PRE_FLIGHT_CHECKS_NOT_PASSED:
        if c.emergency_stop:
            return S.EXCEPTION_FREE_FALL
        return state if c.tumbled else S.PRE_FLIGHT_CHECKS_PASSED  # tumbled blocks (deck faults too, not simulated)
    if state is S.PRE_FLIGHT_CHECKS_PASSED:
        if c.emergency_stop:
            return S.EXCEPTION_FREE_FALL
        if c.tumbled:
            return S.PRE_FLIGHT_CHECKS_NOT_PASSED
        return S.ARMING if c.armed else state
    if state is S.ARMING:
        if c.emergency_stop:
            return S.EXCEPTION_FREE_FALL
        if c.tumbled or c.spinup_timeout or not c.armed:
            return S.PRE_FLIGHT_CHECKS_NOT_PASSED
        return S.READY_TO_FLY if c.rpm_at_arming_valid else state
    if state is S.READY_TO_FLY:
        if c.emergency_stop:
            return S.EXCEPTION_FREE_FALL
        if c.preflight_timeout or not c.armed:
            return S.PRE_FLIGHT_CHECKS_NOT_PASSED
        return S.FLYING if c.is_flying else state
    if state is S.FLYING:
        if c.wdt_timeout or c.emergency_stop:
            return S.EXCEPTION_FREE_FALL
        if not c.armed:
            return S.RESET
        if c.wdt_warning:
            return S.WARNING_LEVEL_OUT
        return state if c.is_flying else S.LANDED
    if state is S.LANDED:
        if c.landing_timeout or not c.armed:
            return S.RESET
        return S.FLYING if c.is_flying else state
    if state is S.RESET:
        return S.PRE_FLIGHT_CHECKS_NOT_PASSED
    if state is S.WARNING_LEVEL_OUT:
        if c.wdt_timeout or c.emergency_stop:
            return S.EXCEPTION_FREE_FALL
        return S.FLYING if not (c.wdt_warning or c.wdt_timeout) else state
    if state is S.EXCEPTION_FREE_FALL:
        return S.LOCKED
    return state  # LOCKED: only a reboot leaves it
