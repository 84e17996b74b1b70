"""The flight loop's first stages (rpf_fly/flight/loop.py): connect every drone, run the preflight until each
passes or fails for good, restart each estimator at its mocap pose, and keep down the drones beside one that stays
on the ground. Why apart: the preflight is the loop's longest stage and the rules it applies come from
:mod:`rpf_fly.flight.preflight`; the loop only sequences them.

:class:`LoopPreflight` is a part of :class:`~rpf_fly.flight.loop.FlightLoop`: it reads and sets the loop's attributes
named in its body.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import TYPE_CHECKING

from rpf_fly.flight.agent import DroneAgent
from rpf_fly.flight.commander import Commander
from rpf_fly.flight.events import ERROR, WARNING, EventBus
from rpf_fly.flight.phases import DronePhase, SwarmPhase
from rpf_fly.flight.poses import PoseTracker
from rpf_fly.flight.preflight import (
    awaits_data,
    estimate_problem,
    orientation_problem,
    preflight_problem,
    yaw_of,
    yaw_problem,
)
from rpf_fly.mission.model import Mission
from rpf_fly.radio.backend import DroneBackend, DroneState

if TYPE_CHECKING:
    from rpf_fly.flight.loop_swarm import SwarmLink


class LoopPreflight:
    """Connecting, the preflight and the estimators' alignment; the grounded drones' neighbours kept down."""

    PREFLIGHT_TIMEOUT_S = 8.0
    """The longest the preflight waits for every drone to pass (a link, telemetry, a pose still to come)."""
    PREFLIGHT_SETTLED_S = 2.0
    """A drone whose preflight finding (tumbled, low battery, off its start, outside the arena...: not an absence of
    data, `preflight.awaits_data`) has held this long, fresh telemetry and mocap repeating it, fails now instead of
    at the timeout, once every other drone has passed or failed so too: a user with a drone on its back hears so in
    2 s, not 8."""
    ESTIMATOR_SETTLE_S = 3.0
    """How long the estimates may take to agree with mocap after their reset (extpos streams meanwhile)."""

    mission: Mission
    backend: DroneBackend
    uris: dict[str, str]
    agents: dict[str, DroneAgent]
    first_order: frozenset[str]
    commander: Commander
    events: EventBus
    tracker: PoseTracker
    swarm: SwarmLink | None
    phase: SwarmPhase
    clock: Callable[[], float]
    _stop: threading.Event
    _states: dict[str, DroneState]
    _set_phase: Callable[[SwarmPhase], None]
    _abort: Callable[[str], None]
    _spin_once: Callable[[float | None], None]
    _finish: Callable[[], None]

    def _connect(self) -> bool:
        self._set_phase(SwarmPhase.CONNECTING)
        failures = self.backend.connect(self.uris)
        for name, why in failures.items():
            why = (why.strip().splitlines() or ["no reason given"])[0]  # cflib appends a traceback to its reason
            self.commander.fail(self.agents[name], why if why.startswith("connection") else f"connection failed: {why}")
        if failures:
            self._abort(f"{len(failures)} drone(s) failed to connect: no drone takes off")
            return False
        for name, agent in self.agents.items():
            agent.set_controller(self.backend.state(name).controller_params, first_order=name in self.first_order)
        return True

    def _preflight(self) -> bool:
        """Every drone tracked, on the ground near its start, inside the arena, battery above the minimum; then its
        estimator restarted at its mocap pose and agreeing with it (preflight.py)."""
        self._set_phase(SwarmPhase.PREFLIGHT)
        deadline = self.clock() + self.PREFLIGHT_TIMEOUT_S
        problems: dict[str, str] = {}
        found_since: dict[str, float] = {}  # drone -> since when a finding (not a wait for data) has held
        while self.clock() < deadline and not self._stop.is_set():
            self._spin_once(deadline)
            problems = {name: self._preflight_problem(agent) for name, agent in self.agents.items()}
            problems = {n: p for n, p in problems.items() if p}
            now = self.clock()
            found_since = {n: found_since.get(n, now) for n, p in problems.items() if not awaits_data(p)}
            if all(n in found_since and now - found_since[n] >= self.PREFLIGHT_SETTLED_S for n in problems):
                break  # every drone passed, or fails for what the data has kept saying
        if not self._stop.is_set():
            problems.update(self._align_estimators([n for n in self.agents if n not in problems]))
        if self._stop.is_set():
            self._abort("interrupted before take-off")
            return False
        if problems:
            for name, problem in problems.items():
                self.commander.fail(self.agents[name], f"preflight failed: {problem}")
            # With a swarm, a loop whose every drone failed still reports and waits: the coordinator decides
            # whether the other loops' drones fly (as a single process would fly them).
            alone = self.swarm is None
            if self.mission.safety.on_preflight_failure == "abort" or (alone and len(problems) == len(self.agents)):
                self._abort(f"preflight failed for {', '.join(sorted(problems))}: no drone takes off")
                return False
            self._ground_neighbours(set(problems))
        flying = [a for a in self.agents.values() if a.phase == DronePhase.WAITING]
        if not flying and self.swarm is None:
            self._abort("no drone passed its preflight: no drone takes off")
            return False
        for agent in flying:
            self.commander.ready(agent)
        if problems:
            grounded = sorted(n for n, a in self.agents.items() if a.phase == DronePhase.FAILED)
            self.events.emit(ERROR, "preflight", f"{', '.join(grounded)} stay on the ground; the others fly")
        return True

    def _ground_neighbours(self, grounded: set[str]) -> None:
        """``safety.on_preflight_failure: ground``: a drone whose start or goal is within 2r of where a grounded
        drone stands could not take off or land there; it stays down too, and then stands where it is for the
        others in turn (A grounded, B's goal at A: B stays at its start, so C, whose goal is B's start, stays too).
        Every drone of the mission counts, this loop's or another's (a distributed flight's worker: the others'
        grounded drones come with the coordinator's go, their spots from this loop's mocap), so every loop reaches
        the same set as a single process would; only this loop's drones are commanded."""
        r2 = 2 * self.mission.planner.safety_radius
        down = set(grounded)
        new = set(grounded)
        while new:
            spots = {n: p.xy for n in sorted(new) if (p := self.tracker.get(n)) is not None}
            new = set()
            for drone in self.mission.drones:
                agent = self.agents.get(drone.name)
                if drone.name in down or (
                    agent is not None and agent.phase not in (DronePhase.WAITING, DronePhase.READY)
                ):
                    continue
                why = next(
                    (
                        f"its {what} is {abs(point - xy):.2f} m from {name}, which stays on the ground"
                        for name, xy in spots.items()
                        for what, point in (("start", complex(*drone.start)), ("goal", complex(*drone.goal)))
                        if abs(point - xy) < r2
                    ),
                    None,
                )
                if why is None:
                    continue
                new.add(drone.name)
                if agent is None:
                    continue  # another loop's: that loop keeps it down (it reaches the same set)
                if agent.phase == DronePhase.READY and self.phase == SwarmPhase.TAKEOFF:  # asked to arm: disarm
                    self.commander.refuse_take_off(agent, why)
                else:
                    self.commander.fail(agent, f"preflight: {why}")
            down |= new

    def _align_estimators(self, names: list[str]) -> dict[str, str]:
        """Restart every drone's on-board estimate at its mocap position and yaw, then wait until each estimate
        agrees with mocap (position and yaw). Why: with position-only extpos the yaw estimate starts wherever the
        estimator started (0 at power-on) and nothing corrects it; a drone powered on facing another way, or
        turned after power-on, flies off under position control (the classic Crazyflie fly-away). Returns
        name -> problem for the drones whose estimate does not agree (they do not take off)."""
        problems: dict[str, str] = {}
        reset_at = self.clock()
        turns = dict(self.tracker.orientation_glitches)
        for name in names:
            pose = self.tracker.get(name)
            before = yaw_problem(self._states.get(name), pose) if pose is not None else ""
            if before:  # the position converges with extpos; a yaw estimate never does
                self.events.emit(
                    WARNING, "estimator", f"before take-off: {before}; restarting its estimator at the mocap pose", name
                )
            if pose is not None and not pose.orientation_trusted:
                problems[name] = orientation_problem(self.tracker, name)
            elif pose is None or not self.commander.reset_estimator(
                self.agents[name], pose.position, yaw_of(pose.quaternion)
            ):
                problems[name] = "its estimator could not be reset (kalman.initialX/Y/Z/Yaw, resetEstimation)"
        deadline = self.clock() + self.ESTIMATOR_SETTLE_S
        pending = {n: "" for n in names if n not in problems}
        while pending and self.clock() < deadline and not self._stop.is_set():
            self._spin_once(min(deadline, self.clock() + 0.05))
            for name in list(pending):
                pose = self.tracker.get(name)
                problem = estimate_problem(self._states.get(name), pose, reset_at) if pose else "not tracked"
                if problem:
                    pending[name] = problem
                else:
                    del pending[name]
        problems.update(pending)
        for name in names:  # the yaw it was reset to came from one of two fits, and nothing says which was right
            if self.tracker.orientation_glitches.get(name, 0) != turns.get(name, 0):
                problems[name] = orientation_problem(self.tracker, name)  # the cause, over the yaw it left off
        return problems

    def preflight_only(self) -> dict[str, str]:
        """``rpf-fly check``: connect and run the preflight checks, take nothing off; name -> problem ('' if ok)."""
        try:
            if not self._connect():
                return {n: a.reason for n, a in self.agents.items()}
            self._preflight()
            return {n: (a.reason if a.phase == DronePhase.FAILED else "") for n, a in self.agents.items()}
        finally:
            self._finish()

    def _estimate_of(self, name: str) -> tuple[float, float, float] | None:
        """The drone's newest on-board position estimate from its telemetry (None: not one of this loop's drones,
        or no estimate yet)."""
        state = self._states.get(name)
        return state.position_m if state is not None else None

    def _airborne_estimate_of(self, name: str) -> tuple[tuple[float, float, float], float] | None:
        """A flying drone's newest on-board estimate and when the drone made it (`PoseTracker.airborne_estimate_of`):
        None on the ground (before take-off the estimate may not have been reset to mocap yet) or without one."""
        agent = self.agents.get(name)
        state = self._states.get(name)
        if agent is None or state is None or not agent.phase.airborne or state.position_m is None:
            return None
        made = state.estimate_stamp_s if state.estimate_stamp_s is not None else state.telemetry_stamp_s
        return (state.position_m, made) if made is not None else None

    def _preflight_problem(self, agent: DroneAgent) -> str:
        pose = self.tracker.get(agent.name)
        problem = preflight_problem(
            self.mission, agent, self._states.get(agent.name), pose, self.tracker.age(agent.name, self.clock())
        )
        if not problem and pose is not None and not pose.orientation_trusted:
            return orientation_problem(self.tracker, agent.name)
        return problem
