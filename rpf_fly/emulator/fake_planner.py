"""The fake Crazyflie's high-level commander (CRTP port 8): take-off, land, go-to, stop, uploaded trajectories.

Mirrors `crtp_commander_high_level.c` and `planner.c` of crazyflie-firmware 2026.08:
- plan states IDLE (stopped: it asks for motors off), FLYING, LANDING and DISABLED;
- take-off only from IDLE (else error 1), land from anything but LANDING; go-to from the current plan, or from the
  last known state when idle; a finished landing returns to IDLE (motors off);
- while the supervisor forbids flying the commander is blocked: commands answer EBUSY and a running plan stops;
- while FLYING or LANDING it produces a fresh setpoint every tick, so the commander watchdog never fires under the
  high-level commander (the firmware documents the same); when IDLE it produces a null setpoint (motors off);
- every command is answered with ``[command, data0, data1, errno]`` like the firmware.

Planned trajectories (take-off, land, go-to) are rest-to-rest: "smooth" is the 7th-order polynomial with zero
velocity, acceleration and jerk at both ends (the firmware's shape when starting from hover), "linear" is linear
interpolation. Unlike the firmware, a go-to started while moving ignores the current velocity. Spirals are not
supported (answer ENOEXEC).

Uploaded trajectories (`fake_trajectory`), as the firmware handles them:
- the trajectory memory is this commander's `trajectory_memory` (4096 bytes of RAM, cleared by a reboot), written
  and read through the memory subsystem (`fake_memory`, memory 1, type 0x12);
- define (command 6, ``<BBBIB``: id, location, type, offset, pieces): stores the description for ids 0-30
  (`NUM_TRAJECTORY_DEFINITIONS` 31), ENOEXEC for a larger id; nothing is checked against the memory;
- start (commands 5 and 13): EBUSY while blocked; not in the group, an id over 30, an undefined id or a location or
  type the firmware does not know: answered 0, nothing happens; poly4d (type 0): flies from now with the time
  scale, reversed or not, shifted to start at the current setpoint when relative (and, with relative yaw, rotated to
  start at the current yaw; command 5 has no relative yaw); compressed (type 1): ENOEXEC unless the time scale is
  exactly 1 and not reversed, else flown, shifted when relative. Starting needs no state: from IDLE on the floor
  (armed) the drone takes off along the trajectory;
- a finished trajectory keeps the plan FLYING and hovers at its end (zero velocity) with the "trajectory finished"
  bit of `supervisor.info` set, until the next command; an invalid evaluation (NaN, pieces outside the memory)
  disables the planner, as the firmware does.

Units: metres, seconds, radians (the high-level protocol uses radians for yaw).
"""

from __future__ import annotations

import enum
import errno
import logging
import math
import struct
from dataclasses import dataclass

from .fake_memory import TRAJECTORY_MEMORY_SIZE
from .fake_setpoint import AxisMode, Setpoint, Vec3, null_setpoint, wrap_angle
from .fake_trajectory import CompressedTrajectory, PiecewiseTrajectory, normalize_radians, shortest_signed_angle_radians

logger = logging.getLogger(__name__)

COMMAND_SET_GROUP_MASK = 0
COMMAND_TAKEOFF = 1
COMMAND_LAND = 2
COMMAND_STOP = 3
COMMAND_GO_TO = 4
COMMAND_START_TRAJECTORY = 5
COMMAND_DEFINE_TRAJECTORY = 6
COMMAND_TAKEOFF_2 = 7
COMMAND_LAND_2 = 8
COMMAND_TAKEOFF_WITH_VELOCITY = 9
COMMAND_LAND_WITH_VELOCITY = 10
COMMAND_SPIRAL = 11
COMMAND_GO_TO_2 = 12
COMMAND_START_TRAJECTORY_2 = 13

DEFAULT_TAKEOFF_VELOCITY_M_S = 0.5
DEFAULT_LANDING_VELOCITY_M_S = 0.5

NUM_TRAJECTORY_DEFINITIONS = 31
TRAJECTORY_LOCATION_INVALID = 0
TRAJECTORY_LOCATION_MEM = 1
TRAJECTORY_TYPE_POLY4D = 0
TRAJECTORY_TYPE_POLY4D_COMPRESSED = 1


def _minus(a: Vec3, b: Vec3) -> Vec3:
    """``a - b``, per axis."""
    return a[0] - b[0], a[1] - b[1], a[2] - b[2]


@dataclass(frozen=True)
class TrajectoryDescription:
    """One defined trajectory (`struct trajectoryDescription`): where it lies in the trajectory memory."""

    location: int
    kind: int
    offset: int
    n_pieces: int


