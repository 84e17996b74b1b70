"""What the flight knows of each drone's pose: the newest valid mocap pose, its age, a velocity and an acceleration.

The planner needs neighbours' velocities (a hovering neighbour is an obstacle for the robust preset) and
accelerations (where a neighbour's setpoint is, `DroneAgent.predict`); mocap gives positions only, so velocity is a
low-pass filtered finite difference of valid samples, and acceleration one of the velocity. Invalid or missing bodies
keep their last pose but age; the supervisor decides what a stale pose means.

Glitches: a pose that jumped further from the previous sample than a Crazyflie can move in that time (a marker
swap, a reflection taken for a marker) is not followed. The body's pose freezes (and ages, so the supervisor holds
the drone) until the track jumps back near the frozen pose, or until the new track has been consistent for
``REACQUIRE_S`` (the drone really is there: Motive fixed its model) and, in flight, the drone's own on-board
estimate is nearer the new track than the frozen pose (a swap that stays, taken after 0.5 s on its own, would fly
the drone into a neighbour). The raw samples are compared
frame to frame, so a swap is caught however long it lasts, and so is the swap back.

After a gap (``GAP_S``: an occlusion, a blackout, a stalled loop) the frame-to-frame bound allows metres, so the
first sample after it must also lie near where the drone's own on-board estimate says it is, while it flies
(a marker swap that begins inside a blackout is not taken and fed to the estimator).

Orientation glitches: an orientation that turned further from the previous sample than a Crazyflie can
turn in that time (``MAX_TURN_RATE_DEG_S`` times the interval plus ``TURN_TOLERANCE_DEG``) is a wrong fit of the
rigid body's markers: the flip Motive makes on a nearly symmetric marker set, a complaint of Crazyswarm and cflib
users. The position is judged on its own (a fit about the body's pivot keeps it), and followed; the orientation
freezes at the last trusted one, ``TrackedPose.orientation_trusted`` is False and the drone is in
``orientation_glitching``, until an orientation within ``ORIENTATION_BACK_DEG`` of the frozen one comes back.
A jumped orientation is never taken as the drone's after a while, as a jumped position is: nothing but the flip
itself says which of the two fits is right, and one wrong yaw fed to the estimator flies the drone off. What the
flight does with that (docs/flight.md): extpose forwards the position only, a drone on the ground does not take
off, the supervisor says so.

Times on a 1 us grid (for ``rpf-fly replay``): the tracker rounds every receive time to a whole
microsecond before it uses it (:func:`stamp_on_grid`). The flight log's times are integer nanoseconds; with the
stamps on this grid the log carries them exactly (:func:`stamp_us`), so a replay feeds the same floats to the same
code and rebuilds the same velocities bit for bit (docs/replay.md). Half a microsecond is far below the receive
jitter of any mocap frame (tens of microseconds and more), so the velocity estimate does not notice.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Collection, Mapping
from dataclasses import dataclass

from rpf_fly.mocap.frame import MocapFrame

POSE_LATE_S = 0.1
"""A flying drone without a valid pose this long (10 frames at 100 Hz) is a warning, before the hold at
``safety.pose_timeout_s`` (0.25 s): an occlusion or a mocap gap shorter than the hold is ridden through on the
last pose, and still said, once (a lab wants to know where its cameras lose a drone). When no flying drone has one,
it is one swarm-wide ``mocap_late`` warning instead of one per drone."""


@dataclass
class TrackedPose:
    """Newest valid pose of one drone: position (x, y, z) metres, quaternion (qx, qy, qz, qw), planar velocity
    (complex, m/s), ``stamp_s`` (monotonic receive time of that sample, on the 1 us grid), ``frame_number``, and whether
    the newest frame tracked it (``valid``)."""

    position: tuple[float, float, float]
    quaternion: tuple[float, float, float, float]
    velocity: complex
    stamp_s: float
    frame_number: int
    valid: bool = True
    orientation_trusted: bool = True
    """False while the body's orientation is refused as a jump (`PoseTracker.orientation_glitching`): ``quaternion``
    is then the last trusted one, not what mocap says."""
    acceleration: complex = 0j
    """Planar acceleration (m/s^2): the low-pass filtered finite difference of ``velocity`` (0 until two valid
    samples in a row follow a gap or a jump)."""

    @property
    def xy(self) -> complex:
        return complex(self.position[0], self.position[1])


MAX_SPEED_M_S = 5.0
"""Faster than a Crazyflie moves: 1 m/s commanded at most, about 4.4 m/s after a free fall from 1 m."""

JUMP_TOLERANCE_M = 0.05
"""Added to ``MAX_SPEED_M_S * dt``: mocap noise and a body's model fit wobble by millimetres, never this."""

