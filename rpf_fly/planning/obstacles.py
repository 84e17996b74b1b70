"""Obstacle geometry: the nearest obstacle surface point for many robots at once.

The APF repels from the single nearest obstacle, measured to its *surface* (paper eq. 2; docs/algorithm.md, *Forces*:
``d_o`` is the distance from the robot centre to the surface, ``p_o`` the nearest surface point). Obstacles are
vertical circles (cylinders) and axis-aligned boxes in the planning plane.

Points are complex (see :mod:`rpf_fly.planning.vectors`) with any leading shape ``S``; obstacle arrays have shape
``(M,)`` (shared) or ``S + (M,)`` (one set per robot or per arena, broadcastable). Distances are *signed*:
negative inside an obstacle, so a collision stays visible instead of being hidden by a clamp. Metres.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import overload

import numpy as np

from rpf_fly.planning.vectors import TINY, Planar, Scalar, per_item

FAR = 1.0e6
"""Distance reported when a robot has no obstacle at all (metres); obstacles padded at FAR are never sensed."""


@dataclass(frozen=True)
class ObstacleSet:
    """Circles: complex ``centers`` and ``radii``; boxes: complex ``box_center`` and half extents ``box_half_x``,
    ``box_half_y``. Each array has a trailing obstacle axis. Build with :meth:`from_shapes`."""

    centers: np.ndarray
    radii: np.ndarray
    box_center: np.ndarray
    box_half_x: np.ndarray
    box_half_y: np.ndarray

    @property
    def n_circles(self) -> int:
        return int(self.radii.shape[-1])

    @property
    def n_boxes(self) -> int:
        return int(self.box_center.shape[-1])

    @property
    def is_empty(self) -> bool:
        return self.n_circles == 0 and self.n_boxes == 0

    @staticmethod
    def empty() -> ObstacleSet:
        """No obstacles."""
        return ObstacleSet.from_shapes()

    @staticmethod
    def from_shapes(
        circles: Iterable[tuple[Sequence[float], float]] = (),
        boxes: Iterable[tuple[Sequence[float], Sequence[float]]] = (),
    ) -> ObstacleSet:
        """Circles as ``(center_xy, radius)`` and boxes as ``(min_xy, max_xy)``, metres."""
        circles = list(circles)
        boxes = list(boxes)
        centers = np.array([complex(c[0], c[1]) for c, _ in circles], dtype=complex)
        radii = np.array([r for _, r in circles], dtype=float)
        lo = np.array([complex(a[0], a[1]) for a, _ in boxes], dtype=complex)
        hi = np.array([complex(b[0], b[1]) for _, b in boxes], dtype=complex)
        if np.any(radii <= 0):
            raise ValueError("circle radii must be positive")
        if np.any(lo.real > hi.real) or np.any(lo.imag > hi.imag):
            raise ValueError("box min must not exceed box max")
        return ObstacleSet(centers, radii, (lo + hi) / 2, (hi - lo).real / 2, (hi - lo).imag / 2)

    @overload
    def signed_distance(self, points: complex) -> float: ...
    @overload
    def signed_distance(self, points: np.ndarray) -> np.ndarray: ...
    def signed_distance(self, points: Planar) -> Scalar:
        """Signed distance from each point to the nearest obstacle surface (FAR without obstacles)."""
        return nearest_obstacle(points, self).distance


@dataclass(frozen=True)
class NearestObstacle:
    """Per robot: signed ``distance`` to the nearest surface (metres, negative inside, FAR if none) and the outward
    unit ``normal`` there (complex; the surface point is ``position - distance * normal``; zero if none)."""

    distance: Scalar
    normal: Planar


def _circles(
    points: Planar, centers: np.ndarray, radii: np.ndarray | float, offsets: tuple[np.ndarray, np.ndarray] | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Signed distance and outward normal for every circle ``S + (M,)``. ``offsets``: the centres' ``(c - p,
    |c - p|)`` when the caller has them (a view's :meth:`~rpf_fly.planning.view.LocalView.neighbour_offsets`;
    ``p - c`` is their exact negation, up to the sign of a zero offset)."""
    if offsets is None:
        diff = per_item(points) - centers
        dist = abs(diff)
    else:
        diff, dist = -offsets[0], offsets[1]
    return dist - radii, diff / (dist + TINY)