class PlanState(enum.IntEnum):
    """The planner's state, with the firmware's values."""

    IDLE = 0
    FLYING = 1
    LANDING = 3
    DISABLED = 4


@dataclass(frozen=True)
class Trajectory:
    """A rest-to-rest segment from `start` to `end` (metres) and `yaw_start` to `yaw_end` (radians)."""

    t0_s: float
    duration_s: float
    start: Vec3
    end: Vec3
    yaw_start: float
    yaw_end: float
    linear: bool = False

    def _shape(self, now_s: float) -> tuple[float, float]:
        """Progress s in [0, 1] and ds/dt in 1/s."""
        if self.duration_s <= 0.0:
            return 1.0, 0.0
        tau = min(max((now_s - self.t0_s) / self.duration_s, 0.0), 1.0)
        if self.linear:
            return tau, (1.0 / self.duration_s if tau < 1.0 else 0.0)
        s = tau**4 * (35.0 - 84.0 * tau + 70.0 * tau**2 - 20.0 * tau**3)
        ds = tau**3 * (140.0 - 420.0 * tau + 420.0 * tau**2 - 140.0 * tau**3) / self.duration_s
        return s, ds

    def evaluate(self, now_s: float) -> tuple[Vec3, Vec3, float]:
        """Position (m), velocity (m/s) and yaw (rad) at `now_s`."""
        s, ds = self._shape(now_s)
        (x0, y0, z0), (x1, y1, z1) = self.start, self.end
        pos = (x0 + (x1 - x0) * s, y0 + (y1 - y0) * s, z0 + (z1 - z0) * s)
        vel = ((x1 - x0) * ds, (y1 - y0) * ds, (z1 - z0) * ds)
        yaw = self.yaw_start + (self.yaw_end - self.yaw_start) * s
        return pos, vel, yaw

    def finished(self, now_s: float) -> bool:
        return now_s >= self.t0_s + self.duration_s


Plan = Trajectory | PiecewiseTrajectory | CompressedTrajectory
"""What the planner flies: a planned segment or an uploaded trajectory (each has `evaluate`, `finished`, `t0_s`)."""


