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

:class:`FlightLoop` is the sequencer of the stages and owns the flight's state; its parts, each in a module of its
own, are the preflight (:mod:`rpf_fly.flight.loop_preflight`), the waits for a swarm's coordinator
(:mod:`rpf_fly.flight.loop_swarm`, where :class:`SwarmLink` is defined), the take-off
(:mod:`rpf_fly.flight.loop_takeoff`), the iteration and its planning tick (:mod:`rpf_fly.flight.loop_tick`), and the
landings and the supervisor's findings (:mod:`rpf_fly.flight.loop_landing`).
"""

from __future__ import annotations

import math
import signal
import threading
import time
from collections.abc import Callable, Collection

from rpf_fly.flight.agent import DroneAgent, PlannerLike
from rpf_fly.flight.commander import Commander
from rpf_fly.flight.events import ERROR, FATAL, INFO, WARNING, EventBus, FlightEvent
from rpf_fly.flight.gc_pacing import GcPacer
from rpf_fly.flight.loop_landing import LoopLanding
from rpf_fly.flight.loop_preflight import LoopPreflight
from rpf_fly.flight.loop_swarm import LoopSwarm, SwarmLink
from rpf_fly.flight.loop_takeoff import LoopTakeoff
from rpf_fly.flight.loop_tick import LoopIteration
from rpf_fly.flight.phases import DronePhase, FlightOutcome, SwarmPhase
from rpf_fly.flight.poses import PoseTracker
from rpf_fly.flight.recorder import NullRecorder, Recorder
from rpf_fly.flight.report import FlightReport, LoopStats
from rpf_fly.flight.supervisor import Supervisor
from rpf_fly.flight.swarm_plan import SwarmPlanner
from rpf_fly.flight.ticks import TickSchedule
from rpf_fly.flight.watchdog import LoopWatchdog, stall_timeout_s
from rpf_fly.mission.model import Drone, Mission
from rpf_fly.mocap.frame import MocapSource
from rpf_fly.radio.backend import DroneBackend, DroneState
from rpf_fly.radio.schedule import ExtposSchedule
from rpf_fly.sim.scenario import obstacle_set

__all__ = ["FlightLoop", "FlightReport", "LoopStats", "NullRecorder", "PlannerFactory", "Recorder", "SwarmLink"]


PlannerFactory = Callable[[Drone], PlannerLike]


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


class FlightLoop(LoopPreflight, LoopSwarm, LoopTakeoff, LoopIteration, LoopLanding):
    """Flies one mission with a backend (cflib over radio or fake radio) and a mocap source: the sequencer of the
    flight's stages. Every command to a drone goes through :attr:`commander`."""

    def __init__(
        self,
        mission: Mission,
        backend: DroneBackend,
        mocap: MocapSource,
        planner_factory: PlannerFactory,
        *,
        uris: dict[str, str] | None = None,
        recorder: Recorder | None = None,
        status_hook: Callable[[FlightLoop], None] | None = None,
        clock: Callable[[], float] = time.monotonic,
        drones: Collection[str] | None = None,
        swarm: SwarmLink | None = None,
        tick_offset: float | None = None,
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
        self.agents: dict[str, DroneAgent] = {
            d.name: DroneAgent.for_mission(d, planner_factory(d), mission) for d in mission.drones if d.name in own
        }
        self.others: tuple[str, ...] = tuple(d.name for d in mission.drones if d.name not in own)
        """The mission's drones this loop does not fly: in its drones' views from mocap only."""
        self.commander = Commander(
            backend,
            self.agents,
            self.events,
            clock,
            land_s=flight.land_s,
            land_settle_s=self.LAND_SETTLE_S,
            floor_z=0.0,
        )
        self.obstacles = obstacle_set(mission.obstacles)
        self.tracker = PoseTracker({d.name: d.rigid_body for d in mission.drones})
        self.tracker.estimate_of = self._estimate_of  # a jumped track is taken only where the drone thinks it is
        self.tracker.airborne_estimate_of = self._airborne_estimate_of  # and so is the first pose after a gap
        self.tracker.blind_drift_m_s2 = mission.safety.blind_drift_m_s2
        self.first_order = frozenset(first_order)
        self.supervisor = Supervisor(mission, self.obstacles, first_order=self.first_order)
        self.phase = SwarmPhase.CONNECTING
        self.stats = LoopStats()
        # A backend that queues setpoints for threads of its own measures their latency to the radio, and says
        # when they went out (CflibBackend); with another, the loop measures to its own send.
        self._take_latencies: Callable[[], list[float]] | None = getattr(backend, "take_setpoint_latencies", None)
        self._wait_sent: Callable[[list[str] | None, float], bool] | None = getattr(backend, "wait_sent", None)
        self.tick = 0
        if tick_offset is not None and not 0.0 <= tick_offset < 1.0:
            raise ValueError(f"tick_offset must be in [0, 1), not {tick_offset}")
        self.tick_offset = tick_offset
        self._ticks = TickSchedule(mission.flight.dt, 0.0)
        self._last_tick_s: float | None = None
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
        self._extpos = ExtposSchedule.for_uris(
            mission.radio.extpos_rate_hz, self.uris, packed=mission.radio.extpos == "packed"
        )  # a group's drones together
        self._last_status_s = -math.inf
        self._states: dict[str, DroneState] = {}
        self._watchdog = LoopWatchdog(self._on_loop_stall, stall_timeout_s(flight.dt), on_emergency=self._emergency_now)
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
        error: str | None = None
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

        def restore() -> None:
            signal.signal(signal.SIGINT, signal.default_int_handler)

        return restore

    def _set_phase(self, phase: SwarmPhase) -> None:
        self.phase = phase
        self.events.emit(INFO, "phase", f"swarm: {phase.value}")

    # -------------------------------------------------------------------------------------------- stages

    def _fly(self) -> None:
        self._set_phase(SwarmPhase.FLYING)
        started = self.clock()
        self._ticks = TickSchedule(self.mission.flight.dt, self._first_tick_s(started))
        self._last_tick_s = None
        all_arrived_at: float | None = None
        self._watchdog.arm(True)
        try:
            while not self._stop.is_set():
                self._spin_once(None)
                now = self.clock()
                flying = [
                    a
                    for a in self.agents.values()
                    if a.phase in (DronePhase.PLANNING, DronePhase.HOLDING, DronePhase.ARRIVED)
                ]
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
                    self.events.emit(
                        WARNING, "timeout", f"mission timeout ({self.mission.flight.timeout_s:.0f} s): landing"
                    )
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

    def _record_event(self, event: FlightEvent) -> None:
        self.recorder.event(event)

    # ---------------------------------------------------------------------------------------- console

    def snapshot(self) -> list[dict[str, object]]:
        """Per-drone status for the console: phase, position, goal distance, battery, link quality."""
        rows: list[dict[str, object]] = []
        for name, agent in self.agents.items():
            pose = self.tracker.get(name)
            state = self._states.get(name)
            rows.append(
                {
                    "name": name,
                    "phase": agent.phase.value,
                    "position": pose.position if pose else None,
                    "goal_distance": abs(agent.goal - pose.xy) if pose else None,
                    "battery_v": state.battery.voltage_v if state and state.battery else None,
                    "link_pct": state.link.quality_pct if state else None,
                    "reason": agent.reason,
                }
            )
        return rows
