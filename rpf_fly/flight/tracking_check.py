"""Tracking: a drone this far from where its setpoints should have brought it, for a while, was pushed (a gust, a
contact, a failing motor). "Should have": the drone's own controller's response to its streamed setpoints
(rpf_fly/flight/response.py, from its gains; a dry run's first-order drones: that model), and, while the high-level
commander flies its take-off or landing, an envelope about the firmware's own target (docs/flight.md, "Tracking")."""

from __future__ import annotations

import math
from collections import deque

from rpf_fly.flight.agent import DroneAgent
from rpf_fly.flight.commander import ON_FLOOR_Z_M
from rpf_fly.flight.events import INFO, WARNING
from rpf_fly.flight.findings import Finding
from rpf_fly.flight.phases import DronePhase
from rpf_fly.flight.poses import POSE_LATE_S, PoseTracker
from rpf_fly.flight.response import Follower
from rpf_fly.radio.backend import DroneState

TRACKING_WARN_M = 0.07
"""A drone this far from where its setpoints should have brought it, for ``TRACKING_WARN_S``: something pushes it
(a gust, a contact, a failing motor). "Should have": the drone's own controller's response to the streamed setpoints
(module doc; a disturbance observer: the carrot's lead and lag and a hold's overshoot are in it, so they are not
taken for a push). A Crazyflie under mocap follows that within 2-5 cm, so the line sits
above that: 5 cm would suit the simulated drone without turbulence (within 1.3 cm), kinder than a real
one; with its turbulence (rpf_fly/emulator/fake_vehicle.py, "Turbulence") it wanders 2.2-4.0 cm from the model in
normal flight (lab-3 and circle-8-r3 dry runs, truth), and 5 cm would cry wolf on a real flight. Pushed for 1 s,
the simulated drone is held about 0.06 m off by 0.6 m/s^2, 0.09 m by 1.0 and 0.18 m by 1.5: a push under about
0.8 m/s^2 or shorter than about 0.7 s moves a drone less than its normal tracking error, cannot be told from it,
and is not said."""
TRACKING_WARN_S = 0.2
TRACKING_TAU_S = 0.25
"""The Crazyflie position loop's time constant (docs/flight.md: drones trail their setpoints by about v tau)."""
TRACKING_SPEED_M_S = 1.1
"""The firmware's horizontal speed limit (posCtlPid.xyVelMax 1 m/s, plus its 10 % overhead)."""
TRACKING_PLAN_TAU_S = 0.5
"""While the high-level commander flies a take-off or landing the follower is an envelope between a first-order
return with ``TRACKING_TAU_S`` (the simulated drone's) and one with this, the slowest a default Crazyflie gives;
this is also how long the overshoot it allows lasts. The firmware's position PID (posCtlPid.xKp 2/s) alone is
0.5 s; with its velocity loop (velCtlPid.vxKp 25 degrees per m/s, about 4.3 /s of acceleration per m/s) the pair is
a damped oscillator (omega 2.95/s, zeta 0.74) that runs a landing begun at 1 m/s 15 cm past its point and brings it
back in about a second. Against that model the slow follower with its overshoot stays within 2.8 cm (a 0.25 s one:
9.4 cm, which would cry wolf); a drone whose estimate snaps back 0.35 m in the air (a blind spell's drift) and
returns with the simulated drone's 0.25 s would leave a 0.5 s follower by 8.8 cm, hence the envelope. Worked out
from the firmware's default gains, not measured on hardware."""
TRACKING_LATENCY_WINDOW_S = 0.5
"""The tracking line is widened by the drone's speed times the largest mocap latency of this long: long enough
for the drone's estimate to settle after the latency changes."""
PLAN_TARGET_AFTER_S = 0.15
"""A take-off's or landing's firmware target is read from telemetry made at least this long after the command was
sent (an outbox, a sender and a radio transaction: milliseconds on a healthy link, tens on a full one)."""
PLAN_TARGET_AGREE_M = 0.01
"""Two target samples this close are the plan's fixed x, y (a streamed setpoint at 0.3 m/s moves 3 cm in a 10 Hz
sample; the compressed target's resolution is 1 mm)."""


