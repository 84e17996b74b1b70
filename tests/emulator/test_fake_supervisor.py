"""The fake supervisor's arming rules, from crazyflie-firmware's `supervisor_state_machine.c`: a tumbled drone
never passes its pre-flight checks (arming refused), and a motor that fails the arming spin-up check ends the
arming after ARMING_SPINUP_TIMEOUT_MS back in pre-flight checks not passed. And its rate in the vehicle: 25 Hz, so
every window takes effect at the first update past it."""

from __future__ import annotations

import struct

import pytest

from rpf_fly.emulator.fake_firmware import FakeFirmware
from rpf_fly.emulator.fake_supervisor import (
    ARMING_SPINUP_TIMEOUT_S,
    UPDATE_PERIOD_S,
    Supervisor,
)
from rpf_fly.emulator.fake_supervisor import (
    SupervisorStateName as S,
)
from rpf_fly.emulator.fake_vehicle import VehicleConfig


def run(sup: Supervisor, seconds: float, start_s: float = 0.0, dt: float = 0.01) -> float:
    t = start_s
    while t < start_s + seconds:
        sup.update(t, thrust_over_idle=False, setpoint_age_s=0.0)
        t += dt
    return t


def test_a_healthy_drone_arms_at_once_and_gets_ready_to_fly() -> None:
    sup = Supervisor(auto_arm=False)
    t = run(sup, 0.05)
    assert sup.state is S.PRE_FLIGHT_CHECKS_PASSED
    assert sup.request_arming(True)
    run(sup, 0.05, t)
    assert sup.state is S.READY_TO_FLY and sup.motors_allowed


def test_a_tumbled_drone_never_passes_its_preflight_and_refuses_to_arm() -> None:
    for auto_arm in (True, False):
        sup = Supervisor(auto_arm=auto_arm, tumbled=True)
        t = run(sup, 0.5)
        assert sup.state is S.PRE_FLIGHT_CHECKS_NOT_PASSED and not sup.armed
        assert sup.request_arming(True) is False  # the firmware's supervisorRequestArming: not supervisorCanArm()
        run(sup, 0.5, t)
        assert not sup.motors_allowed
        assert sup.info_bits(0) & 0x0020 and not sup.info_bits(0) & 0x0001  # tumbled, cannot be armed


def test_a_motor_that_does_not_spin_up_ends_the_arming_after_the_spin_up_timeout() -> None:
    sup = Supervisor(auto_arm=False, spinup_fails=True)
    t = run(sup, 0.05)
    assert sup.request_arming(True)  # the request itself is accepted ...
    t = run(sup, ARMING_SPINUP_TIMEOUT_S - 0.1, t)
    assert sup.state is S.ARMING and not sup.motors_allowed  # ... the motors never get ready
    run(sup, 0.3, t)
    assert sup.state in (S.PRE_FLIGHT_CHECKS_NOT_PASSED, S.PRE_FLIGHT_CHECKS_PASSED) and not sup.armed
    assert S.READY_TO_FLY not in {tr.new for tr in sup.transitions}


# The rate: 25 Hz, as the firmware's (stabilizer_types.h, RATE_SUPERVISOR; supervisor.c, supervisorUpdate) ---------

DT = 0.01


class Clock:
    """A fake firmware on a synthetic clock stepped at 100 Hz (the world's step), hovering under the high-level
    commander, which no watchdog touches."""

    def __init__(self) -> None:
        self.t = 0.0
        self.fw = FakeFirmware(VehicleConfig())
        self.states: list[tuple[float, str, bool]] = []
        """(time, supervisor state, motors on) after each step."""
        self.run(0.15)  # ready to fly: three updates
        assert self.fw.handle(8, 0, struct.pack("<BBff?f", 7, 0, 0.5, 0.0, True, 1.0), self.t)[0][2][3] == 0
        self.run(1.85)
        assert self.state() == ("Flying", True)
        self.states.clear()

    def run(self, seconds: float) -> None:
        end = self.t + seconds
        while self.t < end - 1e-9:
            self.t = round(self.t + DT, 6)
            self.fw.step(self.t)
            snap = self.fw.snapshot()
            self.states.append((self.t, snap.supervisor_state, snap.motors_on))

    def state(self) -> tuple[str, bool]:
        snap = self.fw.snapshot()
        return snap.supervisor_state, snap.motors_on

    def cut_at(self) -> float:
        """The first step since the hover at which the motors were off."""
        return next(t for t, _, on in self.states if not on)


