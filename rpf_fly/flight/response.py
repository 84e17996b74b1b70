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
from collections.abc import Mapping
from dataclasses import dataclass
from functools import lru_cache

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

    PARAMS = {
        "posCtlPid.xKp": "pos_kp",
        "posCtlPid.xKi": "pos_ki",
        "velCtlPid.vxKp": "vel_kp",
        "velCtlPid.vxKi": "vel_ki",
        "posCtlPid.xVelMax": "vel_max",
        "posCtlPid.pLimit": "tilt_limit_deg",
    }
    """The firmware parameters this model reads, and the field each sets."""

    @classmethod
    def from_params(cls, params: Mapping[str, float]) -> ResponseGains:
        """From a drone's parameter values (names as in its TOC); a parameter it lacks keeps the default."""
        given = {field: float(params[name]) for name, field in cls.PARAMS.items() if name in params}
        return cls(**given)

    @property
    def steady_lag_s(self) -> float:
        """How far (in seconds of its speed) the drone trails a setpoint that moves at a steady speed: the position
        loop's 1 / kp, plus the velocity error that holds the tilt against drag (the velocity integrator removes it
        only over seconds): 0.55 s with the defaults, as the reference's carrots at 0.5 and 1 m/s."""
        drag_deg_per_m_s = math.degrees(math.atan(DRAG_PER_S / GRAVITY))
        return 1.0 / self.pos_kp + drag_deg_per_m_s / (self.vel_kp * self.pos_kp)

    @property
    def acceleration_lead_s2(self) -> float:
        """How far a drone's setpoint leads it per m/s^2 of its acceleration, beyond what its speed accounts for:
        the position loop asks ``pos_kp`` m/s per metre of error, the velocity loop tilts ``vel_kp`` degrees per m/s
        of velocity error and a tilt accelerates by g tan(tilt), so for small tilts
        ``a = g rad(vel_kp) (pos_kp (r - p) - v)``, i.e. ``r = p + v / pos_kp + a / (pos_kp g rad(vel_kp))``:
        0.117 s^2 with the defaults. A drone speeding up toward its setpoint is that much further behind it than
        its speed says (docs/flight.md, "Where a neighbour is")."""
        return 1.0 / (self.pos_kp * GRAVITY * math.radians(self.vel_kp))

    @property
    def max_brake_m_s2(self) -> float:
        """The largest horizontal deceleration the tilt limit allows."""
        return GRAVITY * math.tan(math.radians(self.tilt_limit_deg))


DEFAULT_GAINS = ResponseGains()


def respond(
    gains: ResponseGains,
    position: np.ndarray,
    velocity: np.ndarray,
    setpoints: np.ndarray,
    duration_s: float,
    tilt_deg: np.ndarray | None = None,
) -> np.ndarray:
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


WDT_LEVEL_OUT_S = 0.5
"""A streamed setpoint this old and the firmware levels the drone out, holding its height
(COMMANDER_WDT_TIMEOUT_STABILIZE, `commander.c`; rpf_fly/emulator/fake_supervisor.py `WDT_WARNING_S`)."""
ESTOP_WATCHDOG_S = 1.0
"""The emergency-stop watchdog's silence after which the firmware stops the motors (`supervisor.c` line 366;
rpf_fly/emulator/fake_supervisor.py `EMERGENCY_STOP_WATCHDOG_S`): the ground station feeds it with its pings."""
POSE_AGE_ALLOWANCE_S = 0.1
"""How old the pose a carrot was capped against may be (`rpf_fly.flight.poses.POSE_LATE_S`: older, the
supervisor warns, and at 0.25 s it holds): a drone moving away from its carrot meanwhile is that much further
behind it."""


