"""The supervisor: safety checks every loop iteration, each finding an event and a response.

Checks (docs/flight.md):
- pose: a drone whose newest valid mocap pose is older than `POSE_LATE_S` is a warning (it flies on); older than
  ``pose_timeout_s`` it holds; after ``pose_lost_land_s`` it lands; when no drone has a fresh pose the whole swarm
  holds, then lands (mocap lost), and a gap shorter than the hold is one swarm-wide warning (mocap late);
- geofence: a measured position outside the arena lands that drone (setpoints are clamped anyway);
- separation: two drones closer than 2r (centre to centre, 3D) -> event, response ``on_separation``;
- obstacle: a drone closer than r to an obstacle surface (planar, obstacles are vertical) -> event, ``on_obstacle``;
- battery: the firmware reports low power, or the voltage under load is below ``min_battery_v - FLIGHT_SAG_V``:
  that drone lands;
- link: the backend says the link is down: that drone is lost (nothing can reach it); the others continue;
- telemetry: a linked drone whose status telemetry stopped arriving for ``TELEMETRY_STALE_S`` -> warning event;
- pose glitch: the pose tracker refused a pose that jumped further than a drone can fly (a marker swap) -> hold
  until the track is back;
- orientation glitch: the pose tracker refused an orientation that turned further than a drone can turn (a wrong
  fit of its markers) -> warning; it flies on (the position is still followed), and extpose forwards the position
  only until the orientation is back (rpf_fly/flight/poses.py).

A drone nobody commands any more (link lost, motors cut) stays in the separation check at its mocap pose until
mocap shows it on the floor: it may hover, drift or fall for up to 2 s where the others fly. A ``hold`` response
ends (``resume``) when the condition that caused it clears for that drone.

Findings are edge-triggered where a condition persists (an event when it starts, another when it clears), so the
log records episodes, not every tick.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

from rpf_fly.flight.agent import DroneAgent
from rpf_fly.flight.blind import (
    BODY_RADIUS_M,
    ESTIMATE_FRESH_S,
    LAND_EARLY_SHARE,
    blind_drift_m,
    blind_land_s,
)
from rpf_fly.flight.commander import ON_FLOOR_Z_M
from rpf_fly.flight.estimate_check import EstimateCheck
from rpf_fly.flight.events import ERROR, INFO, WARNING
from rpf_fly.flight.findings import Finding
from rpf_fly.flight.phases import DronePhase
from rpf_fly.flight.poses import EXTPOS_LEAD_FROM_S, POSE_LATE_S, PoseTracker
from rpf_fly.flight.proximity_check import RADIO_DELAY_MAX_S, ProximityCheck
from rpf_fly.flight.radio_lag_check import RadioLagCheck
from rpf_fly.flight.tracking_check import TrackingCheck
from rpf_fly.mission.model import Mission
from rpf_fly.planning.obstacles import ObstacleSet
from rpf_fly.radio.backend import DroneState

FLIGHT_SAG_V = 0.4
"""Voltage a Crazyflie battery sags under hover load; the in-flight threshold is the preflight one minus this."""

LOW_BATTERY_SAMPLES = 5
"""Consecutive status samples (10 Hz: half a second) below the in-flight threshold before a drone is landed: one
sample taken during a thrust peak (a turn, a gust) sags far lower than the hover load, and must not end a flight."""

TELEMETRY_STALE_S = 1.0
"""A linked drone whose status telemetry (10 Hz) is older than this: the battery and supervisor checks are blind."""

LINK_QUALITY_WARN_PCT = 96.0
"""cflib's link quality loses 10 points per retry a packet needs on average over its last 100 acks (100 - 10 p /
(1 - p) for a loss p of the radio's attempts): below 96 % 0.4 retries a packet (over 28 % of the attempts lost),
setpoints and extpos arrive late, and the link is on its way to the 100 lost acks in a row after which cflib drops
it. Crazyswarm2 warns under an ack rate of 0.9. A lab's bursts (the dry run's default `RADIO_LOSS`) dip it to 97 %
at worst, so a loss that costs fewer retries than a burst cannot be told from one and is not said. At 95 % (a third
of the attempts lost) a random fault campaign's 30 % loss would pass silently."""

