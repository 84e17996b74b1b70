"""How the flight loop lands its drones and acts on its supervisor's findings (rpf_fly/flight/loop.py): land
every drone and wait for them to come down (a drone nobody commands any more included), confirm each touchdown,
and turn each finding into the commander's hold, resume, land, stop or lost link. Why apart: these are the paths
by which drones leave the air, whatever stage the loop is in.

:class:`LoopLanding` is a part of :class:`~rpf_fly.flight.loop.FlightLoop`: it reads and sets the loop's attributes
named in its body.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

from rpf_fly.flight.agent import DroneAgent
from rpf_fly.flight.commander import ON_FLOOR_Z_M, TOUCHDOWN_TIMEOUT_S, UNCOMMANDED_DOWN_S, Commander
from rpf_fly.flight.events import FATAL, INFO, EventBus
from rpf_fly.flight.phases import DronePhase, SwarmPhase
from rpf_fly.flight.poses import PoseTracker
from rpf_fly.flight.recorder import Recorder
from rpf_fly.flight.supervisor import Finding
from rpf_fly.mission.model import Mission
from rpf_fly.mocap.frame import MocapFrame
from rpf_fly.radio.backend import DroneState


class LoopLanding:
    """Landings, touchdowns and the supervisor's findings."""

    LAND_SETTLE_S = 0.5
    FALL_WAIT_S = UNCOMMANDED_DOWN_S
    """How long the end of a flight waits, after a drone's link was lost or its motors were cut, for mocap to see it
    on the floor: its firmware levels it 0.5 s and cuts its motors 2 s after the last setpoint that reached it, and
    it falls from 1.5 m in 0.6 s. Until then it may still hover or drift where the others land, and the log should
    show where it came down (without the wait a one-drone flight would end, and close its log, with that drone still
    in the air)."""
    RESUMABLE = frozenset({"pose_stale", "mocap_lost", "pose_glitch", "separation", "obstacle", "mocap_latency"})
    """Hold reasons that end when the supervisor says the condition cleared."""

    mission: Mission
    agents: dict[str, DroneAgent]
    commander: Commander
    events: EventBus
    tracker: PoseTracker
    recorder: Recorder
    phase: SwarmPhase
    clock: Callable[[], float]
    _estop: threading.Event
    _states: dict[str, DroneState]
    _down_since: dict[str, float]
    _emergency_now: Callable[[], None]
    _spin_once: Callable[[float | None], None]
    _send: Callable[[DroneAgent, complex, MocapFrame | None, list[tuple[str, tuple[float, float, float], float]]], None]

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
        while self.clock() < deadline and (
            any(a.phase == DronePhase.LANDING for a in self.agents.values()) or self._coming_down(self.clock())
        ):
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

    def _finish_landings(self, now: float) -> None:
        stale_after = self.mission.safety.pose_timeout_s
        for agent in self.agents.values():
            if agent.phase == DronePhase.LANDING:
                pose = self.tracker.get(agent.name)
                fresh = pose is not None and pose.valid and now - pose.stamp_s <= stale_after
                self.commander.confirm_touchdown(
                    agent, now, pose.position[2] if pose is not None else None, fresh, self._states.get(agent.name)
                )

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

    def _on_loop_stall(self) -> None:
        """Watchdog thread: the loop stopped ticking while drones stream setpoints: land them all now, through the
        commander, so the landing stands when the loop recovers (it streams to no drone that was told to land)."""
        self.events.emit(FATAL, "loop", "flight loop stalled: landing every drone (watchdog)")
        self.commander.land_all("flight loop stalled (watchdog)", FATAL)
