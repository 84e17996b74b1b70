"""Separation and clearance: two drones closer than 2r (3D), or a drone closer than r to an obstacle surface, now
or before they could stop if held now (rpf_fly/flight/response.py), and when such an episode ends.

A pair (or a drone and an obstacle) counts as breached when it is closer than 2r (r) now, or when, held now, it
would come closer before it stops: each drone flies on towards its setpoint for its mocap latency plus
`HOLD_REACTION_S`, then brakes as its own controller does from the speed and tilt it reached (`Braking.stop_point`);
a pair's closest approach is taken with both on their ways in step. Edge-triggered: one finding when an episode
starts, one (for a ``hold`` response) when it ends, at rest from the hold on and clear by `RESUME_MARGIN_M`
(docs/flight.md, "How a held drone stops")."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from rpf_fly.flight.agent import DroneAgent
from rpf_fly.flight.commander import STREAMING as STREAMING_PHASES
from rpf_fly.flight.events import ERROR, INFO
from rpf_fly.flight.findings import Finding
from rpf_fly.flight.poses import PoseTracker, TrackedPose
from rpf_fly.flight.response import OVERHEAD, Follower, braking_for
from rpf_fly.mission.model import Mission
from rpf_fly.planning.obstacles import ObstacleSet

RESUME_MARGIN_M = 0.05
REST_M_S = 0.1
REST_S = 0.5
"""A separation or clearance episode ends (its ``hold`` resumes) only once the drones have been at rest (under
`REST_M_S` by the mocap and by their response model) for `REST_S` counted from the hold on, and are clear, braking
from where they are, by `RESUME_MARGIN_M`: a held drone brakes hard and swings back, its braking tilt makes its
stop look short, and resuming at the turn of a swing restarts the approach the hold stopped (a head-on pair at
1 m/s resumed 10 ms into its hold, or at the turn of its swing, and met; a pair held from rest, its carrots just
sent at each other, was "rested" at once and resumed in the next frame)."""
HOLD_REACTION_S = 0.1
"""From the mocap picture of a breach to the hold setpoint acting on the drone: the supervisor's pass (every mocap
frame), the hold setpoint sent at once through the radio's queue, the drone's estimator taking the extpos, and the
firmware's next position-loop tick; twice what an idle host takes (a head-on pair at 1 m/s each met on a loaded
2-core host with 0.05 s). A drone whose radio link is slower takes its link's echo round trip instead
(`ProximityCheck.radio_delay_s`)."""

COAST_MODELLED_S = 0.2
"""How much of a drone's way until a hold acts the response model flies (`Follower.coasted`, 10 ms a step, on every
mocap frame); beyond it (a slow link's round trip, a late mocap picture) the drone goes on at the speed its carrot
pulls it to, at least the speed it reached: the model's cost does not grow with the host's lateness."""
CLEARANCE_KEPT_S = 0.1
CLEARANCE_MOVED_M = 0.15
"""A drone's clearance from the last pass stands for this one's if it is at most `CLEARANCE_KEPT_S` old, less
`CLEARANCE_MOVED_M` (0.1 s at 1.5 m/s): the clearance check works a drone's stop out only when that could bring it
near an obstacle, from one obstacle query a pass."""
REACH_SLACK = 1.2
REACH_SLACK_M = 0.05
"""`ProximityCheck._reach_m`'s margin over its bound."""

RADIO_DELAY_MAX_S = 0.5
"""The most a link's round trip adds to a hold's reaction (cflib's 95th percentile over its last 100 pings)."""


_WAY = np.linspace(0.25, 1.0, 4)
"""Where on its way to rest a drone's clearance is checked: a quarter, half, three quarters and all of it."""


class ProximityCheck:
    """The separation and clearance checks with the memory their episodes need (the supervisor runs them)."""

    def __init__(
        self, mission: Mission, obstacles: ObstacleSet, model_of: Callable[[str], Follower | None] = lambda name: None
    ) -> None:
        """``model_of``: a streaming drone's response model (`TrackingCheck.model_of`), whose velocity and tilt
        are the drone's state for its stop: the mocap's filtered velocity trails a drone that speeds up."""
        self.safety = mission.safety
        self.obstacles = obstacles
        self.r = mission.planner.safety_radius
        self.model_of = model_of
        self._close_pairs: set[tuple[str, str]] = set()
        self._near_obstacle: set[str] = set()
        self._now_s = 0.0
        self._moving_since: dict[str, float] = {}
        """drone -> when it was last seen moving (faster than `REST_M_S`): an episode ends `REST_S` after."""
        self._clearances: dict[str, tuple[float, float]] = {}
        """drone -> (when, its clearance then), from the last clearance pass that saw it."""
        self._reaches: dict[tuple[str, bool], float] = {}
        """(drone, commanded) -> `_reach_m`, for this pass."""
        self._stops: dict[tuple[str, bool], complex] = {}
        """(drone, commanded) -> where it comes to rest if held now (`_stop_point`), for this pass: every pair and the
        clearance read it."""
        self.radio_delay_s: dict[str, float] = {}
        """drone -> its link's echo round trip (s; the supervisor sets it from the telemetry at each pass): a hold
        through a slower link than `HOLD_REACTION_S` allows reaches the drone that much later (8 drones on one
        emulated Crazyradio PA on a full host, round trips of 0.2 s: a pair held 0.3 s before it met)."""

    def rest(self, now_s: float, agents: list[DroneAgent], tracker: PoseTracker) -> None:
        """Note which drones move (by the mocap or by their response model, whichever says faster)."""
        for a in agents:
            pose = tracker.get(a.name)
            if pose is None:
                continue
            model = self.model_of(a.name)
            speed = max(abs(pose.velocity), abs(model.velocity) if model is not None else 0.0)
            if speed > REST_M_S or a.name not in self._moving_since:
                self._moving_since[a.name] = now_s
        self._now_s = now_s
        self._stops = {}
        self._reaches = {}

    def _resting(self, name: str) -> bool:
        """At rest for `REST_S` (a drone another process flies: taken as at rest)."""
        since = self._moving_since.get(name)
        return since is None or self._now_s - since >= REST_S

    def separation(self, agents: list[DroneAgent], tracker: PoseTracker, foreign: Sequence[str] = ()) -> list[Finding]:
        out = []
        close_now: set[tuple[str, str]] = set()
        own_poses = [(a.name, tracker.get(a.name)) for a in agents]
        foreign_poses = [(n, tracker.get(n)) for n in foreign]
        tracked = [(n, p) for n, p in own_poses if p is not None] + [(n, p) for n, p in foreign_poses if p is not None]
        mine = {n for n, _ in tracked} - set(foreign)
        commanded = {a.name: a for a in agents if a.phase.airborne}
        for i, (ni, pi) in enumerate(tracked):
            if ni not in mine:
                break  # two drones of other processes: theirs to check
            for nj, pj in tracked[i + 1 :]:
                d = sum((u - v) ** 2 for u, v in zip(pi.position, pj.position)) ** 0.5
                pair = (ni, nj)
                room = abs(pi.xy - pj.xy) - 2 * self.r - RESUME_MARGIN_M
                if pair not in self._close_pairs and room > 0.0:
                    latency = tracker.latency_s
                    if room >= self._reach_m(ni, pi, commanded.get(ni), latency) + self._reach_m(
                        nj, pj, commanded.get(nj), latency
                    ):
                        continue  # they cannot come within 2r before they stop
                ahead = self._stopped_apart(ni, pi, nj, pj, commanded, tracker.latency_s)
                held = pair in self._close_pairs and (
                    min(d, ahead) < 2 * self.r + RESUME_MARGIN_M or not (self._resting(ni) and self._resting(nj))
                )
                if min(d, ahead) < 2 * self.r or held:
                    pair = (ni, nj)
                    close_now.add(pair)
                    if pair not in self._close_pairs:
                        self._moving_since[ni] = self._moving_since[nj] = self._now_s  # at rest from the hold on
                        response = self.safety.on_separation
                        message = f"separation {d:.3f} m from {nj} is below 2r = {2 * self.r:.2f} m"
                        if d >= 2 * self.r:
                            message = (
                                f"separation {d:.3f} m from {nj}, closing: braking from here they would "
                                f"come within {ahead:.3f} m, below 2r = {2 * self.r:.2f} m"
                            )
                        out.append(Finding("separation", ERROR, message, ni, response))
                        if response != "warn" and nj in mine:
                            out.append(Finding("separation", ERROR, f"separation {d:.3f} m from {ni}", nj, response))
        if self.safety.on_separation == "hold":
            still_close = {n for pair in close_now for n in pair}
            for name in {n for pair in self._close_pairs - close_now for n in pair if n in mine} - still_close:
                out.append(Finding("separation", INFO, "separation restored: resuming", name, "resume"))
        self._close_pairs = close_now
        return out

    def _clearance_before(self, name: str) -> float:
        """A drone's clearance at the last pass, less how far it can have flown since (`CLEARANCE_MOVED_M`); none
        known within `CLEARANCE_KEPT_S`: 0 (work its stop out)."""
        seen = self._clearances.get(name)
        if seen is None or self._now_s - seen[0] > CLEARANCE_KEPT_S:
            return 0.0
        return seen[1] - CLEARANCE_MOVED_M

    def _coast_s(self, agent: DroneAgent | None, latency_s: float | None) -> float:
        """How long a drone flies on before a hold sent now acts on it (`_stop_at`)."""
        reaction_s = max(HOLD_REACTION_S, self.radio_delay_s.get(agent.name, 0.0) if agent is not None else 0.0)
        return reaction_s + (latency_s or 0.0)

    def _reach_m(self, name: str, pose: TrackedPose, agent: DroneAgent | None, latency_s: float | None) -> float:
        """At most how far from ``pose`` a drone's `_stop_at` can be, cheaply (once per drone each pass): speeding
        up at its tilt limit until the hold acts, then braking from its tilt limit along its way, with `REACH_SLACK`.
        A pair further apart than their two reaches and 2r, or a drone further from every obstacle than its reach
        and r, needs no stop worked out (the response model flown on costs 0.07 ms a drone)."""
        key = (name, agent is not None)
        reach = self._reaches.get(key)
        if reach is None:
            braking = agent.braking if agent is not None else braking_for(None)
            model = self.model_of(agent.name) if agent is not None and agent.phase in STREAMING_PHASES else None
            speed = max(abs(pose.velocity), abs(model.velocity) if model is not None else 0.0)
            coast = self._coast_s(agent, latency_s)
            accel = braking.gains.max_brake_m_s2
            flown = speed * coast + 0.5 * accel * coast**2
            brake = braking.stop_m(speed + accel * coast, braking.gains.tilt_limit_deg)
            reach = self._reaches[key] = REACH_SLACK * (flown + brake) + REACH_SLACK_M
        return reach

    def _stop_point(self, name: str, pose: TrackedPose, agent: DroneAgent | None, latency_s: float | None) -> complex:
        """`_stop_at`, once per drone each pass."""
        key = (name, agent is not None)
        stop = self._stops.get(key)
        if stop is None:
            stop = self._stops[key] = self._stop_at(pose, agent, latency_s)
        return stop

    def _stop_at(self, pose: TrackedPose, agent: DroneAgent | None, latency_s: float | None) -> complex:
        """Where a drone at ``pose`` comes to rest if it is held now: its mocap picture is ``latency_s`` old and the
        hold reaches it `HOLD_REACTION_S` (or its link's round trip, if longer) later; until then its controller
        drives it on towards its setpoint (the next its planner may send: `DroneAgent.next_setpoint`), then it brakes
        as that controller does (`Braking.stop_point`) from the speed and tilt it has reached. A streaming drone is
        flown on on its response model (`Follower.coasted`: a drone speeding up from rest goes on speeding up until
        the hold's tilt turns round; flown on at its present speed instead, a pair resuming 0.4 m apart came 4 cm
        closer than predicted and under 2r); one the mocap sees faster than its model (pushed) at its mocap speed,
        with the model's tilt. A drone this process does not command: at its mocap speed, braking with the
        firmware's defaults from steady flight."""
        braking = agent.braking if agent is not None else braking_for(None)
        streaming = agent if agent is not None and agent.phase in STREAMING_PHASES else None
        setpoint = streaming.next_setpoint(pose.xy) if streaming is not None else None
        model = self.model_of(streaming.name) if streaming is not None else None
        coast_s = self._coast_s(agent, latency_s)
        if model is not None and setpoint is not None:
            modelled_s = min(coast_s, COAST_MODELLED_S)
            twin = model.coasted(setpoint, modelled_s)
            velocity = twin.velocity
            if coast_s > modelled_s:  # a slow link: on at the speed its carrot pulls it to, at least the one reached
                lead = setpoint - twin.position
                pulled = min(braking.gains.vel_max * OVERHEAD, braking.gains.pos_kp * abs(lead))
                way = velocity / abs(velocity) if abs(velocity) > 0.05 else (lead / abs(lead) if abs(lead) else 0j)
                velocity = way * max(abs(velocity), pulled)
            if abs(velocity) >= abs(pose.velocity):
                ahead = pose.xy + twin.position - model.position + velocity * (coast_s - modelled_s)
                return braking.stop_point(ahead, velocity, setpoint, twin.tilt_deg)
        velocity, tilt = pose.velocity, None
        if model is not None:
            tilt = model.tilt_deg
            if abs(model.velocity) > abs(velocity):
                velocity = model.velocity
        return braking.stop_point(pose.xy + velocity * coast_s, velocity, setpoint, tilt)

    def _stopped_apart(
        self,
        ni: str,
        pi: TrackedPose,
        nj: str,
        pj: TrackedPose,
        commanded: dict[str, DroneAgent],
        latency_s: float | None,
    ) -> float:
        """The closest two drones come if both are held now (3D, centre to centre): each flies on to its
        `_stop_point`, both taken to cover their way in step."""
        a0, b0 = pi.xy, pj.xy
        a1 = self._stop_point(ni, pi, commanded.get(ni), latency_s)
        b1 = self._stop_point(nj, pj, commanded.get(nj), latency_s)
        start, change = b0 - a0, (b1 - b0) - (a1 - a0)
        s = 0.0 if abs(change) < 1e-12 else min(1.0, max(0.0, -(start * change.conjugate()).real / abs(change) ** 2))
        dz = pi.position[2] - pj.position[2]
        return math.hypot(abs(start + s * change), dz)

    def clearance(self, agents: list[DroneAgent], tracker: PoseTracker) -> list[Finding]:
        if self.obstacles.is_empty:
            return []
        out = []
        near_now = set()
        tracked = [(a, pose) for a in agents if (pose := tracker.get(a.name)) is not None]
        distances = np.empty((0, 1 + len(_WAY)))
        if tracked:  # every drone's position and its way to rest in one call
            here = np.array([pose.xy for _, pose in tracked])
            stops = np.array(
                [
                    self._stop_point(a.name, pose, a, tracker.latency_s)
                    if a.name in self._near_obstacle
                    or self._clearance_before(a.name)
                    < self.r + RESUME_MARGIN_M + self._reach_m(a.name, pose, a, tracker.latency_s)
                    else pose.xy  # it cannot come near one before it stops
                    for a, pose in tracked
                ]
            )
            points = np.concatenate([here[:, None], here[:, None] + (stops - here)[:, None] * _WAY], axis=1)
            distances = self.obstacles.signed_distance(points)
        for (a, _pose), row in zip(tracked, distances):
            clearance = float(row[0])
            self._clearances[a.name] = (self._now_s, clearance)
            ahead = float(np.min(row[1:]))
            held = a.name in self._near_obstacle and (
                min(clearance, ahead) < self.r + RESUME_MARGIN_M or not self._resting(a.name)
            )
            if min(clearance, ahead) < self.r or held:
                near_now.add(a.name)
                if a.name not in self._near_obstacle:
                    self._moving_since[a.name] = self._now_s  # at rest from the hold on
                    message = f"obstacle clearance {clearance:.3f} m is below r = {self.r:.2f} m"
                    if clearance >= self.r:
                        message = (
                            f"obstacle clearance {clearance:.3f} m, closing: braking from here it would come "
                            f"within {ahead:.3f} m, below r = {self.r:.2f} m"
                        )
                    out.append(Finding("obstacle", ERROR, message, a.name, self.safety.on_obstacle))
        if self.safety.on_obstacle == "hold":
            for name in self._near_obstacle - near_now:
                out.append(Finding("obstacle", INFO, "obstacle clearance restored: resuming", name, "resume"))
        self._near_obstacle = near_now
        return out
