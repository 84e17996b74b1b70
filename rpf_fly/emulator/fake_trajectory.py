"""Uploaded trajectories of the fake Crazyflie's high-level commander: poly4d pieces and compressed trajectories,
evaluated as crazyflie-firmware 2026.08 evaluates them (`src/modules/src/pptraj.c`, `pptraj_compressed.c`,
`planner.c`).

Both read the high-level commander's trajectory memory (4096 bytes, `fake_memory.TRAJECTORY_MEMORY_SIZE`) at every
evaluation, as the firmware points its `piecewise_traj` into `trajectories_memory`: rewriting the memory while a
trajectory flies changes what it flies.

Poly4d (`struct poly4d`, 132 bytes a piece): four 8-coefficient polynomials in ascending degree (x, y, z in metres,
yaw in radians) of the time since the piece began, then the piece's duration (float32 seconds). `piecewise_eval`:
- the time since the start walks the pieces, each lasting ``duration * timescale``; the piece found is stretched in
  time by ``timescale`` (coefficient i times ``timescale**-i``) and evaluated (Horner) with its derivative;
- the result is rotated about the world z axis by the yaw shift (``relative_yaw``), its yaw increased by it, then
  shifted by the position shift (``relative_position``): ``pos = R(shift_yaw) p(t) + shift``. The rotation is about
  the world origin, so with a yaw shift the trajectory starts at the current position only if its first point is
  the origin (cflib's example trajectories start there);
- after the last piece: the end of the last piece, transformed, with zero velocity (it hovers there).
`piecewise_eval_reversed`: the pieces from the last to the first, each shifted by the position shift, stretched,
reflected in time (``p(-t)``) and evaluated at ``t - duration * timescale``; no rotation or yaw shift is applied
(the firmware ignores ``relative_yaw`` when reversed); after the first piece: its start, shifted, at rest.

Compressed (`pptraj_compressed.c`): a start ``<hhhh`` (x, y, z in millimetres, yaw in tenths of a degree), then
pieces of a header byte (2 bits a coordinate x, y, z, yaw: 0 constant, 1 linear, 2 cubic Bezier, 3 7th-order
Bezier; the number of stored control points 0, 1, 3, 7), a uint16 duration in milliseconds and the int16 control
points; a piece of duration 0 ends the trajectory. Each piece starts where the previous one ended; it is turned
into a poly4d by the Bezier-to-power-basis conversion (`polybezier`). Only time scale 1, not reversed (the start
command answers ENOEXEC otherwise); relative shifts the position only.

Where the firmware reads outside its 4096-byte array (a definition whose pieces run past the end; a compressed
trajectory without a terminating piece) it reads whatever RAM follows; the fake reads zeros instead for compressed
data (a zero duration ends it) and refuses a poly4d piece outside the memory (the evaluation is invalid, so the
planner disables itself, the firmware's reaction to an invalid evaluation). A definition with zero pieces is
invalid the same way (the firmware would read the piece before it).

Arithmetic is Python's double precision; the firmware's is float32 (differences of order 1e-6 m).
"""

from __future__ import annotations

import math
import struct
from collections.abc import Sequence
from dataclasses import dataclass, field

Vec3 = tuple[float, float, float]
Eval = tuple[Vec3, Vec3, float]
"""Position (m), velocity (m/s), yaw (rad) of a trajectory at one instant."""

PP_SIZE = 8
POLY4D = struct.Struct("<33f")
POLY4D_SIZE = POLY4D.size
"""132 bytes: ``float p[4][8]`` then ``float duration``."""
_DURATION = struct.Struct("<f")
_FACTORIALS = (1, 1, 2, 6, 24, 120, 720, 5040)
_CONTROL_POINTS_BY_TYPE = (0, 1, 3, 7)
STORED_DISTANCE_SCALE = 1000.0
STORED_ANGLE_SCALE = 1800.0 / math.pi
STORED_DURATION_SCALE = 1000.0


