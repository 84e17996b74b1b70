"""The flight's state machines: one phase per drone, one for the swarm, and why each drone's flight ended.

Per drone: waiting (connected) -> ready (preflight passed) -> takeoff -> planning <-> holding -> arrived ->
landing -> landed. Off that path: failed (never flew), link_lost, emergency. The swarm: connecting -> preflight ->
takeoff -> flying -> landing -> done, or aborted before takeoff.
"""

from __future__ import annotations

import enum


class DronePhase(str, enum.Enum):
    """Where one drone is in its flight."""

    WAITING = "waiting"
    """Connected, preflight not passed yet."""
    READY = "ready"
    """Preflight passed, on the ground."""
    TAKEOFF = "takeoff"
    """High-level take-off to the flight height."""
    PLANNING = "planning"
    """Streaming setpoints from its planner."""
    HOLDING = "holding"
    """Streaming a fixed setpoint: pose stale, planner fault, or a supervisor hold."""
    ARRIVED = "arrived"
    """Hovering at its goal."""
    LANDING = "landing"
    LANDED = "landed"
    FAILED = "failed"
    """Never flew: connection or preflight failure."""
    GROUNDED = "grounded"
    """Commanded to take off, never left the floor (a take-off its firmware ignored): disarmed where it stands,
    and an obstacle in every other drone's view and separation check until the flight ends."""
    LINK_LOST = "link_lost"
    """The radio link dropped: no command reaches it any more (the firmware's watchdog stops it)."""
    EMERGENCY = "emergency"
    """Motors cut by an emergency stop."""

    @property
    def airborne(self) -> bool:
        return self in (
            DronePhase.TAKEOFF,
            DronePhase.PLANNING,
            DronePhase.HOLDING,
            DronePhase.ARRIVED,
            DronePhase.LANDING,
        )

    @property
    def terminal(self) -> bool:
        return self in (
            DronePhase.LANDED,
            DronePhase.FAILED,
            DronePhase.GROUNDED,
            DronePhase.LINK_LOST,
            DronePhase.EMERGENCY,
        )


class SwarmPhase(str, enum.Enum):
    """Where the whole flight is."""

    CONNECTING = "connecting"
    PREFLIGHT = "preflight"
    TAKEOFF = "takeoff"
    FLYING = "flying"
    LANDING = "landing"
    DONE = "done"
    ABORTED = "aborted"
    """Stopped before any drone took off (connection or preflight failure, or interrupted)."""


class FlightOutcome(str, enum.Enum):
    """Why one drone's flight ended (CrowdNav-style outcome names)."""

    REACHED = "reached"
    """Reached its goal and landed."""
    TIMEOUT = "timeout"
    """The mission timed out before it arrived; it landed."""
    LANDED_EARLY = "landed_early"
    """The supervisor landed it (stale pose, geofence, battery, planner fault, separation or an interrupt)."""
    LINK_LOST = "link_lost"
    EMERGENCY = "emergency"
    CRASHED = "crashed"
    """Its supervisor reported a crash or tumble in the air (motors cut by the firmware)."""
    NOT_FLOWN = "not_flown"
