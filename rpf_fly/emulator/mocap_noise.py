"""What a real motion-capture system does to every frame of a dry run: jitter on each body's position and
orientation, and now and then a body left untracked for a frame.

Why: without it the dry run's mocap would serve the simulated world's truth, exact, every body tracked in every
frame, which no Motive, Vicon or Qualisys room does. A stack tuned on that (a velocity estimate from differences of
exact positions, a glitch check with no noise to ride through, an extpos stream that never misses a frame) is
tried on something kinder than the lab it will fly in. The simulated drones already wander as real ones do
(``fake_vehicle``, "Turbulence"); this is the same rule for the mocap.

The figures are assumptions, chosen at the worse end of what labs report, not measured here:
- ``POSITION_NOISE_M`` 0.5 mm per axis, white from frame to frame: OptiTrack quotes sub-millimetre residuals for a
  calibrated room; a Crazyflie's markers are small (about 6 mm) and close together, and labs with smaller cameras
  see half a millimetre to a millimetre of jitter;
- ``ORIENTATION_NOISE_DEG`` 0.5 degrees per axis, white: half a millimetre on markers 3-4 cm apart turns the fitted
  body by about that much;
- ``DROPOUT`` 0.1 % of a body's frames untracked (one frame, valid False, its position the truth as the
  emulator's occlusions report it): a marker hidden behind a neighbour or a propeller for one exposure; at 100 Hz
  that is one frame in ten seconds a body, about one a second in a swarm of ten.
A lab with its own figures sets them (`MocapNoise`); the emulator's own precision tests set them to zero.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass

Vec3 = tuple[float, float, float]
Quaternion = tuple[float, float, float, float]

POSITION_NOISE_M = 0.0005
ORIENTATION_NOISE_DEG = 0.5
DROPOUT = 0.001


@dataclass(frozen=True)
class MocapNoise:
    """Per-frame jitter (standard deviations, per axis) and the chance a body is untracked in one frame."""

    position_m: float = POSITION_NOISE_M
    orientation_deg: float = ORIENTATION_NOISE_DEG
    dropout: float = DROPOUT

    @classmethod
    def default(cls) -> MocapNoise:
        """The module's figures as they are now (read at the call, so a test's monkeypatch of them holds)."""
        return cls(POSITION_NOISE_M, ORIENTATION_NOISE_DEG, DROPOUT)

    @property
    def off(self) -> bool:
        return self.position_m == 0.0 and self.orientation_deg == 0.0 and self.dropout == 0.0

    def apply(self, rng: random.Random, position: Vec3, quaternion: Quaternion) -> tuple[Vec3, Quaternion, bool]:
        """One body's pose in one frame as the mocap measures it: (position, orientation, tracked)."""
        if self.off:
            return position, quaternion, True
        gauss = rng.gauss
        s = self.position_m
        measured = (position[0] + gauss(0.0, s), position[1] + gauss(0.0, s), position[2] + gauss(0.0, s))
        a = math.radians(self.orientation_deg)
        turned = _turn((gauss(0.0, a), gauss(0.0, a), gauss(0.0, a)), quaternion) if a > 0.0 else quaternion
        return measured, turned, rng.random() >= self.dropout


def turned(turn: Quaternion, q: Quaternion) -> Quaternion:
    """The orientation ``q`` (qx, qy, qz, qw, world from body) turned by ``turn`` in the world frame: turn * q."""
    ax, ay, az, aw = turn
    bx, by, bz, bw = q
    return (
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    )


def _turn(rotation: Vec3, q: Quaternion) -> Quaternion:
    """``q`` turned by the small world-frame rotation vector ``rotation`` (radians)."""
    rx, ry, rz = rotation
    angle = math.sqrt(rx * rx + ry * ry + rz * rz)
    if angle < 1e-12:
        return q
    k = math.sin(0.5 * angle) / angle
    return turned((rx * k, ry * k, rz * k, math.cos(0.5 * angle)), q)