def normalize_radians(angle: float) -> float:
    """`normalize_radians` of math3d.h: the angle in [-pi, pi] (C fmod with the sign of the angle)."""
    signed_pi = math.copysign(math.pi, angle)
    return math.fmod(angle + signed_pi, 2.0 * math.pi) - signed_pi


def shortest_signed_angle_radians(start: float, goal: float) -> float:
    """`shortest_signed_angle_radians` of math3d.h: goal - start wrapped to [-pi, pi) (floored modulo)."""
    return (goal - start + math.pi) % (2.0 * math.pi) - math.pi


def _reciprocal(value: float) -> float:
    """1 / value with IEEE semantics (a zero gives a signed infinity), as the firmware's float division."""
    return math.copysign(math.inf, value) if value == 0.0 else 1.0 / value


def _stretch(poly: Sequence[float], scale: float) -> list[float]:
    """`polystretchtime`: p(t) -> p(t / scale), coefficient i times scale**-i."""
    recip = _reciprocal(scale)
    out = [float(poly[0])]
    factor = recip
    for coefficient in poly[1:]:
        out.append(coefficient * factor)
        factor *= recip
    return out


def _value_and_slope(poly: Sequence[float], t: float) -> tuple[float, float]:
    """p(t) and p'(t) by Horner's rule (the firmware's `polyval` of the polynomial and of its `polyder`)."""
    value = slope = 0.0
    for coefficient in reversed(poly):
        slope = slope * t + value
        value = value * t + coefficient
    return value, slope


def _eval_poly4d(polys: Sequence[Sequence[float]], t: float) -> Eval:
    x, vx = _value_and_slope(polys[0], t)
    y, vy = _value_and_slope(polys[1], t)
    z, vz = _value_and_slope(polys[2], t)
    yaw, _ = _value_and_slope(polys[3], t)
    return (x, y, z), (vx, vy, vz), yaw


def _polybezier(control_points: Sequence[float], duration: float) -> list[float]:
    """`polybezier`: the power-basis coefficients of the Bezier curve through `control_points` (1: constant,
    2: linear, up to 8: 7th order) over `duration` seconds."""
    dim = len(control_points)
    poly = [0.0] * PP_SIZE
    if dim == 1:
        poly[0] = control_points[0]
        return poly
    if dim == 2:
        poly[0] = control_points[0]
        poly[1] = (control_points[1] - control_points[0]) * _reciprocal(duration)
        return poly
    n = min(dim, PP_SIZE) - 1
    for j in range(n + 1):
        sign = -1 if j % 2 else 1
        coefficient = 0.0
        for i in range(j + 1):
            coefficient += sign * control_points[i] / _FACTORIALS[i] / _FACTORIALS[j - i]
            sign = -sign
        poly[j] = coefficient * _FACTORIALS[n] / _FACTORIALS[n - j]
    return _stretch(poly, duration)


def _valid(ev: Eval) -> bool:
    """`is_traj_eval_valid`: no NaN in the position."""
    return not any(math.isnan(c) for c in ev[0])