def reach_after_death_m(gains: ResponseGains, speed_m_s: float, lead_m: float, height_m: float) -> float:
    """How far (horizontally) a drone can go once its ground station died, at most: the firmware flies it to its last
    setpoint (at most ``lead_m`` ahead of the pose its carrot was capped against, that pose up to
    `POSE_AGE_ALLOWANCE_S` old at ``speed_m_s``) until that setpoint is `WDT_LEVEL_OUT_S` old, then levels it out
    (it coasts) until the emergency-stop watchdog stops the motors `ESTOP_WATCHDOG_S` after the last ping, and it
    falls from ``height_m`` keeping its horizontal speed. Its speed never exceeds what its position loop asks for that
    lead (``pos_kp`` x lead, at most ``xVelMax`` x 1.1) or what it flew at; while it closes on the setpoint it goes
    no further than the lead plus its braking distance at that speed. Checked against the full model
    (tests/flight/test_response.py): 0.62 m found where this says 1.07 m for a 0.5 m/s mission at 0.66 m."""
    lead = lead_m + speed_m_s * POSE_AGE_ALLOWANCE_S
    v_peak = min(gains.vel_max * OVERHEAD, max(speed_m_s, gains.pos_kp * lead))
    closing = min(v_peak * WDT_LEVEL_OUT_S, lead + v_peak**2 / (2.0 * gains.max_brake_m_s2))
    fall_s = math.sqrt(2.0 * max(height_m, 0.0) / GRAVITY)
    return closing + v_peak * (ESTOP_WATCHDOG_S - WDT_LEVEL_OUT_S + fall_s)


SPEEDS_M_S = np.linspace(0.0, 1.5, 16)
"""The speeds `Braking` tabulates (the firmware caps a streamed flight at 1.1 m/s; a push may go faster)."""
TILTS_DEG = np.linspace(-20.0, 20.0, 9)
"""The tilts along the drone's way it tabulates (positive: speeding up along it; the firmware's default limit)."""
OFFSETS = np.linspace(-1.0, 1.0, 21)
"""Hold points searched, as fractions of the tilt-limited braking distance (plus 0.3 s of flight) along the
drone's way."""
NEAR_SHORTEST_M = 0.005
STEADY = None
"""`Braking.stop_m`'s tilt for steady flight: what holds the speed against drag."""


def commanded_tilt(gains: ResponseGains, position: complex, velocity: complex, setpoint: complex) -> complex:
    """The tilt (degrees, x + iy: towards where it accelerates) the firmware's position and velocity loops ask for
    at ``position`` and ``velocity`` with ``setpoint``, before the integrators (the tilt follows it in about
    `ATTITUDE_TAU_S`)."""
    cap, limit = gains.vel_max * OVERHEAD, gains.tilt_limit_deg

    def axis(p: float, v: float, sp: float) -> float:
        v_sp = min(max(gains.pos_kp * (sp - p), -cap), cap)
        return min(max(gains.vel_kp * (v_sp - v), -limit), limit)

    return complex(axis(position.real, velocity.real, setpoint.real), axis(position.imag, velocity.imag, setpoint.imag))


