"""Planner parameters and the two presets: ``paper`` (the formulas as printed) and ``robust`` (the default).

docs/algorithm.md lists what the literal formulas do in practice (*What the literal formulas do*: side flips,
mode-B collisions, livelock on symmetric swaps); *Presets* closes each gap with one option. Every option is a field here
so the bench can compare them one by one. Units: metres, metres per second, radians unless a name says degrees.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any, Literal

RPF3_TUNING: dict[str, float | bool] = {
    "guided_influence_range": 0.2,
    "repulsion_sum": True,
    "static_influence_range": 0.5,
    "waypoint_reach": 0.05,
    "neighbour_range": 0.8,
    "yield_gain": 1.0,
    "brake_distance": 0.1,
    "pair_brake_buffer": 0.04,
    "keep_right_deg": 45.0,
    "guide_around_parked": True,
}
"""What the ``rpf3`` kind flies on top of the robust preset (docs/algorithm.md, *RPF-3's tuning*, each measured on
the scene families): with guidance the mission's obstacles repel within 0.2 m of their margin-grown surface, summed
over every surface in range, the static neighbours within 0.5 m; a corner within 0.05 m counts as reached; the
moving neighbours repel within 0.8 m, their push turned 45 degrees to the right (20 in the robust preset); a drone
slows (to 20 % at most) where they push against its motion, brakes within 0.1 m of 2r + margin (+ 4 cm) of a
neighbour it heads for, and slides (its step into the wall scaled down) within 0.1 m of r + margin (+ 1 cm) of the
nearest obstacle; and the guidance routes round the drones it sees parked in the way, 0.2 m beyond 2r + margin
(``guide_around_parked``, docs/algorithm.md, *Guidance round parked drones*). The gains are the policy's,
unchanged; no other kind uses these."""


@dataclass(frozen=True)
class PlannerConfig:
    """Parameters of the APF with (soft) wall-following. Defaults are the ``robust`` preset with the paper's numbers."""

    safety_radius: float = 0.1
    """r: a drone-drone collision is ``d < 2r``, a drone-obstacle collision ``d_o < r`` (metres)."""
    sensing_range: float = 6.0
    """d_r: neighbours and obstacles farther than this are invisible to the drone (metres)."""
    influence_range: float = 10.0
    """rho: the repulsive force is zero beyond this surface distance (metres)."""
    wall_following: bool = True
    """Modes A (tangent) and B (soft rule); off gives the vanilla APF direction ``F_a + F_r + F_in``."""
    wall_threshold: float = 1.0
    """F_in_bar: above it the inter-robot force, not the current heading, picks the tangent side."""
    neighbour_aggregate: Literal["sum", "mean"] = "sum"
    """Sum (the paper's equation) or mean (the predecessor's code) of the pairwise forces. Keep the sum (4.2)."""
    soft_keeps_inter_robot: bool = True
    """robust 1: mode B heading is ``F_a + F_r + F_in + 2|F_r| n`` (the paper drops F_in in mode B)."""
    side_from_tangential_force: bool = True
    """robust 2: the side test uses ``|n1 . F_in|`` (the tangential part) instead of ``|F_in|``."""
    bend_near_surface: bool = True
    """robust 3: in mode A closer than 2r, bend the tangent outward by ``k = (2r - d_o) / r`` times the push."""
    keep_right_deg: float = 20.0
    """robust 4: rotate the inter-robot repulsion counter-clockwise by this angle so head-on pairs both veer right."""
    repulsive_only: bool = True
    """robust 4: keep only the repulsive part ``min(0, 0.5 - lambda/d)`` of each pairwise term."""
    static_neighbours_as_obstacles: bool = True
    """robust 5: a neighbour slower than ``static_speed`` (hovering, arrived) is an obstacle of radius r, not a
    lambda-neighbour."""
    static_speed: float = 0.15
    """m/s: below this speed a neighbour counts as static (arrived or holding). A hovering Crazyflie wobbles at
    0.05-0.1 m/s as mocap sees it; moving drones fly at the mission speed (0.5 m/s)."""
    min_distance: float = 1.0e-3
    """Distances are clamped to this (metres) inside the force formulas so overlaps give a finite, outward push."""
    margin: float = 0.0
    """Clearance kept beyond contact (metres): the forces, the soft rule, the bend of mode A and the observation see
    every obstacle surface and every other drone ``margin`` closer than it is, so the planner keeps drones
    ``2r + margin`` apart and ``r + margin`` from obstacles where it kept ``2r`` and ``r`` (docs/algorithm.md,
    *Margin*). 0 is the paper's planner, bit for bit."""
    capture_radius: float = 0.3
    """Closer to its goal than this (metres) and than to the nearest obstacle surface, a drone heads straight at
    the goal (plus the moving neighbours' force): :mod:`rpf_fly.planning.arrival`, docs/algorithm.md, *Arrival*.
    Goals inside the band where the repulsion beats the unit attraction are otherwise orbited, never reached.
    0 turns it off (the paper preset)."""
    guided_influence_range: float = 0.0
    """With ``guidance == "path"``: rho of the static repulsion (metres of the margin-grown surface distance) in
    place of ``influence_range``; 0 keeps ``influence_range``. The guidance path already clears every obstacle by
    ``r + margin``, so the repulsion only needs to act near that bound (docs/algorithm.md, *RPF-3's tuning*)."""
    neighbour_range: float = 0.0
    """Robust preset: each pairwise repulsion acts within ``min(2 lambda, neighbour_range)`` of the margin-grown
    distance, the term shifted so it falls to zero there (``max(0.5, lambda/R) - lambda/d``); 0: ``2 lambda``."""
    static_influence_range: float = 0.0
    """With ``repulsion_sum``: rho of the static neighbours' repulsion (metres); 0: as the obstacles'."""
    brake_distance: float = 0.0
    """Within this gap (metres) of ``2r + margin + brake_buffer`` a drone heading toward a neighbour slows in
    proportion to the gap, and within it of ``r + margin + brake_buffer`` from the nearest wall the part of its step
    into the wall shrinks the same way (:func:`rpf_fly.planning.speed.brake`); 0: off (the paper)."""
    brake_buffer: float = 0.01
    """Metres the brake keeps beyond ``r + margin`` from walls (and ``2r + margin`` from neighbours, unless
    ``pair_brake_buffer`` says otherwise)."""
    pair_brake_buffer: float | None = None
    """Metres the brake keeps beyond ``2r + margin`` from neighbours; None: ``brake_buffer``."""
    repulsion_sum: bool = False
    """Sum the static repulsion over every obstacle surface within range instead of the nearest one's (the paper);
    modes, the soft rule and the observation still read the nearest surface."""
    waypoint_reach: float = 0.0
    """With guidance: a drone nearer its waypoint corner than this (metres) is pulled on to the corner's next
    waypoint (:func:`rpf_fly.planning.planner.past_reached`); 0: only once the corner is behind it (the goal or the
    next corner in sight)."""
    yield_gain: float = 0.0
    """k: the drone flies at ``clip(1 + k (d . F_in), min_speed_fraction, 1)`` of its speed, slower where the moving
    neighbours push against its direction ``d`` (:mod:`rpf_fly.planning.speed`); 0: always full speed (the paper)."""
    min_speed_fraction: float = 0.2
    """The slowest a yielding drone flies, as a fraction of its speed."""
    guide_around_parked: bool = False
    """With guidance: the static neighbours (slower than ``static_speed``: parked on their goals, or holding) that
    may lie in a drone's way are routed around: its waypoint comes from the shortest path over the mission's
    obstacles plus those drones, each a circle of radius ``r + parked_clearance`` (else, with no way round, of
    radius ``r``) grown by ``r + margin`` like every obstacle (:meth:`rpf_fly.planning.guidance.Guidance.detour`).
    Off: the guidance knows the mission's obstacles only (the repulsion alone keeps drones off parked ones)."""
    parked_clearance: float = 0.2
    """Metres a detour keeps beyond ``2r + margin`` from a parked drone (``guide_around_parked``): a gap that leaves
    less than this between a parked drone and an obstacle is not taken."""
    guidance: Literal["none", "path"] = "none"
    """``path``: the attraction pulls toward the next waypoint of the shortest path around the obstacles inflated by
    ``r + margin`` that the drone can see, instead of straight at the goal (:mod:`rpf_fly.planning.guidance`)."""

    @staticmethod
    def robust(**overrides: Any) -> PlannerConfig:
        """The default preset (docs/algorithm.md, *Presets*): the paper's method with its gaps closed."""
        return replace(PlannerConfig(), **overrides)

    @staticmethod
    def paper(**overrides: Any) -> PlannerConfig:
        """The formulas as printed in the paper (docs/algorithm.md, *Forces*, *Heading*), kept for reproduction."""
        base = PlannerConfig(
            soft_keeps_inter_robot=False,
            side_from_tangential_force=False,
            bend_near_surface=False,
            keep_right_deg=0.0,
            repulsive_only=False,
            static_neighbours_as_obstacles=False,
            capture_radius=0.0,
        )
        return replace(base, **overrides)

    @staticmethod
    def preset(name: str, **overrides: object) -> PlannerConfig:
        """``robust`` or ``paper``."""
        if name == "robust":
            return PlannerConfig.robust(**overrides)
        if name == "paper":
            return PlannerConfig.paper(**overrides)
        raise ValueError(f"unknown planner preset {name!r} (expected 'robust' or 'paper')")
