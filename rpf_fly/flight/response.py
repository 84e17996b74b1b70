"""How a Crazyflie's position controller answers a position setpoint, from its own gains: the model the ground
station uses to know where a drone will stop and where its setpoints should have brought it.

A real drone under the firmware's default PID cascade does not stop where it is told to: a setpoint held where a
drone flying at 0.3 m/s is carries it 6.8 cm past that point (the dynamics reference's ``p_hold_0p3``, docs/
dynamics.md), further the faster it flew, because braking is capped by the tilt limit. A hold, a separation check
and a tracking check that assume a drone stops dead eat the margin they protect. This module is the firmware's
horizontal cascade reduced to what sets that behaviour, per axis, at the position loop's 100 Hz:

- position PID (``posCtlPid.xKp``, ``xKi``): the velocity setpoint, clamped at ``xVelMax`` x 1.1
  (`position_controller_pid.c`, the velocity overhead);
- velocity PID (``velCtlPid.vxKp``, ``vxKi``; degrees of tilt per m/s): the tilt setpoint, clamped at ``pLimit``
  (``rLimit`` for y) x 1.1, then at the limit itself;
- the attitude and rate loops and the motors as one first-order lag of the tilt (`ATTITUDE_TAU_S`, fitted to the
  full model of rpf_fly/emulator/cf_controller.py on the identified body: tests/flight/test_response.py);
- the body: g tan(tilt) less its linear drag (`DRAG_PER_S`: the identified body's 0.01351 N s/m over 31.8 g).

Against the full model (rpf_fly/emulator/cf_scenario.py) it gives the hold overshoot and the carrot lag within a few
millimetres (tests/flight/test_response.py). Pure functions over floats and numpy arrays; the gains come from the
drone's parameter TOC (`ResponseGains.from_params`) or the firmware's defaults.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Mapping, Optional

import numpy as np

GRAVITY = 9.81
RATE_HZ = 100.0
DT = 1.0 / RATE_HZ
OVERHEAD = 1.10
"""``velMaxOverhead`` and ``rpLimitOverhead`` (`position_controller_pid.c`)."""
ATTITUDE_TAU_S = 0.19
"""The tilt's answer to its setpoint (attitude PID, rate PID, gyro filter and motor lag together) as one
first-order lag; fitted to the full model's hold overshoot and carrot lag (tests/flight/test_response.py)."""
DRAG_PER_S = 0.01351 / 0.0318
"""The identified Crazyflie 2.1's horizontal linear drag over its mass (rpf_fly/emulator/cf_body.py)."""


@dataclass(frozen=True)
class ResponseGains:
    """The horizontal gains and limits of one drone, under their firmware parameter names (x and y alike: the
    firmware's defaults are; a drone whose y gains differ is modelled with its x gains)."""

    pos_kp: float = 2.0
    """``posCtlPid.xKp`` (1/s)."""
    pos_ki: float = 0.0
    """``posCtlPid.xKi``."""
    vel_kp: float = 25.0
    """``velCtlPid.vxKp`` (degrees of tilt per m/s)."""
    vel_ki: float = 1.0
    """``velCtlPid.vxKi``."""
    vel_max: float = 1.0
    """``posCtlPid.xVelMax`` (m/s)."""
    tilt_limit_deg: float = 20.0
    """``posCtlPid.pLimit`` (degrees)."""

    PARAMS = {"posCtlPid.xKp": "pos_kp", "posCtlPid.xKi": "pos_ki", "velCtlPid.vxKp": "vel_kp",
              "velCtlPid.vxKi": "vel_ki", "posCtlPid.xVelMax": "vel_max", "posCtlPid.pLimit": "tilt_limit_deg"}
    """The firmware parameters this model reads, and the field each sets."""

    @classmethod
    def from_params(cls, params: Mapping[str, float]) -> "ResponseGains":
        """From a drone's parameter values (names as in its TOC); a parameter it lacks keeps the default."""
        given = {field: float(params[name]) for name, field in cls.PARAMS.items() if name in params}
        return cls(**given)

    @property
    def max_brake_m_s2(self) -> float:
        """The largest horizontal deceleration the tilt limit allows."""
        return GRAVITY * math.tan(math.radians(self.tilt_limit_deg))


DEFAULT_GAINS = ResponseGains()


