"""The commander: the one object through which every command reaches a drone, and the owner of each drone's phase.

Why one object: a flight has three threads that may command a drone (the loop, the watchdog when the loop is
stuck, the safety thread acting on a second Ctrl-C). If each sent what it thought right, a landing ordered by the
watchdog would be overridden by the loop's next streamed setpoint as soon as the loop recovered (a low-level
setpoint takes priority over the high-level land in the firmware), and the drone would fly on with nobody
planning for it. Here a drone's phase and the command that goes with it change together under that drone's lock:

- a setpoint is streamed only to a drone whose phase streams (planning, holding, arrived); after ``land`` (or an
  emergency stop, a lost link) nothing can stream to it again;
- every transition names the phases it may start from, so a stale decision of one thread (the loop planned a drone
  that the watchdog has since landed) is refused instead of undoing the other's;
- ``land`` and ``emergency_stop`` may be called from any thread; the loop's per-tick calls stay cheap (a lock
  that is never contended in normal flight).

Touchdown is confirmed before disarming (disarming a flying Crazyflie cuts its motors): the drone's mocap height
near the floor and its supervisor no longer reporting flying (:meth:`Commander.confirm_touchdown`).
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterable

from rpf_fly.flight.agent import DroneAgent
from rpf_fly.flight.events import ERROR, FATAL, INFO, WARNING, EventBus
from rpf_fly.flight.phases import DronePhase, FlightOutcome
from rpf_fly.radio.backend import DroneBackend, DroneState, Quaternion, Vec3

STREAMING = frozenset({DronePhase.PLANNING, DronePhase.HOLDING, DronePhase.ARRIVED})
"""Phases in which the drone follows streamed setpoints (the firmware levels out 0.5 s after the last one)."""

ON_FLOOR_Z_M = 0.1
"""Mocap height (above the arena floor) under which a drone counts as on the floor: a Crazyflie's markers sit a few
centimetres above its feet, and a landed drone's estimate settles within a few centimetres of the floor."""

UNCOMMANDED_DOWN_S = 3.0
"""A drone nobody commands any more (link lost, motors cut) is on the floor this long after the last setpoint
reached it, or after mocap last saw it: the firmware's commander watchdog stops its motors 2 s after its last
setpoint (COMMANDER_WDT_TIMEOUT_SHUTDOWN, 2000 ms, crazyflie-firmware src/modules/interface/commander.h), and 1 s
more is a fall from 4.9 m. The end of a flight waits this long for it (`LoopLanding.FALL_WAIT_S`); the others'
views drop its pose once it is this old (`swarm_plan.in_the_way`)."""

TOUCHDOWN_TIMEOUT_S = 3.0
"""How long after its landing should have ended a drone may take to be confirmed down before an event says it is
not (the firmware's own landing timeout is 3 s)."""