class Braking:
    """Where a drone of these gains comes to rest once held, by its speed and its tilt along its way: tabulated once
    (a fifth of a second of numpy, shared by every drone of the same gains), read by interpolation every check.

    For each speed and tilt, hold setpoints along the drone's way are tried (`OFFSETS`); the one kept is the
    furthest ahead whose farthest point is within `NEAR_SHORTEST_M` of the shortest stop. Once the tilt saturates a
    setpoint further behind brakes no harder and only sends the drone back further; one further ahead brakes softer
    and carries it further. `stop_m` is that farthest point's distance, `hold_offset_m` the setpoint's. A drone
    speeding up (tilted along its way) needs further: its tilt must turn round first."""

    def __init__(self, gains: ResponseGains = DEFAULT_GAINS) -> None:
        self.gains = gains
        reach = SPEEDS_M_S**2 / (2.0 * gains.max_brake_m_s2) + 0.3 * SPEEDS_M_S + 0.05
        shape = (len(SPEEDS_M_S), len(TILTS_DEG), len(OFFSETS))
        offsets = np.broadcast_to(reach[:, None, None] * OFFSETS[None, None, :], shape)
        speeds = np.broadcast_to(SPEEDS_M_S[:, None, None], shape).ravel()
        tilts = np.broadcast_to(TILTS_DEG[None, :, None], shape).ravel()
        n = speeds.size
        zeros = np.zeros(n)
        track = respond(
            gains,
            np.zeros((n, 2)),
            np.stack([speeds, zeros], axis=1),
            np.stack([offsets.ravel(), zeros], axis=1),
            3.0,
            tilt_deg=np.stack([tilts, zeros], axis=1),
        )
        farthest = np.maximum(track[:, :, 0].max(axis=0), 0.0).reshape(shape)
        near = farthest <= farthest.min(axis=2, keepdims=True) + NEAR_SHORTEST_M
        chosen = shape[2] - 1 - np.argmax(near[:, :, ::-1], axis=2)  # the last offset within reach of the shortest
        self._stop = np.take_along_axis(farthest, chosen[:, :, None], axis=2)[:, :, 0]
        self._offset = np.take_along_axis(offsets, chosen[:, :, None], axis=2)[:, :, 0]

    def _read(self, table: np.ndarray, speed_m_s: float, tilt_deg: float | None) -> float:
        if tilt_deg is None:
            tilt_deg = math.degrees(math.atan(DRAG_PER_S * speed_m_s / GRAVITY))
        top = SPEEDS_M_S[-1]
        scale = (speed_m_s / top) ** 2 if speed_m_s > top and table is self._stop else 1.0
        v = min(max(speed_m_s, 0.0), top)
        t = min(max(tilt_deg, TILTS_DEG[0]), TILTS_DEG[-1])
        i = min(int(v / (SPEEDS_M_S[1] - SPEEDS_M_S[0])), len(SPEEDS_M_S) - 2)
        j = min(int((t - TILTS_DEG[0]) / (TILTS_DEG[1] - TILTS_DEG[0])), len(TILTS_DEG) - 2)
        fv = (v - SPEEDS_M_S[i]) / (SPEEDS_M_S[i + 1] - SPEEDS_M_S[i])
        ft = (t - TILTS_DEG[j]) / (TILTS_DEG[j + 1] - TILTS_DEG[j])
        low = table[i, j] * (1 - ft) + table[i, j + 1] * ft
        high = table[i + 1, j] * (1 - ft) + table[i + 1, j + 1] * ft
        return float((low * (1 - fv) + high * fv) * scale)

    def stop_m(self, speed_m_s: float, tilt_deg: float | None = STEADY) -> float:
        """How far a drone at ``speed_m_s`` tilted ``tilt_deg`` along its way (default: steady flight) travels
        after its hold before it is at rest (at most: it may come back a little)."""
        return self._read(self._stop, speed_m_s, tilt_deg)

    def hold_offset_m(self, speed_m_s: float, tilt_deg: float | None = STEADY) -> float:
        """Where to hold it, ahead of where it is along its way (negative: behind)."""
        return self._read(self._offset, speed_m_s, tilt_deg)

    def _way(
        self, position: complex, velocity: complex, setpoint: complex | None
    ) -> tuple[complex, float, float | None]:
        """The drone's way (unit, 0 when it goes nowhere), its speed along it and its tilt along it (None: steady,
        when no setpoint is known)."""
        speed = abs(velocity)
        tilt = None if setpoint is None else commanded_tilt(self.gains, position, velocity, setpoint)
        if speed >= 0.05:
            way = velocity / speed
        elif tilt is not None and abs(tilt) > 0.5:
            way = tilt / abs(tilt)
        else:
            return 0j, 0.0, None
        return way, speed, None if tilt is None else (tilt * way.conjugate()).real

    def stop_point(
        self, position: complex, velocity: complex, setpoint: complex | None = None, tilt_deg: complex | None = None
    ) -> complex:
        """Where a drone at ``position`` (x + iy), moving at ``velocity`` and streamed ``setpoint`` (None: in
        steady flight), comes to rest at the farthest if it is held now; ``tilt_deg`` (x + iy, towards where it
        accelerates): its tilt when known (a `Follower`'s), else the one its setpoint asks for."""
        if tilt_deg is None:
            way, speed, tilt = self._way(position, velocity, setpoint)
        else:
            speed = abs(velocity)
            way = velocity / speed if speed >= 0.05 else (tilt_deg / abs(tilt_deg) if abs(tilt_deg) > 0.5 else 0j)
            tilt = (tilt_deg * way.conjugate()).real if way else None
        return position + way * self.stop_m(speed, tilt) if way else position

    def hold_point(self, position: complex, velocity: complex, setpoint: complex | None = None) -> complex:
        """The hold setpoint of a drone at ``position`` moving at ``velocity`` (x + iy, m and m/s) that was
        streamed ``setpoint`` (None: in steady flight)."""
        way, speed, tilt = self._way(position, velocity, setpoint)
        return position + way * self.hold_offset_m(speed, tilt) if way else position


