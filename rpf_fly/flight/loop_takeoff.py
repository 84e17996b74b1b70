"""The flight loop's take-off (rpf_fly/flight/loop.py): arm every ready drone and wait for its supervisor, take
off, send the take-off again to a drone not rising, then start planning the drones that reached the flight height
and keep the others away from a drone that never left the floor. Why apart: the stage between the ground and the
planning has rules of its own (the arming's refusals, the retry, the grounded drones as obstacles).

:class:`LoopTakeoff` is a part of :class:`~rpf_fly.flight.loop.FlightLoop`: it reads and sets the loop's attributes
named in its body.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING

from rpf_fly.flight.agent import DroneAgent
from rpf_fly.flight.commander import ON_FLOOR_Z_M, Commander
from rpf_fly.flight.events import ERROR, INFO, WARNING, EventBus
from rpf_fly.flight.phases import DronePhase, SwarmPhase
from rpf_fly.flight.poses import PoseTracker
from rpf_fly.mission.model import Mission
from rpf_fly.radio.backend import DroneState

if TYPE_CHECKING:
    from rpf_fly.flight.loop_swarm import SwarmLink

ARM_CONFIRM_TIMEOUT_S = 3.0
"""How long a drone's supervisor may take from the arming request to ready-to-fly: immediate for a Crazyflie 2.x
(auto-armed), the motors' spin-up check for a Brushless, which gives up after ARMING_SPINUP_TIMEOUT_MS = 2 s; plus
the 10 Hz status telemetry."""


class LoopTakeoff:
    """Arming and take-off, up to the first planning tick."""

    TAKEOFF_SETTLE_S = 0.5
    TAKEOFF_RETRY_FRACTION = 0.75
    """A drone commanded to take off that has not risen `LIFT_OFF_M` this far into its take-off (at least
    `TAKEOFF_RETRY_MIN_S`) gets it again: the firmware's supervisor answers EBUSY in its short 'cannot fly' window,
    and cflib does not report it. Not sooner: the firmware's own drone leaves the floor late, its height loop's
    integrator winding up first (the reference trace p_hl_slow, tests/data/crazyflie_dynamics: 5 cm up
    1.55 s into a 3 s take-off, 52 % of it; 0.36 m up at 75 %), so an earlier retry would re-send every real
    drone's take-off."""
    TAKEOFF_RETRY_MIN_S = 1.0
    LIFT_OFF_M = 0.05

    mission: Mission
    agents: dict[str, DroneAgent]
    commander: Commander
    events: EventBus
    tracker: PoseTracker
    swarm: SwarmLink | None
    clock: Callable[[], float]
    _stop: threading.Event
    _stop_reason: str
    _states: dict[str, DroneState]
    _set_phase: Callable[[SwarmPhase], None]
    _spin_once: Callable[[float | None], None]
    _ground_neighbours: Callable[[set[str]], None]
    _await_takeoff: Callable[[list[DroneAgent]], list[DroneAgent]]

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
                if (
                    state is not None
                    and state.supervisor is not None
                    and state.telemetry_stamp_s is not None
                    and state.telemetry_stamp_s >= asked_at
                    and state.supervisor.can_fly
                ):
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
                self.commander.refuse_take_off(
                    agent,
                    f"its supervisor was not ready to fly "
                    f"{ARM_CONFIRM_TIMEOUT_S:.0f} s after the arming request ({why})",
                )
        refused = {a.name for a in asked if a.phase == DronePhase.FAILED}
        if refused:
            self._ground_neighbours(refused)
            self.events.emit(ERROR, "takeoff", f"{', '.join(sorted(refused))} stay on the ground; the others fly")
        return [a for a in ready if a.phase == DronePhase.READY]

    def _takeoff(self) -> None:
        self._set_phase(SwarmPhase.TAKEOFF)
        flight = self.mission.flight
        armed = self._arm()
        if self.swarm is not None and not self._stop.is_set():
            armed = self._await_takeoff(armed)
        if self._stop.is_set():  # interrupted while arming: nothing takes off
            for agent in armed:
                self.commander.refuse_take_off(
                    agent, "interrupted before take-off" + (f" ({self._stop_reason})" if self._stop_reason else "")
                )
            return
        floor = {a.name: p.position[2] for a in armed if (p := self.tracker.get(a.name)) is not None}
        commanded = 0
        for agent in armed:
            if self.commander.take_off(agent, flight.height, flight.takeoff_s):
                self.backend_arm_watchdog(agent.name)
                commanded += 1
        self.events.emit(
            INFO,
            "takeoff",
            f"take-off commanded: {commanded} drone(s) to {flight.height:.2f} m in {flight.takeoff_s:g} s",
        )
        started = self.clock()
        until = started + flight.takeoff_s + self.TAKEOFF_SETTLE_S
        retry_after_s = self.takeoff_retry_after_s(flight.takeoff_s)
        retry_s = max(1.0, flight.takeoff_s - retry_after_s)
        retried = False
        while self.clock() < until and not self._stop.is_set():
            self._spin_once(min(until, started + retry_after_s) if not retried else until)
            if not retried and self.clock() >= started + retry_after_s:
                retried = True
                for agent in self.agents.values():
                    pose = self.tracker.get(agent.name)
                    if (
                        agent.phase == DronePhase.TAKEOFF
                        and pose is not None
                        and pose.position[2] < floor.get(agent.name, 0.0) + self.LIFT_OFF_M
                    ):
                        self.events.emit(
                            WARNING,
                            "takeoff",
                            f"not rising {retry_after_s:.1f} s after its take-off: sending it again",
                            agent.name,
                        )
                        if self.commander.retry_take_off(agent, flight.height, retry_s):
                            # its new take-off gets the whole of its time and the settle
                            until = max(until, self.clock() + retry_s + self.TAKEOFF_SETTLE_S)
        grounded: set[str] = set()
        for agent in self.agents.values():
            if agent.phase != DronePhase.TAKEOFF:
                continue
            pose = self.tracker.get(agent.name)
            if pose is not None and pose.position[2] <= ON_FLOOR_Z_M:
                if self.commander.ground(
                    agent,
                    f"take-off did not lift it off (z = {pose.position[2]:.2f} m): "
                    "it stays on the floor, an obstacle in every view",
                ):
                    grounded.add(agent.name)
            elif pose is None or abs(pose.position[2] - flight.height) > max(0.15, 0.3 * flight.height):
                z = "no pose" if pose is None else f"z = {pose.position[2]:.2f} m"
                self.commander.land(agent, f"take-off did not reach {flight.height:.2f} m ({z})")
            elif self.commander.begin_planning(agent, pose.xy, self.clock()):
                self.events.emit(INFO, "takeoff", f"airborne at {pose.position[2]:.2f} m: planning", agent.name)
        if grounded:
            self._keep_clear_of(grounded)

    @classmethod
    def takeoff_retry_after_s(cls, takeoff_s: float) -> float:
        """How long after its take-off command a drone still on the floor gets the command again."""
        return max(cls.TAKEOFF_RETRY_MIN_S, cls.TAKEOFF_RETRY_FRACTION * takeoff_s)

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
            why = next(
                (
                    f"its goal is {abs(agent.goal - xy):.2f} m from {name}, which did not lift off"
                    for name, xy in spots.items()
                    if abs(agent.goal - xy) < r2
                ),
                None,
            )
            if why is not None:
                self.commander.land(agent, f"{why}: it lands where it is", ERROR)
        self.events.emit(
            ERROR,
            "takeoff",
            f"{', '.join(sorted(grounded))} did not lift off: on the floor where "
            f"{'it stands' if len(grounded) == 1 else 'they stand'}, in every view and the separation "
            "check; the others fly",
        )