@dataclass
class PiecewiseTrajectory:
    """A poly4d trajectory in the trajectory memory (`struct piecewise_traj`), started at `t0_s`."""

    memory: bytearray
    offset: int
    n_pieces: int
    t0_s: float
    timescale: float = 1.0
    reversed: bool = False
    shift: Vec3 = (0.0, 0.0, 0.0)
    shift_yaw: float = 0.0

    def _duration(self, index: int) -> float | None:
        start = self.offset + index * POLY4D_SIZE
        if start < 0 or start + POLY4D_SIZE > len(self.memory):
            return None
        return float(_DURATION.unpack_from(self.memory, start + POLY4D_SIZE - 4)[0])

    def _polys(self, index: int) -> list[list[float]]:
        values = POLY4D.unpack_from(self.memory, self.offset + index * POLY4D_SIZE)
        return [list(values[k * PP_SIZE : (k + 1) * PP_SIZE]) for k in range(4)]

    @property
    def duration_s(self) -> float:
        """`piecewise_duration`: the sum of the pieces' durations times the time scale."""
        total = 0.0
        for index in range(self.n_pieces):
            duration = self._duration(index)
            total += duration if duration is not None else 0.0
        return total * self.timescale

    def finished(self, now_s: float) -> bool:
        """`piecewise_is_finished`."""
        return now_s - self.t0_s >= self.duration_s

    def evaluate(self, now_s: float) -> Eval | None:
        """The setpoint at `now_s`, None when the evaluation is invalid (the planner then disables itself)."""
        if self.n_pieces <= 0:
            return None
        ev = self._reversed(now_s) if self.reversed else self._forward(now_s)
        return ev if ev is not None and _valid(ev) else None

    def _transform(self, ev: Eval) -> Eval:
        """`traj_eval_transform`: rotate about z by the yaw shift, add it to the yaw, then shift the position."""
        (x, y, z), (vx, vy, vz), yaw = ev
        rotation = normalize_radians(self.shift_yaw)
        if rotation != 0.0:
            c, s = math.cos(rotation), math.sin(rotation)
            x, y = c * x - s * y, s * x + c * y
            vx, vy = c * vx - s * vy, s * vx + c * vy
        sx, sy, sz = self.shift
        return (x + sx, y + sy, z + sz), (vx, vy, vz), yaw + rotation

    def _forward(self, now_s: float) -> Eval | None:
        t = now_s - self.t0_s
        for index in range(self.n_pieces):
            duration = self._duration(index)
            if duration is None:
                return None
            if t <= duration * self.timescale:
                polys = [_stretch(p, self.timescale) for p in self._polys(index)]
                return self._transform(_eval_poly4d(polys, t))
            t -= duration * self.timescale
        last = self.n_pieces - 1
        duration = self._duration(last)
        if duration is None:
            return None
        pos, _, yaw = self._transform(_eval_poly4d(self._polys(last), duration))
        return pos, (0.0, 0.0, 0.0), yaw

    def _reversed(self, now_s: float) -> Eval | None:
        t = now_s - self.t0_s
        for index in range(self.n_pieces - 1, -1, -1):
            duration = self._duration(index)
            if duration is None:
                return None
            if t <= duration * self.timescale:
                polys = self._polys(index)
                for axis in range(3):
                    polys[axis][0] += self.shift[axis]
                polys = [_stretch(p, self.timescale) for p in polys]
                for p in polys:  # polyreflect: p(-t)
                    for i in range(1, PP_SIZE, 2):
                        p[i] = -p[i]
                return _eval_poly4d(polys, t - duration * self.timescale)
            t -= duration * self.timescale
        if self._duration(0) is None:
            return None
        (x, y, z), _, yaw = _eval_poly4d(self._polys(0), 0.0)
        sx, sy, sz = self.shift
        return (x + sx, y + sy, z + sz), (0.0, 0.0, 0.0), yaw


@dataclass
class _CompressedPiece:
    data: int | None
    """Offset of the piece's header in the memory; None past the end."""
    t_begin_relative: float
    polys: list[list[float]]
    duration: float