@lru_cache(maxsize=32)
def _braking(gains: ResponseGains) -> Braking:
    return Braking(gains)


def braking_for(params: Mapping[str, float] | None) -> Braking:
    """The `Braking` of a drone whose controller parameters are ``params`` (None: the firmware's defaults), shared
    by every drone with the same gains."""
    return _braking(ResponseGains.from_params(params) if params else DEFAULT_GAINS)


class Follower:
    """Where a drone's streamed setpoints should have brought it: the reduced cascade run forward on them, one
    100 Hz step at a time (the supervisor's tracking check: a drone far from this was pushed). Plain floats: it runs
    for every drone on every mocap frame."""

    __slots__ = ("gains", "p", "v", "tilt", "i_pos", "i_vel", "_left")

    def __init__(self, gains: ResponseGains, position: complex, velocity: complex) -> None:
        self.gains = gains
        self.p = [position.real, position.imag]
        self.v = [velocity.real, velocity.imag]
        self.tilt = [math.degrees(math.atan(DRAG_PER_S * v / GRAVITY)) for v in self.v]
        self.i_pos = [0.0, 0.0]
        self.i_vel = [t / gains.vel_ki if gains.vel_ki > 0 else 0.0 for t in self.tilt]
        self._left = 0.0

    @property
    def position(self) -> complex:
        return complex(self.p[0], self.p[1])

    @property
    def velocity(self) -> complex:
        return complex(self.v[0], self.v[1])

    @property
    def tilt_deg(self) -> complex:
        """The tilt (degrees, x + iy: towards where it accelerates)."""
        return complex(self.tilt[0], self.tilt[1])

    def coasted(self, setpoint: complex, seconds: float) -> Follower:
        """A copy of this model flown on for ``seconds`` (rounded up to whole 10 ms steps) towards ``setpoint``:
        where a drone still is, and how fast and tilted, when a command sent now reaches its controller (a drone
        speeding up goes on speeding up until then: its tilt turns round only after)."""
        twin = Follower.__new__(Follower)
        twin.gains = self.gains
        twin.p, twin.v, twin.tilt = list(self.p), list(self.v), list(self.tilt)
        twin.i_pos, twin.i_vel = list(self.i_pos), list(self.i_vel)
        twin._left = 0.0
        twin.step(setpoint, math.ceil(max(seconds, 0.0) / DT - 1e-9) * DT)
        return twin

    def step(self, setpoint: complex, dt_s: float) -> complex:
        """Advance ``dt_s`` (whole 10 ms steps; the rest is carried) towards ``setpoint``; the new position. The two
        axes are independent in this model, so each runs its steps on local names (the separation check flies a copy
        on every mocap frame: `coasted`)."""
        g = self.gains
        vel_cap, limit = g.vel_max * OVERHEAD, g.tilt_limit_deg  # the tilt's 1.1 x overhead clamp is inside it
        pos_kp, pos_ki, vel_kp, vel_ki = g.pos_kp, g.pos_ki, g.vel_kp, g.vel_ki
        follow = 1.0 - math.exp(-DT / ATTITUDE_TAU_S)
        tan, rad = math.tan, math.pi / 180.0
        self._left += dt_s
        steps = int(self._left / DT + 1e-9)
        self._left -= steps * DT
        for k, target in ((0, setpoint.real), (1, setpoint.imag)):
            p, v, tilt, i_pos, i_vel = self.p[k], self.v[k], self.tilt[k], self.i_pos[k], self.i_vel[k]
            for _ in range(steps):
                error = target - p
                i_pos += error * DT
                v_sp = min(max(pos_kp * error + pos_ki * i_pos, -vel_cap), vel_cap)
                v_error = v_sp - v
                i_vel += v_error * DT
                tilt_sp = min(max(vel_kp * v_error + vel_ki * i_vel, -limit), limit)
                tilt += (tilt_sp - tilt) * follow
                v += (GRAVITY * tan(tilt * rad) - DRAG_PER_S * v) * DT
                p += v * DT
            self.p[k], self.v[k], self.tilt[k], self.i_pos[k], self.i_vel[k] = p, v, tilt, i_pos, i_vel
        return self.position
