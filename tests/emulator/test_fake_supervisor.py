"""The fake supervisor's arming rules, from crazyflie-firmware's `supervisor_state_machine.c`: a tumbled drone
never passes its pre-flight checks (arming refused), and a motor that fails the arming spin-up check ends the
arming after ARMING_SPINUP_TIMEOUT_MS back in pre-flight checks not passed."""

from __future__ import annotations

from rpf_fly.emulator.fake_supervisor import ARMING_SPINUP_TIMEOUT_S, Supervisor, SupervisorStateName as S


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
