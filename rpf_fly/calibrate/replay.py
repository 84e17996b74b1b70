"""Replay a recorded setpoint stream on the offline firmware model (`rpf_fly.emulator.cf_drone.CfDrone`) with
chosen gains: what the calibration compares with where the drone really went.

Why the whole model and not a reduced one: the closed loop of a Crazyflie is the firmware's cascade (position and
velocity PIDs at 100 Hz, attitude and rate PIDs at 500 Hz, the motors' lag, the body's drag, the velocity clamp at
1.1 m/s and the tilt clamp at 20 degrees) and `CfDrone` is that cascade, checked against the reference within a
millimetre (docs/dynamics.md). A gain found on it is the firmware parameter that makes the simulated drone fly so.

The start state is the record's: a drone that hovered at its first measured position (`CfDrone.hovering`, settled
for `SETTLE_S`: every loop converges within it, and a long hover costs replay time that the fit pays many times),
at its first setpoint's yaw, its height integrator holding it where it was against its first setpoint's height
(`hold_height`), or one standing on the floor with its motors off for `FLOOR_LEAD_S` (a take-off from the floor).
Each setpoint acts from the 1 ms tick at or after its time, as a streamed setpoint does; the yaw is the
setpoint's. The controller may see its state late (``late_s``: an estimate fed by late mocap poses). The track is
the body's true position at every tick.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from rpf_fly.emulator.cf_body import quaternion_to_rpy_deg
from rpf_fly.emulator.cf_controller import CfGains
from rpf_fly.emulator.cf_drone import CfDrone

from .record import FlightRecord

SETTLE_S = 0.5
"""How long the replayed drone hovers at the start before t = 0 (a settled hover: the reference's start state is
10 s of it; the gains fitted to the reference traces differ by under 0.01 % between the two)."""
FLOOR_LEAD_S = 1.0
"""How long a floor start stands with its motors off before t = 0 (the reference's command scenarios do so)."""
TICK_S = 0.001


def gains_with(params: Mapping[str, float]) -> CfGains:
    """The firmware's default gains with ``params`` (firmware names, ``posCtlPid.xKp``...) written over them."""
    gains = CfGains()
    for name, value in params.items():
        gains.set_param(name, float(value))
    return gains


class Track:
    """The replayed drone's true position at every 1 ms tick from t = 0 (``positions[k]`` at k ms)."""

    def __init__(self, positions: np.ndarray) -> None:
        self.positions = positions
        self.times = np.arange(len(positions)) * TICK_S

    def at(self, times: np.ndarray) -> np.ndarray:
        """(n, 3): the position at each of ``times`` (s), linear between ticks, held beyond the ends."""
        return np.column_stack([np.interp(times, self.times, self.positions[:, i]) for i in range(3)])


def hold_height(drone: CfDrone, error_m: float) -> None:
    """Give the height loop's integrator the value that holds ``drone`` at rest ``error_m`` below its height
    setpoint (above for a negative error), as a drone still unwinding the integrators a take-off wound up hovers
    (docs/dynamics.md: 1.7 cm high 6 s after it, 0.6 cm after 10 s): the height loop's output, kp e + ki I, is 0."""
    pid = drone.controller.pid_z
    if pid.ki > 0.0:
        pid.integ = -pid.kp * error_m / pid.ki


def replay(record: FlightRecord, params: Mapping[str, float], late_s: float = 0.0) -> Track:
    """Fly ``record``'s setpoint stream from its start state on the firmware model with ``params``. ``late_s``: the
    controller sees the body's position and velocity that late, refreshed every 10 ms as the model's estimate is:
    an estimate fed by mocap poses that old lags the truth by about their age (a dry run's log: fitted with the
    lag of the pose behind the truth, the drone's own gains come back within 3 % at 21 ms of mocap latency, where
    a controller that sees the truth makes the velocity gains 10-20 % too high to explain the late loop's
    ringing; docs/dynamics.md, "Calibrating a vehicle profile")."""
    gains = gains_with(params)
    x0, y0, z0 = record.start_position
    yaw = float(record.setpoints[0, 4])  # it held its setpoint's yaw (a mocap's yaw jitters by a degree)
    if record.on_floor:
        drone = CfDrone((x0, y0, 0.0), yaw, t_s=-FLOOR_LEAD_S, gains=gains)
        drone.step(FLOOR_LEAD_S)
    else:
        drone = CfDrone.hovering((x0, y0, z0), yaw, t_s=0.0, settle_s=SETTLE_S, gains=gains)
        hold_height(drone, float(record.setpoints[0, 3]) - z0)
    late_ticks = max(0, round(late_s / TICK_S))
    every = drone.estimate_every_ticks
    if late_ticks:
        drone.estimate_every_ticks = 1 << 62  # the estimate is refreshed here instead, late
    sp = record.setpoints
    send_ticks = [max(0, math.ceil(t / TICK_S - 1e-6)) for t in sp[:, 0]]
    rows = [(float(r[1]), float(r[2]), float(r[3]), float(r[4])) for r in sp]
    n = math.ceil(record.end_s / TICK_S - 1e-6)
    out: list[list[float]] = []
    vels: list[list[float]] = []
    j, count = 0, len(rows)
    step = drone.step
    for k in range(n + 1):
        while j < count and send_ticks[j] <= k:
            x, y, z, yaw_deg = rows[j]
            drone.send_position(x, y, z, yaw_deg)
            j += 1
        body = drone.body
        out.append(body.pos)
        if late_ticks:
            vels.append(body.vel)
            if (drone.tick_count + drone.step_offset) % every == 0:
                i = max(0, len(out) - 1 - late_ticks)
                old, v = out[i], vels[i]
                roll, pitch, yaw_now = quaternion_to_rpy_deg(*body.quat)
                drone.state = (old[0], old[1], old[2], v[0], v[1], v[2], roll, -pitch, yaw_now)
        step(TICK_S)
    return Track(np.array(out, dtype=float))