@dataclass
class CompressedTrajectory:
    """A compressed trajectory (`struct piecewise_traj_compressed`) at `offset` in the trajectory memory, started
    at `t0_s`; time scale 1, never reversed. Keeps the firmware's play head (the current piece)."""

    memory: bytearray
    offset: int
    t0_s: float
    shift: Vec3 = (0.0, 0.0, 0.0)
    duration_s: float = 0.0
    _piece: _CompressedPiece = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self._rewind()
        self.duration_s = self._total_duration(self._piece.data)

    def _int16(self, offset: int) -> int:
        """A little-endian int16 of the memory; zeros beyond its end (module docstring)."""
        lo = self.memory[offset] if 0 <= offset < len(self.memory) else 0
        hi = self.memory[offset + 1] if 0 <= offset + 1 < len(self.memory) else 0
        value = lo | (hi << 8)
        return value - 0x10000 if value >= 0x8000 else value

    def _header(self, ptr: int | None) -> tuple[tuple[int, int, int, int], int, int | None, int | None]:
        """`parse_header_of_current_piece`: (storage types, duration in ms, body offset, next piece or None)."""
        if ptr is None:
            return (0, 0, 0, 0), 0, None, None
        header = self.memory[ptr] if 0 <= ptr < len(self.memory) else 0
        types = (header & 0x03, (header >> 2) & 0x03, (header >> 4) & 0x03, (header >> 6) & 0x03)
        duration_ms = self._int16(ptr + 1) & 0xFFFF
        body = ptr + 3
        if duration_ms == 0:
            return types, 0, body, None
        length = sum(_CONTROL_POINTS_BY_TYPE[kind] for kind in types) * 2
        return types, duration_ms, body, body + length

    def _total_duration(self, ptr: int | None) -> float:
        total_ms = 0
        while ptr is not None:
            _, duration_ms, _, ptr = self._header(ptr)
            total_ms += duration_ms
        return total_ms / STORED_DURATION_SCALE

    def _rewind(self) -> None:
        start = self.offset
        pos = (
            self._int16(start) / STORED_DISTANCE_SCALE,
            self._int16(start + 2) / STORED_DISTANCE_SCALE,
            self._int16(start + 4) / STORED_DISTANCE_SCALE,
        )
        yaw = self._int16(start + 6) / STORED_ANGLE_SCALE
        self._piece = self._make_piece(start + 8, 0.0, pos, yaw)

    def _make_piece(self, data: int | None, t_begin_relative: float, end_pos: Vec3, end_yaw: float) -> _CompressedPiece:
        """`piecewise_compressed_update_current_poly4d`: the piece at `data` as a poly4d starting at the previous
        piece's end."""
        types, duration_ms, body, _ = self._header(data)
        duration = duration_ms / STORED_DURATION_SCALE
        ptr = body
        polys = []
        for kind, initial, scale in zip(
            types, (*end_pos, end_yaw), (STORED_DISTANCE_SCALE,) * 3 + (STORED_ANGLE_SCALE,)
        ):
            points = [initial]
            for _ in range(_CONTROL_POINTS_BY_TYPE[kind]):
                assert ptr is not None
                points.append(self._int16(ptr) / scale)
                ptr += 2
            polys.append(_polybezier(points, duration))
        return _CompressedPiece(data, t_begin_relative, polys, duration)

    def _advance(self) -> None:
        piece = self._piece
        end_pos, _, end_yaw = _eval_poly4d(piece.polys, piece.duration)
        _, _, _, following = self._header(piece.data)
        self._piece = self._make_piece(following, piece.t_begin_relative + piece.duration, end_pos, end_yaw)

    def finished(self, now_s: float) -> bool:
        """`piecewise_compressed_is_finished`."""
        return now_s - self.t0_s >= self.duration_s

    def evaluate(self, now_s: float) -> Eval | None:
        """`piecewise_compressed_eval`: rewind if `now_s` is before the current piece, advance past the pieces that
        ended, evaluate the current one, shift the position."""
        if now_s < self.t0_s + self._piece.t_begin_relative:
            self._rewind()
        while self._piece.data is not None and now_s >= self.t0_s + self._piece.t_begin_relative + self._piece.duration:
            self._advance()
        (x, y, z), vel, yaw = _eval_poly4d(self._piece.polys, now_s - self.t0_s - self._piece.t_begin_relative)
        sx, sy, sz = self.shift
        ev = ((x + sx, y + sy, z + sz), vel, yaw)
        return ev if _valid(ev) else None
