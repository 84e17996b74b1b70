"""Many simulated Crazyflies stepped together: cf_drone.CfDrone's model (the firmware's PID cascade on the
cf2x_P250 body, cf_controller.py and cf_body.py) on numpy arrays of shape (.., N), one column a drone.

The arithmetic is the per-drone model's, operation for operation (its integer truncations included), so a swarm of
one flies as `CfDrone` does (tests/emulator/test_cf_controller.py compares them); only the cost differs: a tick
costs the same few hundred numpy operations whatever N is, so the cost per drone falls as the swarm grows
(tools/bench_cf_model.py). The high-level commanders stay per drone (fake_planner.HighLevelCommander, called at
100 Hz for the drones they fly).

`CfSwarm.drone(i)` is drone i's view with `CfDrone`'s calls (setpoints, high-level commands, position, velocity,
quaternion, motors, external force, parameters); `CfSwarm.step(dt)` advances every drone.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Sequence
from typing import Any

import numpy as np

from .cf_body import P250, CfBodyParams
from .cf_controller import (
    ATTITUDE_DT,
    ATTITUDE_EVERY,
    DEFAULT_INTEGRATION_LIMIT,
    INT16_MAX,
    MODE_ABS,
    MODE_DISABLE,
    MODE_VELOCITY,
    PITCH_INTEGRATION_LIMIT,
    PITCH_RATE_INTEGRATION_LIMIT,
    POSITION_DT,
    POSITION_EVERY,
    ROLL_INTEGRATION_LIMIT,
    ROLL_RATE_INTEGRATION_LIMIT,
    RP_LIMIT_OVERHEAD,
    THRUST_MAX_N,
    THRUST_MIN_N,
    THRUST_SCALE,
    UINT16_MAX,
    VEL_MAX_OVERHEAD,
    YAW_INTEGRATION_LIMIT,
    YAW_RATE_INTEGRATION_LIMIT,
    CfGains,
    ControlSetpoint,
    lpf2p_coefficients,
)
from .cf_drone import PRIORITY_CRTP, PRIORITY_HIGH_LEVEL, PRIORITY_NONE, TICK_S
from .fake_planner import (
    COMMAND_GO_TO_2,
    COMMAND_LAND_2,
    COMMAND_STOP,
    COMMAND_TAKEOFF_2,
    HighLevelCommander,
    PlanState,
)
from .fake_setpoint import Setpoint
from .swarm_math import cap_angle, rotated

_RPM_TO_RAD_S = 2.0 * math.pi / 60.0
_DEG = 180.0 / math.pi
_GROUPS = ("pos", "vel", "att", "rate")
_PREFIXES = {
    "pos": ("pos_x", "pos_y", "pos_z"),
    "vel": ("vel_x", "vel_y", "vel_z"),
    "att": ("att_roll", "att_pitch", "att_yaw"),
    "rate": ("rate_roll", "rate_pitch", "rate_yaw"),
}
_I_LIMITS = {
    "pos": (DEFAULT_INTEGRATION_LIMIT,) * 3,
    "vel": (DEFAULT_INTEGRATION_LIMIT,) * 3,
    "att": (ROLL_INTEGRATION_LIMIT, PITCH_INTEGRATION_LIMIT, YAW_INTEGRATION_LIMIT),
    "rate": (ROLL_RATE_INTEGRATION_LIMIT, PITCH_RATE_INTEGRATION_LIMIT, YAW_RATE_INTEGRATION_LIMIT),
}
_DT = {"pos": POSITION_DT, "vel": POSITION_DT, "att": ATTITUDE_DT, "rate": ATTITUDE_DT}


class CfSwarm:
    """N Crazyflies (module doc). `positions` (N, 3) in metres; each drone starts at rest there, motors off,
    unless `hovering` (below)."""

    def __init__(
        self,
        positions: Sequence[Sequence[float]],
        *,
        t_s: float = 0.0,
        gains: Sequence[CfGains] | None = None,
        body_params: CfBodyParams = P250,
        step_offset: int = 1,
        estimate_every_ticks: int = POSITION_EVERY,
    ) -> None:
        start = np.asarray(positions, dtype=float).reshape(-1, 3).T.copy()
        n = start.shape[1]
        self.n = n
        self.params = body_params
        self.tick_count = round(t_s / TICK_S)
        self.step_offset = step_offset
        self.estimate_every_ticks = estimate_every_ticks
        # body
        self.pos = start
        self.vel = np.zeros((3, n))
        self.quat = np.zeros((4, n))
        self.quat[3] = 1.0
        self.omega = np.zeros((3, n))
        self.rotor = np.zeros((4, n))
        self.rotor_cmd = np.zeros((4, n))
        self.external_force = np.zeros((3, n))
        self.floor_z = np.minimum(start[2], 0.0)
        self.on_floor = start[2] <= self.floor_z
        # gyro filter
        self._lpf = lpf2p_coefficients(1000.0, 80.0)
        self.gyro_d1 = np.zeros((3, n))
        self.gyro_d2 = np.zeros((3, n))
        # controller
        self.gains = [CfGains(**vars(g)) for g in gains] if gains is not None else [CfGains() for _ in range(n)]
        if len(self.gains) != n:
            raise ValueError("one CfGains per drone")
        self._k: dict[str, np.ndarray] = {}
        self._gather_gains()
        self.integ = {g: np.zeros((3, n)) for g in _GROUPS}
        self.prev = {g: np.zeros((3, n)) for g in _GROUPS}
        self.previous_modes = np.zeros((6, n), dtype=np.int8)
        self.att_desired = np.zeros((3, n))
        self.rate_desired = np.zeros((3, n))
        self.actuator_thrust = np.zeros(n)
        self.thrust = np.zeros(n)
        self.cmd = np.zeros((3, n))
        """roll, pitch, yaw commands (integers held as floats)."""
        self.motor_commands = np.zeros((4, n))
        self._last_thrust = np.full(n, np.nan)
        # setpoints
        self.modes = np.zeros((6, n), dtype=np.int8)
        self.sp_pos = np.zeros((3, n))
        self.sp_vel = np.zeros((3, n))
        self.sp_att = np.zeros((3, n))
        self.sp_rate = np.zeros((3, n))
        self.sp_thrust = np.zeros(n)
        self.priority = np.full(n, PRIORITY_NONE)
        self.hl = [
            HighLevelCommander((float(start[0, i]), float(start[1, i]), float(start[2, i])), 0.0) for i in range(n)
        ]
        self.state = np.zeros((9, n))
        self._refresh_state()

    @classmethod
    def hovering(
        cls, positions: Sequence[Sequence[float]], *, t_s: float = 0.0, settle_s: float = 10.0, **kwargs: Any
    ) -> CfSwarm:
        """Drones that have hovered at `positions` for `settle_s` before `t_s` (`CfDrone.hovering`)."""
        swarm = cls(positions, t_s=t_s - settle_s, **kwargs)
        p = swarm.params
        swarm.floor_z = np.minimum(swarm.floor_z, 0.0)
        swarm.on_floor[:] = False
        rpm = p.rpm_for_thrust(p.hover_thrust_n)
        swarm.rotor[:] = rpm
        swarm.rotor_cmd[:] = rpm
        hover_command = p.hover_thrust_n / THRUST_MAX_N * UINT16_MAX
        for i in range(swarm.n):
            x, y, z = swarm.pos[:, i]
            swarm.drone(i).send_position(float(x), float(y), float(z))
        swarm.previous_modes[:] = swarm.modes
        swarm._reinitialize(np.ones(swarm.n, dtype=bool))
        thrust_base = swarm._k["thrust_base"]
        swarm.integ["vel"][2] = (hover_command - thrust_base) / (1000.0 * swarm._k["vel_ki"][2])
        swarm.actuator_thrust[:] = hover_command
        swarm.thrust[:] = hover_command
        swarm.step(settle_s)
        return swarm

    # Gains ------------------------------------------------------------------------------------------------------

    def _gather_gains(self) -> None:
        k: dict[str, np.ndarray] = {}
        for group in _GROUPS:
            for term in ("kp", "ki", "kd", "kff"):
                k[f"{group}_{term}"] = np.array(
                    [[getattr(g, f"{p}_{term}") for g in self.gains] for p in _PREFIXES[group]]
                )
            k[f"{group}_ilimit"] = np.array(_I_LIMITS[group]).reshape(3, 1)
        for name in (
            "thrust_base",
            "thrust_min",
            "r_limit",
            "p_limit",
            "x_vel_max",
            "y_vel_max",
            "z_vel_max",
            "yaw_max_delta",
        ):
            k[name] = np.array([getattr(g, name) for g in self.gains])
        k["pos_olimit"] = np.array(
            [
                k["x_vel_max"] * VEL_MAX_OVERHEAD,
                k["y_vel_max"] * VEL_MAX_OVERHEAD,
                np.maximum(k["z_vel_max"], 0.5) * VEL_MAX_OVERHEAD,
            ]
        )
        k["vel_olimit"] = np.array(
            [
                k["p_limit"] * RP_LIMIT_OVERHEAD,
                k["r_limit"] * RP_LIMIT_OVERHEAD,
                np.full(self.n, UINT16_MAX / 2 / THRUST_SCALE),
            ]
        )
        self._k = k

    def set_param(self, i: int, name: str, value: float) -> None:
        """Set drone i's parameter `name` (firmware name, e.g. ``posCtlPid.xKp``)."""
        self.gains[i].set_param(name, value)
        self._gather_gains()

    # Controller -------------------------------------------------------------------------------------------------

    def _pid(
        self,
        group: str,
        desired: np.ndarray,
        measured: np.ndarray,
        olimit: np.ndarray | None,
        mask: np.ndarray | None = None,
    ) -> np.ndarray:
        """`pidUpdate` on the three PIDs of `group` for every drone (where `mask`, rows by columns, is True)."""
        k = self._k
        dt = _DT[group]
        prev = self.prev[group]
        error = desired - measured
        delta = prev - measured
        if group == "att":  # the yaw row wraps (isYawAngle)
            e2, d2 = error[2], delta[2]
            error[2] = np.where(e2 > 180.0, e2 - 360.0, np.where(e2 < -180.0, e2 + 360.0, e2))
            delta[2] = np.where(d2 > 180.0, d2 - 360.0, np.where(d2 < -180.0, d2 + 360.0, d2))
        integ = np.clip(self.integ[group] + error * dt, -k[f"{group}_ilimit"], k[f"{group}_ilimit"])
        out = k[f"{group}_kp"] * error + k[f"{group}_kd"] * (delta / dt)
        out = out + k[f"{group}_ki"] * integ + k[f"{group}_kff"] * desired
        if olimit is not None:
            out = np.clip(out, -olimit, olimit)
        if mask is None:
            self.integ[group] = integ
            self.prev[group] = measured
        else:
            self.integ[group] = np.where(mask, integ, self.integ[group])
            self.prev[group] = np.where(mask, measured, prev)
        return out

    def _reinitialize(self, which: np.ndarray) -> None:
        """`controllerPidReinitialize` for the drones in `which`."""
        s = self.state
        for group in _GROUPS:
            self.integ[group][:, which] = 0.0
        self.prev["pos"][:, which] = s[0:3, which]
        self.prev["vel"][:, which] = 0.0
        self.prev["att"][:, which] = s[6:9, which]
        self.prev["rate"][:, which] = 0.0
        self.att_desired[0:2, which] = s[6:8, which]

    def _refresh_state(self) -> None:
        qx, qy, qz, qw = self.quat
        s = self.state
        s[0:3] = self.pos
        s[3:6] = self.vel
        s[6] = np.arctan2(2.0 * (qy * qz + qw * qx), qw * qw - qx * qx - qy * qy + qz * qz) * _DEG
        sp = np.clip(-2.0 * (qx * qz - qw * qy), -1.0, 1.0)
        s[7] = -(np.arcsin(sp) * _DEG)
        s[8] = np.arctan2(2.0 * (qx * qy + qw * qz), qw * qw + qx * qx - qy * qy - qz * qz) * _DEG

    def _controller(self, step: int, gyro: np.ndarray) -> None:
        k, s, modes = self._k, self.state, self.modes
        changed = np.any(modes != self.previous_modes, axis=0)
        if changed.any():
            self._reinitialize(changed)
        self.previous_modes = modes.copy()
        attitude_tick = step % ATTITUDE_EVERY == 0
        att = self.att_desired
        if attitude_tick:
            yaw_mode = modes[5]
            turned = cap_angle(att[2] + self.sp_rate[2] * ATTITUDE_DT)
            if np.any(k["yaw_max_delta"] != 0.0):
                md = k["yaw_max_delta"]
                delta = cap_angle(turned - s[8])
                limited = np.where(delta > md, s[8] + md, np.where(delta < -md, s[8] - md, turned))
                turned = np.where(md != 0.0, limited, turned)
            yaw = np.where(yaw_mode == MODE_VELOCITY, turned, np.where(yaw_mode == MODE_ABS, self.sp_att[2], att[2]))
            att[2] = cap_angle(yaw)
        if step % POSITION_EVERY == 0:
            self._position_controller()
        if attitude_tick:
            self.actuator_thrust = np.where(modes[2] == MODE_DISABLE, self.sp_thrust, self.actuator_thrust)
            free = (modes[0] == MODE_DISABLE) | (modes[1] == MODE_DISABLE)
            att[0:2] = np.where(free, self.sp_att[0:2], att[0:2])
            rate = self._pid("att", att.copy(), s[6:9].copy(), None)
            rate[0] = np.where(modes[3] == MODE_VELOCITY, self.sp_rate[0], rate[0])
            rate[1] = np.where(modes[4] == MODE_VELOCITY, self.sp_rate[1], rate[1])
            self.rate_desired = rate
            measured = np.array([gyro[0], -gyro[1], gyro[2]])
            out = np.trunc(np.clip(self._pid("rate", rate.copy(), measured, None), -INT16_MAX, INT16_MAX))
            out[2] = -out[2]
            self.cmd = out
        self.thrust = self.actuator_thrust.copy()
        zero = self.thrust == 0.0
        if zero.any():
            self.cmd[:, zero] = 0.0
            self._reinitialize(zero)
            att[2, zero] = s[8, zero]

    def _position_controller(self) -> None:
        k, s, modes = self._k, self.state, self.modes
        yaw = s[8] * (math.pi / 180.0)
        c, sn = np.cos(yaw), np.sin(yaw)
        spx, spy, spz = self.sp_pos
        x, y, z = s[0], s[1], s[2]
        desired = np.array([spx * c + spy * sn, -spx * sn + spy * c, spz])
        measured = np.array([x * c + y * sn, -x * sn + y * c, z])
        absolute = modes[0:3] == MODE_ABS
        out = self._pid("pos", desired, measured, k["pos_olimit"], absolute)
        svx, svy, svz = self.sp_vel
        v_sp = np.where(absolute, out, np.array([svx * c + svy * sn, svy * c - svx * sn, svz]))
        vx, vy, vz = s[3], s[4], s[5]
        vel_out = self._pid("vel", v_sp, np.array([vx * c + vy * sn, -vx * sn + vy * c, vz]), k["vel_olimit"])
        pitch = -vel_out[0]
        roll = -vel_out[1]
        self.att_desired[0] = np.clip(roll, -k["r_limit"], k["r_limit"])
        self.att_desired[1] = np.clip(pitch, -k["p_limit"], k["p_limit"])
        thrust = vel_out[2] * THRUST_SCALE + k["thrust_base"]
        thrust = np.where(thrust < k["thrust_min"], k["thrust_min"], thrust)
        self.actuator_thrust = np.clip(thrust, 0.0, float(UINT16_MAX))

    def _motors(self) -> None:
        """Legacy power distribution, cap, battery-compensated thrust, commanded rotor speeds."""
        thrust = self.thrust
        r = np.trunc(self.cmd[0] / 2.0)
        p = np.trunc(self.cmd[1] / 2.0)
        yaw = self.cmd[2]
        m = np.array(
            [
                np.trunc(thrust - r + p + yaw),
                np.trunc(thrust - r - p - yaw),
                np.trunc(thrust + r - p + yaw),
                np.trunc(thrust + r + p - yaw),
            ]
        )
        excess = m.max(axis=0) - UINT16_MAX
        m = np.where(excess > 0, m - excess, m)
        m = np.maximum(m, 0.0)
        self.motor_commands = m
        force = m / UINT16_MAX * THRUST_MAX_N
        force = np.where(force >= THRUST_MIN_N, force, 0.0)
        a1, a2 = self.params.thrust_a1, self.params.thrust_a2
        self.rotor_cmd = np.where(force > 0.0, (-a1 + np.sqrt(a1 * a1 + 4.0 * a2 * force)) / (2.0 * a2), 0.0)

    # Body -------------------------------------------------------------------------------------------------------

    def _body_step(self, dt: float) -> None:
        """cf_body.CfBody's midpoint step on every column."""
        p = self.params
        c, r = self.rotor_cmd, self.rotor
        up0, up1, down0, down1 = p.rotor_up_k0, p.rotor_up_k1, p.rotor_down_k2, p.rotor_down_k3
        d0 = np.where(c > r, up0 * (c - r) + up1 * (c * c - r * r), down0 * (c - r) + down1 * (c * c - r * r))
        r1 = np.maximum(r + d0 * dt, 0.0)
        d1 = np.where(c > r1, up0 * (c - r1) + up1 * (c * c - r1 * r1), down0 * (c - r1) + down1 * (c * c - r1 * r1))
        dm = 0.5 * (d0 + d1)
        r1 = np.maximum(r + dm * dt, 0.0)
        w = 0.5 * (r + r1)
        o = self.omega
        qm = rotated(self.quat, 0.5 * dt * o[0], 0.5 * dt * o[1], 0.5 * dt * o[2])
        # forces and torques (cf_body.CfBody._accelerations)
        f = p.thrust_a1 * w + p.thrust_a2 * w * w
        q = p.torque_b1 * w + p.torque_b2 * w * w
        f1, f2, f3, f4 = f
        thrust = f1 + f2 + f3 + f4
        qx, qy, qz, qw = qm
        xx, yy, zz = qx * qx, qy * qy, qz * qz
        xy, xz, yz = qx * qy, qx * qz, qy * qz
        wx, wy, wz = qw * qx, qw * qy, qw * qz
        r00, r01, r02 = 1.0 - 2.0 * (yy + zz), 2.0 * (xy - wz), 2.0 * (xz + wy)
        r10, r11, r12 = 2.0 * (xy + wz), 1.0 - 2.0 * (xx + zz), 2.0 * (yz - wx)
        r20, r21, r22 = 2.0 * (xz - wy), 2.0 * (yz + wx), 1.0 - 2.0 * (xx + yy)
        vx, vy, vz = self.vel
        bx = p.drag_xy * (r00 * vx + r10 * vy + r20 * vz)
        by = p.drag_xy * (r01 * vx + r11 * vy + r21 * vz)
        bz = p.drag_z * (r02 * vx + r12 * vy + r22 * vz)
        ext = self.external_force
        m = p.mass
        ax = (r02 * thrust + r00 * bx + r01 * by + r02 * bz + ext[0]) / m
        ay = (r12 * thrust + r10 * bx + r11 * by + r12 * bz + ext[1]) / m
        az = (r22 * thrust + r20 * bx + r21 * by + r22 * bz + ext[2]) / m - p.gravity
        ox, oy, oz = o
        spin = _RPM_TO_RAD_S * (-w[0] + w[1] - w[2] + w[3])
        spin_dot = _RPM_TO_RAD_S * (-dm[0] + dm[1] - dm[2] + dm[3])
        jp, arm = p.prop_inertia, p.arm
        tx = arm * (-f1 - f2 + f3 + f4) - jp * oy * spin
        ty = arm * (-f1 + f2 + f3 - f4) - jp * ox * spin
        tz = (-q[0] + q[1] - q[2] + q[3]) + jp * spin_dot
        jx, jy, jz = p.jxx, p.jyy, p.jzz
        o1 = np.array(
            [
                ox + (tx - (jz - jy) * oy * oz) / jx * dt,
                oy + (ty - (jx - jz) * oz * ox) / jy * dt,
                oz + (tz - (jy - jx) * ox * oy) / jz * dt,
            ]
        )
        v1 = np.array([vx + ax * dt, vy + ay * dt, vz + az * dt])
        self.pos = self.pos + 0.5 * (self.vel + v1) * dt
        self.quat = rotated(self.quat, 0.5 * (ox + o1[0]) * dt, 0.5 * (oy + o1[1]) * dt, 0.5 * (oz + o1[2]) * dt)
        self.vel = v1
        self.omega = o1
        self.rotor = r1
        # floor: no penetration, no sliding
        z = self.pos[2]
        down = (z < self.floor_z) | (self.on_floor & (z <= self.floor_z))
        if down.any():
            self.pos[2] = np.where(down, self.floor_z, z)
            self.vel[:, down] = 0.0
            self.omega[:, down] = 0.0
        self.on_floor = down

    # Loop -------------------------------------------------------------------------------------------------------

    @property
    def time_s(self) -> float:
        return self.tick_count * TICK_S

    def step(self, dt_s: float) -> None:
        """Advance every drone by `dt_s` (whole 1 ms ticks)."""
        for _ in range(round(dt_s / TICK_S)):
            self._tick()

    def _tick(self) -> None:
        k = self.tick_count + self.step_offset
        b0, b1, b2, a1, a2 = self._lpf
        g = self.omega * _DEG
        d0 = g - self.gyro_d1 * a1 - self.gyro_d2 * a2
        gyro = d0 * b0 + self.gyro_d1 * b1 + self.gyro_d2 * b2
        self.gyro_d2 = self.gyro_d1
        self.gyro_d1 = d0
        if k % self.estimate_every_ticks == 0:
            self._refresh_state()
        if k % POSITION_EVERY == 0:
            self._high_level()
        self._controller(k, gyro)
        if k % ATTITUDE_EVERY == 0 or np.any(self.thrust != self._last_thrust):
            self._motors()
        self._last_thrust = self.thrust
        self._body_step(TICK_S)
        self.tick_count += 1

    def _high_level(self) -> None:
        now = self.tick_count * TICK_S
        s = self.state
        for i in np.flatnonzero(self.priority <= PRIORITY_HIGH_LEVEL).tolist():
            hl = self.hl[i]
            sp = hl.get_setpoint(
                now,
                (float(s[0, i]), float(s[1, i]), float(s[2, i])),
                (float(s[3, i]), float(s[4, i]), float(s[5, i])),
                math.radians(float(s[8, i])),
            )
            if sp is not None:
                self._write(i, ControlSetpoint.from_setpoint(sp))
                self.priority[i] = PRIORITY_HIGH_LEVEL

    def _write(self, i: int, sp: ControlSetpoint) -> None:
        self.modes[:, i] = sp.modes
        self.sp_pos[:, i] = (sp.x, sp.y, sp.z)
        self.sp_vel[:, i] = (sp.vx, sp.vy, sp.vz)
        self.sp_att[:, i] = (sp.roll, sp.pitch, sp.yaw)
        self.sp_rate[:, i] = (sp.roll_rate, sp.pitch_rate, sp.yaw_rate)
        self.sp_thrust[i] = sp.thrust

    def drone(self, i: int) -> SwarmDrone:
        return SwarmDrone(self, i)


