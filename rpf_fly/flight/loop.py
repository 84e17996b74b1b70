"""The flight loop: connect, preflight, take off, plan every drone from its own view, supervise, land.

One thread runs the loop. Every iteration takes the newest mocap frame (waiting at most until the end of the next
planning tick's window, so setpoints keep streaming even when mocap stops), forwards extpos to each drone at
``extpos_rate_hz``, runs the supervisor and applies its findings; at each planning tick (the mission rate, fired by
a frame the moment it arrives: :mod:`rpf_fly.flight.ticks`) every planning drone's own planner runs on that drone's
local view and its setpoint goes to the backend. A drone whose planner fails holds and
lands alone (:mod:`rpf_fly.flight.agent`); a loop that stops altogether is caught by the watchdog thread.

Every path out ends with the drones landing or stopped and the log closed: normal end, timeout, interrupt
(:meth:`FlightLoop.request_stop`: all land; :meth:`FlightLoop.emergency_stop`: motors off), an exception inside the
loop (all land, then the error is reported).
"""

from __future__ import annotations

import math
import signal
import threading
import time
from typing import Callable, Collection, Optional, Protocol, Union

import numpy as np

from rpf_fly.flight.agent import DroneAgent, PlannerFault, PlannerLike, PlanResult
from rpf_fly.flight.commander import ON_FLOOR_Z_M, TOUCHDOWN_TIMEOUT_S, Commander
from rpf_fly.flight.events import ERROR, FATAL, INFO, WARNING, EventBus, FlightEvent
from rpf_fly.flight.gc_pacing import GcPacer
from rpf_fly.flight.phases import DronePhase, FlightOutcome, SwarmPhase
from rpf_fly.flight.poses import PoseTracker, TrackedPose
from rpf_fly.flight.preflight import (awaits_data, estimate_problem, orientation_problem, preflight_problem,
                                     yaw_of, yaw_problem)
from rpf_fly.flight.recorder import NullRecorder, PlannerRecord, Recorder
from rpf_fly.flight.report import FlightReport, LoopStats
from rpf_fly.flight.supervisor import Finding, Supervisor
from rpf_fly.flight.swarm_plan import Neighbourhood, SwarmPlanner, foreign_in_the_way, in_the_way
from rpf_fly.flight.ticks import TickSchedule
from rpf_fly.flight.watchdog import LoopWatchdog, stall_timeout_s
from rpf_fly.mission.model import Drone, Mission
from rpf_fly.mocap.frame import MocapFrame, MocapSource
from rpf_fly.planning.wall_following import MODE_NAMES
from rpf_fly.radio.backend import DroneBackend, DroneState
from rpf_fly.radio.schedule import ExtposSchedule
from rpf_fly.sim.scenario import obstacle_set

__all__ = ["FlightLoop", "FlightReport", "LoopStats", "NullRecorder", "PlannerFactory", "Recorder"]


PlannerFactory = Callable[[Drone], PlannerLike]


class SwarmLink(Protocol):
    """What a loop that flies part of a swarm (a distributed flight's worker: rpf_fly/runtime/worker.py) asks of
    the swarm's coordinator. Without one the loop flies its drones alone: it takes off right after its preflight
    and ends once every drone arrived (``safety.arrival_hold_s``)."""

    def preflight_done(self, loop: "FlightLoop") -> None:
        """This loop's drones passed (or failed) their preflight: tell the coordinator."""

    def verdict(self) -> Optional[str]:
        """``go`` (take off), ``abort`` (nothing takes off) or None (not yet)."""

    def grounded(self) -> Collection[str]:
        """With ``go``: every drone of the swarm that stays on the ground (``safety.on_preflight_failure:
        ground``), whichever loop flies it; this loop keeps down its own drones beside them
        (:meth:`FlightLoop._ground_neighbours`)."""

    def armed(self, loop: "FlightLoop", refused: Collection[str]) -> None:
        """This loop armed its drones; ``refused``: those that stay down (their supervisors refused, or kept down
        beside them): tell the coordinator, which then says who takes off."""

    def takeoff(self) -> Optional[Collection[str]]:
        """Once every loop armed: every drone of the swarm that stays on the ground (the arming refusals of every
        loop, and the drones down since the go), this loop keeping its own beside them down; None: not yet."""


INTERRUPT_STOP = ("interrupted by Ctrl-C", "Ctrl-C: all drones land (Ctrl-C again: emergency stop)")
"""The first Ctrl-C's :meth:`FlightLoop.request_stop`: the reason each drone landed, and what the console says once
as the landing starts."""


def signal_stop(signum: int, drones: str = "all drones") -> tuple[str, str]:
    """:meth:`FlightLoop.request_stop`'s reason and notice for the signal ``signum``: SIGINT is Ctrl-C (a second
    one stops the motors), SIGTERM lands ``drones`` and says no more."""
    if signum == signal.SIGINT:
        return INTERRUPT_STOP[0], INTERRUPT_STOP[1].replace("all drones", drones)
    name = signal.Signals(signum).name
    return f"interrupted by {name}", f"{name}: {drones} land"


GO_TIMEOUT_S = 60.0
"""How long a loop with a :class:`SwarmLink` waits for its coordinator's go after its preflight, drones on the
ground, before it gives up (nothing takes off)."""

ARM_CONFIRM_TIMEOUT_S = 3.0
"""How long a drone's supervisor may take from the arming request to ready-to-fly: immediate for a Crazyflie 2.x
(auto-armed), the motors' spin-up check for a Brushless, which gives up after ARMING_SPINUP_TIMEOUT_MS = 2 s; plus
the 10 Hz status telemetry."""


