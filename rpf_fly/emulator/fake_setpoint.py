"""Commander setpoints of the fake Crazyflie and the decoding of CRTP setpoint packets (ports 3 and 7).

A `Setpoint` is a reduced `setpoint_t`: per axis absolute position, velocity or disabled; yaw absolute (degrees) or
rate (degrees/s); and a thrust flag for the attitude-only modes. A null setpoint (everything disabled, no thrust)
means motors off, as in the firmware.

Decoded generic setpoint types (port 7, channel 0; cflib `Commander`): stop (0), velocity world (1 legacy, 8),
z-distance (2 legacy, 9), alt-hold (4), hover (5 legacy, 10), full state (6), position (7), manual (11). Legacy
RPYT (port 3, ``<fffH`` roll, pitch, yaw rate, thrust): thrust 0 is a null setpoint (motors off, as cflib's
`close_link` sends it), any other thrust is modelled as "hold altitude, level attitude".
Attitude (roll/pitch) commands are not simulated: they are modelled as a level attitude.
"""

from __future__ import annotations

import enum
import math
import struct
from dataclasses import dataclass

from cflib.utils.encoding import decompress_quaternion

Vec3 = tuple[float, float, float]


class AxisMode(enum.Enum):
    """How one axis is controlled."""

    DISABLE = 0
    ABS = 1
    """Absolute position."""
    VELOCITY = 2


@dataclass(frozen=True)
class Setpoint:
    """What the controller should do. Positions in metres, velocities in m/s, yaw in degrees (rate in deg/s)."""

    modes: tuple[AxisMode, AxisMode, AxisMode]
    position: Vec3 = (0.0, 0.0, 0.0)
    velocity: Vec3 = (0.0, 0.0, 0.0)
    yaw_mode: AxisMode = AxisMode.DISABLE
    yaw_deg: float = 0.0
    yaw_rate_deg_s: float = 0.0
    thrust: bool = False
    """Attitude-only modes with thrust above zero (RPYT, manual)."""
    timestamp_s: float = 0.0
    source: str = ""

    @property
    def commands_thrust(self) -> bool:
        """True when the controller produces thrust: z is controlled or an attitude mode asks for thrust."""
        return self.modes[2] is not AxisMode.DISABLE or self.thrust

    @property
    def is_null(self) -> bool:
        """True for the motors-off setpoint."""
        return (
            all(mode is AxisMode.DISABLE for mode in self.modes)
            and self.yaw_mode is AxisMode.DISABLE
            and not self.thrust
        )


def null_setpoint(timestamp_s: float = 0.0, source: str = "null") -> Setpoint:
    """The motors-off setpoint."""
    modes = (AxisMode.DISABLE, AxisMode.DISABLE, AxisMode.DISABLE)
    return Setpoint(modes=modes, timestamp_s=timestamp_s, source=source)


def wrap_angle(angle_rad: float) -> float:
    """Wrap to (-pi, pi]."""
    wrapped = math.remainder(angle_rad, 2.0 * math.pi)
    return math.pi if wrapped == -math.pi else wrapped


def yaw_from_quaternion(qx: float, qy: float, qz: float, qw: float) -> float:
    """Yaw (rad) of a quaternion (Z-Y-X Euler angles)."""
    return math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))


TYPE_STOP = 0
TYPE_VELOCITY_WORLD_LEGACY = 1
TYPE_ZDISTANCE_LEGACY = 2
TYPE_CPPM_EMU = 3
TYPE_ALTHOLD = 4
TYPE_HOVER_LEGACY = 5
TYPE_FULL_STATE = 6
TYPE_POSITION = 7
TYPE_VELOCITY_WORLD = 8
TYPE_ZDISTANCE = 9
TYPE_HOVER = 10
TYPE_MANUAL = 11

_ABS3 = (AxisMode.ABS, AxisMode.ABS, AxisMode.ABS)
_VEL3 = (AxisMode.VELOCITY, AxisMode.VELOCITY, AxisMode.VELOCITY)
_HOLD_Z = (AxisMode.DISABLE, AxisMode.DISABLE, AxisMode.ABS)


