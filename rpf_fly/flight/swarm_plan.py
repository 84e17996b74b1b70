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
A drone with a different planner (a wrapper, another policy, ORCA, a user's planner) is always planned alone, on a
thread of its own (`isolated`), because such a planner may block. The tick hands each of them its view first and
plans the rest meanwhile (:meth:`SwarmPlanner.start`); the loop streams every drone that has its answer, then waits
a short while (the planning budget) for the isolated ones, streaming each as it answers (:meth:`TickPlan.collect`).
One that has not answered streams its reference unchanged this tick, takes its answer at the next tick, and is
faulted once its call is older than ``hang_s``: a planner that blocks never holds back another drone's setpoint
(before, the tick waited out the 0.25 s deadline, one isolated drone after the other, and every drone flew on an
old setpoint meanwhile).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import Future, as_completed
from concurrent.futures import TimeoutError as FutureTimeout
from dataclasses import dataclass, field
from typing import TypeAlias

import numpy as np

from rpf_fly.flight.agent import MAX_DIRECTION_NORM, DroneAgent, PlannerFault, PlanResult
from rpf_fly.flight.commander import ON_FLOOR_Z_M, UNCOMMANDED_DOWN_S
from rpf_fly.flight.phases import DronePhase
from rpf_fly.flight.poses import TrackedPose
from rpf_fly.planning.gains import FixedGains
from rpf_fly.planning.obstacles import ObstacleSet
from rpf_fly.planning.onnx_policy import OnnxGains
from rpf_fly.planning.planner import Planner
from rpf_fly.planning.view import view_of_drone, views_of_drones

Outcome: TypeAlias = PlanResult | PlannerFault


def _same_obstacles(a: ObstacleSet, b: ObstacleSet) -> bool:
    return a is b or all(
        np.array_equal(getattr(a, f.name), getattr(b, f.name)) for f in dataclasses.fields(ObstacleSet)
    )


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
        and a.config == b.config
        and _same_obstacles(a.obstacles, b.obstacles)
        and _same_gains(a.gains, b.gains)
    )


def in_the_way(phase: DronePhase, z: float, flight_height: float, unseen_s: float = 0.0) -> bool:
    """Whether a drone in ``phase`` whose mocap height is ``z`` is in the other drones' views: airborne near the
    planning plane (above half the flight height: a drone on the floor is in nobody's way); a drone nobody commands
    any more (link lost, motors cut) until mocap shows it on the floor, since it may still hover, drift or fall
    there for up to 2 s, or until its pose is ``UNCOMMANDED_DOWN_S`` old (``unseen_s``: how long ago mocap last
    saw it where its pose says); a drone that never left the floor (`DronePhase.GROUNDED`) wherever it stands, so
    nobody plans through its place. Pure, so the flight loop and ``rpf-fly replay`` decide it by the same code.

    Why the age: a crashed drone whose track froze in the air (mocap refused its fall to the wreck as a jump, and
    its estimate never agreed with the wreck) stayed in every view for the rest of the flight at its last speed, a
    moving neighbour repelling the others from goals within its range until the mission timed out."""
    if phase == DronePhase.GROUNDED:
        return True
    if phase in (DronePhase.LINK_LOST, DronePhase.EMERGENCY):
        return z > ON_FLOOR_Z_M and unseen_s <= UNCOMMANDED_DOWN_S
    return z > 0.5 * flight_height and not phase.terminal


def foreign_in_the_way(z: float) -> bool:
    """Whether a drone another process flies (a distributed flight's other worker) is in this one's drones' views:
    its phase is not known here, only what mocap sees, so it counts whenever it is off the floor (taking off,
    flying, landing, falling after its worker died). Pure, as :func:`in_the_way`."""
    return z > ON_FLOOR_Z_M


@dataclass
class Neighbourhood:
    """Every airborne drone's name, measured planar position, velocity and acceleration (complex): what the mocap
    sees."""

    names: list[str]
    xy: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray

    @classmethod
    def of(cls, poses: Mapping[str, TrackedPose]) -> Neighbourhood:
        """The neighbourhood of these tracked poses (the drones in the others' way), in their order: the order
        is the order of every drone's neighbours in its view, so the flight and a replay build it the same."""
        names = list(poses)
        return cls(
            names,
            np.array([poses[n].xy for n in names], dtype=complex),
            np.array([poses[n].velocity for n in names], dtype=complex),
            np.array([poses[n].acceleration for n in names], dtype=complex),
        )

    def others_of(self, agent: DroneAgent, measured: complex) -> tuple[np.ndarray, np.ndarray]:
        """The others as ``agent`` plans with them: positions predicted where their setpoints are
        (`DroneAgent.predict`), velocities."""
        keep = np.array([n != agent.name for n in self.names], dtype=bool)
        xy, velocity, acceleration = self.xy[keep], self.velocity[keep], self.acceleration[keep]
        return agent.predict(xy, velocity, acceleration, measured), velocity


def isolated(planner: object) -> bool:
    """Whether a drone's planner runs on a thread of its own with a wall-clock deadline: every planner but the
    product's own :class:`Planner` (pure numpy and onnxruntime, planned inline and batched, its stalls left to the
    loop watchdog). A wrapper, ORCA, the heading policy or a user's planner may block (a lock, I/O, a bug): on the
    loop thread it would stop every drone's setpoints; on its own thread it faults only its drone. Costs one thread
    hand-off per call (tens of microseconds)."""
    return type(planner) is not Planner


@dataclass
class _Call:
    """An isolated drone's planning call on its own thread: when it was handed its view (wall clock) and the
    drone's measured position then."""

    agent: DroneAgent
    future: Future
    submitted_s: float
    measured: complex


