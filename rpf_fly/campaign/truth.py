"""What the simulated world says happened (``/truth/<drone>``: true position, motors, crash), judged the same way
for every run, dry run or lab: no crash, no contact, nothing out of the arena, every drone down at the end.

The truth is the world's state, not what the stack believed: a stack that thinks a drone landed while it hovers
fails here.
"""

from __future__ import annotations

import math
from typing import Any

Truth = dict[str, list[tuple[int, dict]]]
"""Drone name -> its ``/truth`` samples [(log time ns, message)], one a world step."""

CONTACT_M = 0.13
"""Two airborne drones' true centres closer than this touch (a Crazyflie 2.1's rotor-tip span)."""
ON_FLOOR_M = 0.05
"""A drone at or below this true height stands on the floor."""
GOAL_M = 0.25
"""A drone reached its goal when it landed within this of it (goal tolerance 0.1 m plus the landing's drift)."""


def outside_arena(truth: Truth, arena: Any, r: float) -> list[str]:
    """The drones whose true position left the arena by more than ``r`` while flying or spinning, with how far. A
    drone standing with its motors off where it was put (a start offset beyond the edge, which its preflight rightly
    kept there) left nothing, so only airborne or motors-on samples count."""
    outside = []
    for n, samples in truth.items():
        for _, m in samples:
            p = m["position"]
            if not m["motors"] and p["z"] <= ON_FLOOR_M:
                continue
            excess = max(
                arena.x[0] - p["x"], p["x"] - arena.x[1], arena.y[0] - p["y"], p["y"] - arena.y[1], p["z"] - arena.z[1]
            )
            if excess > r:
                outside.append(f"{n} {excess:.2f} m")
                break
    return outside


def min_separation(truth: Truth) -> float | None:
    """Smallest true distance between two airborne drones at the same sample index (samples are per world step);
    None when no two drones were airborne together."""
    best: float | None = None
    length = min(len(s) for s in truth.values())
    for k in range(length):
        airborne = []
        for samples in truth.values():
            m = samples[k][1]
            p = m["position"]
            if m["motors"] or p["z"] > ON_FLOOR_M:
                airborne.append((p["x"], p["y"], p["z"]))
        for i in range(len(airborne)):
            for j in range(i + 1, len(airborne)):
                d = math.dist(airborne[i], airborne[j])
                best = d if best is None or d < best else best
    return best


def at_goal(samples: list[tuple[int, dict]], goal: tuple[float, float]) -> bool:
    """The drone's last true position is within `GOAL_M` of ``goal`` (horizontally)."""
    p = samples[-1][1]["position"]
    return math.dist((p["x"], p["y"]), goal) < GOAL_M


def truth_failures(truth: Truth, arena: Any, r: float) -> tuple[list[str], float | None]:
    """Every run's truth checks: no crash, no true position outside the arena by more than ``r``, no two airborne
    drones closer than `CONTACT_M`, every drone's motors off and on the floor at the end. The failures, and the
    smallest separation (for the report)."""
    failures = []
    crashed = sorted(n for n, s in truth.items() if any(m["crashed"] for _, m in s))
    if crashed:
        failures.append("crashed: " + ", ".join(crashed))
    outside = outside_arena(truth, arena, r)
    if outside:
        failures.append("outside the arena by more than r: " + ", ".join(outside))
    separation = min_separation(truth)
    if separation is not None and separation < CONTACT_M:
        failures.append(f"two airborne drones {separation:.3f} m apart (< {CONTACT_M} m)")
    for n, samples in truth.items():
        last = samples[-1][1]
        if last["motors"] or last["position"]["z"] > ON_FLOOR_M:
            failures.append(f"{n} not down at the end (motors {last['motors']}, z {last['position']['z']:.2f} m)")
    return failures, separation
