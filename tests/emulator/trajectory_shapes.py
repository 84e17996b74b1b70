"""Trajectories for the tests of uploaded trajectories, and a reference evaluation independent of the emulator.

`figure_eight` builds a figure-8 (x = a sin(wt), y = b sin(2wt), yaw = c sin(wt), constant height) as degree-7
poly4d pieces that match position and its first three derivatives at each piece's ends (Hermite), with the
coefficients rounded to float32 as they travel. `reference` evaluates such pieces with numpy the way cflib's
documentation describes a poly4d trajectory: the polynomial of the time since the piece began, the whole stretched
by the time scale.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from cflib.crazyflie.mem import Poly4D

Derivatives = Callable[[float], tuple[float, float, float, float]]
"""t -> (value, first, second, third derivative)."""


@dataclass(frozen=True)
class Piece:
    """One poly4d piece: x, y, z, yaw coefficients in ascending degree (float32 values) and its duration."""

    polys: tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...], tuple[float, ...]]
    duration: float

    def packed(self) -> bytes:
        """The 132 bytes cflib's `Poly4D.pack` writes."""
        return struct.pack("<33f", *[c for p in self.polys for c in p], self.duration)

    def to_cflib(self) -> Poly4D:
        return Poly4D(self.duration, *(Poly4D.Poly(list(p)) for p in self.polys))


def _f32(value: float) -> float:
    return float(np.float32(value))


def hermite7(f: Derivatives, t0: float, duration: float) -> tuple[float, ...]:
    """Coefficients of the degree-7 polynomial p(s), s in [0, duration], with p..p''' equal to f's at both ends."""
    matrix = np.zeros((8, 8))
    rhs = np.zeros(8)
    for k in range(4):
        for end, s in ((0, 0.0), (1, duration)):
            for i in range(k, 8):
                matrix[2 * k + end, i] = math.factorial(i) / math.factorial(i - k) * s ** (i - k)
            rhs[2 * k + end] = f(t0 + end * duration)[k]
    return tuple(_f32(c) for c in np.linalg.solve(matrix, rhs))


def sine(amplitude: float, omega: float, offset: float = 0.0) -> Derivatives:
    return lambda t: (
        offset + amplitude * math.sin(omega * t),
        amplitude * omega * math.cos(omega * t),
        -amplitude * omega**2 * math.sin(omega * t),
        -amplitude * omega**3 * math.cos(omega * t),
    )


def figure_eight(
    a: float = 0.4,
    b: float = 0.2,
    period_s: float = 4.0,
    height: float = 0.5,
    yaw_amplitude: float = 0.5,
    pieces: int = 8,
) -> list[Piece]:
    """A figure-8 through the origin (at `height`), starting and ending there."""
    omega = 2.0 * math.pi / period_s
    axes = (sine(a, omega), sine(b, 2.0 * omega), sine(0.0, 0.0, height), sine(yaw_amplitude, omega))
    duration = period_s / pieces
    return [
        Piece(tuple(hermite7(f, i * duration, duration) for f in axes), _f32(duration))  # type: ignore[arg-type]
        for i in range(pieces)
    ]


def reference(
    pieces: Sequence[Piece], t: float, timescale: float = 1.0
) -> tuple[tuple[float, float, float], tuple[float, float, float], float]:
    """Position, velocity and yaw of `pieces` `t` seconds after the start; after the end: the end, at rest."""
    for piece in pieces:
        length = piece.duration * timescale
        if t <= length:
            s = t / timescale
            value = [float(np.polyval(p[::-1], s)) for p in piece.polys]
            slope = [float(np.polyval(np.polyder(np.array(p[::-1])), s)) / timescale for p in piece.polys]
            return (value[0], value[1], value[2]), (slope[0], slope[1], slope[2]), value[3]
        t -= length
    last = pieces[-1]
    value = [float(np.polyval(p[::-1], last.duration)) for p in last.polys]
    return (value[0], value[1], value[2]), (0.0, 0.0, 0.0), value[3]


def total_duration(pieces: Sequence[Piece]) -> float:
    return sum(piece.duration for piece in pieces)