@dataclass
class TickPlan:
    """One tick's planning as it comes in: :attr:`ready` at once (batched and inline drones, the faults, an isolated
    drone's answer that came in after its tick), then :meth:`collect` for the isolated drones handed a view this
    tick, as each answers. A drone in neither has no answer this tick (its planner is still computing): the loop
    streams its reference unchanged, and it is faulted once its call is older than the deadline."""

    ready: dict[str, Outcome]
    _planner: SwarmPlanner
    _calls: list[_Call]

    def collect(self, wait_s: float) -> Iterator[tuple[str, Outcome]]:
        """The answers of this tick's isolated calls, in the order they come, for up to ``wait_s`` of wall time."""
        if not self._calls:
            return
        pending = {c.future: c for c in self._calls}
        self._calls = []
        try:
            for future in as_completed(pending, timeout=wait_s):
                call = pending[future]
                yield call.agent.name, self._planner._finish(call)
        except FutureTimeout:
            return


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
    """Wall-clock deadline of an isolated planner's call (below the loop watchdog's 0.35 s): past it, the drone is
    faulted. The loop never waits that long: the drones that answered are streamed at once."""
    wall: Callable[[], float] = time.monotonic
    _leaders: list[object] = field(default_factory=list, repr=False)
    _known: dict[int, tuple[object, int]] = field(default_factory=dict, repr=False)
    _calls: dict[str, _Call] = field(default_factory=dict, repr=False)
    """Isolated calls handed out and not yet taken, by drone."""

    def plan(self, requests: Sequence[tuple[DroneAgent, complex]], world: Neighbourhood) -> dict[str, Outcome]:
        """``requests``: (agent, measured position) of every drone to plan this tick. Returns each drone's
        :class:`PlanResult`, or the :class:`PlannerFault` of its own planner: waits for every isolated call (all
        at once) up to the deadline, and faults the ones that did not answer (``rpf-fly replay``, the tests)."""
        tick = self.start(requests, world)
        out = dict(tick.ready)
        out.update(tick.collect(self.hang_s))
        for agent, _ in requests:
            if agent.name not in out:
                self._calls.pop(agent.name, None)
                out[agent.name] = self._hung()
        return out

    def start(self, requests: Sequence[tuple[DroneAgent, complex]], world: Neighbourhood) -> TickPlan:
        """Hand every isolated drone its view (each planner's own thread computes meanwhile), plan the rest here
        (batched where planners allow), and return the tick's :class:`TickPlan`."""
        now = self.wall()
        ready: dict[str, Outcome] = {}
        fresh: list[_Call] = []
        inline: list[tuple[DroneAgent, complex]] = []
        for agent, measured in requests:
            if not isolated(agent.planner):
                inline.append((agent, measured))
                continue
            call = self._calls.get(agent.name)
            if call is not None:
                age = now - call.submitted_s
                if call.future.done() and age <= self.hang_s:
                    # Answered after its tick (the loop did not wait for it): take it now, planned one tick ago.
                    call.measured = measured
                    ready[agent.name] = self._finish(call)
                    continue
                if not call.future.done():
                    if age > self.hang_s:
                        del self._calls[agent.name]  # abandoned: its worker stays busy, a new call is refused
                        ready[agent.name] = self._hung()
                    continue  # still computing: no answer this tick
                del self._calls[agent.name]  # answered long ago (the drone was not planning since): stale
            view = self._view_of(agent, measured, world)
            try:
                future = agent.submit(view)
            except PlannerFault as fault:
                ready[agent.name] = fault
                continue
            call = self._calls[agent.name] = _Call(agent, future, now, measured)
            fresh.append(call)
        if self.batching:
            for group in self._groups(inline):
                if len(group) > 1:
                    ready.update(self._plan_batch(group, world))
        for agent, measured in inline:
            if agent.name not in ready:
                ready[agent.name] = self._plan_alone(agent, measured, world)
        return TickPlan(ready, self, fresh)

    def _hung(self) -> PlannerFault:
        return PlannerFault(f"planner did not return within {self.hang_s * 1e3:.0f} ms")

    def _finish(self, call: _Call) -> Outcome:
        self._calls.pop(call.agent.name, None)
        try:
            return call.agent.finish(call.future.result(timeout=0), call.measured)
        except PlannerFault as fault:
            return fault

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

    def _view_of(self, agent: DroneAgent, measured: complex, world: Neighbourhood):
        others, velocity = world.others_of(agent, measured)
        return view_of_drone(agent.reference, agent.goal, agent.heading, others, velocity, self.sensing_range)

    def _plan_alone(self, agent: DroneAgent, measured: complex, world: Neighbourhood) -> Outcome:
        """A drone of the product's own planner, planned inline on its own view."""
        try:
            return agent.plan(self._view_of(agent, measured, world), measured)
        except PlannerFault as fault:
            return fault

    def _plan_batch(self, group: list[tuple[DroneAgent, complex]], world: Neighbourhood) -> dict[str, Outcome]:
        agents = [a for a, _ in group]
        measured = np.array([m for _, m in group], dtype=complex)
        present = (
            np.array(world.names, dtype=object)[None, :] != np.array([a.name for a in agents], dtype=object)[:, None]
        )
        lag_s, lead_s2 = np.array([a.prediction(m) for a, m in group]).reshape(len(group), 2).T
        others = (
            world.xy[None, :]
            + lag_s[:, None] * world.velocity[None, :]
            + lead_s2[:, None] * world.acceleration[None, :]
        )
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