class FlightLoop:
    """Flies one mission with a backend (cflib over radio or fake radio) and a mocap source: the sequencer of the
    flight's stages. Every command to a drone goes through :attr:`commander`."""

    TAKEOFF_SETTLE_S = 0.5
    LAND_SETTLE_S = 0.5
    FALL_WAIT_S = 3.0
    """How long the end of a flight waits, after a drone's link was lost or its motors were cut, for mocap to see it
    on the floor: its firmware levels it 0.5 s and cuts its motors 2 s after the last setpoint that reached it, and
    it falls from 1.5 m in 0.6 s. Until then it may still hover or drift where the others land, and the log should
    show where it came down (without the wait a one-drone flight would end, and close its log, with that drone still
    in the air)."""
    PREFLIGHT_TIMEOUT_S = 8.0
    """The longest the preflight waits for every drone to pass (a link, telemetry, a pose still to come)."""
    PREFLIGHT_SETTLED_S = 2.0
    """A drone whose preflight finding (tumbled, low battery, off its start, outside the arena...: not an absence of
    data, `preflight.awaits_data`) has held this long, fresh telemetry and mocap repeating it, fails now instead of
    at the timeout, once every other drone has passed or failed so too: a user with a drone on its back hears so in
    2 s, not 8."""
    STATUS_PERIOD_S = 0.1
    SEND_WAIT_S = 0.002
    """How long a tick waits for the backend's sender threads to hand its setpoints to cflib (see `_plan_tick`)."""
    LATE_TICK_S = 0.1
    """A planning tick this much later than its period after the last one is a warning (``loop``): the drones
    flew on old setpoints that long (the firmware levels out 0.5 s after the last one). A normal flight's longest
    gap is the period plus 15-35 ms (a garbage collection: docs/performance.md); a stall the watchdog caught is
    said by the watchdog instead."""

    def __init__(
        self,
        mission: Mission,
        backend: DroneBackend,
        mocap: MocapSource,
        planner_factory: PlannerFactory,
        *,
        uris: Optional[dict[str, str]] = None,
        recorder: Optional[Recorder] = None,
        status_hook: Optional[Callable[["FlightLoop"], None]] = None,
        clock: Callable[[], float] = time.monotonic,
        drones: Optional[Collection[str]] = None,
        swarm: Optional[SwarmLink] = None,
        tick_offset: Optional[float] = None,
        first_order: Collection[str] = (),
    ):
        """``first_order``: drones that are simulated with the first-order model (a dry run's `dynamics:
        first-order`), whose tracking the supervisor follows with that model, not the firmware's cascade.
        ``drones``: the names of the drones this loop flies (default: all of the mission's); the others are only
        seen, from mocap, as every drone sees its neighbours (a distributed flight's worker flies one dongle's).
        ``swarm``: the coordinator this loop waits for before take-off and whose ``finish`` ends it
        (:class:`SwarmLink`, :meth:`end`). ``tick_offset``: where in the planning period this loop's ticks fall, a
        fraction of the period in [0, 1) on a lattice of the monotonic clock (which every process of a host
        shares): the workers of a distributed flight on one host spread their ticks over the period (worker k of n
        at k/n), so they do not all plan on the same mocap frame and queue for the same cores (docs/distributed.md,
        *Ticks*). None: the ticks start when the flight does."""
        self.mission = mission
        self.backend = backend
        self.mocap = mocap
        own = {d.name for d in mission.drones} if drones is None else set(drones)
        unknown = sorted(own - {d.name for d in mission.drones})
        if unknown or not own:
            raise ValueError(f"drones not in the mission: {', '.join(unknown)}" if unknown else "no drone to fly")
        self.swarm = swarm
        self.uris = {n: u for n, u in (uris or {d.name: d.uri for d in mission.drones}).items() if n in own}
        self.recorder: Recorder = recorder or NullRecorder()
        self.status_hook = status_hook
        self.clock = clock
        self.events = EventBus(clock)
        self.events.subscribe(self._record_event)
        flight = mission.flight
        self.agents: dict[str, DroneAgent] = {d.name: DroneAgent.for_mission(d, planner_factory(d), mission)
                                              for d in mission.drones if d.name in own}
        self.others: tuple[str, ...] = tuple(d.name for d in mission.drones if d.name not in own)
        """The mission's drones this loop does not fly: in its drones' views from mocap only."""
        self.commander = Commander(backend, self.agents, self.events, clock, land_s=flight.land_s,
                                   land_settle_s=self.LAND_SETTLE_S, floor_z=0.0)
        self.obstacles = obstacle_set(mission.obstacles)
        self.tracker = PoseTracker({d.name: d.rigid_body for d in mission.drones})
        self.tracker.estimate_of = self._estimate_of  # a jumped track is taken only where the drone thinks it is
        self.tracker.airborne_estimate_of = self._airborne_estimate_of  # and so is the first pose after a gap
        self.tracker.blind_drift_m_s2 = mission.safety.blind_drift_m_s2
        self.supervisor = Supervisor(mission, self.obstacles, first_order=frozenset(first_order))
        self.phase = SwarmPhase.CONNECTING
        self.stats = LoopStats()
        # A backend that queues setpoints for threads of its own measures their latency to the radio, and says
        # when they went out (CflibBackend); with another, the loop measures to its own send.
        self._take_latencies: Optional[Callable[[], list[float]]] = getattr(backend, "take_setpoint_latencies", None)
        self._wait_sent: Optional[Callable[[Optional[list[str]], float], bool]] = getattr(backend, "wait_sent", None)
        self.tick = 0
        if tick_offset is not None and not 0.0 <= tick_offset < 1.0:
            raise ValueError(f"tick_offset must be in [0, 1), not {tick_offset}")
        self.tick_offset = tick_offset
        self._ticks = TickSchedule(mission.flight.dt, 0.0)
        self._last_tick_s: Optional[float] = None
        self._stalls_seen = 0
        """The watchdog's stall count at the last planning tick (`_late_tick`)."""
        self._down_since: dict[str, float] = {}
        """When mocap first saw each drone nobody commands any more on the floor (`_coming_down`)."""
        self._stop = threading.Event()
        self._stop_reason = ""
        self._stop_notice = ""
        self._end_reason = "mission complete"
        self._estop = threading.Event()
        self._estop_reason = ""
        self._estop_lock = threading.Lock()
        self._estop_done = False
        self._extpos = ExtposSchedule.for_uris(mission.radio.extpos_rate_hz, self.uris,
                                               packed=mission.radio.extpos == "packed")  # a group's drones together
        self._last_status_s = -math.inf
        self._states: dict[str, DroneState] = {}
        self._watchdog = LoopWatchdog(self._on_loop_stall, stall_timeout_s(flight.dt),
                                      on_emergency=self._emergency_now)
        self._gc = GcPacer()
        self._swarm_planner = SwarmPlanner(mission.planner.sensing_range, mission.safety.planner_budget_s)

    # ----------------------------------------------------------------------------------- external control

    def request_stop(self, reason: str = "interrupted", notice: str = "") -> None:
        """Land every drone and end the flight (first Ctrl-C). Safe from a signal handler: it only sets flags; the
        loop does the landing. ``reason`` is why each drone landed (its outcome's reason, the final table);
        ``notice`` what the ``interrupt`` event says once, as the landing starts (``reason`` when empty)."""
        self._stop_reason = reason
        self._stop_notice = notice or reason
        self._stop.set()

    def emergency_stop(self, reason: str = "emergency stop requested") -> None:
        """Cut every drone's motors now (second Ctrl-C). Safe from a signal handler: it only sets flags and wakes
        the safety thread, which sends the stop (radio I/O in a handler could deadlock on cflib's send lock, which
        the interrupted thread may hold); the loop does it too if it gets there first."""
        self._estop_reason = reason
        self._estop.set()
        self._stop.set()
        self._watchdog.emergency()

    def _emergency_now(self) -> None:
        """The safety thread or the loop thread: send the requested emergency stop, once."""
        with self._estop_lock:
            if self._estop_done:
                return
            self._estop_done = True
            self.commander.emergency_stop(self._estop_reason or "emergency stop requested")

    def end(self, reason: str) -> None:
        """End the flight normally: every drone lands (a distributed flight's coordinator: the mission is over).
        Safe from any thread: it only sets flags."""
        self._end_reason = reason
        self._stop.set()

    # ------------------------------------------------------------------------------------------------ run

    def run(self) -> FlightReport:
        """Fly the mission; always returns a report (and leaves no drone flying without a landing command).

        A KeyboardInterrupt (library use: Python's own SIGINT handler) lands every drone like the first Ctrl-C of
        ``rpf-fly fly``; a second one during that landing stops every motor. The report then says interrupted."""
        error: Optional[str] = None
        restore_interrupt = self._take_interrupts()
        self._watchdog.start()
        try:
            try:
                if self._connect() and self._preflight() and self._await_go() and not self._stop.is_set():
                    self._gc.start()  # from here on the collector runs in the gaps between frames (gc_pacing.py)
                    self._takeoff()
                    self._fly()
                if self.phase not in (SwarmPhase.ABORTED,):
                    if self._stop_reason:
                        self.events.emit(WARNING, "interrupt", self._stop_notice)
                    self._land_all(self._stop_reason or self._end_reason, told=bool(self._stop_reason))
            except KeyboardInterrupt:
                self.request_stop("interrupted by KeyboardInterrupt", "KeyboardInterrupt: every drone lands")
                self.events.emit(WARNING, "interrupt", self._stop_notice)
                try:
                    self._land_all(self._stop_reason, told=True)
                except KeyboardInterrupt:
                    self._estop_reason = "second KeyboardInterrupt: emergency stop, motors off"
                    self._estop.set()
                    self._emergency_now()
        except Exception as err:  # noqa: BLE001 - every path out lands the drones
            error = f"{type(err).__name__}: {err}"
            self.events.emit(FATAL, "error", f"flight loop failed ({error}): landing every drone")
            self._land_all("flight loop error", wait=True)
        finally:
            self._gc.stop()
            self.stats.gc = self._gc.stats
            try:
                self._finish()
            finally:
                self._watchdog.close()
                restore_interrupt()
        return FlightReport(
            mission=self.mission.name,
            phase=self.phase,
            outcomes={n: a.outcome or FlightOutcome.NOT_FLOWN for n, a in self.agents.items()},
            reasons={n: a.reason for n, a in self.agents.items()},
            events=list(self.events.history),
            stats=self.stats,
            interrupted=self._stop.is_set() and self._stop_reason != "",
            error=error,
        )

    def _take_interrupts(self) -> Callable[[], None]:
        """Library use on the main thread with Python's own SIGINT handler: for the flight, Ctrl-C sets flags as
        in ``rpf-fly fly`` (once: land every drone; twice: stop every motor) instead of raising KeyboardInterrupt
        wherever the loop happens to be (inside cflib's ``send_packet``, whose lock is then never released and
        that drone's link is dead). Returns what puts the previous handler back. A caller's own handler is kept."""
        if threading.current_thread() is not threading.main_thread():
            return lambda: None
        if signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
            return lambda: None
        presses = [0]

        def on_interrupt(signum: int, frame: object) -> None:
            presses[0] += 1
            if presses[0] == 1:
                self.request_stop(*INTERRUPT_STOP)
            else:
                self.emergency_stop("second Ctrl-C: emergency stop, motors off")

        signal.signal(signal.SIGINT, on_interrupt)
        return lambda: signal.signal(signal.SIGINT, signal.default_int_handler)

    def _set_phase(self, phase: SwarmPhase) -> None:
        self.phase = phase
        self.events.emit(INFO, "phase", f"swarm: {phase.value}")

    # -------------------------------------------------------------------------------------------- stages

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
            agent.set_controller(self.backend.state(name).controller_params)
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

    def _await_go(self) -> bool:
        """With a :class:`SwarmLink`: report the preflight and wait, drones on the ground, for the coordinator's go
        (mocap and telemetry keep flowing); its abort, a stop or the timeout: nothing takes off."""
        if self.swarm is None:
            return True
        self.swarm.preflight_done(self)
        deadline = self.clock() + GO_TIMEOUT_S
        while not self._stop.is_set():
            verdict = self.swarm.verdict()
            if verdict == "go":
                return self._ground_for_swarm(set(self.swarm.grounded()))
            if verdict == "abort":
                break
            if self.clock() > deadline:
                self.events.emit(ERROR, "swarm", f"no go from the coordinator within {GO_TIMEOUT_S:.0f} s")
                break
            self._spin_once(self.clock() + 0.05)
        self._abort("the swarm does not take off" + (f" ({self._stop_reason})" if self._stop_reason else ""))
        return False

    def _ground_for_swarm(self, grounded: set[str]) -> bool:
        """The coordinator's go names every drone of the swarm that stays on the ground: keep down this loop's
        drones beside them, before anything takes off, as a single process would (their spots from this loop's
        own mocap, which sees every drone). False when none of this loop's drones is left to fly."""
        ready = [n for n, a in self.agents.items() if a.phase == DronePhase.READY]
        if grounded - set(self.agents):
            self._ground_neighbours(grounded)
        kept = sorted(n for n in ready if self.agents[n].phase == DronePhase.FAILED)
        if kept:
            others = ", ".join(sorted(grounded - set(self.agents)))
            self.events.emit(ERROR, "preflight", f"{', '.join(kept)} stay on the ground beside the swarm's grounded "
                             f"drones ({others}); the others fly")
        if not any(a.phase == DronePhase.READY for a in self.agents.values()):
            self._abort("every drone of this loop stays on the ground; the swarm's others fly")
            return False
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
                if drone.name in down or (agent is not None and agent.phase not in (DronePhase.WAITING,
                                                                                    DronePhase.READY)):
                    continue
                why = next((f"its {what} is {abs(point - xy):.2f} m from {name}, which stays on the ground"
                            for name, xy in spots.items()
                            for what, point in (("start", complex(*drone.start)), ("goal", complex(*drone.goal)))
                            if abs(point - xy) < r2), None)
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

    ESTIMATOR_SETTLE_S = 3.0
    """How long the estimates may take to agree with mocap after their reset (extpos streams meanwhile)."""

    def _align_estimators(self, names: list[str]) -> dict[str, str]:
        """Restart every drone's on-board estimate at its mocap position and yaw, then wait until each estimate
        agrees with mocap (position and yaw). Why: with position-only extpos the yaw estimate starts wherever the
        estimator started (0 at power-on) and nothing corrects it; a drone powered on facing another way, or
        turned after power-on, flies off under position control (the classic Crazyflie fly-away). Returns
        name -> problem for the drones whose estimate does not agree (they do not take off)."""
        problems: dict[str, str] = {}
        reset_at = self.clock()
        for name in names:
            pose = self.tracker.get(name)
            before = yaw_problem(self._states.get(name), pose) if pose is not None else ""
            if before:  # the position converges with extpos; a yaw estimate never does
                self.events.emit(WARNING, "estimator", f"before take-off: {before}; restarting its estimator at the "
                                 "mocap pose", name)
            if pose is not None and not pose.orientation_trusted:
                problems[name] = orientation_problem(self.tracker, name)
            elif pose is None or not self.commander.reset_estimator(self.agents[name], pose.position,
                                                                    yaw_of(pose.quaternion)):
                problems[name] = "its estimator could not be reset (kalman.initialX/Y/Z/Yaw, resetEstimation)"
        deadline = self.clock() + self.ESTIMATOR_SETTLE_S
        pending = {n: "" for n in names if n not in problems}
        turns = dict(self.tracker.orientation_glitches)
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
            if name not in problems and self.tracker.orientation_glitches.get(name, 0) != turns.get(name, 0):
                problems[name] = orientation_problem(self.tracker, name)
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

    def _estimate_of(self, name: str) -> Optional[tuple[float, float, float]]:
        """The drone's newest on-board position estimate from its telemetry (None: not one of this loop's drones,
        or no estimate yet)."""
        state = self._states.get(name)
        return state.position_m if state is not None else None

    def _airborne_estimate_of(self, name: str) -> Optional[tuple[tuple[float, float, float], float]]:
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
        problem = preflight_problem(self.mission, agent, self._states.get(agent.name), pose,
                                    self.tracker.age(agent.name, self.clock()))
        if not problem and pose is not None and not pose.orientation_trusted:
            return orientation_problem(self.tracker, agent.name)
        return problem

    def _arm(self) -> list[DroneAgent]:
        """Arm every ready drone and wait until its supervisor says it can fly (a fresh telemetry sample after the
        request): the firmware refuses to arm a tumbled drone, and a motor that fails the arming spin-up check
        ends the arming 2 s later. Those stay on the ground with the reason; the armed ones are returned."""
        asked_at = time.monotonic()  # telemetry stamps are on time.monotonic()
        asked = [a for a in self.agents.values() if self.commander.arm(a)]
        pending = {a.name for a in asked}
        deadline = self.clock() + ARM_CONFIRM_TIMEOUT_S
        while pending and self.clock() < deadline and not self._stop.is_set():
            self._spin_once(min(deadline, self.clock() + 0.05))
            for name in list(pending):
                state = self._states.get(name)
                if (state is not None and state.supervisor is not None and state.telemetry_stamp_s is not None
                        and state.telemetry_stamp_s >= asked_at and state.supervisor.can_fly):
                    pending.discard(name)
        ready = []
        for agent in asked:
            if agent.name not in pending:
                ready.append(agent)
                continue
            state = self._states.get(agent.name)
            sup = state.supervisor if state is not None else None
            if sup is None:
                why = "no supervisor telemetry"
            elif sup.tumbled:
                why = "it reports tumbled (lying on its back or tilted): set it upright"
            elif sup.armed:
                why = "armed but its motors did not pass the spin-up check"
            else:
                why = "not armed (its pre-flight checks did not pass)"
            if not self._stop.is_set():
                self.commander.refuse_take_off(agent, f"its supervisor was not ready to fly "
                                                      f"{ARM_CONFIRM_TIMEOUT_S:.0f} s after the arming request ({why})")
        refused = {a.name for a in asked if a.phase == DronePhase.FAILED}
        if refused:
            self._ground_neighbours(refused)
            self.events.emit(ERROR, "takeoff", f"{', '.join(sorted(refused))} stay on the ground; the others fly")
        return [a for a in ready if a.phase == DronePhase.READY]

    TAKEOFF_RETRY_S = 1.0
    """A drone commanded to take off that has not risen `LIFT_OFF_M` this long after the command gets it again
    (the firmware's supervisor answers EBUSY in its short 'cannot fly' window, and cflib does not report it)."""
    LIFT_OFF_M = 0.05

    def _takeoff(self) -> None:
        self._set_phase(SwarmPhase.TAKEOFF)
        flight = self.mission.flight
        armed = self._arm()
        if self.swarm is not None and not self._stop.is_set():
            armed = self._await_takeoff(armed)
        if self._stop.is_set():  # interrupted while arming: nothing takes off
            for agent in armed:
                self.commander.refuse_take_off(agent, "interrupted before take-off" + (
                    f" ({self._stop_reason})" if self._stop_reason else ""))
            return
        floor = {a.name: p.position[2] for a in armed if (p := self.tracker.get(a.name)) is not None}
        commanded = 0
        for agent in armed:
            if self.commander.take_off(agent, flight.height, flight.takeoff_s):
                self.backend_arm_watchdog(agent.name)
                commanded += 1
        self.events.emit(INFO, "takeoff", f"take-off commanded: {commanded} drone(s) to {flight.height:.2f} m in "
                         f"{flight.takeoff_s:g} s")
        started = self.clock()
        until = started + flight.takeoff_s + self.TAKEOFF_SETTLE_S
        retried = False
        while self.clock() < until and not self._stop.is_set():
            self._spin_once(min(until, started + self.TAKEOFF_RETRY_S) if not retried else until)
            if not retried and self.clock() >= started + self.TAKEOFF_RETRY_S:
                retried = True
                for agent in self.agents.values():
                    pose = self.tracker.get(agent.name)
                    if agent.phase == DronePhase.TAKEOFF and pose is not None and \
                            pose.position[2] < floor.get(agent.name, 0.0) + self.LIFT_OFF_M:
                        self.events.emit(WARNING, "takeoff", f"not rising {self.TAKEOFF_RETRY_S:.0f} s after its "
                                         "take-off: sending it again", agent.name)
                        self.commander.retry_take_off(agent, flight.height, max(1.0, flight.takeoff_s -
                                                                                self.TAKEOFF_RETRY_S))
        grounded: set[str] = set()
        for agent in self.agents.values():
            if agent.phase != DronePhase.TAKEOFF:
                continue
            pose = self.tracker.get(agent.name)
            if pose is not None and pose.position[2] <= ON_FLOOR_Z_M:
                if self.commander.ground(agent, f"take-off did not lift it off (z = {pose.position[2]:.2f} m): "
                                                "it stays on the floor, an obstacle in every view"):
                    grounded.add(agent.name)
            elif pose is None or abs(pose.position[2] - flight.height) > max(0.15, 0.3 * flight.height):
                z = "no pose" if pose is None else f"z = {pose.position[2]:.2f} m"
                self.commander.land(agent, f"take-off did not reach {flight.height:.2f} m ({z})")
            elif self.commander.begin_planning(agent, pose.xy, self.clock()):
                self.events.emit(INFO, "takeoff", f"airborne at {pose.position[2]:.2f} m: planning", agent.name)
        if grounded:
            self._keep_clear_of(grounded)

    def backend_arm_watchdog(self, name: str) -> None:
        """From its take-off on, the drone's firmware stops it about 1 s after the keep-alives stop (a killed
        ground station, an unplugged dongle, a lost link), in every phase (docs/flight.md)."""
        arm = getattr(self.commander.backend, "arm_watchdog", None)
        if arm is not None:
            arm(name)

    def _keep_clear_of(self, grounded: set[str]) -> None:
        """Drones that never left the floor stand where they are: a drone whose goal is within 2r of one would
        land on it, so it lands now, where it took off, instead of flying there."""
        r2 = 2 * self.mission.planner.safety_radius
        spots = {n: p.xy for n in sorted(grounded) if (p := self.tracker.get(n)) is not None}
        for agent in self.agents.values():
            if agent.phase not in (DronePhase.PLANNING, DronePhase.HOLDING, DronePhase.TAKEOFF):
                continue
            why = next((f"its goal is {abs(agent.goal - xy):.2f} m from {name}, which did not lift off"
                        for name, xy in spots.items() if abs(agent.goal - xy) < r2), None)
            if why is not None:
                self.commander.land(agent, f"{why}: it lands where it is", ERROR)
        self.events.emit(ERROR, "takeoff", f"{', '.join(sorted(grounded))} did not lift off: on the floor where "
                         f"{'it stands' if len(grounded) == 1 else 'they stand'}, in every view and the separation "
                         "check; the others fly")

    def _await_takeoff(self, armed: list[DroneAgent]) -> list[DroneAgent]:
        """With a :class:`SwarmLink`: report the arming and wait, drones armed on the ground, for the coordinator's
        ``takeoff``; keep down this loop's armed drones beside every drone of the swarm that stays on the ground
        (another loop's arming refusal included: a drone landing on one would crash), as a single process keeps
        them down beside its own refusals (:meth:`_arm`). Its abort, a stop or the timeout: every armed drone is
        disarmed and stays down. Returns the drones that take off."""
        refused = sorted(n for n, a in self.agents.items() if a.phase == DronePhase.FAILED)
        self.swarm.armed(self, refused)  # type: ignore[union-attr]
        deadline = self.clock() + GO_TIMEOUT_S
        why = "the swarm does not take off"
        while not self._stop.is_set():
            grounded = self.swarm.takeoff()  # type: ignore[union-attr]
            if grounded is not None:
                others = set(grounded) - set(self.agents)
                if others:
                    self._ground_neighbours(set(grounded))
                kept = sorted(a.name for a in armed if a.phase == DronePhase.FAILED)
                if kept:
                    self.events.emit(ERROR, "takeoff", f"{', '.join(kept)} stay on the ground beside the swarm's "
                                     f"grounded drones ({', '.join(sorted(others))}); the others fly")
                return [a for a in armed if a.phase == DronePhase.READY]
            if self.swarm.verdict() == "abort":  # type: ignore[union-attr]
                break
            if self.clock() > deadline:
                why = f"no take-off from the coordinator within {GO_TIMEOUT_S:.0f} s"
                self.events.emit(ERROR, "swarm", why)
                break
            self._spin_once(self.clock() + 0.05)
        for agent in armed:  # on the ground, armed: disarming is safe
            self.commander.refuse_take_off(agent, why + (f" ({self._stop_reason})" if self._stop_reason else ""))
        return []

    def _fly(self) -> None:
        self._set_phase(SwarmPhase.FLYING)
        started = self.clock()
        self._ticks = TickSchedule(self.mission.flight.dt, self._first_tick_s(started))
        self._last_tick_s = None
        all_arrived_at: Optional[float] = None
        self._watchdog.arm(True)
        try:
            while not self._stop.is_set():
                self._spin_once(None)
                now = self.clock()
                flying = [a for a in self.agents.values() if a.phase in (DronePhase.PLANNING, DronePhase.HOLDING, DronePhase.ARRIVED)]
                if not flying:
                    self._end_reason = "no drone is flying its mission any more"
                    break
                if self.swarm is None and all(a.phase == DronePhase.ARRIVED for a in flying):
                    all_arrived_at = all_arrived_at if all_arrived_at is not None else now
                    if now - all_arrived_at >= self.mission.safety.arrival_hold_s:
                        self.events.emit(INFO, "arrived", "every flying drone is at its goal")
                        break
                else:
                    all_arrived_at = None
                if now - started > self.mission.flight.timeout_s:
                    self.events.emit(WARNING, "timeout", f"mission timeout ({self.mission.flight.timeout_s:.0f} s): landing")
                    for a in flying:
                        if a.phase != DronePhase.ARRIVED:
                            a.outcome = FlightOutcome.TIMEOUT
                    self._end_reason = "mission timeout"
                    break
        finally:
            self._watchdog.arm(False)

    def _first_tick_s(self, started: float) -> float:
        """The first planning tick's nominal time: at the start, or the lattice point of ``tick_offset`` at or
        after it (clock times ``(k + tick_offset) * period``)."""
        if self.tick_offset is None:
            return started
        period = self.mission.flight.dt
        return (math.ceil(started / period - self.tick_offset) + self.tick_offset) * period

    def _land_all(self, reason: str, wait: bool = True, told: bool = False) -> None:
        """Land every drone for ``reason``; the phase event names it unless an ``interrupt`` event just ``told``
        it (the console then says it once)."""
        if self.phase not in (SwarmPhase.ABORTED,):
            self.phase = SwarmPhase.LANDING
            self.events.emit(INFO, "phase", "swarm: landing" if told else f"swarm: landing ({reason})")
        self.commander.land_all(reason)
        if not wait:
            return
        deadline = self.clock() + self.mission.flight.land_s + self.LAND_SETTLE_S + TOUCHDOWN_TIMEOUT_S + 1.0
        while self.clock() < deadline and (any(a.phase == DronePhase.LANDING for a in self.agents.values())
                                           or self._coming_down(self.clock())):
            if self._estop.is_set():
                self._emergency_now()
                break
            try:
                self._spin_once(min(deadline, self.clock() + 0.1))
            except Exception:  # noqa: BLE001 - landing must finish even if the mocap or log misbehaves
                time.sleep(0.05)
                self._finish_landings(self.clock())

    def _coming_down(self, now: float) -> list[str]:
        """Drones nobody commands any more (link lost, motors cut) that mocap has not yet seen on the floor for
        `LAND_SETTLE_S` (a falling drone passes the floor line moving), within `FALL_WAIT_S` of losing them."""
        out = []
        for agent in self.agents.values():
            if agent.phase not in (DronePhase.LINK_LOST, DronePhase.EMERGENCY):
                continue
            if now - agent.phase_since_s >= self.FALL_WAIT_S:
                continue
            pose = self.tracker.get(agent.name)
            if pose is None or pose.position[2] > ON_FLOOR_Z_M:
                self._down_since.pop(agent.name, None)
                out.append(agent.name)
            elif now - self._down_since.setdefault(agent.name, now) < self.LAND_SETTLE_S:
                out.append(agent.name)
        return out

    def _abort(self, message: str) -> None:
        self.phase = SwarmPhase.ABORTED
        self.events.emit(ERROR, "phase", f"swarm: aborted ({message})")

    def _finish(self) -> None:
        """Close the backend only when nothing flies (cflib's close cuts the motors), then the recorder."""
        if self._estop.is_set():
            self._emergency_now()
        airborne = [a.name for a in self.agents.values() if a.phase.airborne]
        if self.phase != SwarmPhase.ABORTED and not airborne:
            self.phase = SwarmPhase.DONE
            self.events.emit(INFO, "phase", "swarm: done")
        if airborne:
            self.events.emit(FATAL, "error", f"still airborne at the end: {', '.join(airborne)}; emergency stop")
            self.commander.emergency_stop("still airborne at the end of the flight", airborne)
        for agent in self.agents.values():
            agent.close()
        try:
            now = self.clock()
            for agent in self.agents.values():
                if agent.outcome is None:
                    agent.outcome = FlightOutcome.NOT_FLOWN
                self.recorder.status(now, agent, self._states.get(agent.name))
        finally:
            try:
                self.backend.close()
                self._collect_latencies()
            finally:
                self.recorder.close()

    # ------------------------------------------------------------------------------------- the iteration

    def _spin_once(self, until_s: Optional[float]) -> None:
        """Receive the newest frame (waiting until ``until_s`` at most); at a planning tick plan and send first (its
        latency is what the drones feel), then forward extpos, record, and supervise. ``until_s`` None: flying,
        the wait and the ticks follow the flight's :class:`TickSchedule` (ticks locked to the mocap frames)."""
        if self._estop.is_set():
            self._emergency_now()
        ticks = self._ticks
        plan = until_s is None
        if until_s is None:
            until_s = ticks.window_end_s
        frame = self.mocap.receive(max(0.0, until_s - self.clock()))
        now = self.clock()
        if frame is not None:
            self.tracker.update(frame)
        ticked = plan and ticks.is_due(now, frame is not None)
        if ticked:
            self._plan_tick(now, frame)
            if self._last_tick_s is not None:
                self.stats.tick_intervals.append(now - self._last_tick_s)
                self._late_tick(now - self._last_tick_s)
            self._last_tick_s = now
            ticks.fired(now, frame is not None)
            self.stats.overruns, self.stats.frameless_ticks = ticks.overruns, ticks.frameless
        self._states = self.backend.states()
        if frame is not None:
            self._on_frame(frame, now)
        self._apply(self.supervisor.check(now, self.agents.values(), self.tracker, self._states, self.others), now)
        self._finish_landings(now)
        if now - self._last_status_s >= self.STATUS_PERIOD_S:
            self._last_status_s = now
            for agent in self.agents.values():
                self.recorder.status(now, agent, self._states.get(agent.name))
            if self.status_hook is not None:
                self.status_hook(self)
        self._gc.collect_if_due()  # the frame's work is done: a due collection goes in the gap before the next
        if ticked:
            self.recorder.after_tick(now)  # the log writer's burst goes in the gap before the next frame

    def _on_frame(self, frame: MocapFrame, now: float) -> None:
        """Record the frame's poses of the drones this loop flies and forward them to their estimators, each drone
        in its own extpos slots (``radio.extpos_rate_hz``, phased across the drones of a dongle:
        rpf_fly/radio/schedule.py)."""
        fresh = {n: p for n, p in self.tracker.poses.items()
                 if p.frame_number == frame.frame_number and p.valid and n in self.agents}
        self.recorder.poses(now, fresh)
        extpose = self.mission.radio.extpos == "extpose"
        for name, pose in fresh.items():
            agent = self.agents[name]
            if agent.phase.terminal or not self._extpos.due(name, now):
                continue
            # an orientation refused as a jump (a wrong fit of the markers) is not fed to the estimator
            self.commander.extpos(agent, pose.position,
                                  pose.quaternion if extpose and pose.orientation_trusted else None)

    def _finish_landings(self, now: float) -> None:
        stale_after = self.mission.safety.pose_timeout_s
        for agent in self.agents.values():
            if agent.phase == DronePhase.LANDING:
                pose = self.tracker.get(agent.name)
                fresh = pose is not None and pose.valid and now - pose.stamp_s <= stale_after
                self.commander.confirm_touchdown(agent, now, pose.position[2] if pose is not None else None, fresh,
                                                 self._states.get(agent.name))

    def _in_the_way(self, agent: DroneAgent, pose: TrackedPose) -> bool:
        """Whether a drone is in the other drones' views: airborne near the planning plane; a drone nobody
        commands any more (link lost, motors cut) until mocap shows it on the floor, since it may still hover,
        drift or fall there for up to 2 s."""
        return in_the_way(agent.phase, pose.position[2], self.mission.flight.height)

    def _plan_tick(self, now: float, frame: Optional[MocapFrame]) -> None:
        """Plan and send every drone's setpoint; the log records are written after the last send."""
        self.stats.ticks += 1
        self.tick += 1
        self._collect_latencies()  # the previous tick's, measured by the backend's sender threads
        self._watchdog.beat()
        flight = self.mission.flight
        stale_after = self.mission.safety.pose_timeout_s
        agents = self.agents
        airborne_poses = {n: p for n, p in self.tracker.poses.items()
                          if (self._in_the_way(agents[n], p) if n in agents else foreign_in_the_way(p.position[2]))}
        records: list[PlannerRecord] = []
        sent: list[tuple[str, tuple[float, float, float], float]] = []
        requests: list[tuple[DroneAgent, TrackedPose]] = []
        planned: list[tuple[DroneAgent, TrackedPose, PlanResult]] = []
        for agent in self.agents.values():
            pose = self.tracker.get(agent.name)
            mode = agent.phase.value
            fresh = pose is not None and pose.valid and now - pose.stamp_s <= stale_after
            if agent.phase == DronePhase.PLANNING and pose is not None and not fresh:
                # Never plan on a stale pose; the supervisor puts the drone on hold right after this tick.
                mode = "hold"
                self._send(agent, agent.reference, frame, sent)
            elif agent.phase == DronePhase.PLANNING and pose is not None:
                if abs(agent.goal - pose.xy) < flight.goal_tolerance:
                    self.commander.arrive(agent, now)
                else:
                    requests.append((agent, pose))
                    continue
            if agent.phase in (DronePhase.HOLDING, DronePhase.ARRIVED):
                mode = "arrived" if agent.phase == DronePhase.ARRIVED else "hold"
                if fresh:
                    agent.refine_hold(pose.xy, pose.velocity)
                self._send(agent, agent.hold_point, frame, sent)
            if agent.phase not in (DronePhase.WAITING, DronePhase.READY, DronePhase.FAILED):
                records.append((agent, pose, None, mode))
        if requests:
            # Plan on the commanded geometry (see flight/agent.py): each drone from its own reference, with each
            # neighbour predicted ahead by that drone's observed tracking lag; batched where planners allow
            # (flight/swarm_plan.py). Isolated planners (their own threads) get their views first; the drones that
            # have an answer are streamed at once, then each isolated one as it answers within the planning budget;
            # one still computing streams its reference unchanged.
            world = Neighbourhood.of(airborne_poses)
            tick = self._swarm_planner.start([(a, p.xy) for a, p in requests], world)
            by_name = {a.name: (a, p) for a, p in requests}
            for agent, pose in requests:
                outcome = tick.ready.get(agent.name)
                if outcome is not None:
                    del by_name[agent.name]
                    self._take_plan(agent, pose, outcome, now, frame, sent, records, planned)
            for name, outcome in tick.collect(min(self._swarm_planner.budget_s, self._swarm_planner.hang_s)):
                agent, pose = by_name.pop(name)
                self._take_plan(agent, pose, outcome, now, frame, sent, records, planned)
            for agent, pose in by_name.values():  # planner still computing: stay on the reference this tick
                self._send(agent, agent.reference, frame, sent)
                records.append((agent, pose, None, "hold"))
            for note in self._swarm_planner.notes:
                self.events.emit(WARNING, "planner_batch", note)
            self._swarm_planner.notes.clear()
        if sent and self._wait_sent is not None:
            # The backend's sender threads hand the setpoints to cflib now: wait (releasing the interpreter) until
            # they did, or SEND_WAIT_S at most, so the tick's records and checks come after them, not before (a
            # running thread keeps Python's interpreter lock for up to 5 ms). A dying link's sender stays blocked
            # in cflib; the loop does not wait for it longer than that.
            self._wait_sent(None, self.SEND_WAIT_S)
        for agent, pose, outcome in planned:  # after the sends: a batched row is cut out only now
            step = outcome.step
            records.append((agent, pose, step, MODE_NAMES.get(int(step.mode), "apf")))
        self.recorder.setpoints(sent)
        self.recorder.planner_steps(now, self.tick, records)

    def _take_plan(self, agent: DroneAgent, pose: TrackedPose, outcome: Union[PlanResult, PlannerFault], now: float,
                   frame: Optional[MocapFrame], sent: list, records: list, planned: list) -> None:
        """Stream a drone's planned setpoint, or hold and land it on its planner's fault."""
        if isinstance(outcome, PlannerFault):
            self.commander.hold(agent, pose.xy, now, str(outcome), pose.velocity)
            self.events.emit(ERROR, "planner_fault", f"{outcome}: holding, then landing", agent.name)
            self.commander.land(agent, "planner fault")
            records.append((agent, pose, None, "hold"))
            return
        self.stats.planner_seconds.append(outcome.seconds)
        self._send(agent, outcome.setpoint, frame, sent)
        planned.append((agent, pose, outcome))

    def _send(self, agent: DroneAgent, xy: complex, frame: Optional[MocapFrame],
              sent: list[tuple[str, tuple[float, float, float], float]]) -> None:
        z = agent.clamp_height(self.mission.flight.height)
        xy = agent.clamp(xy)
        origin = frame.receive_time_s if frame is not None else None
        if not self.commander.stream(agent, xy.real, xy.imag, z, origin):
            return
        t = self.clock()
        if origin is not None and self._take_latencies is None:  # a backend that sends at once
            self.stats.latencies.append(t - origin)
        sent.append((agent.name, (xy.real, xy.imag, z), t))

    def _collect_latencies(self) -> None:
        """The latencies the backend measured to cflib's hand-over of each setpoint (its sender threads)."""
        if self._take_latencies is not None:
            self.stats.latencies.extend(self._take_latencies())

    # ---------------------------------------------------------------------------------------- findings

    RESUMABLE = frozenset({"pose_stale", "mocap_lost", "pose_glitch", "separation", "obstacle"})
    """Hold reasons that end when the supervisor says the condition cleared."""

    def _apply(self, findings: list[Finding], now: float) -> None:
        sent: list[tuple[str, tuple[float, float, float], float]] = []
        for f in findings:
            self.events.emit(f.level, f.kind, f.message, f.drone)
            targets = [self.agents[f.drone]] if f.drone else list(self.agents.values())
            for agent in targets:
                if not agent.phase.airborne:
                    continue
                if f.response == "lost":
                    self.commander.link_lost(agent, f.message)
                elif f.response == "crashed":
                    self.commander.crashed(agent, f.message)
                elif f.response == "stop":
                    self.commander.emergency_stop(f.message, [agent.name], wait_s=Commander.LOOP_STOP_WAIT_S)
                elif f.response == "land":
                    self.commander.land(agent, f.message, duration_s=f.land_s)
                elif f.response == "hold":
                    pose = self.tracker.get(agent.name)
                    if pose is not None:
                        held = self.commander.hold(agent, pose.xy, now, f.kind, pose.velocity)
                    else:
                        held = self.commander.hold(agent, agent.reference, now, f.kind)
                    if held:  # now, not at the next planning tick: at 1 m/s a tick's wait is 0.1 m more
                        self._send(agent, agent.hold_point, None, sent)
                elif f.response == "resume" and agent.phase == DronePhase.HOLDING and agent.reason == f.kind:
                    pose = self.tracker.get(agent.name)
                    if pose is not None and pose.valid and f.kind in self.RESUMABLE:
                        self.commander.begin_planning(agent, pose.xy, now)
        if sent:
            self.recorder.setpoints(sent)

    def _late_tick(self, interval_s: float) -> None:
        """Say a gap between two planning ticks longer than the period plus `LATE_TICK_S` (the loop was blocked or
        starved), unless the watchdog already said it (it fired during the gap)."""
        stalls = self._watchdog.stalls
        caught, self._stalls_seen = stalls != self._stalls_seen, stalls
        period = self.mission.flight.dt
        if interval_s > period + self.LATE_TICK_S and not caught:
            self.events.emit(WARNING, "loop", f"flight loop late: {interval_s * 1e3:.0f} ms between two planning "
                             f"ticks (period {period * 1e3:.0f} ms): the drones flew on old setpoints")

    def _on_loop_stall(self) -> None:
        """Watchdog thread: the loop stopped ticking while drones stream setpoints: land them all now, through the
        commander, so the landing stands when the loop recovers (it streams to no drone that was told to land)."""
        self.events.emit(FATAL, "loop", "flight loop stalled: landing every drone (watchdog)")
        self.commander.land_all("flight loop stalled (watchdog)", FATAL)

    def _record_event(self, event: FlightEvent) -> None:
        self.recorder.event(event)

    # ---------------------------------------------------------------------------------------- console

    def snapshot(self) -> list[dict[str, object]]:
        """Per-drone status for the console: phase, position, goal distance, battery, link quality."""
        rows = []
        for name, agent in self.agents.items():
            pose = self.tracker.get(name)
            state = self._states.get(name)
            rows.append({
                "name": name,
                "phase": agent.phase.value,
                "position": pose.position if pose else None,
                "goal_distance": abs(agent.goal - pose.xy) if pose else None,
                "battery_v": state.battery.voltage_v if state and state.battery else None,
                "link_pct": state.link.quality_pct if state else None,
                "reason": agent.reason,
            })
        return rows
