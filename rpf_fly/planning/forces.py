"""The three APF forces of the paper (Section III-B), batched over leading dimensions, planar vectors complex.

- attractive ``F_a = (p_g - p) / d_g``: a unit vector (zero at the goal);
- repulsive from the nearest obstacle, ``F_r = eta (1/d_o - 1/rho) (p - p_o) / d_o^3`` for ``d_o <= rho`` (and
  within the sensing range), else 0; as ``|p - p_o| = d_o`` this is ``eta (1/d_o - 1/rho) / d_o^2`` along the
  outward surface normal;
- inter-robot, ``F_in = sum_j (0.5 - lambda/d_ji) (p_j - p) / d_ji`` over the visible neighbours (``d_ji < d_r``).

With ``config.margin`` ``m > 0`` the planner measures from surfaces grown by ``m``: ``d_o - m`` in the repulsion
(the caller passes the shifted :class:`NearestObstacle`, :func:`perceived`) and ``d_ji - m`` in the inter-robot
coefficient (the direction stays the true one).

Gains ``eta`` and ``lambda`` broadcast against the leading shape, so a policy can set them per robot.
"""

from __future__ import annotations

import cmath
import math

import numpy as np

from rpf_fly.planning.config import PlannerConfig
from rpf_fly.planning.obstacles import FAR, NearestObstacle, Surfaces
from rpf_fly.planning.vectors import TINY, Planar, Scalar, maximum, norm, per_item, plain
from rpf_fly.planning.vectors import offsets as offsets_of


def attractive(position: Planar, goal: Planar) -> tuple[Planar, Scalar]:
    """Unit vector toward the goal (zero at the goal) and the goal distance ``d_g`` (metres)."""
    delta = goal - position
    d_g = norm(delta)
    return delta / (d_g + TINY), d_g


def perceived(nearest: NearestObstacle, config: PlannerConfig) -> NearestObstacle:
    """The nearest obstacle as the forces see it: ``margin`` closer (the same object when the margin is 0)."""
    if not config.margin:
        return nearest
    return NearestObstacle(nearest.distance - config.margin, nearest.normal)


def repulsive(nearest: NearestObstacle, eta: Scalar, config: PlannerConfig) -> Planar:
    """Repulsion from the nearest visible obstacle surface; zero beyond rho or the sensing range.

    Inside an obstacle or closer than ``min_distance`` the distance is clamped, giving a large finite outward push.
    """
    d_raw = nearest.distance
    d = maximum(d_raw, config.min_distance)
    rho = config.influence_range
    if config.guided_influence_range and config.guidance == "path":
        rho = config.guided_influence_range
    visible = d_raw <= min(rho, config.sensing_range)
    magnitude = eta * (1.0 / d - 1.0 / rho) / (d * d)
    return (visible * magnitude) * nearest.normal


def repulsive_sum(surfaces: Surfaces, eta: Scalar, config: PlannerConfig) -> Planar:
    """The repulsion of :func:`repulsive` summed over every surface within range (each seen ``margin`` closer),
    where :func:`repulsive` takes the nearest only: between two obstacles nearer than the range the two pushes
    cancel along the gap instead of flipping side from one step to the next. With guidance the mission's obstacles
    (the first ``surfaces.mapped``) act within ``guided_influence_range``; the static neighbours (which the guidance
    path does not know) within ``static_influence_range`` (0: as the obstacles)."""
    if surfaces.distance.shape[-1] == 0:
        return np.zeros(surfaces.distance.shape[:-1], dtype=complex) if surfaces.distance.ndim > 1 else 0j
    d_raw = surfaces.distance - config.margin
    d = np.maximum(d_raw, config.min_distance)
    guided = bool(config.guided_influence_range) and config.guidance == "path"
    base = config.guided_influence_range if guided else config.influence_range
    rho = np.full(d.shape[-1], base)
    rho[surfaces.mapped :] = config.static_influence_range or base
    visible = d_raw <= np.minimum(rho, config.sensing_range)
    magnitude = np.where(visible, per_item(eta) * (1.0 / d - 1.0 / rho) / (d * d), 0.0)
    return plain((magnitude * surfaces.normal).sum(axis=-1))