def _boxes(points: Planar, obstacles: ObstacleSet) -> tuple[np.ndarray, np.ndarray]:
    """Signed distance and outward normal for every axis-aligned box ``S + (M,)`` (the box signed-distance field)."""
    a = per_item(points) - obstacles.box_center
    sx = np.sign(a.real)
    sy = np.sign(a.imag)
    qx = abs(a.real) - obstacles.box_half_x  # > 0: outside the slab in x
    qy = abs(a.imag) - obstacles.box_half_y
    mx = np.maximum(qx, 0.0)
    my = np.maximum(qy, 0.0)
    offset = sx * mx + 1j * sy * my  # from the nearest surface point to the robot, when outside
    outside = abs(offset)
    inside = np.minimum(np.maximum(qx, qy), 0.0)  # minus the depth to the nearest face, when inside
    out = outside > 0.0
    x_face = qx > qy
    normal_inside = x_face * sx + (~x_face) * (1j * sy)
    normal = out * (offset / (outside + TINY)) + (~out) * normal_inside
    return outside + inside, normal


def _reduce(dist: np.ndarray, normal: np.ndarray) -> tuple[Scalar, Planar]:
    """The minimum over the obstacle axis: Python numbers for one robot, arrays for many."""
    k = dist.argmin(axis=-1)
    if dist.ndim == 1:
        return dist.item(k), normal.item(k)
    k = k[..., None]
    return np.take_along_axis(dist, k, -1)[..., 0], np.take_along_axis(normal, k, -1)[..., 0]


def nearest_obstacle(
    points: Planar,
    obstacles: ObstacleSet,
    extra_centers: np.ndarray | None = None,
    extra_radius: float = 0.0,
    extra_mask: np.ndarray | None = None,
    extra_offsets: tuple[np.ndarray, np.ndarray] | None = None,
) -> NearestObstacle:
    """Nearest obstacle surface for each point (complex, leading shape ``S``; a Python complex for one robot).

    ``extra_centers`` ``S + (K,)`` selected by ``extra_mask`` adds per-robot circles of radius ``extra_radius``:
    the robust preset treats hovering (arrived) neighbours as obstacles this way.
    """
    found = []
    if obstacles.n_circles:
        found.append(_reduce(*_circles(points, obstacles.centers, obstacles.radii)))
    if obstacles.n_boxes:
        found.append(_reduce(*_boxes(points, obstacles)))
    if extra_mask is not None and extra_centers is not None and extra_mask.any():
        d, n = _circles(points, extra_centers, extra_radius, extra_offsets)
        found.append(_reduce(d + (~extra_mask) * FAR, n))
    if not found:
        if isinstance(points, np.ndarray):
            return NearestObstacle(np.full(points.shape, FAR), np.zeros(points.shape, dtype=complex))
        return NearestObstacle(FAR, 0j)
    dist, normal = found[0]
    for d_k, n_k in found[1:]:
        closer = d_k < dist
        dist = dist + closer * (d_k - dist)
        normal = normal + closer * (n_k - normal)
    return NearestObstacle(dist, normal)


@dataclass(frozen=True)
class Surfaces:
    """Per robot, every obstacle ``S + (M,)``: signed ``distance`` and outward ``normal`` as in
    :class:`NearestObstacle`; the first ``mapped`` are the mission's obstacles (the guidance path clears them), the
    rest static neighbours (padding at FAR)."""

    distance: np.ndarray
    normal: np.ndarray
    mapped: int


def every_surface(
    points: Planar,
    obstacles: ObstacleSet,
    extra_centers: np.ndarray | None = None,
    extra_radius: float = 0.0,
    extra_mask: np.ndarray | None = None,
    extra_offsets: tuple[np.ndarray, np.ndarray] | None = None,
) -> Surfaces:
    """Every obstacle surface (circles, boxes, then the extra circles of :func:`nearest_obstacle`, those outside
    ``extra_mask`` at FAR), where :func:`nearest_obstacle` keeps the nearest. For the summed repulsion
    (:func:`rpf_fly.planning.forces.repulsive_sum`)."""
    dists, normals = [], []
    if obstacles.n_circles:
        d, n = _circles(points, obstacles.centers, obstacles.radii)
        dists.append(d)
        normals.append(n)
    if obstacles.n_boxes:
        d, n = _boxes(points, obstacles)
        dists.append(d)
        normals.append(n)
    mapped = sum(d.shape[-1] for d in dists)
    if extra_mask is not None and extra_centers is not None and extra_mask.any():
        d, n = _circles(points, extra_centers, extra_radius, extra_offsets)
        dists.append(d + (~extra_mask) * FAR)
        normals.append(n)
    if not dists:
        shape = np.shape(points) + (0,)
        return Surfaces(np.zeros(shape), np.zeros(shape, dtype=complex), 0)
    lead = np.broadcast_shapes(*(d.shape[:-1] for d in dists))
    dist = np.concatenate([np.broadcast_to(d, lead + d.shape[-1:]) for d in dists], axis=-1)
    normal = np.concatenate([np.broadcast_to(n, lead + n.shape[-1:]) for n in normals], axis=-1)
    return Surfaces(dist, normal, mapped)
