"""Contact between the fake world's drones, and between a drone and the mission's obstacles: who crashed, when.

A real Crazyflie that touches another one or a pole with a rotor does not fly on: it tumbles and falls. The fake
world (:class:`rpf_fly.emulator.fake_world.FakeWorld`) asks :class:`ContactModel` after every step which drones touched
something, and crashes them (:meth:`rpf_fly.emulator.fake_vehicle.Vehicle.crash`).

The model, on the drones' *true* centres (not the estimates, not the mocap):

- two drones touch when their centres come closer than `DRONE_CONTACT_M` (3D distance: each drone a sphere of half
  its rotor-tip span; a disc would let one pass 0.1 m under another, where its downwash alone would knock it down);
- a drone touches an obstacle when its centre comes within `OBSTACLE_CONTACT_M` of the obstacle's surface, in the
  plane (the mission's obstacles are vertical prisms; the geometry is the planner's own signed distance,
  :mod:`rpf_fly.planning.obstacles`, negative inside);
- only contacts where at least one of the two is airborne (above its floor or motors on) count: two drones resting
  on the floor cannot collide, and a drone parked next to a pole does not hit it. A wreck lying on the floor is
  still there to be hit by a drone that flies or takes off into it.

Pairs are checked along the straight segment each drone moved since the previous check (the exact first touch on
that segment), obstacles at points at most `SWEEP_STEP_M` apart along it, so a step made long by a busy machine
cannot carry a drone through another or through a thin obstacle. Each contact reports where on the segment it
happened; the world puts the drone back there (it stops where it hit).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from rpf_fly.mission.model import Obstacle
from rpf_fly.planning.factory import obstacle_set
from rpf_fly.planning.obstacles import nearest_obstacle

from .fake_firmware import Body

DRONE_SPAN_M = 0.13
"""Rotor-tip span of a Crazyflie 2.1 (metres). Source: the project's brief for the contact model, which gives
0.13 m. Cross-check: Bitcraze's Crazyflie 2.1 datasheet gives 92 x 92 x 29 mm "motor-to-motor and including
motor mount feet"; the stock propellers add about half their 45 mm diameter beyond each motor axis, so the tips
span between about 0.11 m (across a side) and 0.14 m (along a diagonal). The figure is the model's only size."""

DRONE_CONTACT_M = DRONE_SPAN_M
"""Two drones touch when their centres are closer than this: half a span each."""

OBSTACLE_CONTACT_M = DRONE_SPAN_M / 2.0
"""A drone touches an obstacle when its centre is closer than this to the obstacle's surface: half a span."""

SWEEP_STEP_M = 0.01
"""Largest spacing of the points checked against the obstacles along one step's motion."""


@dataclass(frozen=True)
class Contact:
    """One drone that touched something in the step just checked."""

    address: int
    reason: str
    """``"contact with <other address>"`` (10 hex digits, as in a radio URI) or ``"obstacle"``."""
    fraction: float
    """Where on the step's motion it touched: 0 at the previous check, 1 now."""
    position: tuple[float, float, float]
    """The drone's true centre at the touch (metres)."""


def address_text(address: int) -> str:
    """A radio address as the 10 hex digits of a URI (``E7E7E7E701``)."""
    return f"{address:010X}"