def respond(gains: ResponseGains, position: np.ndarray, velocity: np.ndarray, setpoints: np.ndarray,
            duration_s: float, tilt_deg: Optional[np.ndarray] = None) -> np.ndarray:
    """Positions (steps x ... x 2) of drones that start at ``position`` with ``velocity`` (... x 2, m and m/s) and
    are held at ``setpoints`` (... x 2; or steps x ... x 2, one per 10 ms step) for ``duration_s``, one row per
    10 ms step. ``tilt_deg``: the tilt each starts with (default: what holds its velocity against drag, as in
    steady flight); the position integrator starts at zero and the velocity integrator with the drag's share (as
    after steady flight)."""
    p = np.array(position, dtype=float)
    v = np.array(velocity, dtype=float)
    given = np.asarray(setpoints, dtype=float)
    per_step = given.ndim == p.ndim + 1
    tilt = np.degrees(np.arctan(DRAG_PER_S * v / GRAVITY)) if tilt_deg is None else np.array(tilt_deg, float)
    i_pos = np.zeros_like(p)
    i_vel = np.degrees(np.arctan(DRAG_PER_S * v / GRAVITY)) / gains.vel_ki if gains.vel_ki > 0 else np.zeros_like(p)
    vel_cap = gains.vel_max * OVERHEAD
    tilt_cap = gains.tilt_limit_deg * OVERHEAD
    follow = 1.0 - math.exp(-DT / ATTITUDE_TAU_S)
    steps = max(1, int(round(duration_s * RATE_HZ)))
    out = np.empty((steps,) + p.shape)
    for k in range(steps):
        sp = given[min(k, len(given) - 1)] if per_step else given
        error = sp - p
        i_pos += error * DT
        v_sp = np.clip(gains.pos_kp * error + gains.pos_ki * i_pos, -vel_cap, vel_cap)
        v_error = v_sp - v
        i_vel += v_error * DT
        tilt_sp = np.clip(gains.vel_kp * v_error + gains.vel_ki * i_vel, -tilt_cap, tilt_cap)
        tilt_sp = np.clip(tilt_sp, -gains.tilt_limit_deg, gains.tilt_limit_deg)
        tilt += (tilt_sp - tilt) * follow
        accel = GRAVITY * np.tan(np.radians(tilt)) - DRAG_PER_S * v
        v = v + accel * DT
        p = p + v * DT
        out[k] = p
    return out


def overshoot_m(gains: ResponseGains, speed_m_s: float, offset_m: float = 0.0) -> float:
    """How far past the point where it was a drone flying at ``speed_m_s`` goes, once held at that point moved
    ``offset_m`` along its way (negative: behind it)."""
    track = respond(gains, np.zeros(2), np.array([speed_m_s, 0.0]), np.array([offset_m, 0.0]), 3.0)
    return float(max(0.0, track[:, 0].max()))


SPEEDS_M_S = np.linspace(0.0, 1.5, 31)
"""The speeds `Braking` tabulates (the firmware caps a streamed flight at 1.1 m/s; a push may go faster)."""
OFFSETS = np.linspace(-1.0, 1.0, 41)
"""Hold points searched, as fractions of the tilt-limited braking distance (plus 0.2 s of flight) along the
drone's way."""
NEAR_SHORTEST_M = 0.005


class Braking:
    """Where a drone of these gains comes to rest once held, by speed: tabulated once (a tenth of a second of numpy),
    read by interpolation every tick.

    For each speed, hold setpoints along the drone's way are tried (`OFFSETS`); the one kept is the furthest ahead
    whose farthest point is within `NEAR_SHORTEST_M` of the shortest stop. Once the tilt saturates a setpoint further
    behind brakes no harder and only sends the drone back further; one further ahead brakes softer and carries it
    further. `stop_m` is that farthest point's distance, `hold_offset_m` the setpoint's."""

    def __init__(self, gains: ResponseGains = DEFAULT_GAINS) -> None:
        self.gains = gains
        reach = SPEEDS_M_S**2 / (2.0 * gains.max_brake_m_s2) + 0.2 * SPEEDS_M_S
        offsets = reach[:, None] * OFFSETS[None, :]
        n = offsets.size
        start = np.zeros((n, 2))
        velocity = np.stack([np.repeat(SPEEDS_M_S, len(OFFSETS)), np.zeros(n)], axis=1)
        setpoints = np.stack([offsets.ravel(), np.zeros(n)], axis=1)
        farthest = respond(gains, start, velocity, setpoints, 2.5)[:, :, 0].max(axis=0).reshape(offsets.shape)
        farthest = np.maximum(farthest, 0.0)
        near = farthest <= farthest.min(axis=1, keepdims=True) + NEAR_SHORTEST_M
        chosen = np.array([int(np.flatnonzero(row).max()) for row in near])
        rows = np.arange(len(SPEEDS_M_S))
        self._stop = farthest[rows, chosen]
        self._offset = offsets[rows, chosen]

    def stop_m(self, speed_m_s: float) -> float:
        """How far a drone flying at ``speed_m_s`` travels after its hold before it is at rest (at most: it may
        come back a little)."""
        return float(np.interp(speed_m_s, SPEEDS_M_S, self._stop, right=self._extrapolate(speed_m_s)))

    def hold_offset_m(self, speed_m_s: float) -> float:
        """Where to hold it, ahead of where it is along its way (negative: behind)."""
        return float(np.interp(speed_m_s, SPEEDS_M_S, self._offset))

    def hold_point(self, position: complex, velocity: complex) -> complex:
        """The hold setpoint of a drone at ``position`` moving at ``velocity`` (x + iy, m and m/s)."""
        speed = abs(velocity)
        if speed < 1e-3:
            return position
        return position + velocity / speed * self.hold_offset_m(speed)

    def _extrapolate(self, speed_m_s: float) -> float:
        """Beyond the table: the braking distance grows with the square of the speed."""
        top = SPEEDS_M_S[-1]
        return float(self._stop[-1] * (speed_m_s / top) ** 2) if speed_m_s > top else float(self._stop[-1])


@lru_cache(maxsize=32)
def _braking(gains: ResponseGains) -> Braking:
    return Braking(gains)


def braking_for(params: Optional[Mapping[str, float]]) -> Braking:
    """The `Braking` of a drone whose controller parameters are ``params`` (None: the firmware's defaults), shared
    by every drone with the same gains."""
    return _braking(ResponseGains.from_params(params) if params else DEFAULT_GAINS)
