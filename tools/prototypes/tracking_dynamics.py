"""Prototype, not part of the product: how a default Crazyflie's position loop compares with the simulated one, and
what that does to the supervisor's tracking follower.

    python tools/prototypes/tracking_dynamics.py

Why it exists (docs/flight.md, "The simulated drone: the firmware's cascade, and the first-order option"). The
first-order simulated drone (rpf_fly/emulator/fake_vehicle.py) takes a position setpoint as a first-order
lag of 0.25 s (4 /s) with no momentum: its velocity is whatever the position loop asks, at once. The firmware's
default PID is a cascade: a position loop of ``posCtlPid.xKp`` 2 /s asking a velocity, and a velocity loop of
``velCtlPid.vxKp`` 25 degrees of tilt per m/s (g tan(25 deg x v) = about 4.3 m/s^2 per m/s: 0.23 s), tilt capped at
``posCtlPid.rLimit`` 20 degrees (3.57 m/s^2), speed at 1.1 m/s. The supervisor's flight follower
(rpf_fly/flight/supervisor.py ``_Follower`` with ``TRACKING_TAU_S``) is set on the simulated drone.

Each pattern streams a 10 Hz carrot as the agent does (0.05 m a tick at 0.5 m/s, never more than 0.3 m ahead of
the drone), flies a "truth" model on it, and prints the largest distance of the truth from a follower envelope: the
segment between two followers of the same setpoints. Figures in cm; the supervisor's line is 7 cm (plus the
turbulence's 2-4 cm, which these noise-free runs leave out).

Truths: the simulated drone; the firmware cascade; the cascade with the attitude loop's 1/6 s lag; that with a
lab's stiffer position gain (3 /s). Envelopes: the supervisor's follower as it is (0.25 s: one point); 0.25 s to a
first-order 0.5 s; 0.25 s to the firmware cascade itself.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from rpf_fly.flight.tracking_check import _to_segment  # noqa: E402

DT = 0.01
PLAN_PERIOD_S = 0.1
SPEED_M_S = 0.5
CARROT_LEAD_M = 0.3
G = 9.81


class PositionLoop:
    """A horizontal position loop: ``kp`` (1/s) asks a velocity (capped at ``v_max``); with ``tau_v`` > 0 a velocity
    loop brings the velocity there with that time constant, its acceleration capped at ``a_max`` (the tilt limit)
    and delayed by the attitude loop's ``tau_att``; with ``tau_v`` = 0 the velocity is the asked one at once."""

    def __init__(
        self,
        kp: float,
        tau_v: float = 0.0,
        tau_att: float = 0.0,
        a_max: float = G * math.tan(math.radians(20)),
        v_max: float = 1.1,
    ) -> None:
        self.kp, self.tau_v, self.tau_att, self.a_max, self.v_max = kp, tau_v, tau_att, a_max, v_max
        self.p = self.v = self.a = 0j

    def step(self, setpoint: complex) -> complex:
        asked = self.kp * (setpoint - self.p)
        if abs(asked) > self.v_max:
            asked *= self.v_max / abs(asked)
        if self.tau_v <= 0.0:
            self.v = asked
        else:
            a = (asked - self.v) / self.tau_v
            if abs(a) > self.a_max:
                a *= self.a_max / abs(a)
            self.a = a if self.tau_att <= 0.0 else self.a + (a - self.a) * (1.0 - math.exp(-DT / self.tau_att))
            self.v += self.a * DT
        self.p += self.v * DT
        return self.p


def fly(pattern: str, truth: PositionLoop, fast: PositionLoop, slow: PositionLoop, seconds: float = 8.0) -> float:
    """Largest distance (m) of ``truth`` from the segment between ``fast`` and ``slow`` over one pattern."""
    reference = setpoint = position = 0j
    heading = 1 + 0j
    worst = 0.0
    ticks_per_plan = round(PLAN_PERIOD_S / DT)
    for k in range(round(seconds / DT)):
        t = k * DT
        if k % ticks_per_plan == 0:
            if pattern == "turn" and t > 2.5:
                heading = 1j
            elif pattern == "zigzag":
                heading = 1 + 0j if int(t) % 2 == 0 else 1j
            elif pattern == "stop" and t > 3.0:
                heading = 0j
            if pattern == "hold" and t > 3.0:
                if t - 3.0 < PLAN_PERIOD_S:
                    setpoint = position  # the supervisor's hold: where the drone is
            else:
                reference += SPEED_M_S * PLAN_PERIOD_S * heading
                if abs(reference - position) > CARROT_LEAD_M:
                    reference = position + (reference - position) * CARROT_LEAD_M / abs(reference - position)
                setpoint = reference
        position = truth.step(setpoint)
        fast.step(setpoint)
        slow.step(setpoint)
        worst = max(worst, _to_segment(position, fast.p, slow.p))
    return worst


def main() -> None:
    simulated: Callable[[], PositionLoop] = lambda: PositionLoop(kp=4.0)  # noqa: E731
    cascade: Callable[[], PositionLoop] = lambda: PositionLoop(kp=2.0, tau_v=0.23)  # noqa: E731
    truths = {
        "simulated drone": simulated,
        "firmware cascade": cascade,
        "cascade + attitude lag": lambda: PositionLoop(kp=2.0, tau_v=0.23, tau_att=1.0 / 6.0),
        "cascade + att, kp 3": lambda: PositionLoop(kp=3.0, tau_v=0.23, tau_att=1.0 / 6.0),
    }
    envelopes = {
        "0.25 s (as flown)": (simulated, simulated),
        "0.25 s .. 0.5 s": (simulated, lambda: PositionLoop(kp=2.0)),
        "0.25 s .. cascade": (simulated, cascade),
    }
    patterns = ("straight", "turn", "zigzag", "stop", "hold")
    print(f"largest distance from the follower envelope, cm (the supervisor warns at 7; {SPEED_M_S} m/s carrot)")
    for envelope, (fast, slow) in envelopes.items():
        print(f"\nenvelope {envelope}")
        print(f"  {'truth':24s}" + "".join(f"{p:>9s}" for p in patterns))
        for name, truth in truths.items():
            row = [fly(p, truth(), fast(), slow()) * 100 for p in patterns]
            print(f"  {name:24s}" + "".join(f"{v:9.1f}" for v in row))


if __name__ == "__main__":
    main()
