"""Planar vectors as complex numbers ``x + iy``: the representation every planning function uses.

Why: a planar vector operation is then ONE numpy operation (``abs(z)`` is the norm, ``1j * z`` the 90-degree
counter-clockwise turn, ``z * exp(i a)`` a rotation), and the same code runs on numpy scalars (one drone in
flight: operators on scalars cost ~70 ns, a numpy call on a tiny array ~0.5-2 us) and on arrays (thousands of
drones in training). Measured: the per-drone step costs the figure in docs/performance.md (*Planning*), against
189 us with ``(..., 2)`` float arrays. Convert at the edges with :func:`to_complex` and :func:`to_xy`.

Conventions (docs/architecture.md): metres, Z-up world, angles from +x counter-clockwise in (-pi, pi].
"""

from __future__ import annotations

import math
from typing import Any, TypeAlias, overload

import numpy as np

Planar: TypeAlias = "np.ndarray | complex"
"""Planar vector(s) as the planner takes them: a complex array of leading shape ``S`` (drones planned together), or
one drone's Python complex (see the helpers below: the one-drone path runs on Python numbers)."""

Scalar: TypeAlias = "np.ndarray | float"
"""Real value(s) per drone, as :data:`Planar`: an array of leading shape ``S``, or one drone's Python number."""

TINY = 1e-300
"""Added to norms before dividing: a zero vector normalises to zero instead of NaN (callers read 0 as 'none')."""


def to_complex(xy: np.ndarray) -> np.ndarray:
    """``(..., 2)`` float ``[x, y]`` to ``(...)`` complex ``x + iy``."""
    xy = np.asarray(xy, dtype=float)
    return xy[..., 0] + 1j * xy[..., 1]


def to_xy(z: np.ndarray) -> np.ndarray:
    """``(...)`` complex to ``(..., 2)`` float ``[x, y]``."""
    z = np.asarray(z)
    return np.stack([z.real, z.imag], axis=-1)


@overload
def norm(z: complex) -> float: ...
@overload
def norm(z: np.ndarray) -> np.ndarray: ...
def norm(z: Any) -> Any:
    """``abs(z)``: the length of one drone's vector (a float) or of every drone's (an array). Typed per case, as
    mypy cannot infer ``abs`` of a :data:`Planar` union."""
    return abs(z)


@overload
def unit(z: complex) -> complex: ...
@overload
def unit(z: np.ndarray) -> np.ndarray: ...
def unit(z: Any) -> Any:
    """Unit vector(s); zero stays zero."""
    return z / (abs(z) + TINY)


def dot(a: Planar, b: Planar) -> Scalar:
    """Planar dot product ``a . b``."""
    return a.real * b.real + a.imag * b.imag


def cross(a: Planar, b: Planar) -> Scalar:
    """z-component of ``a x b``: positive when ``b`` is counter-clockwise from ``a``."""
    return a.real * b.imag - a.imag * b.real


def wrap_angle(a: np.ndarray) -> np.ndarray:
    """Map any angle to (-pi, pi]."""
    return a - 2.0 * np.pi * np.ceil((a - np.pi) / (2.0 * np.pi))


def heading_angle(z: np.ndarray) -> np.ndarray:
    """Angle of ``z`` from +x, counter-clockwise, in (-pi, pi]."""
    return wrap_angle(np.angle(z))


def relative_angle(frame: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Signed angle of ``z`` seen from a frame whose x axis is the unit vector ``frame``, in (-pi, pi]."""
    return wrap_angle(np.arctan2(cross(frame, z), dot(frame, z)))


def from_angle(angle: np.ndarray | float) -> np.ndarray:
    """Unit vector at ``angle`` radians."""
    return np.exp(1j * np.asarray(angle, dtype=float))


# The planner is written once with operators, so it runs on numpy arrays (batches of drones) and on plain Python
# numbers (one drone, where a numpy call costs 10-50x an operator). These helpers are the few places the two
# need different calls.


def maximum(a, b):
    """Elementwise max for arrays, ``max`` for Python numbers."""
    return np.maximum(a, b) if isinstance(a, np.ndarray) else (a if a > b else b)


def minimum(a, b):
    """Elementwise min for arrays, ``min`` for Python numbers."""
    return np.minimum(a, b) if isinstance(a, np.ndarray) else (a if a < b else b)


def any_true(mask) -> bool:
    """Whether any element is true (a Python bool passes through)."""
    return bool(mask.any()) if isinstance(mask, np.ndarray) else bool(mask)


def plain(x):
    """A numpy scalar as a Python number; arrays and Python numbers pass through."""
    return x.item() if isinstance(x, np.generic) else x


def per_item(x):
    """Add a trailing axis to an array so it broadcasts against ``S + (K,)``; Python numbers pass through."""
    return x[..., None] if isinstance(x, np.ndarray) and x.ndim else x


def offsets(position, neighbour_position: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each neighbour's offset ``p_j - p`` (complex ``S + (K,)``) and its length: what the observation, the
    inter-robot force, the brake and the static-neighbour circles all start from (a view computes them once:
    :meth:`~rpf_fly.planning.view.LocalView.neighbour_offsets`)."""
    delta = neighbour_position - per_item(position)
    return delta, abs(delta)


def phase(z):
    """Angle of ``z`` in (-pi, pi], for a Python number or an array.

    The angle of a vector ``v`` seen from a unit heading ``h`` is ``phase(v * conj(h))``.
    """
    # atan2 returns -pi only for an imaginary part of -0.0 with a negative real part; adding +0.0 turns -0.0 into
    # +0.0 (IEEE 754), so the result is always in (-pi, pi] without a fix-up pass (one numpy call fewer).
    if isinstance(z, np.ndarray):
        return np.arctan2(z.imag + 0.0, z.real)
    return math.atan2(z.imag + 0.0, z.real)