class ContactModel:
    """Finds the contacts of one step from the drones' bodies; remembers each drone's previous centre."""

    def __init__(self, obstacles: Sequence[Obstacle] = ()) -> None:
        self.obstacles = obstacle_set(list(obstacles))
        self._previous: dict[int, tuple[float, float, float]] = {}

    def check(self, bodies: Mapping[int, Body]) -> list[Contact]:
        """The contacts since the previous check, earliest first, at most one per drone (its first)."""
        addresses = list(bodies)
        if not addresses:
            return []
        now = np.array([bodies[a].position for a in addresses], dtype=float)
        before = np.array([self._previous.get(a, bodies[a].position) for a in addresses], dtype=float)
        self._previous = {a: bodies[a].position for a in addresses}
        airborne = np.array([bodies[a].airborne for a in addresses], dtype=bool)
        crashed = np.array([bodies[a].crashed for a in addresses], dtype=bool)
        found: list[tuple[float, int, str]] = []  # (fraction, index, reason)
        if len(addresses) > 1 and airborne.any():
            found += self._pairs(addresses, before, now, airborne, crashed)
        if not self.obstacles.is_empty:
            found += self._obstacles(before, now, airborne & ~crashed)
        contacts: list[Contact] = []
        seen: set[int] = set()
        for fraction, index, reason in sorted(found):
            if index in seen or crashed[index]:
                continue
            seen.add(index)
            p = before[index] + fraction * (now[index] - before[index])
            contacts.append(Contact(addresses[index], reason, fraction, (float(p[0]), float(p[1]), float(p[2]))))
        return contacts

    @staticmethod
    def _pairs(
        addresses: list[int], before: np.ndarray, now: np.ndarray, airborne: np.ndarray, crashed: np.ndarray
    ) -> list[tuple[float, int, str]]:
        """Pairs whose relative motion, a straight segment from ``before`` to ``now``, enters the contact distance:
        the first fraction ``s`` with ``|d0 + s (d1 - d0)| = DRONE_CONTACT_M``."""
        d0 = before[:, None, :] - before[None, :, :]
        delta = (now[:, None, :] - now[None, :, :]) - d0
        a = np.einsum("ijk,ijk->ij", delta, delta)
        b = np.einsum("ijk,ijk->ij", d0, delta)
        c = np.einsum("ijk,ijk->ij", d0, d0) - DRONE_CONTACT_M**2
        with np.errstate(divide="ignore", invalid="ignore"):
            root = np.sqrt(np.maximum(b * b - a * c, 0.0))
            first = np.where(c < 0.0, 0.0, (-b - root) / a)
        touching = (c < 0.0) | ((b * b - a * c >= 0.0) & (a > 0.0) & (first >= 0.0) & (first <= 1.0))
        n = len(addresses)
        upper = np.triu(np.ones((n, n), dtype=bool), 1)
        counts = airborne[:, None] | airborne[None, :]
        fresh = ~(crashed[:, None] & crashed[None, :])
        out: list[tuple[float, int, str]] = []
        for i, j in zip(*np.nonzero(touching & upper & counts & fresh)):
            s = float(first[i, j])
            out.append((s, int(i), f"contact with {address_text(addresses[j])}"))
            out.append((s, int(j), f"contact with {address_text(addresses[i])}"))
        return out

    def _obstacles(self, before: np.ndarray, now: np.ndarray, candidates: np.ndarray) -> list[tuple[float, int, str]]:
        """Candidates whose centre came within `OBSTACLE_CONTACT_M` of an obstacle surface along the step."""
        indices = np.flatnonzero(candidates)
        if not indices.size:
            return []
        moves = now[indices, :2] - before[indices, :2]
        steps = np.maximum(1, np.ceil(np.hypot(moves[:, 0], moves[:, 1]) / SWEEP_STEP_M)).astype(int)
        owner = np.repeat(np.arange(indices.size), steps)
        starts = np.cumsum(steps) - steps
        fractions = (np.arange(owner.size) - starts[owner] + 1) / steps[owner]
        xy = before[indices[owner], :2] + fractions[:, None] * moves[owner]
        distance = np.asarray(nearest_obstacle(xy[:, 0] + 1j * xy[:, 1], self.obstacles).distance).reshape(-1)
        out: list[tuple[float, int, str]] = []
        hit = distance < OBSTACLE_CONTACT_M
        for k in range(indices.size):
            where = np.flatnonzero(hit[starts[k] : starts[k] + steps[k]])
            if where.size:
                out.append((float(fractions[starts[k] + where[0]]), int(indices[k]), "obstacle"))
        return out