def test_the_supervisor_updates_at_25_hz_on_the_worlds_lattice_and_its_last_decision_holds_between() -> None:
    """An emergency stop sent 10 ms after an update: the motors keep turning for the three steps up to the next
    update (40 ms after the last), are off from that one on, and the drone locks at the update after (free fall ->
    locked is one update). A supervisor updated every step cut them at the next step."""
    clock = Clock()
    assert clock.t == pytest.approx(2.0)  # a multiple of 40 ms: an update
    clock.run(0.01)
    clock.fw.handle(9, 1, bytes([0x03]), clock.t)  # at 2.01
    clock.run(0.02)
    assert clock.state() == ("Flying", True)  # 2.03: the request is latched, the last decision stands
    clock.run(0.01)
    assert clock.state() == ("Exception, free fall", False)  # 2.04: the update
    assert clock.cut_at() == pytest.approx(2.04)
    clock.run(0.03)
    assert clock.state() == ("Exception, free fall", False)
    clock.run(0.01)
    snap = clock.fw.snapshot()
    assert snap.supervisor_state == "Locked" and snap.entered("Locked") == pytest.approx(2.08)
    entered = [tr.time_s for tr in snap.transitions]
    assert all(abs(t / UPDATE_PERIOD_S - round(t / UPDATE_PERIOD_S)) < 1e-6 for t in entered), entered


def test_an_emergency_stop_watchdog_expires_at_the_first_update_at_or_past_its_second() -> None:
    """The emergency-stop watchdog trips at an update at or past the last feed plus 1000 ms (supervisor.c:
    ``tick < latest + 1000`` is fine): fed at 2.01 s it expires at 3.01 s and acts at the update of 3.04 s; fed at
    2.00 s it acts at the update of 3.00 s exactly. A supervisor updated every step cut the first at 3.02 s and
    the second at 3.01 s."""
    between = Clock()
    between.run(0.01)
    between.fw.handle(9, 1, bytes([0x04]), between.t)  # fed at 2.01
    between.run(1.02)
    assert between.state() == ("Flying", True)  # 3.03: expired 20 ms ago, no update yet
    between.run(0.01)
    assert between.state() == ("Exception, free fall", False) and between.cut_at() == pytest.approx(3.04)
    on_the_lattice = Clock()
    on_the_lattice.fw.handle(9, 1, bytes([0x04]), on_the_lattice.t)  # fed at 2.00
    on_the_lattice.run(0.99)
    assert on_the_lattice.state() == ("Flying", True)
    on_the_lattice.run(0.01)
    assert on_the_lattice.state() == ("Exception, free fall", False) and on_the_lattice.cut_at() == pytest.approx(3.0)


def test_the_commander_watchdog_acts_at_the_first_update_past_its_window() -> None:
    """Streamed setpoints that stop at 2.01 s: older than 0.5 s from 2.51 s on, levelled out at the update of
    2.52 s; older than 2 s from 4.01 s on, motors off at the update of 4.04 s."""
    clock = Clock()
    clock.run(0.01)
    clock.fw.handle(7, 0, struct.pack("<Bffff", 7, 0.0, 0.0, 0.5, 0.0), clock.t)  # the last, at 2.01
    clock.run(0.5)
    assert clock.state() == ("Flying", True)  # 2.51: the age is past 0.5 s, no update yet
    clock.run(0.01)
    assert clock.state() == ("Warning, level out", True)  # 2.52
    clock.run(1.51)
    assert clock.state() == ("Warning, level out", True)  # 4.03
    clock.run(0.01)
    assert clock.state() == ("Exception, free fall", False) and clock.cut_at() == pytest.approx(4.04)