class HighLevelCommander:
    """One drone's high-level commander. Not thread-safe: the owning vehicle serialises calls."""

    def __init__(self, position: Vec3, yaw_rad: float) -> None:
        self.state = PlanState.IDLE
        self.trajectory: Plan | None = None
        self.trajectory_memory = bytearray(TRAJECTORY_MEMORY_SIZE)
        """`trajectories_memory`: RAM the memory subsystem writes uploads into (memory id 1)."""
        self.definitions: list[TrajectoryDescription | None] = [None] * NUM_TRAJECTORY_DEFINITIONS
        self.group_mask = 0
        self.blocked = False
        self.pos: Vec3 = position
        self.vel: Vec3 = (0.0, 0.0, 0.0)
        self.yaw = yaw_rad
        self.commands_rejected = 0

    def _in_group(self, mask: int) -> bool:
        return mask == 0 or (mask & self.group_mask) != 0

    def stop(self) -> None:
        """Plan to IDLE (the firmware's `plan_stop`): motors off unless a higher priority source flies."""
        self.state = PlanState.IDLE

    def block(self, do_block: bool) -> None:
        """Block (while the supervisor forbids flying) or unblock; blocking stops a running plan."""
        if do_block and not self.blocked and self.state not in (PlanState.DISABLED, PlanState.IDLE):
            self.stop()
        self.blocked = do_block

    def tell_state(self, position: Vec3, velocity: Vec3, yaw_rad: float) -> None:
        """Set the last known state (on notify-setpoint-stop), the start of the next plan."""
        self.pos, self.vel, self.yaw = position, velocity, yaw_rad

    def _plan(self, now_s: float, end: Vec3, yaw_end: float, duration_s: float, linear: bool = False) -> None:
        start = self.pos
        yaw_start = wrap_angle(self.yaw)
        goal_yaw = yaw_start + wrap_angle(yaw_end - yaw_start)
        self.trajectory = Trajectory(now_s, max(duration_s, 0.0), start, end, yaw_start, goal_yaw, linear)

    def _current_goal(self, now_s: float) -> tuple[Vec3, Vec3, float] | None:
        """`plan_current_goal`: None when there is no goal or the evaluation is invalid."""
        if self.state is PlanState.LANDING and self.trajectory is not None and self.trajectory.finished(now_s):
            self.state = PlanState.IDLE
            return self.trajectory.evaluate(now_s)
        if self.state in (PlanState.FLYING, PlanState.LANDING) and self.trajectory is not None:
            return self.trajectory.evaluate(now_s)
        return None

    @property
    def plan_start_s(self) -> float | None:
        """When the current plan (segment or trajectory) began, on the caller's clock; None before the first."""
        return self.trajectory.t0_s if self.trajectory is not None else None

    # CRTP -----------------------------------------------------------------------------------------------------

    def handle(self, data: bytes, now_s: float) -> bytes:
        """Act on one port-8 packet; return the firmware's answer ``[cmd, data0, data1, errno]``."""
        if not data:
            return b""
        try:
            result = self._dispatch(data[0], bytes(data[1:]), now_s)
        except struct.error:
            logger.warning("malformed high-level command %d (%d bytes)", data[0], len(data))
            result = errno.EINVAL
        if result:
            self.commands_rejected += 1
        answer = bytearray(data[:3].ljust(3, b"\0"))
        answer.append(result & 0xFF)
        return bytes(answer)

    def _dispatch(self, cmd: int, body: bytes, now_s: float) -> int:
        if cmd == COMMAND_SET_GROUP_MASK:
            self.group_mask = body[0]
            return 0
        if cmd == COMMAND_STOP:
            if self._in_group(body[0]):
                self.stop()
            return 0
        if cmd == COMMAND_DEFINE_TRAJECTORY:
            return self._define_trajectory(body)
        if cmd == COMMAND_SPIRAL:
            logger.warning("fake high-level commander: command %d is not supported", cmd)
            return errno.EBUSY if self.blocked else errno.ENOEXEC
        if self.blocked:
            return errno.EBUSY
        if cmd in (COMMAND_START_TRAJECTORY, COMMAND_START_TRAJECTORY_2):
            return self._start_trajectory(cmd, body, now_s)
        if cmd in (COMMAND_TAKEOFF, COMMAND_TAKEOFF_2, COMMAND_TAKEOFF_WITH_VELOCITY):
            return self._takeoff(cmd, body, now_s)
        if cmd in (COMMAND_LAND, COMMAND_LAND_2, COMMAND_LAND_WITH_VELOCITY):
            return self._land(cmd, body, now_s)
        if cmd in (COMMAND_GO_TO, COMMAND_GO_TO_2):
            return self._go_to(cmd, body, now_s)
        return errno.ENOEXEC

    def _height_yaw_duration(self, cmd: int, body: bytes, *, landing: bool) -> tuple[int, float, float, float]:
        """Group mask, absolute height (m), hover yaw (rad) and duration (s) of a take-off or land command."""
        if cmd in (COMMAND_TAKEOFF, COMMAND_LAND):
            group, height, duration = struct.unpack("<Bff", body[:9])
            return group, height, 0.0, duration
        if cmd in (COMMAND_TAKEOFF_2, COMMAND_LAND_2):
            group, height, yaw, use_current_yaw, duration = struct.unpack("<Bff?f", body[:14])
            return group, height, (self.yaw if use_current_yaw else yaw), duration
        group, height, relative, yaw, use_current_yaw, velocity = struct.unpack("<Bf?f?f", body[:15])
        if relative:
            height = self.pos[2] - height if landing else self.pos[2] + height
        default = DEFAULT_LANDING_VELOCITY_M_S if landing else DEFAULT_TAKEOFF_VELOCITY_M_S
        velocity = velocity if velocity > 0 else default
        return group, height, (self.yaw if use_current_yaw else yaw), abs(height - self.pos[2]) / velocity

    def _takeoff(self, cmd: int, body: bytes, now_s: float) -> int:
        group, height, yaw, duration = self._height_yaw_duration(cmd, body, landing=False)
        if not self._in_group(group):
            return 0
        if self.state is not PlanState.IDLE:
            return 1
        self._plan(now_s, (self.pos[0], self.pos[1], height), yaw, duration)
        self.state = PlanState.FLYING
        return 0

    def _land(self, cmd: int, body: bytes, now_s: float) -> int:
        group, height, yaw, duration = self._height_yaw_duration(cmd, body, landing=True)
        if not self._in_group(group):
            return 0
        if self.state is PlanState.LANDING:
            return 1
        self._plan(now_s, (self.pos[0], self.pos[1], height), yaw, duration)
        self.state = PlanState.LANDING
        return 0

    def _go_to(self, cmd: int, body: bytes, now_s: float) -> int:
        if cmd == COMMAND_GO_TO:
            group, relative, x, y, z, yaw, duration = struct.unpack("<BBfffff", body[:22])
            linear = False
        else:
            group, relative, linear, x, y, z, yaw, duration = struct.unpack("<BBBfffff", body[:23])
        if not self._in_group(group):
            return 0
        if self.state not in (PlanState.IDLE, PlanState.DISABLED):
            goal = self._current_goal(now_s)
            if goal is not None:
                self.pos, self.vel, self.yaw = goal
        end = (x, y, z)
        if relative:
            end = (self.pos[0] + x, self.pos[1] + y, self.pos[2] + z)
            yaw += self.yaw
        self._plan(now_s, end, yaw, duration, linear=bool(linear))
        self.state = PlanState.FLYING
        return 0

    def _define_trajectory(self, body: bytes) -> int:
        trajectory_id, location, kind, offset, n_pieces = struct.unpack("<BBBIB", body[:8])
        if trajectory_id >= NUM_TRAJECTORY_DEFINITIONS:
            return errno.ENOEXEC
        self.definitions[trajectory_id] = TrajectoryDescription(location, kind, offset, n_pieces)
        return 0

    def _start_trajectory(self, cmd: int, body: bytes, now_s: float) -> int:
        if cmd == COMMAND_START_TRAJECTORY:
            group, relative, reversed_, trajectory_id, timescale = struct.unpack("<BBBBf", body[:8])
            relative_yaw = 0
        else:
            group, relative, relative_yaw, reversed_, trajectory_id, timescale = struct.unpack("<BBBBBf", body[:9])
        if not self._in_group(group) or trajectory_id >= NUM_TRAJECTORY_DEFINITIONS:
            return 0
        description = self.definitions[trajectory_id]
        if description is None or description.location != TRAJECTORY_LOCATION_MEM:
            return 0
        if description.kind == TRAJECTORY_TYPE_POLY4D:
            trajectory = PiecewiseTrajectory(
                self.trajectory_memory, description.offset, description.n_pieces, now_s, timescale, bool(reversed_)
            )
            if relative:  # plan_start_trajectory: shift the start onto the last setpoint
                start = trajectory.evaluate(now_s)
                if start is not None:
                    trajectory.shift = _minus(self.pos, start[0])
                    if relative_yaw:
                        trajectory.shift_yaw = shortest_signed_angle_radians(
                            normalize_radians(start[2]), normalize_radians(self.yaw)
                        )
                else:  # an invalid start: the firmware's shift is NaN, so is every evaluation
                    trajectory.shift = (math.nan, math.nan, math.nan)
            self.trajectory = trajectory
        elif description.kind == TRAJECTORY_TYPE_POLY4D_COMPRESSED:
            if timescale != 1.0 or reversed_:
                return errno.ENOEXEC
            compressed = CompressedTrajectory(self.trajectory_memory, description.offset, now_s)
            if relative:
                start = compressed.evaluate(now_s)
                compressed.shift = (math.nan, math.nan, math.nan) if start is None else _minus(self.pos, start[0])
            self.trajectory = compressed
        else:
            return 0
        self.state = PlanState.FLYING
        return 0

    # Stabilizer tick ------------------------------------------------------------------------------------------

    def get_setpoint(self, now_s: float, est_pos: Vec3, est_vel: Vec3, est_yaw: float) -> Setpoint | None:
        """The setpoint this tick (None: leave the commander's setpoint alone). Called only when flying is allowed."""
        if self.trajectory is not None:  # a plan is never evaluated before it began (a command within the tick)
            now_s = max(now_s, self.trajectory.t0_s)
        goal = self._current_goal(now_s)
        if self.state in (PlanState.IDLE, PlanState.DISABLED):
            self.pos, self.vel, self.yaw = est_pos, est_vel, est_yaw
            return null_setpoint(now_s, "high-level") if self.state is PlanState.IDLE else None
        if goal is None:
            self.state = PlanState.DISABLED
            return None
        self.pos, self.vel, self.yaw = goal
        return Setpoint(
            modes=(AxisMode.ABS, AxisMode.ABS, AxisMode.ABS),
            position=goal[0],
            velocity=goal[1],
            yaw_mode=AxisMode.ABS,
            yaw_deg=math.degrees(goal[2]),
            timestamp_s=now_s,
            source="high-level",
        )

    def info_bits(self, now_s: float) -> int:
        """Bits 8-10 of `supervisor.info`: active, trajectory finished, disabled."""
        bits = 0
        if self.state in (PlanState.FLYING, PlanState.LANDING):
            bits |= 0x0100
        if self.trajectory is None or self.trajectory.finished(now_s):
            bits |= 0x0200
        if self.state is PlanState.DISABLED:
            bits |= 0x0400
        return bits