class _Follower:
    """Where a drone's setpoints should have brought it. While it streams: its own controller's response
    (``model``: rpf_fly/flight/response.py, from its gains: it trails a moving setpoint by 0.55 s x speed and
    overshoots a hold), one point; a drone simulated first-order: a first-order follower with ``fast_s``. While the
    high-level commander flies it: two first-order followers of the firmware's target (time constants ``fast_s``
    and ``slow_s``, each at most the firmware's speed limit) and an overshoot ``momentum`` (m) that fades with
    ``slow_s`` from ``since``; a pose anywhere on the segment between the two followers, or within the overshoot
    past the slow one, follows. Once a landing drone reaches the floor (`touch`) it may stop there or
    slide on to its point: anywhere from where the followers were then to where they are now follows too.
    ``key``: the take-off's or landing's start (a new one starts a new follower); None while the drone plans,
    holds or hovers (both constants then the position loop's: one point)."""

    def __init__(
        self,
        key: float | None,
        at: complex,
        now_s: float,
        momentum: complex,
        fast_s: float,
        slow_s: float,
        model: Follower | None = None,
    ) -> None:
        self.key = key
        self.fast = self.slow = at
        self.then = self.since = now_s
        self.momentum = momentum
        self.fast_s, self.slow_s = fast_s, slow_s
        self.model = model
        """While the drone streams: its own controller's response (`response.Follower`), the slow edge."""
        self.touched: tuple[complex, complex] | None = None

    def step(self, setpoint: complex, now_s: float) -> None:
        """Advance to ``now_s`` towards ``setpoint``."""
        dt = max(0.0, min(now_s - self.then, 0.1))
        self.then = now_s
        if self.model is not None:
            self.fast = self.slow = self.model.step(setpoint, dt)
        elif dt > 0.0:
            limit = TRACKING_SPEED_M_S * dt
            for name, tau in (("fast", self.fast_s), ("slow", self.slow_s)):
                at = getattr(self, name)
                step = (setpoint - at) * (1.0 - math.exp(-dt / tau))
                if abs(step) > limit:
                    step *= limit / abs(step)
                setattr(self, name, at + step)

    def touch(self) -> None:
        """The drone is on the floor now (the first call counts)."""
        if self.touched is None:
            self.touched = (self.fast, self.slow)

    def off(self, position: complex) -> float:
        """How far ``position`` is from where the drone should be now."""
        overshoot = self.momentum * math.exp(-max(0.0, self.then - self.since) / self.slow_s)
        off = min(_to_segment(position, self.fast, self.slow), _to_segment(position, self.slow, self.slow + overshoot))
        if self.touched is not None:
            fast, slow = self.touched
            off = min(
                off,
                _to_segment(position, fast, self.fast),
                _to_segment(position, slow, self.slow),
                _to_segment(position, fast, slow),
            )
        return off


def _to_segment(p: complex, a: complex, b: complex) -> float:
    """Distance from ``p`` to the segment from ``a`` to ``b`` (a point when they coincide)."""
    ab = b - a
    if abs(ab) < 1e-12:
        return abs(p - a)
    w = ((p - a) * ab.conjugate()).real / (abs(ab) ** 2)
    return abs(p - (a + min(max(w, 0.0), 1.0) * ab))