REACQUIRE_S = 0.5
"""A jumped track consistent for this long is taken as the drone's real pose."""

GAP_S = 0.05
"""Two samples of a body further apart than this (five frames at 100 Hz: an occlusion, a blackout, a stalled loop)
span a gap over which ``MAX_SPEED_M_S`` allows metres: the sample after it must also lie near the drone's own
on-board estimate (`PoseTracker.airborne_estimate_of`) while it flies. Motive often re-acquires a body after an
occlusion with the wrong markers; without this a swap that began inside a 0.43 s blackout (2.2 m allowed) was taken,
fed to the estimator, and the controller flew the drone 1.5 m the other way into a neighbour (random fault
campaign, seed 19, run 2: two crashes)."""

ESTIMATE_TOLERANCE_M = 0.15
"""How far from the drone's on-board estimate the first sample after a gap may lie, before the estimate's age and
drift are added: the estimate follows extpos within millimetres while mocap flows, and a swap with a neighbour moves
the body at least the 0.2 m two drones keep apart."""

ESTIMATE_SPEED_M_S = 1.5
"""How fast a flying drone may have moved between its estimate's telemetry and the sample (horizontally): the
firmware's 1.1 m/s position-control limit, with room for a gust."""

MAX_TURN_RATE_DEG_S = 720.0
"""Faster than a Crazyflie turns while it is not tumbling: this stack holds its yaw at 0, tilts stay under about
20 degrees, and the firmware's hardest manoeuvres turn it a few hundred degrees a second."""

TURN_TOLERANCE_DEG = 10.0
"""Added to ``MAX_TURN_RATE_DEG_S * dt``: a small rigid body's orientation noise is a fraction of a degree, and a
flip of a nearly symmetric marker set turns it by tens of degrees or more (90 or 180 on a square or a line)."""

SEEN_GAP_CAP_S = 0.05
"""The longest interval whose turn (`MAX_TURN_RATE_DEG_S` times it) is allowed between two samples of a body the
mocap saw throughout: the ground station read the frames in between late and skipped them (the loop takes the
newest frame), not the cameras lost it. Only an occlusion allows the turn of its whole length. Why: through a shared
Crazyradio a preflight spin read two frames 0.31 s apart, and a 91 deg marker flip passed as a 223 deg/s turn."""

ORIENTATION_BACK_DEG = 30.0
"""A refused orientation's glitch ends when mocap's orientation comes back this close to the frozen one (a flying
drone holds its yaw; its tilt stays within about 20 degrees)."""

STAMP_GRID_PER_S = 1_000_000
"""The tracker's time grid: whole microseconds (module docstring)."""


def stamp_us(t_s: float) -> int:
    """A tracker time (seconds, on the grid) as whole microseconds: exact for any time on the grid."""
    return round(t_s * STAMP_GRID_PER_S)


def stamp_from_us(t_us: int) -> float:
    """The tracker time of ``t_us`` whole microseconds: the float :func:`stamp_on_grid` gives (the inverse of
    :func:`stamp_us`, bit for bit)."""
    return t_us / STAMP_GRID_PER_S


def stamp_on_grid(t_s: float) -> float:
    """``t_s`` rounded to the tracker's 1 us grid; idempotent (a time on the grid stays the same float)."""
    return stamp_from_us(stamp_us(t_s))


def turn_deg(a: tuple[float, float, float, float], b: tuple[float, float, float, float]) -> float:
    """The angle (degrees, 0-180) of the rotation between two unit quaternions (qx, qy, qz, qw): any axis, so a
    flip about x or y counts as well as one about z."""
    dot = abs(a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3])
    return math.degrees(2.0 * math.acos(min(1.0, dot)))


EXTPOS_LEAD_FROM_S = 0.1
"""Mocap latency (camera to receipt, as the mocap measures it) from which the pose a drone's estimator gets is carried
ahead by that latency (`estimator_position`), and every flying drone holds (the supervisor's `MOCAP_LATENCY_HOLD_S`).
Under it extpos is the mocap position as measured: carrying poses ahead along a velocity measured on the same late
poses throws braking and turning drones the wrong way (a 0.08 s delay in circle-8-r3's swap brought two drones within
0.13 m), while over it the firmware's cascade on the late picture oscillates even at rest (docs/flight.md)."""


