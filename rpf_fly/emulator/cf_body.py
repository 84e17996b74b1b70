"""The rigid body of a Crazyflie 2.x with the 2.1+ propellers: drone-models 0.1.0's first-principles model with its
`cf2x_P250` parameters (`drone_models/data/params.toml:41-78`, `drone_models/first_principles/model.py:31-155`).

- Mass 31.8 g, gravity 9.81 m/s^2; L 0.03253 m, each rotor's moment arm about the body x and y axes; inertia
  diag(16.8, 16.8, 29.8) x 1e-6 kg m^2; propeller inertia 26.97e-9 kg m^2.
- Rotor i (speed w in RPM): thrust a1 w + a2 w^2 N (a1 = -3.6200e-7, a2 = 1.6061e-10) along the body z axis; drag
  torque b1 w + b2 w^2 N m (b1 = -2.2665e-9, b2 = 1.1149e-12).
- Torques: x = L (-f1 - f2 + f3 + f4), y = L (-f1 + f2 + f3 - f4), z = -q1 + q2 - q3 + q4 (the mixing matrix's
  rows (-1, -1, 1, 1), (-1, 1, 1, -1), (-1, 1, -1, 1)); rotor 1 front right, 2 back right, 3 back left, 4 front
  left, as the firmware numbers its motors. The propellers' gyroscopic terms as the package has them:
  Jp x (-wy S, -wx S, dS/dt) with S = sum of (-1, 1, -1, 1) x rotor speeds in rad/s.
- Linear drag diag(-0.01351, -0.01351, -0.01677) N s/m in the body frame (force = R D R^T v).
- Rotor dynamics: the speed w chases its command c at k0 (c - w) + k1 (c^2 - w^2) RPM/s while c > w and at
  k2 (c - w) + k3 (c^2 - w^2) otherwise, (k0, k1, k2, k3) = (5.1726, 8.1477e-5, 0, 2.0953e-4): about 0.11 s up and
  0.10 s down near hover (23 200 RPM).
- A motor's commanded speed is the inverse of the thrust curve at the thrust the firmware asks of it (cf_controller:
  command / 65535 x 0.12 N, 0 when off).
- Newton-Euler: v' = (R (0, 0, sum f) + R D R^T v + f_ext) / m - g z; w' = J^-1 (tau - w x J w); the orientation
  (quaternion x, y, z, w, body to world) is integrated from the body rates (not from the package's quaternion
  derivative, wrong for its own xyzw quaternions).
- The floor is z = 0 (or the body's `floor_z`): no penetration, no sliding. A body that would go below it rests on
  it: z on the floor, no velocity, no rotation, until the thrust lifts it.

Integration: `step(dt)` advances by dt with the rotor commands held. "midpoint" (the default) is a second-order
step with one evaluation of the forces: the rotors by Heun's rule, then the accelerations at the rotors' mean speed
and the orientation half a step on, then velocity and rates, and position and orientation with the mean of the old
and new velocity and rates. "rk4" is the classic Runge-Kutta step, what the reference integrates with at 1 kHz, at
four evaluations. At 1 kHz the two fly a 0.5 m step within 0.05 mm and 0.01 deg of each other
(tests/emulator/test_cf_controller.py).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

RPM_TO_RAD_S = 2.0 * math.pi / 60.0


@dataclass(frozen=True)
class CfBodyParams:
    """drone-models 0.1.0 `cf2x_P250` (`params.toml:41-78`)."""

    mass: float = 0.0318
    gravity: float = 9.81
    arm: float = 0.03253
    jxx: float = 16.8e-6
    jyy: float = 16.8e-6
    jzz: float = 29.8e-6
    prop_inertia: float = 26.97e-9
    thrust_a1: float = -3.6200e-7
    thrust_a2: float = 1.6061e-10
    torque_b1: float = -2.2665e-9
    torque_b2: float = 1.1149e-12
    drag_xy: float = -0.01351
    drag_z: float = -0.01677
    rotor_up_k0: float = 5.1726
    rotor_up_k1: float = 8.1477e-5
    rotor_down_k2: float = 0.0
    rotor_down_k3: float = 2.0953e-4

    def rpm_for_thrust(self, thrust_n: float) -> float:
        """The rotor speed (RPM) that makes `thrust_n` (the thrust curve's positive root); 0 for no thrust."""
        if thrust_n <= 0.0:
            return 0.0
        a1, a2 = self.thrust_a1, self.thrust_a2
        return (-a1 + math.sqrt(a1 * a1 + 4.0 * a2 * thrust_n)) / (2.0 * a2)

    def thrust_of_rpm(self, rpm: float) -> float:
        return self.thrust_a1 * rpm + self.thrust_a2 * rpm * rpm

    @property
    def hover_thrust_n(self) -> float:
        """Each rotor's share of the weight."""
        return self.mass * self.gravity / 4.0

    @property
    def hover_rpm(self) -> float:
        return self.rpm_for_thrust(self.hover_thrust_n)


P250 = CfBodyParams()


def rotation_matrix(qx: float, qy: float, qz: float, qw: float) -> tuple[float, ...]:
    """Body-to-world rotation matrix, row-major 3x3, of a unit quaternion (x, y, z, w)."""
    xx, yy, zz = qx * qx, qy * qy, qz * qz
    xy, xz, yz = qx * qy, qx * qz, qy * qz
    wx, wy, wz = qw * qx, qw * qy, qw * qz
    return (
        1.0 - 2.0 * (yy + zz),
        2.0 * (xy - wz),
        2.0 * (xz + wy),
        2.0 * (xy + wz),
        1.0 - 2.0 * (xx + zz),
        2.0 * (yz - wx),
        2.0 * (xz - wy),
        2.0 * (yz + wx),
        1.0 - 2.0 * (xx + yy),
    )


def quaternion_to_rpy_deg(qx: float, qy: float, qz: float, qw: float) -> tuple[float, float, float]:
    """Roll, pitch, yaw (deg, Z-Y-X, right-handed) as the Kalman filter converts its quaternion
    (`kalman_core.c:800-802`)."""
    roll = math.atan2(2.0 * (qy * qz + qw * qx), qw * qw - qx * qx - qy * qy + qz * qz)
    s = -2.0 * (qx * qz - qw * qy)
    pitch = math.asin(1.0 if s > 1.0 else (-1.0 if s < -1.0 else s))
    yaw = math.atan2(2.0 * (qx * qy + qw * qz), qw * qw + qx * qx - qy * qy - qz * qz)
    return math.degrees(roll), math.degrees(pitch), math.degrees(yaw)


def _rotated(q: list[float], ax: float, ay: float, az: float) -> list[float]:
    """q (x) exp(a / 2): `q` turned by the body-frame rotation vector (ax, ay, az) rad."""
    angle2 = ax * ax + ay * ay + az * az
    if angle2 < 1e-24:
        return list(q)
    angle = math.sqrt(angle2)
    s = math.sin(0.5 * angle) / angle
    dx, dy, dz, dw = ax * s, ay * s, az * s, math.cos(0.5 * angle)
    qx, qy, qz, qw = q
    return [
        qw * dx + qx * dw + qy * dz - qz * dy,
        qw * dy - qx * dz + qy * dw + qz * dx,
        qw * dz + qx * dy - qy * dx + qz * dw,
        qw * dw - qx * dx - qy * dy - qz * dz,
    ]


class CfBody:
    """One Crazyflie's rigid body and rotors (module doc). State: `pos`, `vel` (world, m, m/s), `quat` (x, y, z, w,
    body to world), `omega` (body rates, rad/s), `rotor_rpm` (4); `rotor_cmd_rpm` is held between `step` calls
    (set it with `command_thrusts`). `external_force` (world frame, N) acts on the centre of mass while it is set
    (a gust)."""

    __slots__ = (
        "params",
        "pos",
        "vel",
        "quat",
        "omega",
        "rotor_rpm",
        "rotor_cmd_rpm",
        "external_force",
        "floor_z",
        "integrator",
        "on_floor",
    )

    def __init__(
        self,
        position: Sequence[float] = (0.0, 0.0, 0.0),
        yaw_rad: float = 0.0,
        *,
        params: CfBodyParams = P250,
        integrator: str = "midpoint",
        floor_z: float = 0.0,
    ) -> None:
        if integrator not in ("midpoint", "rk4"):
            raise ValueError(f"integrator must be 'midpoint' or 'rk4', not {integrator!r}")
        self.params = params
        self.pos = [float(position[0]), float(position[1]), float(position[2])]
        self.vel = [0.0, 0.0, 0.0]
        self.quat = [0.0, 0.0, math.sin(yaw_rad / 2.0), math.cos(yaw_rad / 2.0)]
        self.omega = [0.0, 0.0, 0.0]
        self.rotor_rpm = [0.0, 0.0, 0.0, 0.0]
        self.rotor_cmd_rpm = [0.0, 0.0, 0.0, 0.0]
        self.external_force = (0.0, 0.0, 0.0)
        self.floor_z = floor_z
        self.integrator = integrator
        self.on_floor = self.pos[2] <= floor_z

    def command_thrusts(self, thrusts_n: tuple[float, float, float, float] | list[float]) -> None:
        """Each rotor's commanded thrust (N): its commanded speed through the inverse thrust curve."""
        rpm = self.params.rpm_for_thrust
        self.rotor_cmd_rpm = [rpm(thrusts_n[0]), rpm(thrusts_n[1]), rpm(thrusts_n[2]), rpm(thrusts_n[3])]

    def spin_at(self, thrust_n: float) -> None:
        """Rotors spinning steadily at, and commanded to, `thrust_n` each (a hovering drone)."""
        rpm = self.params.rpm_for_thrust(thrust_n)
        self.rotor_rpm = [rpm] * 4
        self.rotor_cmd_rpm = [rpm] * 4

    @property
    def tilt_deg(self) -> float:
        """Angle between the body z axis and the vertical."""
        qx, qy = self.quat[0], self.quat[1]
        c = 1.0 - 2.0 * (qx * qx + qy * qy)
        return math.degrees(math.acos(1.0 if c > 1.0 else (-1.0 if c < -1.0 else c)))

    def rpy_deg(self) -> tuple[float, float, float]:
        return quaternion_to_rpy_deg(*self.quat)

    # Dynamics ---------------------------------------------------------------------------------------------------

    def _rotor_dot(self, w: list[float]) -> list[float]:
        p = self.params
        out = []
        for c, r in zip(self.rotor_cmd_rpm, w):
            if c > r:
                out.append(p.rotor_up_k0 * (c - r) + p.rotor_up_k1 * (c * c - r * r))
            else:
                out.append(p.rotor_down_k2 * (c - r) + p.rotor_down_k3 * (c * c - r * r))
        return out

    def _accelerations(
        self, vel: list[float], quat: list[float], omega: list[float], w: list[float], w_dot: list[float]
    ) -> tuple[float, float, float, float, float, float]:
        """Linear acceleration (world) and angular acceleration (body) at one state."""
        p = self.params
        a1, a2, b1, b2 = p.thrust_a1, p.thrust_a2, p.torque_b1, p.torque_b2
        f1 = a1 * w[0] + a2 * w[0] * w[0]
        f2 = a1 * w[1] + a2 * w[1] * w[1]
        f3 = a1 * w[2] + a2 * w[2] * w[2]
        f4 = a1 * w[3] + a2 * w[3] * w[3]
        q1 = b1 * w[0] + b2 * w[0] * w[0]
        q2 = b1 * w[1] + b2 * w[1] * w[1]
        q3 = b1 * w[2] + b2 * w[2] * w[2]
        q4 = b1 * w[3] + b2 * w[3] * w[3]
        thrust = f1 + f2 + f3 + f4
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = rotation_matrix(quat[0], quat[1], quat[2], quat[3])
        vx, vy, vz = vel
        # drag in the body frame: D R^T v, then back to the world
        bx = p.drag_xy * (r00 * vx + r10 * vy + r20 * vz)
        by = p.drag_xy * (r01 * vx + r11 * vy + r21 * vz)
        bz = p.drag_z * (r02 * vx + r12 * vy + r22 * vz)
        fx = r02 * thrust + r00 * bx + r01 * by + r02 * bz + self.external_force[0]
        fy = r12 * thrust + r10 * bx + r11 * by + r12 * bz + self.external_force[1]
        fz = r22 * thrust + r20 * bx + r21 * by + r22 * bz + self.external_force[2]
        m = p.mass
        L = p.arm
        ox, oy, oz = omega
        spin = RPM_TO_RAD_S * (-w[0] + w[1] - w[2] + w[3])
        spin_dot = RPM_TO_RAD_S * (-w_dot[0] + w_dot[1] - w_dot[2] + w_dot[3])
        jp = p.prop_inertia
        tx = L * (-f1 - f2 + f3 + f4) - jp * oy * spin
        ty = L * (-f1 + f2 + f3 - f4) - jp * ox * spin
        tz = (-q1 + q2 - q3 + q4) + jp * spin_dot
        jx, jy, jz = p.jxx, p.jyy, p.jzz
        return (
            fx / m,
            fy / m,
            fz / m - p.gravity,
            (tx - (jz - jy) * oy * oz) / jx,
            (ty - (jx - jz) * oz * ox) / jy,
            (tz - (jy - jx) * ox * oy) / jz,
        )

    @staticmethod
    def _quat_dot(q: list[float], o: list[float]) -> list[float]:
        qx, qy, qz, qw = q
        ox, oy, oz = o
        return [
            0.5 * (qw * ox + qy * oz - qz * oy),
            0.5 * (qw * oy + qz * ox - qx * oz),
            0.5 * (qw * oz + qx * oy - qy * ox),
            -0.5 * (qx * ox + qy * oy + qz * oz),
        ]

    def step(self, dt: float) -> None:
        """Advance by `dt` seconds with the rotor commands held."""
        if self.integrator == "rk4":
            self._step_rk4(dt)
        else:
            self._step_midpoint(dt)
        self._floor()

    def _step_midpoint(self, dt: float) -> None:
        """The default step (module doc): rotors by Heun's rule, then the accelerations once, at the rotors' mean
        speed and the orientation half a step on, and velocity, rates, position and orientation from them (the
        position and orientation with the mean of the old and new velocity and rates)."""
        w, cmd, p = self.rotor_rpm, self.rotor_cmd_rpm, self.params
        up0, up1, down0, down1 = p.rotor_up_k0, p.rotor_up_k1, p.rotor_down_k2, p.rotor_down_k3
        w_mid = [0.0] * 4
        wd_mid = [0.0] * 4
        w_new = [0.0] * 4
        for i in range(4):
            c, r = cmd[i], w[i]
            d0 = up0 * (c - r) + up1 * (c * c - r * r) if c > r else down0 * (c - r) + down1 * (c * c - r * r)
            r1 = r + d0 * dt
            r1 = r1 if r1 > 0.0 else 0.0
            d1 = up0 * (c - r1) + up1 * (c * c - r1 * r1) if c > r1 else down0 * (c - r1) + down1 * (c * c - r1 * r1)
            dm = 0.5 * (d0 + d1)
            r1 = r + dm * dt
            r1 = r1 if r1 > 0.0 else 0.0
            w_new[i] = r1
            w_mid[i] = 0.5 * (r + r1)
            wd_mid[i] = dm
        o, v, pos = self.omega, self.vel, self.pos
        q_mid = _rotated(self.quat, 0.5 * dt * o[0], 0.5 * dt * o[1], 0.5 * dt * o[2])
        ax, ay, az, dox, doy, doz = self._accelerations(v, q_mid, o, w_mid, wd_mid)
        ox, oy, oz = o
        o1 = [ox + dox * dt, oy + doy * dt, oz + doz * dt]
        vx, vy, vz = v
        v1 = [vx + ax * dt, vy + ay * dt, vz + az * dt]
        self.pos = [
            pos[0] + 0.5 * (vx + v1[0]) * dt,
            pos[1] + 0.5 * (vy + v1[1]) * dt,
            pos[2] + 0.5 * (vz + v1[2]) * dt,
        ]
        self.quat = _rotated(self.quat, 0.5 * (ox + o1[0]) * dt, 0.5 * (oy + o1[1]) * dt, 0.5 * (oz + o1[2]) * dt)
        self.vel = v1
        self.omega = o1
        self.rotor_rpm = w_new

    def _derivative(
        self, vel: list[float], quat: list[float], omega: list[float], w: list[float]
    ) -> tuple[list[float], list[float], list[float], list[float], list[float]]:
        w_dot = self._rotor_dot(w)
        ax, ay, az, dox, doy, doz = self._accelerations(vel, quat, omega, w, w_dot)
        return list(vel), [ax, ay, az], self._quat_dot(quat, omega), [dox, doy, doz], w_dot

    def _step_rk4(self, dt: float) -> None:
        pos, vel, quat, omega, w = self.pos, self.vel, self.quat, self.omega, self.rotor_rpm

        def add(a: list[float], b: list[float], h: float) -> list[float]:
            return [x + h * y for x, y in zip(a, b)]

        k1 = self._derivative(vel, quat, omega, w)
        k2 = self._derivative(
            add(vel, k1[1], dt / 2), add(quat, k1[2], dt / 2), add(omega, k1[3], dt / 2), add(w, k1[4], dt / 2)
        )
        k3 = self._derivative(
            add(vel, k2[1], dt / 2), add(quat, k2[2], dt / 2), add(omega, k2[3], dt / 2), add(w, k2[4], dt / 2)
        )
        k4 = self._derivative(add(vel, k3[1], dt), add(quat, k3[2], dt), add(omega, k3[3], dt), add(w, k3[4], dt))

        def combine(x: list[float], i: int) -> list[float]:
            return [x[j] + dt / 6.0 * (k1[i][j] + 2.0 * k2[i][j] + 2.0 * k3[i][j] + k4[i][j]) for j in range(len(x))]

        self.pos = combine(pos, 0)
        self.vel = combine(vel, 1)
        q = combine(quat, 2)
        n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
        self.quat = [c / n for c in q]
        self.omega = combine(omega, 3)
        self.rotor_rpm = [max(r, 0.0) for r in combine(w, 4)]

    def _floor(self) -> None:
        pos = self.pos
        if pos[2] < self.floor_z or (self.on_floor and pos[2] <= self.floor_z):
            pos[2] = self.floor_z
            self.vel = [0.0, 0.0, 0.0]
            self.omega = [0.0, 0.0, 0.0]
            self.on_floor = True
        else:
            self.on_floor = False