class TrackingCheck:
    """The tracking check with its followers (the supervisor runs it). ``first_order``: drones simulated with the
    first-order model, followed with it."""

    def __init__(self, first_order: frozenset[str] = frozenset()) -> None:
        self.first_order = first_order
        self._off_track: dict[str, float] = {}
        self._off_track_warned: set[str] = set()
        self._predicted: dict[str, _Follower] = {}
        """drone -> where its setpoints should have brought it."""
        self._latencies: deque[tuple[float, float]] = deque()
        """(when, the mocap's latency) of the last ``TRACKING_LATENCY_WINDOW_S``."""
        self._plan_targets: dict[str, tuple[float, complex, bool, float]] = {}
        """drone -> (the take-off's or landing's start, its firmware target x + iy, confirmed by a second sample,
        when the last sample was made)."""

    def model_of(self, name: str) -> Follower | None:
        """The response model following ``name``'s streamed setpoints now (None while it does not stream, or
        before its first check): its velocity and tilt, which a filtered mocap velocity gives late."""
        follower = self._predicted.get(name)
        return follower.model if follower is not None else None

    def check(
        self, now_s: float, agents: list[DroneAgent], tracker: PoseTracker, states: dict[str, DroneState]
    ) -> list[Finding]:
        """Measured position against a follower of where the drone is being taken (``TRACKING_WARN_M``): the
        streamed setpoints while it plans, holds or hovers; while the high-level commander flies its take-off or
        landing, the firmware's own target (`_plan_target`), which keeps the x, y where the plan began (the
        estimate of that moment, not the mocap pose: after a stall or a blind spell the estimate snaps back to mocap
        and the drone moves by the difference, which is no push). There the follower is an envelope (`_Follower`):
        anywhere between a first-order return with the position loop's 0.25 s and one with 0.5 s, plus an overshoot
        along the drone's velocity at its start; from the moment the drone reaches the floor (mocap height under
        ``ON_FLOOR_Z_M``) it may also have stopped anywhere on the way (on the floor it cannot slide, and it reaches
        it before it touches), and a follower starts only while the drone is off the floor. The line is widened by
        the drone's speed times the mocap's latency (the largest of the last 0.5 s): the drone's estimator takes the
        same late poses as extpos, so its truth runs ahead of them by that much, and when the latency changes the
        drone surges or drops back until its estimate settles (compound campaign seed 17, run 13: 137 ms of mocap
        delay at 0.5 m/s said 6 drones "pushed"). Under a healthy latency (3-8 ms) the widening is under 1 cm.

        Take-off and landing are watched too: a gust during a watchdog's landing moves cf2 0.13 m (extpose compound
        campaign seed 16, run 14)."""
        out = []
        latencies = self._latencies
        latencies.append((now_s, tracker.latency_s or 0.0))
        while len(latencies) > 1 and latencies[0][0] < now_s - TRACKING_LATENCY_WINDOW_S:
            latencies.popleft()
        late = max(latency for _, latency in latencies)
        for a in agents:
            pose = tracker.get(a.name)
            planned = a.phase in (DronePhase.TAKEOFF, DronePhase.LANDING)
            if planned:  # the target is read while the drone is unseen too, to be known the moment it is seen
                setpoint = self._plan_target(a, states.get(a.name))
                if a.phase == DronePhase.LANDING and a.touchdown_s is not None and now_s > a.touchdown_s:
                    setpoint = None
            else:
                setpoint = a.last_setpoint
            if setpoint is None or pose is None or now_s - pose.stamp_s > POSE_LATE_S:
                self._off_track.pop(a.name, None)
                self._predicted.pop(a.name, None)
                continue
            if not pose.valid:  # a frame or a few without it: the model waits (restarted at the next pose, one
                continue  # dropped frame in a push would hide the push)
            on_floor = planned and pose.position[2] <= ON_FLOOR_Z_M
            key = a.phase_since_s if planned else None  # a take-off or landing starts the model afresh
            follower = self._predicted.get(a.name)
            if follower is None or follower.key != key:
                if on_floor:  # first seen on the floor (landed blind, or not yet lifted): nothing to follow
                    self._predicted.pop(a.name, None)
                    continue
                cascade = not planned and a.name not in self.first_order
                model = Follower(a.braking.gains, pose.xy, pose.velocity) if cascade else None
                follower = _Follower(
                    key,
                    pose.xy,
                    now_s,
                    pose.velocity * TRACKING_PLAN_TAU_S if planned else 0j,
                    TRACKING_TAU_S,
                    TRACKING_PLAN_TAU_S if planned else TRACKING_TAU_S,
                    model,
                )
                self._predicted[a.name] = follower
            follower.step(setpoint, now_s)
            if on_floor:
                follower.touch()
            off = follower.off(pose.xy)
            if off > TRACKING_WARN_M + abs(pose.velocity) * late:
                started = self._off_track.setdefault(a.name, now_s)
                if now_s - started >= TRACKING_WARN_S and a.name not in self._off_track_warned:
                    self._off_track_warned.add(a.name)
                    being = {DronePhase.LANDING: " while landing", DronePhase.TAKEOFF: " while taking off"}
                    out.append(
                        Finding(
                            "tracking",
                            WARNING,
                            f"{off:.2f} m from where its setpoints should have "
                            f"brought it{being.get(a.phase, '')}: something pushes it (a gust, a "
                            "contact?)",
                            a.name,
                            "warn",
                        )
                    )
            else:
                self._off_track.pop(a.name, None)
                if off < TRACKING_WARN_M / 2 and a.name in self._off_track_warned:
                    self._off_track_warned.discard(a.name)
                    out.append(Finding("tracking", INFO, "following its setpoints again", a.name, "warn"))
        return out

    def _plan_target(self, a: DroneAgent, state: DroneState | None) -> complex | None:
        """The x, y the high-level commander's take-off or landing holds, from the firmware's logged target
        (`DroneState.target_m`): two telemetry samples in a row, both made at least ``PLAN_TARGET_AFTER_S`` after
        the command was sent, that agree within ``PLAN_TARGET_AGREE_M`` (a sample made before the command reached
        the drone holds the last streamed setpoint, up to the carrot's lead ahead; a streamed setpoint moves
        between samples, the plan's x, y does not). Kept for the rest of the phase; None until then, or where
        the firmware logs no target."""
        held = self._plan_targets.get(a.name)
        if held is not None and held[0] != a.phase_since_s:
            held = None
        if held is not None and held[2]:
            return held[1]
        if state is None or state.target_m is None:
            return None
        made = state.estimate_stamp_s if state.estimate_stamp_s is not None else state.telemetry_stamp_s
        if made is None or made < a.phase_since_s + PLAN_TARGET_AFTER_S or (held is not None and held[3] == made):
            return None
        target = complex(state.target_m[0], state.target_m[1])
        if held is not None and abs(target - held[1]) <= PLAN_TARGET_AGREE_M:
            self._plan_targets[a.name] = (a.phase_since_s, held[1], True, made)
            return held[1]
        self._plan_targets[a.name] = (a.phase_since_s, target, False, made)
        return None
