"""One planning tick for every drone that plans: batched where the planners are the same function, alone otherwise.

Why batch: planning ten drones one call at a time costs ten times the per-call overhead of numpy and onnxruntime
(about 50-130 us a drone inside the flight loop), and the last drone's setpoint leaves a millisecond after the mocap
frame. Drones whose planners compute the same pure function of a view (the same :class:`Planner` class, preset,
obstacles and gains source) are planned in ONE call on a batch of their own views, built exactly as each drone's
sensors would see it (:func:`views_of_drones`: row ``i`` holds drone ``i``'s neighbours in its range, predicted by
its own tracking lag). Every operation of the planner is row-wise, so no row sees another drone's view: the
isolation of one planner per drone is kept, at a fraction of the cost.

Isolation under faults: a batched call that raises, or a row whose direction is not finite, is not trusted; those
drones are planned alone on their own planner instance, so a fault stays that drone's :class:`PlannerFault` (it
holds and lands; the others fly on). A batched call over the planning budget cannot say which drone was slow, so
batching is switched off for the rest of the flight and each drone's own call is timed against the budget again.
A drone with a different planner (a wrapper, another policy) is always planned alone.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from typing import Callable, Mapping, Sequence, Union

import numpy as np

from rpf_fly.flight.agent import MAX_DIRECTION_NORM, DroneAgent, PlannerFault, PlanResult
from rpf_fly.flight.commander import ON_FLOOR_Z_M
from rpf_fly.flight.phases import DronePhase
from rpf_fly.flight.poses import TrackedPose
from rpf_fly.planning.gains import FixedGains
from rpf_fly.planning.obstacles import ObstacleSet
from rpf_fly.planning.onnx_policy import OnnxGains
from rpf_fly.planning.planner import Planner
from rpf_fly.planning.view import view_of_drone, views_of_drones

Outcome = Union[PlanResult, PlannerFault]


def _same_obstacles(a: ObstacleSet, b: ObstacleSet) -> bool:
    return a is b or all(np.array_equal(getattr(a, f.name), getattr(b, f.name)) for f in dataclasses.fields(ObstacleSet))


def _same_gains(a: object, b: object) -> bool:
    if isinstance(a, FixedGains) and isinstance(b, FixedGains):
        return a == b
    if type(a) is OnnxGains and type(b) is OnnxGains:
        return a.policy.path.resolve() == b.policy.path.resolve()
    return a is b


def same_function(a: object, b: object) -> bool:
    """Whether two drones' planners compute the same function of a view (so one batched call can serve both)."""
    return (
        type(a) is Planner
        and type(b) is Planner
        and a.config == b.config  # type: ignore[attr-defined]
        and _same_obstacles(a.obstacles, b.obstacles)  # type: ignore[attr-defined]
        and _same_gains(a.gains, b.gains)  # type: ignore[attr-defined]
    )


def in_the_way(phase: DronePhase, z: float, flight_height: float) -> bool:
    """Whether a drone in ``phase`` whose mocap height is ``z`` is in the other drones' views: airborne near the
    planning plane (above half the flight height: a drone on the floor is in nobody's way); a drone nobody commands
    any more (link lost, motors cut) until mocap shows it on the floor, since it may still hover, drift or fall
    there for up to 2 s. Pure, so the flight loop and ``rpf-fly replay`` decide it by the same code."""
    if phase in (DronePhase.LINK_LOST, DronePhase.EMERGENCY):
        return z > ON_FLOOR_Z_M
    return z > 0.5 * flight_height and not phase.terminal


def foreign_in_the_way(z: float) -> bool:
    """Whether a drone another process flies (a distributed flight's other worker) is in this one's drones' views:
    its phase is not known here, only what mocap sees, so it counts whenever it is off the floor (taking off,
    flying, landing, falling after its worker died). Pure, as :func:`in_the_way`."""
    return z > ON_FLOOR_Z_M


@dataclass
class Neighbourhood:
    """Every airborne drone's name, measured planar position and velocity (complex): what the mocap sees."""

    names: list[str]
    xy: np.ndarray
    velocity: np.ndarray

    @classmethod
    def of(cls, poses: Mapping[str, TrackedPose]) -> "Neighbourhood":
        """The neighbourhood of these tracked poses (the drones in the others' way), in their order: the order
        is the order of every drone's neighbours in its view, so the flight and a replay build it the same."""
        names = list(poses)
        return cls(
            names,
            np.array([poses[n].xy for n in names], dtype=complex),
            np.array([poses[n].velocity for n in names], dtype=complex),
        )

    def others_of(self, agent: DroneAgent) -> tuple[np.ndarray, np.ndarray]:
        """The others as ``agent`` plans with them: positions predicted by its own tracking lag, velocities."""
        keep = np.array([n != agent.name for n in self.names], dtype=bool)
        return self.xy[keep], self.velocity[keep]