def decode_generic(data: bytes, now_s: float, yaw_rad: float) -> Setpoint | None:
    """Decode a port-7 channel-0 packet; None for an unknown type (ignored, as the firmware does).

    `yaw_rad` is the current yaw estimate, used to rotate body-frame hover velocities into the world frame."""
    if not data:
        return None
    kind, body = data[0], bytes(data[1:])
    src = f"crtp-{kind}"
    if kind == TYPE_STOP:
        return null_setpoint(now_s, src)
    if kind == TYPE_POSITION:
        x, y, z, yaw = struct.unpack("<ffff", body[:16])
        return Setpoint(_ABS3, (x, y, z), yaw_mode=AxisMode.ABS, yaw_deg=yaw, timestamp_s=now_s, source=src)
    if kind in (TYPE_VELOCITY_WORLD, TYPE_VELOCITY_WORLD_LEGACY):
        vx, vy, vz, yaw_rate = struct.unpack("<ffff", body[:16])
        yaw_rate = -yaw_rate if kind == TYPE_VELOCITY_WORLD_LEGACY else yaw_rate
        return Setpoint(
            _VEL3, velocity=(vx, vy, vz), yaw_mode=AxisMode.VELOCITY, yaw_rate_deg_s=yaw_rate, timestamp_s=now_s,
            source=src,
        )
    if kind in (TYPE_HOVER, TYPE_HOVER_LEGACY):
        vx, vy, yaw_rate, z = struct.unpack("<ffff", body[:16])
        yaw_rate = -yaw_rate if kind == TYPE_HOVER_LEGACY else yaw_rate
        c, s = math.cos(yaw_rad), math.sin(yaw_rad)
        world_velocity = (c * vx - s * vy, s * vx + c * vy, 0.0)
        return Setpoint(
            (AxisMode.VELOCITY, AxisMode.VELOCITY, AxisMode.ABS), (0.0, 0.0, z), world_velocity,
            yaw_mode=AxisMode.VELOCITY, yaw_rate_deg_s=yaw_rate, timestamp_s=now_s, source=src,
        )
    if kind in (TYPE_ZDISTANCE, TYPE_ZDISTANCE_LEGACY):
        _roll, _pitch, yaw_rate, z = struct.unpack("<ffff", body[:16])
        yaw_rate = -yaw_rate if kind == TYPE_ZDISTANCE_LEGACY else yaw_rate
        return Setpoint(
            _HOLD_Z, (0.0, 0.0, z), yaw_mode=AxisMode.VELOCITY, yaw_rate_deg_s=yaw_rate, timestamp_s=now_s, source=src
        )
    if kind == TYPE_ALTHOLD:
        _roll, _pitch, yaw_rate, vz = struct.unpack("<ffff", body[:16])
        return Setpoint(
            (AxisMode.DISABLE, AxisMode.DISABLE, AxisMode.VELOCITY), velocity=(0.0, 0.0, vz),
            yaw_mode=AxisMode.VELOCITY, yaw_rate_deg_s=yaw_rate, timestamp_s=now_s, source=src,
        )
    if kind == TYPE_FULL_STATE:
        values = struct.unpack("<hhhhhhhhhIhhh", body[:28])
        pos = tuple(v / 1000.0 for v in values[0:3])
        vel = tuple(v / 1000.0 for v in values[3:6])
        qx, qy, qz, qw = (float(q) for q in decompress_quaternion(values[9]))
        yaw_deg = math.degrees(yaw_from_quaternion(qx, qy, qz, qw))
        return Setpoint(
            _ABS3, pos, vel, yaw_mode=AxisMode.ABS, yaw_deg=yaw_deg, timestamp_s=now_s, source=src,  # type: ignore[arg-type]
        )
    if kind == TYPE_MANUAL:
        _roll, _pitch, yaw_rate, thrust, _rate = struct.unpack("<fffHB", body[:15])
        return _attitude_setpoint(thrust, yaw_rate, now_s, src)
    if kind == TYPE_CPPM_EMU:
        return _attitude_setpoint(1, 0.0, now_s, src)
    return None


def decode_rpyt(data: bytes, now_s: float) -> Setpoint | None:
    """Decode a legacy port-3 RPYT packet ``<fffH`` (roll, pitch deg; yaw rate deg/s; thrust 0-65535)."""
    if len(data) < 14:
        return None
    _roll, _pitch, yaw_rate, thrust = struct.unpack("<fffH", bytes(data[:14]))
    return _attitude_setpoint(thrust, yaw_rate, now_s, "crtp-rpyt")


def _attitude_setpoint(thrust: int, yaw_rate: float, now_s: float, source: str) -> Setpoint:
    if thrust == 0:
        return null_setpoint(now_s, source)
    modes = (AxisMode.DISABLE, AxisMode.DISABLE, AxisMode.DISABLE)
    return Setpoint(modes, yaw_mode=AxisMode.VELOCITY, yaw_rate_deg_s=yaw_rate, thrust=True, timestamp_s=now_s,
                    source=source)
