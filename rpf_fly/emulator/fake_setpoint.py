"""Commander setpoints of the fake Crazyflie and the decoding of CRTP setpoint packets (ports 3 and 7).

A `Setpoint` is a reduced `setpoint_t`: per axis absolute position, velocity or disabled; yaw absolute (degrees) or
rate (degrees/s); roll and pitch absolute (degrees) or rates (degrees/s) where the horizontal axes are not
controlled; and the firmware's integer thrust (0-60000) where the height is not controlled. A null setpoint
(everything disabled, no thrust) means motors off, as in the firmware.

Decoded generic setpoint types (port 7, channel 0; cflib `Commander`): stop (0), velocity world (1 legacy, 8),
z-distance (2 legacy, 9), CPPM emulation (3), alt-hold (4), hover (5 legacy, 10), full state (6), position (7),
manual (11). Legacy RPYT (port 3, ``<fffH`` roll, pitch, yaw rate, thrust), as `crtp_commander_rpyt.c` decodes it:
its thrust is LOCKED at power-on until a packet with thrust 0 arrives (cflib programs send one first: "unlock
startup thrust protection"); locked, or under `RPYT_MIN_THRUST` (1000), it is 0; above `RPYT_MAX_THRUST` (60000) it
is clipped; roll and pitch are angles (the firmware's default `flightmode.stabModeRoll/Pitch`), the yaw a rate.

Roll and pitch are in the firmware's own (legacy) convention, as the packets carry them: a POSITIVE pitch tilts
the nose UP and accelerates the drone BACKWARDS (-x of its body), a positive roll accelerates it to its right (-y).
cflib's `send_setpoint` and `send_setpoint_manual` negate the pitch they are given (so a positive pitch there flies
forwards); `send_zdistance_setpoint` does not (a positive pitch there flies backwards). Facts from
crazyflie-firmware (`crtp_commander_rpyt.c`, `crtp_commander_generic.c`, `position_controller_pid.c`: the position
controller asks for a negative pitch to accelerate along +x) and cflib's `commander.py`; the emulator's dynamics of
these modes are in `fake_vehicle.py` ("Attitude modes").
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
    thrust: int = 0
    """The firmware's integer thrust (0-65535, `setpoint.thrust`) of the modes that do not control the height
    (RPYT, manual, CPPM); 0 elsewhere."""
    attitude_mode: AxisMode = AxisMode.DISABLE
    """Roll and pitch: ABS (`attitude_deg` are angles), VELOCITY (they are rates, deg/s) or DISABLE (the
    horizontal axes' controller sets the attitude, or nothing is asked: level)."""
    attitude_deg: tuple[float, float] = (0.0, 0.0)
    """Roll, pitch in the firmware's legacy convention (module doc): degrees, or degrees/s for rates."""
    timestamp_s: float = 0.0
    source: str = ""

    @property
    def commands_thrust(self) -> bool:
        """True when the controller produces thrust: z is controlled, or an attitude mode's thrust spins the
        motors (below `MOTOR_MIN_THRUST` the firmware gives them nothing)."""
        return self.modes[2] is not AxisMode.DISABLE or self.thrust >= MOTOR_MIN_THRUST

    @property
    def is_null(self) -> bool:
        """True for the motors-off setpoint."""
        return (
            all(mode is AxisMode.DISABLE for mode in self.modes)
            and self.yaw_mode is AxisMode.DISABLE
            and not self.thrust
            and self.attitude_mode is AxisMode.DISABLE
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


RPYT_MIN_THRUST = 1000
"""`crtp_commander_rpyt.c` MIN_THRUST: an RPYT thrust under this is 0."""
RPYT_MAX_THRUST = 60000
"""`crtp_commander_rpyt.c` MAX_THRUST: an RPYT thrust above this is clipped to it."""
MOTOR_MIN_THRUST = 7000
"""The integer thrust under which a Crazyflie 2.1's motors give nothing: the firmware's battery compensation maps
thrust / 65535 x `THRUST_MAX` (0.12 N a motor) and returns 0 under `THRUST_MIN` (0.0128 N a motor:
platform_defaults_cf2.h), i.e. under an integer thrust of about 7000."""

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
            _VEL3,
            velocity=(vx, vy, vz),
            yaw_mode=AxisMode.VELOCITY,
            yaw_rate_deg_s=yaw_rate,
            timestamp_s=now_s,
            source=src,
        )
    if kind in (TYPE_HOVER, TYPE_HOVER_LEGACY):
        vx, vy, yaw_rate, z = struct.unpack("<ffff", body[:16])
        yaw_rate = -yaw_rate if kind == TYPE_HOVER_LEGACY else yaw_rate
        c, s = math.cos(yaw_rad), math.sin(yaw_rad)
        world_velocity = (c * vx - s * vy, s * vx + c * vy, 0.0)
        return Setpoint(
            (AxisMode.VELOCITY, AxisMode.VELOCITY, AxisMode.ABS),
            (0.0, 0.0, z),
            world_velocity,
            yaw_mode=AxisMode.VELOCITY,
            yaw_rate_deg_s=yaw_rate,
            timestamp_s=now_s,
            source=src,
        )
    if kind in (TYPE_ZDISTANCE, TYPE_ZDISTANCE_LEGACY):
        roll, pitch, yaw_rate, z = struct.unpack("<ffff", body[:16])
        yaw_rate = -yaw_rate if kind == TYPE_ZDISTANCE_LEGACY else yaw_rate
        return Setpoint(
            _HOLD_Z,
            (0.0, 0.0, z),
            yaw_mode=AxisMode.VELOCITY,
            yaw_rate_deg_s=yaw_rate,
            attitude_mode=AxisMode.ABS,
            attitude_deg=(roll, pitch),
            timestamp_s=now_s,
            source=src,
        )
    if kind == TYPE_ALTHOLD:
        roll, pitch, yaw_rate, vz = struct.unpack("<ffff", body[:16])
        return Setpoint(
            (AxisMode.DISABLE, AxisMode.DISABLE, AxisMode.VELOCITY),
            velocity=(0.0, 0.0, vz),
            yaw_mode=AxisMode.VELOCITY,
            yaw_rate_deg_s=yaw_rate,
            attitude_mode=AxisMode.ABS,
            attitude_deg=(roll, pitch),
            timestamp_s=now_s,
            source=src,
        )
    if kind == TYPE_FULL_STATE:
        values = struct.unpack("<hhhhhhhhhIhhh", body[:28])
        pos = tuple(v / 1000.0 for v in values[0:3])
        vel = tuple(v / 1000.0 for v in values[3:6])
        qx, qy, qz, qw = (float(q) for q in decompress_quaternion(values[9]))
        yaw_deg = math.degrees(yaw_from_quaternion(qx, qy, qz, qw))
        return Setpoint(
            _ABS3,
            pos,
            vel,
            yaw_mode=AxisMode.ABS,
            yaw_deg=yaw_deg,
            timestamp_s=now_s,
            source=src,
        )
    if kind == TYPE_MANUAL:
        roll, pitch, yaw_rate, thrust, rate = struct.unpack("<fffHB", body[:15])
        mode = AxisMode.VELOCITY if rate else AxisMode.ABS
        return _attitude_setpoint(roll, pitch, yaw_rate, thrust, mode, now_s, src)
    if kind == TYPE_CPPM_EMU:
        return _decode_cppm(body, now_s, src)
    return None


def decode_rpyt(data: bytes, now_s: float, thrust_locked: bool) -> tuple[Setpoint | None, bool]:
    """Decode a legacy port-3 RPYT packet ``<fffH`` (roll, pitch deg; yaw rate deg/s; thrust 0-65535) as
    `crtp_commander_rpyt.c` does; returns the setpoint and whether the thrust is locked after it (module doc)."""
    if len(data) < 14:
        return None, thrust_locked
    roll, pitch, yaw_rate, raw = struct.unpack("<fffH", bytes(data[:14]))
    if raw == 0:
        thrust_locked = False
    thrust = 0 if thrust_locked or raw < RPYT_MIN_THRUST else min(raw, RPYT_MAX_THRUST)
    return _attitude_setpoint(roll, pitch, yaw_rate, thrust, AxisMode.ABS, now_s, "crtp-rpyt"), thrust_locked


CPPM_MAX_ANGLE_DEG = 50.0
CPPM_MAX_RATE_DEG_S = 720.0
CPPM_MAX_YAW_RATE_DEG_S = 400.0


def _decode_cppm(body: bytes, now_s: float, source: str) -> Setpoint | None:
    """CPPM emulation (type 3): channels of 1000-2000 (midpoint 1500), roll, pitch and yaw inverted; self-levelling
    unless aux channel 0 is given and under 1500 (`crtp_commander_generic.c`, its default scales)."""
    if len(body) < 9:
        return None
    aux_count = body[0] & 0x0F
    ch_roll, ch_pitch, ch_yaw, ch_thrust = struct.unpack("<HHHH", body[1:9])
    aux0 = struct.unpack("<H", body[9:11])[0] if aux_count >= 1 and len(body) >= 11 else None
    level = aux0 is None or aux0 >= 1500
    scale = CPPM_MAX_ANGLE_DEG if level else CPPM_MAX_RATE_DEG_S
    roll = -(ch_roll - 1500) / 500.0 * scale
    pitch = -(ch_pitch - 1500) / 500.0 * scale
    yaw_rate = -(ch_yaw - 1500) / 500.0 * CPPM_MAX_YAW_RATE_DEG_S
    thrust = max(0, int((ch_thrust - 1000) / 1000.0 * 65535))
    mode = AxisMode.ABS if level else AxisMode.VELOCITY
    return _attitude_setpoint(roll, pitch, yaw_rate, thrust, mode, now_s, source)


def _attitude_setpoint(
    roll: float, pitch: float, yaw_rate: float, thrust: int, mode: AxisMode, now_s: float, source: str
) -> Setpoint:
    """Roll and pitch (angles or rates), a yaw rate and a raw thrust; the height is not controlled."""
    modes = (AxisMode.DISABLE, AxisMode.DISABLE, AxisMode.DISABLE)
    return Setpoint(
        modes,
        yaw_mode=AxisMode.VELOCITY,
        yaw_rate_deg_s=yaw_rate,
        thrust=min(int(thrust), 65535),
        attitude_mode=mode,
        attitude_deg=(roll, pitch),
        timestamp_s=now_s,
        source=source,
    )