def isolated(planner: object) -> bool:
    """Whether a drone's planner runs on a thread of its own with a wall-clock deadline: every planner but the
    product's own :class:`Planner` (pure numpy and onnxruntime, planned inline and batched, its stalls left to the
    loop watchdog). A wrapper, ORCA, the heading policy or a user's planner may block (a lock, I/O, a bug): on the
    loop thread it would stop every drone's setpoints; on its own thread it faults only its drone. Costs one thread
    hand-off per call (tens of microseconds)."""
    return type(planner) is not Planner


@dataclass
class SwarmPlanner:
    """Plans a tick of drones; ``batching`` turns off (for good) when a batched call runs over ``budget_s``."""

    sensing_range: float
    budget_s: float
    batching: bool = True
    clock: Callable[[], float] = time.thread_time
    """CPU time of the loop thread: a batch is judged by its own computing, not by GIL waits or pre-emption."""
    notes: list[str] = field(default_factory=list)
    """Why batching changed or a batch was not trusted, for the flight's event log (the caller drains it)."""
    hang_s: float = 0.25
    """Wall-clock deadline of an isolated planner's call (below the loop watchdog's 0.35 s: the loop keeps
    ticking for everyone else)."""
    _leaders: list[object] = field(default_factory=list, repr=False)
    _known: dict[int, tuple[object, int]] = field(default_factory=dict, repr=False)

    def plan(self, requests: Sequence[tuple[DroneAgent, complex]], world: Neighbourhood) -> dict[str, Outcome]:
        """``requests``: (agent, measured position) of every drone to plan this tick. Returns each drone's
        :class:`PlanResult`, or the :class:`PlannerFault` of its own planner."""
        out: dict[str, Outcome] = {}
        if self.batching:
            for group in self._groups(requests):
                if len(group) > 1:
                    out.update(self._plan_batch(group, world))
        for agent, measured in requests:
            if agent.name not in out:
                out[agent.name] = self._plan_alone(agent, measured, world)
        return out

    def _groups(self, requests: Sequence[tuple[DroneAgent, complex]]) -> list[list[tuple[DroneAgent, complex]]]:
        groups: dict[int, list[tuple[DroneAgent, complex]]] = {}
        for request in requests:
            groups.setdefault(self._group_of(request[0].planner), []).append(request)
        return list(groups.values())

    def _group_of(self, planner: object) -> int:
        """Index of the first planner seen that computes the same function (cached: planners live for the flight)."""
        known = self._known.get(id(planner))
        if known is None:
            group = next((i for i, leader in enumerate(self._leaders) if same_function(leader, planner)), None)
            if group is None:
                group = len(self._leaders)
                self._leaders.append(planner)
            known = self._known[id(planner)] = (planner, group)
        return known[1]

    def _plan_alone(self, agent: DroneAgent, measured: complex, world: Neighbourhood) -> Outcome:
        lag_s = agent.tracking_lag_s(measured)
        xy, velocity = world.others_of(agent)
        view = view_of_drone(agent.reference, agent.goal, agent.heading, xy + lag_s * velocity, velocity, self.sensing_range)
        try:
            return agent.plan(view, measured, deadline_s=self.hang_s if isolated(agent.planner) else None)
        except PlannerFault as fault:
            return fault

    def _plan_batch(self, group: list[tuple[DroneAgent, complex]], world: Neighbourhood) -> dict[str, Outcome]:
        agents = [a for a, _ in group]
        measured = np.array([m for _, m in group], dtype=complex)
        lag_s = np.array([a.tracking_lag_s(m) for a, m in group])
        present = np.array(world.names, dtype=object)[None, :] != np.array([a.name for a in agents], dtype=object)[:, None]
        others = world.xy[None, :] + lag_s[:, None] * world.velocity[None, :]
        view = views_of_drones(
            np.array([a.reference for a in agents], dtype=complex),
            np.array([a.goal for a in agents], dtype=complex),
            np.array([a.heading for a in agents], dtype=complex),
            others,
            np.broadcast_to(world.velocity, others.shape),
            present,
            self.sensing_range,
        )
        started = self.clock()
        try:
            step = agents[0].planner.step(view)
            directions = np.asarray(step.direction, dtype=complex).reshape(len(agents))
        except Exception as err:  # noqa: BLE001 - the drones are planned alone next, where a fault is attributed
            self.notes.append(f"batched planning raised {type(err).__name__}: {err}; planning each drone alone")
            return {}
        seconds = self.clock() - started
        if seconds > self.budget_s:
            self.batching = False
            self.notes.append(
                f"batched planning of {len(agents)} drones took {seconds * 1e3:.1f} ms (budget "
                f"{self.budget_s * 1e3:.0f} ms): planning each drone alone from now on"
            )
        ok = np.isfinite(directions.real) & np.isfinite(directions.imag) & (abs(directions) <= MAX_DIRECTION_NORM)
        share = seconds / len(agents)
        return {
            agent.name: agent.accept(step, complex(directions[i]), complex(measured[i]), share, row=i)
            for i, agent in enumerate(agents)
            if ok[i]
        }