LINK_QUALITY_CLEAR_PCT = 99.0
"""Back at or above this, a poor link's episode ends (an info event), so the next one is said again. It must be
reachable: cflib's link quality is at most 100 %, so an end above that would leave a drone's link never said poor
again after its first episode."""

MOCAP_LATENCY_WARN_S = 0.02
"""Mocap latency (camera to receipt, as the mocap measures it) above this: the estimators and the planners act on
a picture that old (Crazyswarm2 warns at 10 ms over unicast; a healthy Motive link is 3-8 ms). 20 ms: over twice
the worst healthy link, so a healthy system never warns, and 2 cm of lag at 1 m/s. At 50 ms the
random fault campaign's 33 ms of mocap delay (plus the emulated camera's 4 ms), a picture five times older than a
healthy one, would go unsaid."""
MOCAP_LATENCY_HOLD_S = EXTPOS_LEAD_FROM_S
"""Mocap latency above this (0.1 s): every flying drone holds (brought to rest where it is) until the latency is back
under half of it, then plans on, and its extpos is carried ahead by the latency (`poses.estimator_position`). The
firmware's estimator takes each late pose as current, so a moving drone's estimate trails it by its speed x the
latency and its controller lurches after it. Measured on the firmware model (docs/flight.md): a mocap delay of 0.08
and 0.10 s flown through campaign/pillars-6 passes as it is, 0.12 s crashed two drones into pillars."""


def radio_delay_s(state: DroneState) -> float:
    """How long a command may take through the drone's link: cflib's echo round trip (95th percentile), at most
    `RADIO_DELAY_MAX_S`; 0 for a link that is down or has not measured one yet."""
    return min(RADIO_DELAY_MAX_S, state.link.round_trip_s) if state.link.up else 0.0