def repulsion_one(
    position: complex,
    circles: list[tuple[float, float, float]],
    boxes: list[tuple[float, float, float, float]],
    statics: list[complex],
    static_radius: float,
    config: PlannerConfig,
) -> tuple[complex, float, complex]:
    """:func:`repulsive_sum` for one drone with ``eta`` 1, in plain Python (the flight's one-drone call: a few
    obstacles, where a numpy call per array costs more than the loop), and the nearest of the mission's obstacles
    (signed distance, outward normal; FAR and 0 without any) as :func:`~rpf_fly.planning.obstacles.nearest_obstacle`
    gives it, for the brake. ``circles``: ``(x, y, radius)``; ``boxes``: ``(centre x, centre y, half x, half y)``;
    ``statics``: the static neighbours' centres (radius ``static_radius``). Agrees with the batched functions to
    rounding (tests/planning/test_planner.py)."""
    guided = bool(config.guided_influence_range) and config.guidance == "path"
    rho = config.guided_influence_range if guided else config.influence_range
    rho_static = config.static_influence_range or rho
    margin, floor, sensing = config.margin, config.min_distance, config.sensing_range
    px, py = position.real, position.imag
    fx = fy = 0.0
    wall, wall_normal = FAR, 0j

    def push(distance: float, nx: float, ny: float, reach: float, mapped: bool = True) -> None:
        nonlocal fx, fy, wall, wall_normal
        if mapped and distance < wall:
            wall, wall_normal = distance, complex(nx, ny)
        d_raw = distance - margin
        if d_raw <= reach and d_raw <= sensing:
            d = d_raw if d_raw > floor else floor
            magnitude = (1.0 / d - 1.0 / reach) / (d * d)
            fx += magnitude * nx
            fy += magnitude * ny

    for cx, cy, radius in circles:
        dx, dy = px - cx, py - cy
        length = math.hypot(dx, dy)
        push(length - radius, dx / (length + TINY), dy / (length + TINY), rho)
    for cx, cy, hx, hy in boxes:
        ax, ay = px - cx, py - cy
        sx = (ax > 0) - (ax < 0)
        sy = (ay > 0) - (ay < 0)
        qx, qy = abs(ax) - hx, abs(ay) - hy
        mx, my = (qx if qx > 0.0 else 0.0), (qy if qy > 0.0 else 0.0)
        outside = math.hypot(mx, my)
        if outside > 0.0:
            push(outside, sx * mx / (outside + TINY), sy * my / (outside + TINY), rho)
        else:
            depth = qx if qx > qy else qy
            push(depth if depth < 0.0 else 0.0, float(sx) if qx > qy else 0.0, 0.0 if qx > qy else float(sy), rho)
    for q in statics:
        dx, dy = px - q.real, py - q.imag
        length = math.hypot(dx, dy)
        push(length - static_radius, dx / (length + TINY), dy / (length + TINY), rho_static, False)
    return complex(fx, fy), wall, wall_normal


def inter_robot(
    position: Planar,
    neighbour_position: np.ndarray,
    neighbour_mask: np.ndarray,
    lam: Scalar,
    config: PlannerConfig,
    offsets: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[Planar, Scalar]:
    """Force from the lambda-neighbours ``S + (K,)`` selected by ``neighbour_mask``, and how many contributed.

    ``sum`` aggregates as the paper's equation; ``mean`` divides by the count (the predecessor's code;
    docs/algorithm.md, *What the literal formulas do*, shows it lets crowds collide). The robust preset keeps only the
    repulsive part of each term and rotates the total counter-clockwise by ``keep_right_deg`` (rotating every term by
    one angle is rotating their sum).
    """
    if neighbour_position.shape[-1] == 0:
        if isinstance(position, np.ndarray):
            return np.zeros(position.shape, dtype=complex), np.zeros(position.shape, dtype=int)
        return 0j, 0
    delta, d_true = offsets if offsets is not None else offsets_of(position, neighbour_position)
    mask = neighbour_mask & (d_true < config.sensing_range)
    d = np.maximum(d_true, config.min_distance)
    if config.margin:  # the neighbour seen margin closer: its repulsion ranges shift outward by the margin
        coefficient = 0.5 - per_item(lam) / np.maximum(d_true - config.margin, config.min_distance)
    else:
        coefficient = 0.5 - per_item(lam) / d
    if config.repulsive_only:
        if config.neighbour_range:
            coefficient = coefficient + np.maximum(per_item(lam) / config.neighbour_range - 0.5, 0.0)
        coefficient = np.minimum(coefficient, 0.0)
    force = plain(((mask * coefficient / d) * delta).sum(axis=-1))
    count = int(np.count_nonzero(mask)) if mask.ndim == 1 else mask.sum(axis=-1)
    if config.neighbour_aggregate == "mean":
        force = force / maximum(count, 1)
    if config.keep_right_deg:
        force = force * cmath.rect(1.0, math.radians(config.keep_right_deg))
    return force, count
