"""One iteration of the flight loop (rpf_fly/flight/loop.py): receive the newest mocap frame, plan and send at a
planning tick, forward extpos, record, supervise. Why apart: this is the loop's hot path, run at every frame of
every stage; the stages around it only decide when it plans.

:class:`LoopIteration` is a part of :class:`~rpf_fly.flight.loop.FlightLoop`: it reads and sets the loop's
attributes named in its body.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

from rpf_fly.flight.agent import DroneAgent, PlannerFault, PlanResult
from rpf_fly.flight.commander import Commander
from rpf_fly.flight.events import ERROR, WARNING, EventBus
from rpf_fly.flight.gc_pacing import GcPacer
from rpf_fly.flight.phases import DronePhase
from rpf_fly.flight.poses import PoseTracker, TrackedPose, estimator_position
from rpf_fly.flight.recorder import PlannerRecord, Recorder
from rpf_fly.flight.report import LoopStats
from rpf_fly.flight.supervisor import Finding, Supervisor
from rpf_fly.flight.swarm_plan import Neighbourhood, SwarmPlanner, foreign_in_the_way, in_the_way
from rpf_fly.flight.ticks import TickSchedule
from rpf_fly.flight.watchdog import LoopWatchdog
from rpf_fly.mission.model import Mission
from rpf_fly.mocap.frame import MocapFrame, MocapSource
from rpf_fly.planning.wall_following import MODE_NAMES
from rpf_fly.radio.backend import DroneBackend, DroneState
from rpf_fly.radio.schedule import ExtposSchedule


class LoopIteration:
    """The loop's iteration and its planning tick."""

    STATUS_PERIOD_S = 0.1
    SEND_WAIT_S = 0.002
    """How long a tick waits for the backend's sender threads to hand its setpoints to cflib (see `_plan_tick`)."""
    LATE_TICK_S = 0.1
    """A planning tick this much later than its period after the last one is a warning (``loop``): the drones
    flew on old setpoints that long (the firmware levels out 0.5 s after the last one). A normal flight's longest
    gap is the period plus 15-35 ms (a garbage collection: docs/performance.md); a stall the watchdog caught is
    said by the watchdog instead."""

    mission: Mission
    backend: DroneBackend
    mocap: MocapSource
    agents: dict[str, DroneAgent]
    others: tuple[str, ...]
    commander: Commander
    events: EventBus
    tracker: PoseTracker
    supervisor: Supervisor
    recorder: Recorder
    stats: LoopStats
    status_hook: Callable[..., None] | None
    clock: Callable[[], float]
    tick: int
    _ticks: TickSchedule
    _last_tick_s: float | None
    _last_status_s: float
    _stalls_seen: int
    _states: dict[str, DroneState]
    _estop: threading.Event
    _extpos: ExtposSchedule
    _watchdog: LoopWatchdog
    _gc: GcPacer
    _swarm_planner: SwarmPlanner
    _take_latencies: Callable[[], list[float]] | None
    _wait_sent: Callable[[list[str] | None, float], bool] | None
    _emergency_now: Callable[[], None]
    _apply: Callable[[list[Finding], float], None]
    _finish_landings: Callable[[float], None]

    def _spin_once(self, until_s: float | None) -> None:
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
        fresh = {
            n: p
            for n, p in self.tracker.poses.items()
            if p.frame_number == frame.frame_number and p.valid and n in self.agents
        }
        self.recorder.poses(now, fresh)
        extpose = self.mission.radio.extpos == "extpose"
        for name, pose in fresh.items():
            agent = self.agents[name]
            if agent.phase.terminal or not self._extpos.due(name, now):
                continue
            # an orientation refused as a jump (a wrong fit of the markers) is not fed to the estimator; a picture
            # later than the hold bound is carried ahead by its latency (estimator_position)
            self.commander.extpos(
                agent,
                estimator_position(pose, self.tracker.latency_s),
                pose.quaternion if extpose and pose.orientation_trusted else None,
                pose.stamp_s,  # a pose the loop or the radio held back too long is dropped (`EXTPOS_MAX_WAIT_S`)
            )

    def _in_the_way(self, agent: DroneAgent, pose: TrackedPose, now: float) -> bool:
        """Whether a drone is in the other drones' views: airborne near the planning plane; a drone nobody
        commands any more (link lost, motors cut) until mocap shows it on the floor, since it may still hover,
        drift or fall there for up to 2 s, or until the firmware has surely stopped it (`in_the_way`)."""
        return in_the_way(agent.phase, pose.position[2], self.mission.flight.height, now - pose.stamp_s)

    def _plan_tick(self, now: float, frame: MocapFrame | None) -> None:
        """Plan and send every drone's setpoint; the log records are written after the last send."""
        self.stats.ticks += 1
        self.tick += 1
        self._collect_latencies()  # the previous tick's, measured by the backend's sender threads
        self._watchdog.beat()
        flight = self.mission.flight
        stale_after = self.mission.safety.pose_timeout_s
        agents = self.agents
        airborne_poses = {
            n: p
            for n, p in self.tracker.poses.items()
            if (self._in_the_way(agents[n], p, now) if n in agents else foreign_in_the_way(p.position[2]))
        }
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
                if fresh and pose is not None:  # fresh: a pose, valid and recent
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

    def _take_plan(
        self,
        agent: DroneAgent,
        pose: TrackedPose,
        outcome: PlanResult | PlannerFault,
        now: float,
        frame: MocapFrame | None,
        sent: list,
        records: list,
        planned: list,
    ) -> None:
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

    def _send(
        self,
        agent: DroneAgent,
        xy: complex,
        frame: MocapFrame | None,
        sent: list[tuple[str, tuple[float, float, float], float]],
    ) -> None:
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

    def _late_tick(self, interval_s: float) -> None:
        """Say a gap between two planning ticks longer than the period plus `LATE_TICK_S` (the loop was blocked or
        starved), unless the watchdog already said it (it fired during the gap)."""
        stalls = self._watchdog.stalls
        caught, self._stalls_seen = stalls != self._stalls_seen, stalls
        period = self.mission.flight.dt
        if interval_s > period + self.LATE_TICK_S and not caught:
            self.events.emit(
                WARNING,
                "loop",
                f"flight loop late: {interval_s * 1e3:.0f} ms between two planning "
                f"ticks (period {period * 1e3:.0f} ms): the drones flew on old setpoints",
            )