class Supervisor:
    """Stateless checks plus the memory needed for edge-triggered events."""

    def __init__(self, mission: Mission, obstacles: ObstacleSet, first_order: frozenset[str] = frozenset()):
        """``first_order``: drones simulated with the first-order model, whose tracking is followed with it (every
        other drone's with its own controller's response: `tracking_check`)."""
        self.mission = mission
        self._tracking = TrackingCheck(first_order)
        self._proximity = ProximityCheck(mission, obstacles, self._tracking.model_of)
        self.safety = mission.safety
        self.obstacles = obstacles
        self.r = mission.planner.safety_radius
        self._stale: set[str] = set()
        self._late: set[str] = set()
        """Drones whose missing pose `POSE_LATE_S` was said (cleared once their pose is fresh)."""
        self._mocap_late = False
        self._mocap_lost = False
        self._low_battery: dict[str, tuple[int, float]] = {}
        """drone -> (consecutive low samples, stamp of the last one counted)."""
        self._telemetry_stale: set[str] = set()
        self._glitching: set[str] = set()
        self._turned: set[str] = set()
        self._estimates = EstimateCheck(mission.safety)
        self._radio_lag = RadioLagCheck(mission.flight.rate_hz)
        self._poor_link: set[str] = set()
        self._late_landing: set[str] = set()
        self._late_mocap = False
        self._latency_hold = False
        self._blind_landed: set[str] = set()
        self._blind_stopped: set[str] = set()

    def check(
        self,
        now_s: float,
        agents: Iterable[DroneAgent],
        tracker: PoseTracker,
        states: dict[str, DroneState],
        others: Iterable[str] = (),
    ) -> list[Finding]:
        """``others``: drones another process flies (a distributed flight's other workers): in the separation check
        at their mocap pose while off the floor; a finding names only this process's drones."""
        everyone = list(agents)
        agents = [a for a in everyone if a.phase.airborne]
        uncommanded = [
            a
            for a in everyone
            if a.phase in (DronePhase.LINK_LOST, DronePhase.EMERGENCY)
            and (p := tracker.get(a.name)) is not None
            and p.position[2] > ON_FLOOR_Z_M
        ]
        grounded = [a for a in everyone if a.phase == DronePhase.GROUNDED]  # on the floor, in everyone's way
        findings: list[Finding] = []
        findings += self._links(agents, states)
        findings += self._glitches(agents, tracker)
        findings += self._orientations(agents, tracker)
        findings += self._poses(now_s, agents, tracker)
        findings += self._geofence(agents, tracker)
        foreign = [n for n in others if (p := tracker.get(n)) is not None and p.position[2] > ON_FLOOR_Z_M]
        self._proximity.rest(now_s, agents + uncommanded, tracker)
        self._proximity.radio_delay_s = {n: radio_delay_s(state) for n, state in states.items()}
        findings += self._proximity.separation(agents + uncommanded + grounded, tracker, foreign)
        findings += self._blind(now_s, agents, uncommanded, foreign, tracker, states)
        findings += self._proximity.clearance(agents, tracker)
        findings += self._battery(agents, states)
        findings += self._telemetry(now_s, agents, states)
        findings += self._crashes(agents, states)
        findings += self._estimates.check(now_s, agents, tracker, states)
        findings += self._link_quality(agents, states)
        findings += self._radio_lag.check(now_s, agents, states)
        findings += self._tracking.check(now_s, agents, tracker, states)
        findings += self._mocap_latency(tracker)
        return findings

    # -------------------------------------------------------------------------------------------- checks

    def _links(self, agents: list[DroneAgent], states: dict[str, DroneState]) -> list[Finding]:
        out = []
        for a in agents:
            state = states.get(a.name)
            if state is not None and not state.link.up:
                why = state.link.error or "link down"
                others = "; the others continue" if any(b is not a for b in agents) else ""  # not for a lone drone
                out.append(Finding("link_lost", ERROR, f"radio link lost ({why}){others}", a.name, "lost"))
        return out

    def _poses(self, now_s: float, agents: list[DroneAgent], tracker: PoseTracker) -> list[Finding]:
        s = self.safety
        out: list[Finding] = []
        flying = [a for a in agents if a.phase != DronePhase.LANDING]
        ages = {a.name: tracker.age(a.name, now_s) for a in flying}
        all_stale = bool(flying) and all(age > s.pose_timeout_s for age in ages.values())
        if all_stale and not self._mocap_lost:
            self._mocap_lost = True
            out.append(Finding("mocap_lost", ERROR, "no fresh mocap pose for any drone: all hold", None, "hold"))
        elif self._mocap_lost and any(tracker.age(a.name, now_s) <= s.pose_timeout_s for a in agents):
            # a fresh pose of any airborne drone, landing ones included (not the moment every blind drone begins its
            # landing, with no pose back at all)
            self._mocap_lost = False
            out.append(Finding("mocap_lost", INFO, "mocap poses are back", None, "resume"))
        late = {n for n, age in ages.items() if age > POSE_LATE_S}
        all_late = bool(flying) and len(late) == len(flying)
        # Landing drones are not held on a lost pose (their landing stands), but a pose they miss is said: they
        # land on their estimates, and a review must tell why one ended off its spot (extpose campaign seed 16, run 11:
        # a watchdog's landing, then cf3 occluded for 1.3 s).
        landing = {a.name: tracker.age(a.name, now_s) for a in agents if a.phase == DronePhase.LANDING}
        late_landing = {n for n, age in landing.items() if age > POSE_LATE_S}
        landing_only = not flying and bool(landing) and len(late_landing) == len(landing)
        if (all_late or landing_only) and not self._mocap_late and not self._mocap_lost:
            self._mocap_late = True
            oldest = max({**ages, **landing}.values())
            tail = "flying on the last ones" if all_late else "the landing drones land on their estimates"
            out.append(
                Finding(
                    "mocap_late",
                    WARNING,
                    f"no mocap pose for any drone for {oldest * 1e3:.0f} ms: {tail}",
                    None,
                    "warn",
                )
            )
        elif not (late if flying else late_landing):
            self._mocap_late = False
        for name, age in landing.items():
            if age <= POSE_LATE_S:
                self._late_landing.discard(name)
            elif name not in self._late_landing:
                self._late_landing.add(name)
                if not (self._mocap_late or self._mocap_lost):
                    out.append(
                        Finding(
                            "pose_late",
                            WARNING,
                            f"no pose for {age * 1e3:.0f} ms while landing (occluded?): it lands on its estimate",
                            name,
                            "warn",
                        )
                    )
        out += self._unseen(agents, tracker)
        for a in flying:
            age = ages[a.name]
            if age <= POSE_LATE_S:
                self._late.discard(a.name)
            elif a.name not in self._late and age <= s.pose_timeout_s:
                self._late.add(a.name)
                if not all_late:
                    out.append(
                        Finding(
                            "pose_late",
                            WARNING,
                            f"no pose for {age * 1e3:.0f} ms (occluded?): flying on its last one",
                            a.name,
                            "warn",
                        )
                    )
            if age > s.pose_lost_land_s:
                pose = tracker.get(a.name)
                duration = blind_land_s(pose.position[2] if pose is not None else 1.0, self.mission.flight.land_s)
                out.append(
                    Finding(
                        "pose_lost",
                        ERROR,
                        f"no valid pose for {age:.1f} s: landing (in {duration:.1f} s: "
                        "without mocap its estimate drifts)",
                        a.name,
                        "land",
                        duration,
                    )
                )
            elif age > s.pose_timeout_s:
                if a.name not in self._stale:
                    self._stale.add(a.name)
                    out.append(Finding("pose_stale", WARNING, f"pose {age * 1e3:.0f} ms old: holding", a.name, "hold"))
            elif a.name in self._stale:
                self._stale.discard(a.name)
                out.append(Finding("pose_stale", INFO, "pose fresh again: resuming", a.name, "resume"))
        return out

    @staticmethod
    def _unseen(agents: list[DroneAgent], tracker: PoseTracker) -> list[Finding]:
        """Pose gaps of at least ``POSE_LATE_S`` that began and ended between two frames the loop was given (it was
        stalled; the mocap source saw them: `MocapFrame.unseen_untracked_s`), said after the fact: the gap cost
        nothing the stall had not already (no extpos went out either way), but a lab wants to know its cameras
        lost the drones. Every airborne drone in one: one ``mocap_late`` (compound campaign seed 17, run 15: a
        0.47 s blackout inside a 1.58 s loop stall)."""
        unseen = tracker.take_unseen()
        named = {a.name: unseen[a.name] for a in agents if a.name in unseen}
        if not named:
            return []
        if len(named) == len(agents) and len(agents) > 1:
            return [
                Finding(
                    "mocap_late",
                    WARNING,
                    f"no mocap pose for any drone for {max(named.values()) * 1e3:.0f} "
                    "ms while the loop was not reading (stalled): said after the fact",
                    None,
                    "warn",
                )
            ]
        return [
            Finding(
                "pose_late",
                WARNING,
                f"no pose for {gap * 1e3:.0f} ms while the loop was not reading "
                "(stalled; occluded?): said after the fact",
                name,
                "warn",
            )
            for name, gap in named.items()
        ]

    def _blind(
        self,
        now_s: float,
        agents: list[DroneAgent],
        uncommanded: list[DroneAgent],
        foreign: list[str],
        tracker: PoseTracker,
        states: dict[str, DroneState] | None = None,
    ) -> list[Finding]:
        """A drone without a fresh pose flies on its estimate, which drifts (`blind_drift_m`). Its room: the
        clearance of its last pose to obstacle surfaces and the arena's edge (plus r, the geofence's allowance), and
        half its distance to another blind drone (both drift) or all of it to one mocap sees, less the bodies'
        radii. Land now (fast: `blind_land_s`) when a landing begun later could not end inside
        `LAND_EARLY_SHARE` of it; cut the motors when even the landing under way cannot end inside it and a fall
        begun later would not either (a fall takes sqrt(2 z / g)). A drone far from everything keeps the hold of
        ``pose_timeout_s`` and the landing of ``pose_lost_land_s``. Its height z: its on-board estimate's (fresh
        telemetry) plus the drift it may have had, at most its last pose's: a blind landing's drone is lower than
        where mocap last saw it, and a fall from there ends sooner (with the last pose's height, a landing 0.15 m
        above the floor was cut as if it fell from 0.6 m: campaign lab-3, blackout)."""
        s, out = self.safety, []
        land_s = self.mission.flight.land_s
        rate = s.blind_drift_m_s2
        ages = {a.name: tracker.age(a.name, now_s) for a in agents + uncommanded}
        ages.update({n: tracker.age(n, now_s) for n in foreign})
        for a in agents:
            age = ages[a.name]
            pose = tracker.get(a.name)
            if pose is None or age <= s.pose_timeout_s:
                self._blind_landed.discard(a.name)
                continue
            if a.name in self._blind_stopped:
                continue
            room, what = self._room(a.name, pose.position, ages, tracker, agents + uncommanded, foreign)
            height = self._blind_height(now_s, pose.position[2], age, (states or {}).get(a.name))
            if a.phase == DronePhase.LANDING:
                if a.touchdown_s is None or a.touchdown_s <= now_s:
                    continue  # its descent has ended: down, as far as anything here knows
                touchdown = age + a.touchdown_s - now_s
            else:
                touchdown = age + blind_land_s(height, land_s)
            fall = math.sqrt(2.0 * height / 9.81)
            if blind_drift_m(touchdown, rate) > room and blind_drift_m(age + fall, rate) >= room:
                self._blind_stopped.add(a.name)
                where = (
                    f"{touchdown - age:.1f} s before its landing would end, " if a.phase == DronePhase.LANDING else ""
                )
                out.append(
                    Finding(
                        "pose_lost",
                        ERROR,
                        f"no valid pose for {age:.1f} s, {room:.2f} m of room to "
                        f"{what}: its estimate may drift it {blind_drift_m(touchdown, rate):.2f} m before a "
                        f"landing could end: motors off ({where}at most {height:.2f} m up)",
                        a.name,
                        "stop",
                    )
                )
            elif (
                a.phase != DronePhase.LANDING
                and a.name not in self._blind_landed
                and blind_drift_m(touchdown, rate) >= LAND_EARLY_SHARE * room
            ):
                self._blind_landed.add(a.name)
                duration = blind_land_s(height, land_s)
                out.append(
                    Finding(
                        "pose_lost",
                        ERROR,
                        f"no valid pose for {age:.1f} s, {room:.2f} m of room to "
                        f"{what}: landing now (in {duration:.1f} s), before its estimate's drift could "
                        "take it there",
                        a.name,
                        "land",
                        duration,
                    )
                )
        return out

    def _blind_height(self, now_s: float, pose_z: float, age: float, state: DroneState | None) -> float:
        """How high a blind drone may be: its estimate's height (telemetry under `ESTIMATE_FRESH_S` old) plus its
        possible drift, at most its last pose's height; the last pose's height without a fresh estimate."""
        height = pose_z
        if (
            state is not None
            and state.position_m is not None
            and state.telemetry_stamp_s is not None
            and now_s - state.telemetry_stamp_s <= ESTIMATE_FRESH_S
        ):
            height = min(height, state.position_m[2] + blind_drift_m(age, self.safety.blind_drift_m_s2))
        return max(0.0, height)

    def _room(
        self,
        name: str,
        position: tuple[float, float, float],
        ages: dict[str, float],
        tracker: PoseTracker,
        airborne: list[DroneAgent],
        foreign: list[str],
    ) -> tuple[float, str]:
        """How far a blind drone at ``position`` may drift before it touches something, and what."""
        x, y = position[0], position[1]
        arena = self.mission.arena
        best = min(x - arena.x[0], arena.x[1] - x, y - arena.y[0], arena.y[1] - y) + self.r
        what = "the arena's edge"
        if not self.obstacles.is_empty:
            clearance = float(self.obstacles.signed_distance(complex(x, y))) - BODY_RADIUS_M
            if clearance < best:
                best, what = clearance, "an obstacle"
        blind = self.safety.pose_timeout_s
        for other in [o.name for o in airborne if o.name != name] + list(foreign):
            pose = tracker.get(other)
            if pose is None or pose.position[2] <= ON_FLOOR_Z_M:
                continue
            gap = math.dist(position, pose.position) - 2.0 * BODY_RADIUS_M
            if ages.get(other, 0.0) > blind:
                gap /= 2.0
            if gap < best:
                best, what = gap, other
        return best, what

    def _geofence(self, agents: list[DroneAgent], tracker: PoseTracker) -> list[Finding]:
        arena = self.mission.arena
        out = []
        for a in agents:
            pose = tracker.get(a.name)
            if pose is None or not pose.valid or a.phase == DronePhase.LANDING:
                continue
            x, y, z = pose.position
            outside = not (arena.x[0] <= x <= arena.x[1] and arena.y[0] <= y <= arena.y[1] and z <= arena.z[1])
            if outside:
                out.append(
                    Finding(
                        "geofence", ERROR, f"outside the arena at ({x:.2f}, {y:.2f}, {z:.2f}): landing", a.name, "land"
                    )
                )
        return out

    def _battery(self, agents: list[DroneAgent], states: dict[str, DroneState]) -> list[Finding]:
        """Land after ``LOW_BATTERY_SAMPLES`` consecutive new samples that are low (each sample counted once). A
        landing drone's low battery is said too, without a second landing (it would restart the one under way): the
        person at the bench should not fly that pack again (random fault campaign seed 19, run 10: a low battery during
        a planner fault's landing)."""
        out = []
        limit = self.mission.radio.min_battery_v - FLIGHT_SAG_V
        for a in agents:
            state = states.get(a.name)
            battery = state.battery if state else None
            if battery is None or state is None or state.telemetry_stamp_s is None:
                continue
            count, stamp = self._low_battery.get(a.name, (0, -1.0))
            if state.telemetry_stamp_s == stamp:
                continue
            low = battery.low or battery.voltage_v < limit
            count = count + 1 if low else 0
            self._low_battery[a.name] = (count, state.telemetry_stamp_s)
            if count == LOW_BATTERY_SAMPLES:
                landing = a.phase == DronePhase.LANDING
                message = (
                    f"battery low ({battery.voltage_v:.2f} V, {battery.pm_state.name.lower()}; "
                    f"{count} samples in a row): {'it is landing already' if landing else 'landing'}"
                )
                out.append(Finding("battery", WARNING, message, a.name, "warn" if landing else "land"))
        return out

    def _telemetry(self, now_s: float, agents: list[DroneAgent], states: dict[str, DroneState]) -> list[Finding]:
        """A linked drone whose status telemetry stopped: its battery and supervisor are no longer watched."""
        out = []
        for a in agents:
            state = states.get(a.name)
            if state is None or not state.link.up:
                continue
            stamp = state.telemetry_stamp_s
            age = float("inf") if stamp is None else now_s - stamp
            if age > TELEMETRY_STALE_S and a.name not in self._telemetry_stale:
                self._telemetry_stale.add(a.name)
                out.append(
                    Finding(
                        "telemetry",
                        WARNING,
                        f"no status telemetry for {age:.1f} s: battery and supervisor unwatched",
                        a.name,
                        "warn",
                    )
                )
            elif age <= TELEMETRY_STALE_S and a.name in self._telemetry_stale:
                self._telemetry_stale.discard(a.name)
                out.append(Finding("telemetry", INFO, "status telemetry is back", a.name, "warn"))
        return out

    def _glitches(self, agents: list[DroneAgent], tracker: PoseTracker) -> list[Finding]:
        """Poses the tracker refused as jumps (edge-triggered): hold until the track is back."""
        out = []
        for a in agents:
            glitching = a.name in tracker.glitching
            if glitching and a.name not in self._glitching:
                self._glitching.add(a.name)
                metres, seconds = tracker.last_jump.get(a.name, (math.nan, math.nan))
                if tracker.last_jump_from_estimate.get(a.name, False):
                    text = (
                        f"mocap pose back after {seconds * 1e3:.0f} ms unseen lies {metres:.2f} m from the drone's "
                        "own estimate (re-acquired on the wrong markers?): not followed, holding"
                    )
                else:
                    text = (
                        f"mocap pose jumped {metres:.2f} m in {seconds * 1e3:.0f} ms, further than a drone can fly "
                        "(marker swap?): not followed, holding"
                    )
                out.append(Finding("pose_glitch", WARNING, text, a.name, "hold"))
            elif not glitching and a.name in self._glitching:
                self._glitching.discard(a.name)
                out.append(Finding("pose_glitch", INFO, "mocap track consistent again: resuming", a.name, "resume"))
        return out

    def _orientations(self, agents: list[DroneAgent], tracker: PoseTracker) -> list[Finding]:
        """Orientations the tracker refused as jumps (edge-triggered): a warning; the drone flies on its position."""
        out = []
        extpose = self.mission.radio.extpos == "extpose"
        for a in agents:
            turned = a.name in tracker.orientation_glitching
            if turned and a.name not in self._turned:
                self._turned.add(a.name)
                degrees, seconds = tracker.last_turn.get(a.name, (math.nan, math.nan))
                use = (
                    "extpose sends its position only until it turns back"
                    if extpose
                    else "its orientation is not used in flight"
                )
                out.append(
                    Finding(
                        "orientation_glitch",
                        WARNING,
                        f"mocap orientation turned {degrees:.0f} deg in "
                        f"{seconds * 1e3:.0f} ms, faster than a drone turns (a wrong fit of its "
                        f"markers?): not followed; {use}",
                        a.name,
                        "warn",
                    )
                )
            elif not turned and a.name in self._turned:
                self._turned.discard(a.name)
                out.append(Finding("orientation_glitch", INFO, "mocap orientation consistent again", a.name, "warn"))
        return out

    def _crashes(self, agents: list[DroneAgent], states: dict[str, DroneState]) -> list[Finding]:
        """An airborne drone whose firmware reports a crash, a tumble or a lock: its motors are cut."""
        out = []
        for a in agents:
            sup = states[a.name].supervisor if a.name in states else None
            if sup is not None and (sup.crashed or sup.tumbled or sup.locked):
                what = "crashed" if sup.crashed else "tumbled" if sup.tumbled else "locked"
                out.append(
                    Finding("crashed", ERROR, f"its supervisor says {what}: motors cut, it falls", a.name, "crashed")
                )
        return out

    def _link_quality(self, agents: list[DroneAgent], states: dict[str, DroneState]) -> list[Finding]:
        out = []
        for a in agents:
            state = states.get(a.name)
            quality = state.link.quality_pct if state is not None and state.link.up else None
            if quality is None:
                continue
            if quality < LINK_QUALITY_WARN_PCT and a.name not in self._poor_link:
                self._poor_link.add(a.name)
                out.append(
                    Finding(
                        "radio",
                        WARNING,
                        f"radio link quality {quality:.0f} % (packets retried or "
                        "lost): its setpoints and extpos arrive late",
                        a.name,
                        "warn",
                    )
                )
            elif quality >= LINK_QUALITY_CLEAR_PCT and a.name in self._poor_link:
                self._poor_link.discard(a.name)
                out.append(Finding("radio", INFO, f"radio link quality back to {quality:.0f} %", a.name, "warn"))
        return out

    def _mocap_latency(self, tracker: PoseTracker) -> list[Finding]:
        latency = tracker.latency_s
        if latency is None:
            return []
        out: list[Finding] = []
        if latency > MOCAP_LATENCY_WARN_S and not self._late_mocap:
            self._late_mocap = True
            out.append(
                Finding(
                    "mocap_latency",
                    WARNING,
                    f"mocap latency {latency * 1e3:.0f} ms: estimators and planners act on an old picture",
                    None,
                    "warn",
                )
            )
        if latency > MOCAP_LATENCY_HOLD_S and not self._latency_hold:
            self._latency_hold = True
            out.append(
                Finding(
                    "mocap_latency",
                    ERROR,
                    f"mocap latency {latency * 1e3:.0f} ms, over {MOCAP_LATENCY_HOLD_S * 1e3:.0f} ms: every drone "
                    "holds (its estimator takes the late poses as current: a moving drone lurches after them) "
                    f"until it is back under {MOCAP_LATENCY_HOLD_S / 2 * 1e3:.0f} ms",
                    None,
                    "hold",
                )
            )
        if latency < MOCAP_LATENCY_HOLD_S / 2 and self._latency_hold:
            self._latency_hold = False
            out.append(
                Finding(
                    "mocap_latency", INFO, f"mocap latency back to {latency * 1e3:.0f} ms: resuming", None, "resume"
                )
            )
        if latency < MOCAP_LATENCY_WARN_S / 2 and self._late_mocap:
            self._late_mocap = False
            out.append(Finding("mocap_latency", INFO, f"mocap latency back to {latency * 1e3:.0f} ms", None, "warn"))
        return out