class Commander:
    """Owns each drone's phase and sends every command (see the module docstring). Thread-safe."""

    def __init__(
        self,
        backend: DroneBackend,
        agents: dict[str, DroneAgent],
        events: EventBus,
        clock: Callable[[], float],
        *,
        land_s: float,
        land_settle_s: float,
        floor_z: float,
    ):
        self.backend = backend
        self.agents = agents
        self.events = events
        self.clock = clock
        self.land_s = land_s
        self.land_settle_s = land_settle_s
        self.floor_z = floor_z
        self._locks = {name: threading.RLock() for name in agents}
        self._touchdown_late: set[str] = set()

    # ------------------------------------------------------------------------------------------ phases

    def _set(self, agent: DroneAgent, phase: DronePhase, reason: str = "", level: int = INFO) -> None:
        agent.set_phase(phase, self.clock(), reason)
        self.events.emit(level, "phase", f"{phase.value}{': ' + reason if reason else ''}", agent.name)

    def fail(self, agent: DroneAgent, reason: str) -> None:
        """Connection or preflight failure: the drone never flies."""
        with self._locks[agent.name]:
            agent.outcome = FlightOutcome.NOT_FLOWN
            self._set(agent, DronePhase.FAILED, reason, ERROR)

    def ready(self, agent: DroneAgent) -> None:
        with self._locks[agent.name]:
            if agent.phase == DronePhase.WAITING:
                self._set(agent, DronePhase.READY, "preflight passed")

    def reset_estimator(self, agent: DroneAgent, position: Vec3, yaw_rad: float) -> bool:
        """Restart the on-board estimate at the mocap pose; only on the ground, before take-off."""
        with self._locks[agent.name]:
            if agent.phase != DronePhase.WAITING:
                return False
            return self.backend.reset_estimator(agent.name, position, yaw_rad)

    def arm(self, agent: DroneAgent) -> bool:
        """Ask a ready drone's supervisor to arm it. The request is only asked: the sequencer takes off a drone
        once its telemetry says it can fly (:meth:`refuse_take_off` otherwise)."""
        with self._locks[agent.name]:
            if agent.phase != DronePhase.READY:
                return False
            if not self.backend.arm(agent.name, True):
                self.fail(agent, "arming request not delivered: it stays on the ground")
                return False
            return True

    def refuse_take_off(self, agent: DroneAgent, reason: str) -> None:
        """A ready drone whose supervisor did not get ready to fly: disarm (it is on the ground) and keep it
        there with ``reason``."""
        with self._locks[agent.name]:
            if agent.phase != DronePhase.READY:
                return
            self.backend.arm(agent.name, False)
            self.fail(agent, f"{reason}: it stays on the ground")

    def take_off(self, agent: DroneAgent, height_m: float, duration_s: float) -> bool:
        """High-level take-off of an armed drone (:meth:`arm`); one whose take-off is refused stays on the
        ground."""
        with self._locks[agent.name]:
            if agent.phase != DronePhase.READY:
                return False
            if not self.backend.takeoff(agent.name, height_m, duration_s):
                self.backend.arm(agent.name, False)  # still on the ground: disarming is safe
                self.fail(agent, "take-off command failed: it stays on the ground")
                return False
            self._set(agent, DronePhase.TAKEOFF)
            return True

    def retry_take_off(self, agent: DroneAgent, height_m: float, duration_s: float) -> bool:
        """Send a drone that is taking off but has not left the floor its take-off again (the firmware refused
        the first: its supervisor's short 'cannot fly' window answers EBUSY, which cflib does not report)."""
        with self._locks[agent.name]:
            if agent.phase != DronePhase.TAKEOFF:
                return False
            return self.backend.takeoff(agent.name, height_m, duration_s)

    def ground(self, agent: DroneAgent, reason: str) -> bool:
        """A drone commanded to take off that never left the floor: stop its plan and disarm it (it is on the
        floor), and keep it as an obstacle where it stands (`DronePhase.GROUNDED`)."""
        with self._locks[agent.name]:
            if agent.phase != DronePhase.TAKEOFF:
                return False
            self.backend.stop(agent.name)
            self.backend.arm(agent.name, False)
            agent.outcome = FlightOutcome.NOT_FLOWN
            self._set(agent, DronePhase.GROUNDED, reason, ERROR)
            return True

    def begin_planning(self, agent: DroneAgent, measured: complex, now_s: float) -> bool:
        """Take-off done, or a hold over: plan from the measured position again."""
        with self._locks[agent.name]:
            if agent.phase not in (DronePhase.TAKEOFF, DronePhase.HOLDING):
                return False
            agent.begin_planning(measured, now_s)
            return True

    def hold(self, agent: DroneAgent, at: complex, now_s: float, reason: str, velocity: complex = 0j) -> bool:
        """Stop planning and bring the drone to rest near ``at`` (where it is, moving at ``velocity``:
        `DroneAgent.hold`)."""
        with self._locks[agent.name]:
            if agent.phase != DronePhase.PLANNING:
                return False
            agent.hold(at, now_s, reason, velocity)
            return True

    def arrive(self, agent: DroneAgent, now_s: float) -> bool:
        with self._locks[agent.name]:
            if agent.phase != DronePhase.PLANNING:
                return False
            agent.hold_point = agent.goal
            agent.arrived_at_s = now_s
            self._set(agent, DronePhase.ARRIVED, "reached its goal")
            return True

    def link_lost(self, agent: DroneAgent, message: str) -> None:
        """Nothing reaches the drone any more: its firmware levels out, then cuts its motors."""
        with self._locks[agent.name]:
            if not agent.phase.airborne:
                return
            agent.outcome = FlightOutcome.LINK_LOST
            self._set(agent, DronePhase.LINK_LOST, message, ERROR)

    def crashed(self, agent: DroneAgent, message: str) -> None:
        """Its firmware says it crashed or tumbled (motors cut, locked): nothing to command, it falls."""
        with self._locks[agent.name]:
            if not agent.phase.airborne:
                return
            agent.outcome = FlightOutcome.CRASHED
            self._set(agent, DronePhase.EMERGENCY, message, FATAL)

    # ---------------------------------------------------------------------------------------- commands

    def stream(self, agent: DroneAgent, x: float, y: float, z: float, origin_s: float | None = None) -> bool:
        """Stream one position setpoint, only to a drone whose phase streams (never after ``land``); ``origin_s``:
        the receipt of the mocap frame it was planned from."""
        with self._locks[agent.name]:
            if agent.phase not in STREAMING:
                return False
            agent.last_setpoint = complex(x, y)
            return self.backend.send_position_setpoint(agent.name, x, y, z, 0.0, origin_s=origin_s)

    def extpos(
        self, agent: DroneAgent, position: Vec3, quaternion: Quaternion | None, received_s: float | None = None
    ) -> bool:
        """Forward a mocap pose to the drone's estimator (also while it lands: the landing needs it); ``received_s``:
        when the pose was received, so that the radio drops it if it waited too long (`EXTPOS_MAX_WAIT_S`)."""
        if agent.phase in (DronePhase.LINK_LOST, DronePhase.FAILED):
            return False
        if quaternion is None:
            return self.backend.send_extpos(agent.name, position, received_s)
        return self.backend.send_extpose(agent.name, position, quaternion, received_s)

    def land(self, agent: DroneAgent, reason: str, level: int = WARNING, duration_s: float | None = None) -> bool:
        """High-level landing of an airborne drone (once; from any thread), over ``duration_s`` (the mission's
        ``land_s`` unless given: a drone without mocap lands faster, docs/flight.md). A land command that cannot be
        sent is followed by an emergency stop: a drone nobody can land must not fly on."""
        land_s = self.land_s if duration_s is None else duration_s
        with self._locks[agent.name]:
            if not agent.phase.airborne or agent.phase == DronePhase.LANDING:
                return False
            if agent.outcome is None:
                agent.outcome = (
                    FlightOutcome.REACHED if agent.phase == DronePhase.ARRIVED else FlightOutcome.LANDED_EARLY
                )
            self._set(agent, DronePhase.LANDING, reason, level)
            agent.landing_until_s = self.clock() + land_s + self.land_settle_s
            agent.touchdown_s = self.clock() + land_s
            if self.backend.land(agent.name, 0.0, land_s):
                return True
            self.events.emit(ERROR, "error", "land command failed: emergency stop", agent.name)
            self._emergency(agent)
            return False

    def land_all(self, reason: str, level: int = INFO) -> None:
        for agent in self.agents.values():
            self.land(agent, reason, level)

    def confirm_touchdown(
        self, agent: DroneAgent, now_s: float, pose_z: float | None, pose_fresh: bool, state: DroneState | None
    ) -> bool:
        """A landing drone is down when its supervisor no longer says flying (its motors have idled for the
        firmware's hysteresis: the landing ended) and, where mocap sees it, its height is near the floor; only then
        is it disarmed (disarming in flight cuts the motors). With mocap lost the supervisor alone decides: the
        on-board height estimate drifts by decimetres within seconds without extpos. Late confirmation is an event
        (once), never a disarm."""
        with self._locks[agent.name]:
            if agent.phase != DronePhase.LANDING or agent.landing_until_s is None or now_s < agent.landing_until_s:
                return False
            low = pose_z - self.floor_z < ON_FLOOR_Z_M if pose_fresh and pose_z is not None else True
            flying = state is None or state.supervisor is None or state.supervisor.flying
            if low and not flying:
                self.backend.arm(agent.name, False)
                self._set(agent, DronePhase.LANDED)
                return True
            if now_s > agent.landing_until_s + TOUCHDOWN_TIMEOUT_S and agent.name not in self._touchdown_late:
                self._touchdown_late.add(agent.name)
                why = "its height is not near the floor" if not low else "its supervisor still says flying"
                self.events.emit(
                    ERROR,
                    "touchdown",
                    f"touchdown not confirmed {TOUCHDOWN_TIMEOUT_S:.0f} s after landing ({why}): not disarmed",
                    agent.name,
                )
            return False

    def _emergency(self, agent: DroneAgent) -> None:
        self.backend.emergency_stop(agent.name)
        if agent.phase.airborne or agent.phase == DronePhase.READY:
            agent.outcome = FlightOutcome.EMERGENCY
            agent.set_phase(DronePhase.EMERGENCY, self.clock(), "emergency stop")

    LOOP_STOP_WAIT_S = 0.05
    """How long the flight loop waits for an emergency stop it orders (:meth:`emergency_stop` ``wait_s``): the
    packets of a drone whose link is blocked go on from their own thread, and the loop ticks on."""

    def emergency_stop(self, reason: str, names: Iterable[str] | None = None, wait_s: float | None = None) -> None:
        """Motors off now (latched until reboot), from any thread but a signal handler (it does radio I/O). It takes
        no drone lock first: a drone whose link is blocked must not delay the stop of the others (the backend sends
        each drone's from a thread of its own, waiting ``wait_s`` at most: its default when None); the phase is
        set after."""
        targets = [self.agents[n] for n in names] if names is not None else list(self.agents.values())
        wait = {} if wait_s is None else {"wait_s": wait_s}
        failures = dict(self.backend.emergency_stop(None if names is None else [a.name for a in targets], **wait))
        for agent in targets:
            with self._locks[agent.name]:
                if agent.phase.airborne or agent.phase == DronePhase.READY:
                    agent.outcome = FlightOutcome.EMERGENCY
                    agent.set_phase(DronePhase.EMERGENCY, self.clock(), reason)
        if names is None:
            self.events.emit(FATAL, "emergency", reason)
        else:
            for agent in targets:
                self.events.emit(FATAL, "emergency", reason, agent.name)
        for name, why in failures.items():
            self.events.emit(FATAL, "emergency", why, name)