class SwarmDrone:
    """Drone i of a `CfSwarm`, with `CfDrone`'s calls."""

    __slots__ = ("swarm", "i")

    def __init__(self, swarm: CfSwarm, i: int) -> None:
        self.swarm, self.i = swarm, i

    def send_setpoint(self, setpoint: ControlSetpoint | Setpoint) -> None:
        if isinstance(setpoint, Setpoint):
            setpoint = ControlSetpoint.from_setpoint(setpoint)
        self.swarm._write(self.i, setpoint)
        self.swarm.priority[self.i] = PRIORITY_CRTP
        self.swarm.hl[self.i].stop()

    def send_position(self, x: float, y: float, z: float, yaw_deg: float = 0.0) -> None:
        self.send_setpoint(ControlSetpoint.position(x, y, z, yaw_deg))

    def notify_setpoint_stop(self) -> None:
        s = self.swarm.state[:, self.i]
        self.swarm.hl[self.i].tell_state(
            (float(s[0]), float(s[1]), float(s[2])), (float(s[3]), float(s[4]), float(s[5])), math.radians(float(s[8]))
        )
        self.swarm.priority[self.i] = PRIORITY_HIGH_LEVEL

    def _hl(self, command: int, body: bytes) -> int:
        answer = self.swarm.hl[self.i].handle(bytes([command]) + body, self.swarm.time_s)
        return answer[3] if len(answer) > 3 else 0

    def takeoff(self, height_m: float, duration_s: float, yaw_deg: float = 0.0) -> int:
        return self._hl(COMMAND_TAKEOFF_2, struct.pack("<Bff?f", 0, height_m, math.radians(yaw_deg), False, duration_s))

    def land(self, height_m: float, duration_s: float, yaw_deg: float = 0.0) -> int:
        return self._hl(COMMAND_LAND_2, struct.pack("<Bff?f", 0, height_m, math.radians(yaw_deg), False, duration_s))

    def go_to(
        self,
        x: float,
        y: float,
        z: float,
        duration_s: float,
        yaw_deg: float = 0.0,
        *,
        relative: bool = False,
        linear: bool = False,
    ) -> int:
        return self._hl(
            COMMAND_GO_TO_2, struct.pack("<BBBfffff", 0, relative, linear, x, y, z, math.radians(yaw_deg), duration_s)
        )

    def stop(self) -> int:
        return self._hl(COMMAND_STOP, bytes([0]))

    def plan_position(self, t_s: float) -> tuple[float, float, float] | None:
        trajectory = self.swarm.hl[self.i].trajectory
        evaluated = trajectory.evaluate(t_s) if trajectory is not None else None
        return None if evaluated is None else evaluated[0]

    @property
    def position(self) -> tuple[float, float, float]:
        p = self.swarm.pos[:, self.i]
        return (float(p[0]), float(p[1]), float(p[2]))

    @property
    def velocity(self) -> tuple[float, float, float]:
        v = self.swarm.vel[:, self.i]
        return (float(v[0]), float(v[1]), float(v[2]))

    @property
    def quaternion(self) -> tuple[float, float, float, float]:
        q = self.swarm.quat[:, self.i]
        return (float(q[0]), float(q[1]), float(q[2]), float(q[3]))

    @property
    def tilt_deg(self) -> float:
        qx, qy = self.swarm.quat[0, self.i], self.swarm.quat[1, self.i]
        return math.degrees(math.acos(min(1.0, max(-1.0, 1.0 - 2.0 * (qx * qx + qy * qy)))))

    @property
    def motor_commands(self) -> tuple[int, int, int, int]:
        m = self.swarm.motor_commands[:, self.i]
        return (int(m[0]), int(m[1]), int(m[2]), int(m[3]))

    @property
    def motors_on(self) -> bool:
        return bool(np.any(self.swarm.motor_commands[:, self.i] / UINT16_MAX * THRUST_MAX_N >= THRUST_MIN_N))

    @property
    def flying(self) -> bool:
        return self.swarm.hl[self.i].state in (PlanState.FLYING, PlanState.LANDING)

    @property
    def external_force(self) -> tuple[float, float, float]:
        f = self.swarm.external_force[:, self.i]
        return (float(f[0]), float(f[1]), float(f[2]))

    @external_force.setter
    def external_force(self, force: tuple[float, float, float]) -> None:
        self.swarm.external_force[:, self.i] = force

    def params(self) -> dict[str, float]:
        return self.swarm.gains[self.i].params()

    def set_param(self, name: str, value: float) -> None:
        self.swarm.set_param(self.i, name, value)
