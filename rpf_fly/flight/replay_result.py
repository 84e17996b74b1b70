"""What a replay found (rpf_fly/flight/replay.py): per drone and planning tick the logged and the replayed
decision, their difference, and the whole replay's JSON (``rpf-fly replay --json``, docs/replay.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any


@dataclass
class TickComparison:
    """One planning tick of one drone: what the flight logged and what the replay decided."""

    tick: int
    t_ns: int
    logged_mode: str
    logged_direction: complex
    replayed_mode: str
    replayed_direction: complex

    @property
    def direction_diff(self) -> float:
        """``|d_replay - d_log|``: the distance of the two planar direction vectors (each a unit vector or zero;
        for two unit vectors ``2 sin(angle / 2)``, the angle itself to 1e-7 below 1e-2 rad)."""
        return abs(self.replayed_direction - self.logged_direction)

    @property
    def angle_diff_rad(self) -> float | None:
        """The angle between the two directions (radians), None when either is zero (a stalled or faulted step)."""
        if abs(self.replayed_direction) == 0 or abs(self.logged_direction) == 0:
            return None
        a, b = self.logged_direction, self.replayed_direction
        return abs(math.atan2(a.real * b.imag - a.imag * b.real, a.real * b.real + a.imag * b.imag))


@dataclass
class DroneReplay:
    """Every compared tick of one drone, and what the replay had to say about it."""

    name: str
    tolerance: float
    ticks: list[TickComparison] = field(default_factory=list)
    restarts: int = 0
    """Planning (re)starts taken from the log (take-off, resumes after holds)."""
    skipped: int = 0
    """Logged planning ticks the replay could not plan: the drone had no tracked pose in the log then."""
    pose_mismatches: int = 0
    """Planning ticks where the rebuilt pose is not the logged one (a refused jump, a dropped frame)."""
    note: str = ""

    def diverges(self, c: TickComparison) -> bool:
        return c.replayed_mode != c.logged_mode or not c.direction_diff <= self.tolerance

    @property
    def first_divergence_tick(self) -> int | None:
        return next((c.tick for c in self.ticks if self.diverges(c)), None)

    @property
    def max_direction_diff(self) -> float:
        return max((c.direction_diff for c in self.ticks), default=0.0)

    @property
    def max_angle_diff_rad(self) -> float:
        return max((a for c in self.ticks if (a := c.angle_diff_rad) is not None), default=0.0)

    @property
    def mode_changes(self) -> int:
        """Ticks on which the replayed mode is not the logged one."""
        return sum(c.replayed_mode != c.logged_mode for c in self.ticks)

    @property
    def divergent_ticks(self) -> int:
        return sum(self.diverges(c) for c in self.ticks)

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "ticks": len(self.ticks),
            "first_divergence_tick": self.first_divergence_tick,
            "max_direction_diff": self.max_direction_diff,
            "mode_changes": self.mode_changes,
            "max_angle_diff_rad": self.max_angle_diff_rad,
            "divergent_ticks": self.divergent_ticks,
            "restarts": self.restarts,
            "skipped_ticks": self.skipped,
            "pose_mismatches": self.pose_mismatches,
        }
        if self.note:
            out["note"] = self.note
        return out


@dataclass
class ReplayResult:
    """A whole replay: the planner replayed, per drone the comparison, the cost, and the warnings to print."""

    planner: str
    policy: Path | None
    flown_planner: str
    same_as_flown: bool
    tolerance: float
    drones: dict[str, DroneReplay]
    ticks: int
    seconds: float
    exact_times: bool
    warnings: list[str] = field(default_factory=list)

    @property
    def seconds_per_tick(self) -> float:
        return self.seconds / self.ticks if self.ticks else 0.0

    def to_json(self) -> dict[str, Any]:
        """The JSON contract of ``rpf-fly replay --json`` (docs/replay.md)."""
        return {
            "planner": self.planner,
            "policy": str(self.policy) if self.policy is not None else None,
            "flown_planner": self.flown_planner,
            "same_as_flown": self.same_as_flown,
            "direction_diff": "unit-vector distance |d_replay - d_log| (0..2; ~ the angle in rad when small)",
            "tolerance": self.tolerance,
            "exact_times": self.exact_times,
            "ticks": self.ticks,
            "seconds_per_tick": self.seconds_per_tick,
            "drones": {name: d.to_json() for name, d in self.drones.items()},
            "warnings": list(self.warnings),
        }
