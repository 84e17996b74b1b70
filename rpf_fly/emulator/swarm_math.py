"""Column-wise angle and quaternion arithmetic for `CfSwarm` (each column one drone): the firmware's `capAngle` and a
quaternion turned by its body-frame rotation vector."""

from __future__ import annotations

import numpy as np


def cap_angle(a: np.ndarray) -> np.ndarray:
    """`capAngle`: into [-180, 180] by whole turns (180 and -180 kept)."""
    a = np.where(a > 180.0, a - 360.0 * np.ceil((a - 180.0) / 360.0), a)
    return np.where(a < -180.0, a + 360.0 * np.ceil((-180.0 - a) / 360.0), a)


def rotated(q: np.ndarray, ax: np.ndarray, ay: np.ndarray, az: np.ndarray) -> np.ndarray:
    """Each quaternion column of `q` (x, y, z, w) turned by its body-frame rotation vector."""
    angle2 = ax * ax + ay * ay + az * az
    small = angle2 < 1e-24
    angle = np.sqrt(np.where(small, 1.0, angle2))
    s = np.sin(0.5 * angle) / angle
    dx, dy, dz, dw = ax * s, ay * s, az * s, np.cos(0.5 * angle)
    qx, qy, qz, qw = q
    out = np.array(
        [
            qw * dx + qx * dw + qy * dz - qz * dy,
            qw * dy - qx * dz + qy * dw + qz * dx,
            qw * dz + qx * dy - qy * dx + qz * dw,
            qw * dw - qx * dx - qy * dy - qz * dz,
        ]
    )
    return np.where(small, q, out)