def estimator_position(pose: TrackedPose, latency_s: float | None) -> tuple[float, float, float]:
    """The position to feed a drone's estimator from its newest mocap pose: the pose itself, or, while the mocap's
    latency is at least `EXTPOS_LEAD_FROM_S`, the pose carried ahead along the drone's tracked planar velocity by
    that latency. Why: the firmware's estimator takes each extpos as the drone's position now; a pose ``latency_s``
    old puts its estimate speed x latency behind the drone, and the cascade's correction lurches it after the late
    picture: on the firmware model a drone held at rest on a 0.146 s old picture swung 0.12, 0.21, 0.25, 0.29 m
    in 0.75 s periods until its pose, back on time, leapt further than a drone flies (docs/flight.md)."""
    x, y, z = pose.position
    if latency_s is None or latency_s < EXTPOS_LEAD_FROM_S:
        return pose.position
    ahead = pose.velocity * latency_s
    return (x + ahead.real, y + ahead.imag, z)


class PoseTracker:
    """Folds mocap frames into per-drone poses. ``bodies`` maps drone name -> rigid body name."""

    def __init__(self, bodies: Mapping[str, str], velocity_tau_s: float = 0.1, acceleration_tau_s: float = 0.1):
        self.bodies = dict(bodies)
        self.velocity_tau_s = velocity_tau_s
        self.acceleration_tau_s = acceleration_tau_s
        self.poses: dict[str, TrackedPose] = {}
        self.last_frame_s: float | None = None
        self.latency_s: float | None = None
        """The newest frame's camera-to-receipt latency as the mocap measures it (None if it does not)."""
        self.glitching: set[str] = set()
        """Drones whose newest samples are refused as a jump."""
        self.glitches: dict[str, int] = {}
        """Samples refused as jumps, per drone."""
        self._raw: dict[str, tuple[tuple[float, float, float], float, float]] = {}
        """drone -> its newest sample: (position, receive time, capture time)."""
        self._jumped_at: dict[str, float] = {}
        self.last_jump: dict[str, tuple[float, float]] = {}
        """drone -> (metres, seconds) of its newest refused jump, for the event that reports it."""
        self.orientation_glitching: set[str] = set()
        """Drones whose mocap orientation is refused as a jump (a wrong fit of its markers): module docstring."""
        self.orientation_glitches: dict[str, int] = {}
        """Samples whose orientation was refused, per drone."""
        self.last_turn: dict[str, tuple[float, float]] = {}
        """drone -> (degrees, seconds) of its newest refused orientation jump, for the event that reports it."""
        self.airborne_estimate_of: Callable[[str], tuple[tuple[float, float, float], float] | None] | None = None
        """drone -> (its on-board position estimate, when the drone made it, on the receive clock) while it flies
        (None on the ground, before its estimator was reset to mocap, or without telemetry), or None: the check of a
        sample after a gap (``GAP_S``). The flight loop sets it."""
        self.blind_drift_m_s2 = 0.45
        """How fast a blind estimate may drift off the truth (the mission's ``safety.blind_drift_m_s2``; its
        default, `rpf_fly.flight.blind.BLIND_DRIFT_M_S2`)."""
        self.last_jump_from_estimate: dict[str, bool] = {}
        """drone -> whether its newest refused jump was measured from its on-board estimate after a gap (else from
        its previous sample)."""
        self.estimate_of: Callable[[str], tuple[float, float, float] | None] | None = None
        """drone -> its on-board position estimate (None: none known), or None (no estimates): see
        `_estimate_agrees`. The flight loop sets it from the drones' telemetry."""
        self._raw_turn: dict[str, tuple[tuple[float, float, float, float], float, float]] = {}
        """drone -> its newest sample's orientation: (quaternion, receive time, capture time)."""
        self._unseen_since_raw: set[str] = set()
        """drones given an untracked sample (or none) since their newest tracked one: an occlusion, whose whole
        length a turn may take (`SEEN_GAP_CAP_S`)."""
        self.unseen_untracked: dict[str, float] = {}
        """drone -> the longest stretch it went untracked entirely between two frames it was given (the caller
        busy: `MocapFrame.unseen_untracked_s`), gathered until `take_unseen`."""

    @staticmethod
    def _jump(a: tuple[float, ...], b: tuple[float, ...], dt: float) -> bool:
        return math.dist(a, b) > MAX_SPEED_M_S * max(dt, 0.0) + JUMP_TOLERANCE_M

    def _accept(
        self, name: str, position: tuple[float, float, float], t: float, captured: float, previous: TrackedPose | None
    ) -> bool:
        """Whether this sample may be followed (see the module docstring); updates the glitch state. The time a
        sample had to move is the longer of its receive and capture intervals: frames delayed and then received
        in a burst (a loaded host or network) are close in receive time but not in capture time."""
        raw = self._raw.get(name)
        self._raw[name] = (position, t, captured)
        dt = 0.0
        if raw is not None:
            dt_capture = captured - raw[2]
            dt = max(t - raw[1], dt_capture if 0.0 <= dt_capture < 10.0 else 0.0)
        if name not in self.glitching:
            if raw is None or previous is None:
                return True
            if self._jump(position, raw[0], dt):
                self.last_jump[name] = (math.dist(position, raw[0]), dt)
                self.last_jump_from_estimate[name] = False
            else:
                off = self._off_estimate(name, position, t, dt) if dt > GAP_S else None
                if off is None:
                    return True
                self.last_jump[name] = (off, dt)
                self.last_jump_from_estimate[name] = True
            self.glitching.add(name)
            self._jumped_at[name] = t
        elif raw is not None and self._jump(position, raw[0], dt):
            if previous is not None and not self._jump(position, previous.position, t - previous.stamp_s):
                self.glitching.discard(name)  # jumped back onto the frozen track
                return True
            self._jumped_at[name] = t  # jumped elsewhere: a new candidate track
        elif t - self._jumped_at[name] >= REACQUIRE_S and self._estimate_agrees(name, position, previous):
            self.glitching.discard(name)  # the new track held: the drone is there
            return True
        self.glitches[name] = self.glitches.get(name, 0) + 1
        if previous is not None:
            previous.valid = False
        return False

    def _trust_orientation(
        self,
        name: str,
        quaternion: tuple[float, float, float, float],
        t: float,
        captured: float,
        trusted: tuple[float, float, float, float] | None,
        occluded: bool,
    ) -> bool:
        """Whether this sample's orientation may be followed (module docstring); updates the orientation glitch
        state. ``trusted``: the orientation the drone's pose holds now (None before its first pose). ``occluded``:
        the body went untracked since its previous sample (else the turn's interval is capped at `SEEN_GAP_CAP_S`)."""
        raw = self._raw_turn.get(name)
        self._raw_turn[name] = (quaternion, t, captured)
        if name in self.orientation_glitching:
            if trusted is not None and turn_deg(quaternion, trusted) > ORIENTATION_BACK_DEG:
                self.orientation_glitches[name] = self.orientation_glitches.get(name, 0) + 1
                return False
            self.orientation_glitching.discard(name)
            return True
        if raw is None or trusted is None:
            return True
        dt_capture = captured - raw[2]
        dt = max(t - raw[1], dt_capture if 0.0 <= dt_capture < 10.0 else 0.0)
        if not occluded:
            dt = min(dt, SEEN_GAP_CAP_S)
        turned = turn_deg(quaternion, raw[0])
        if turned <= MAX_TURN_RATE_DEG_S * max(dt, 0.0) + TURN_TOLERANCE_DEG:
            return True
        self.orientation_glitching.add(name)
        self.orientation_glitches[name] = self.orientation_glitches.get(name, 0) + 1
        self.last_turn[name] = (turned, dt)
        return False

    def _off_estimate(self, name: str, position: tuple[float, float, float], t: float, gap_s: float) -> float | None:
        """How far (m, horizontally) the first sample after a ``gap_s`` gap lies from the flying drone's on-board
        estimate, when that is further than the estimate can be off (``ESTIMATE_TOLERANCE_M``, plus what the drone
        may have flown since the estimate was made at ``ESTIMATE_SPEED_M_S``, plus its drift over the gap at
        ``blind_drift_m_s2``); None when it is near enough, or nothing is known (on the ground, no telemetry)."""
        if self.airborne_estimate_of is None:
            return None
        known = self.airborne_estimate_of(name)
        if known is None:
            return None
        estimate, made_s = known
        off = math.hypot(position[0] - estimate[0], position[1] - estimate[1])
        allowed = (
            ESTIMATE_TOLERANCE_M + ESTIMATE_SPEED_M_S * abs(t - made_s) + 0.5 * self.blind_drift_m_s2 * gap_s * gap_s
        )
        return off if off > allowed else None

    def _estimate_agrees(self, name: str, position: tuple[float, float, float], frozen: TrackedPose | None) -> bool:
        """Whether a jumped track that held for ``REACQUIRE_S`` is the drone: without an ``estimate_of`` (a replay,
        a bare tracker) it is taken; with one, only when the drone's on-board estimate (which
        flew on its IMU alone while the glitch lasted: centimetres of drift) is nearer the new track than the frozen
        pose. A marker swap that stays is otherwise taken, fed to the estimator as extpos, and the controller flies
        the true drone the jump's length the other way (random fault campaign, seed 8: two crashes)."""
        if self.estimate_of is None:
            return True
        estimate = self.estimate_of(name)
        if estimate is None or frozen is None:
            return False
        return math.dist(estimate, position) < math.dist(estimate, frozen.position)

    def update(self, frame: MocapFrame, reacquired: Collection[str] = ()) -> None:
        """Take the frame's poses of our drones (Z-up world frame). ``reacquired``: drones whose sample in this
        frame ends a glitch the tracker did not see (a replay learns it from the log's ``pose_glitch`` events,
        since refused samples are not logged): no velocity across the jump, as for a glitch it saw itself."""
        t = stamp_on_grid(frame.receive_time_s)
        self.last_frame_s = t
        self.latency_s = frame.latency_s
        if frame.unseen_untracked_s:
            unseen = self.unseen_untracked
            for name, body_name in self.bodies.items():
                gap = frame.unseen_untracked_s.get(body_name)
                if gap is not None and gap > unseen.get(name, 0.0):
                    unseen[name] = gap
        for name, body_name in self.bodies.items():
            body = frame.bodies.get(body_name)
            previous = self.poses.get(name)
            if body is None or not body.valid:
                self._unseen_since_raw.add(name)
                if previous is not None:
                    previous.valid = False
                continue
            occluded = name in self._unseen_since_raw or frame.unseen_untracked_s.get(body_name, 0.0) > 0.0
            self._unseen_since_raw.discard(name)
            px, py, pz = body.position
            qx, qy, qz, qw = body.quaternion
            position = (px, py, pz)
            quaternion = (qx, qy, qz, qw)
            trusted = self._trust_orientation(
                name,
                quaternion,
                t,
                frame.capture_time_s,
                previous.quaternion if previous is not None else None,
                occluded,
            )
            if not trusted and previous is not None:
                quaternion = previous.quaternion
            jumped = name in self.glitching or name in reacquired
            if not self._accept(name, position, t, frame.capture_time_s, previous):
                if previous is not None:
                    previous.orientation_trusted = trusted
                continue
            if jumped:
                previous = None  # a re-acquired track: no velocity across the jump
            velocity = acceleration = 0j
            if previous is not None:
                dt = t - previous.stamp_s
                if dt > 1e-4:
                    raw = (complex(body.position[0], body.position[1]) - previous.xy) / dt
                    blend = min(dt / self.velocity_tau_s, 1.0) if previous.valid else 1.0
                    velocity = previous.velocity + blend * (raw - previous.velocity)
                    if previous.valid:  # not across a gap: the velocity restarted from one difference
                        raw_a = (velocity - previous.velocity) / dt
                        acceleration = previous.acceleration + min(dt / self.acceleration_tau_s, 1.0) * (
                            raw_a - previous.acceleration
                        )
                else:
                    velocity, acceleration = previous.velocity, previous.acceleration
            self.poses[name] = TrackedPose(
                position,
                quaternion,
                velocity,
                t,
                frame.frame_number,
                orientation_trusted=trusted,
                acceleration=acceleration,
            )

    def get(self, name: str) -> TrackedPose | None:
        return self.poses.get(name)

    def take_unseen(self) -> dict[str, float]:
        """`unseen_untracked` so far, and forget it (the supervisor reports each stretch once)."""
        unseen, self.unseen_untracked = self.unseen_untracked, {}
        return unseen

    def age(self, name: str, now_s: float) -> float:
        """Seconds since the drone's newest valid pose (infinite if it never had one)."""
        pose = self.poses.get(name)
        return float("inf") if pose is None else now_s - pose.stamp_s
