"""The on-board estimate against mocap: a drone whose estimator no longer follows extpos would fly wherever its
estimate goes, a landing included, so the supervisor cuts its motors (docs/flight.md, "The supervisor")."""

from __future__ import annotations

import math
from collections import deque

from rpf_fly.flight.agent import DroneAgent
from rpf_fly.flight.commander import ON_FLOOR_Z_M
from rpf_fly.flight.events import ERROR, WARNING
from rpf_fly.flight.findings import Finding
from rpf_fly.flight.phases import DronePhase
from rpf_fly.flight.poses import PoseTracker, estimator_position
from rpf_fly.mission.model import SafetySettings
from rpf_fly.radio.backend import DroneState
from rpf_fly.radio.outbox import EXTPOS_MAX_WAIT_S

ESTIMATE_DIVERGENCE_M = 0.15
"""In flight, an on-board position estimate this far from a fresh mocap pose (in 2 status samples in a row) means
the estimator no longer takes extpos: the drone holds its ESTIMATE at the setpoint while its true position drifts.
With extpos streaming the two agree within a centimetre or two."""

ESTIMATE_WRONG_M = 0.10
"""In flight, an on-board estimate this far from the mocap poses OF ITS OWN TIME (the telemetry's firmware
timestamp, `DroneState.estimate_stamp_s`, and the `extpos_late_s` before it that an extpos may take to reach the
drone; in 2 status samples in a row) is wrong, not late: motors off. With extpos streaming the estimate lies on that
stretch of the fed path within 1-3 cm (the mocap's own lag and the stamp's few milliseconds at flight speed), so
10 cm is a diverged estimator 0.2 s after it diverged at 0.5 m/s (plus the stretch's length on a slow link).
Without the stamp the check must find the estimate far from EVERY pose of the last `ESTIMATE_HISTORY_S` to tell
wrong from late: a drone whose estimator runs away at 0.57 m/s is then stopped 0.75 s after, 0.6 m off its track
(into a wall, in random fault campaign seed 9)."""

ESTIMATE_HISTORY_S = 0.5
"""How far back an on-board estimate may be matched against mocap: telemetry queued behind a full radio arrives
hundreds of milliseconds late, and a late estimate of a drone at 0.5 m/s is decimetres behind the newest pose."""

FEED_GAP_S = 0.25
"""A drone whose poses stopped reaching this check (and with them its extpos, forwarded in the same loop) for longer
than this flew on its IMU alone: a loop stall, a blackout, an occlusion. The firmware's estimator drifts meanwhile,
about 0.5 x 0.3 m/s^2 x gap^2 plus its noise (1 cm over this gap; 4.7-17.5 cm over 1 s, `fake_vehicle`), and the
controller holds that drifted estimate on its setpoint: off the mocap poses of its own time because it went unfed, not
because it stopped following extpos."""

FEED_SETTLE_S = 0.5
"""... so an estimate made within this long after the poses came back is not judged wrong: the first extpos since
must reach the firmware (behind a full radio, hundreds of milliseconds: `ESTIMATE_HISTORY_S`) before the estimate
snaps back to it. Judged, two such estimates 0.1 m off cut the motors of a drone the watchdog was landing after a 1 s
loop stall on lab-3.

The same holds when the poses kept coming but the radio did not carry them (`DroneState.extpos_sent_s`: no extpos
handed to its link, or no packed broadcast with it out, for over `FEED_GAP_S`): a radio too full for its traffic
drops the positions that waited too long (`outbox.EXTPOS_MAX_WAIT_S`), and eight drones on one emulated Crazyradio PA
that carried half their transactions drifted 6-16 cm unfed; two of them, landing, had their motors cut 0.9 m up. A
drone left unfed is the radio's failing, which the radio lag and link checks land; its estimator is judged again once
it has been fed for `FEED_SETTLE_S`."""


UNFED_LAND_S = 1.0
"""A drone in the air that mocap sees but whose radio has carried none of its extpos this long
(`DroneState.extpos_sent_s`; its setpoints may still get through: extpos go last in each turn of its link) lands: its
estimate drifts on its IMU (5-18 cm over 1 s in the emulator, `fake_vehicle`), the controller flies that drift, and
the estimate check cannot judge an estimator nothing feeds. A drone mocap lost is the mocap rules' (hold, then land
by its blind drift)."""


def _pose_at(
    history: deque[tuple[float, tuple[float, float, float]]], stamp_s: float | None
) -> tuple[float, float, float] | None:
    """The mocap position at ``stamp_s`` (linear between the two poses around it); None without a stamp or when
    the history does not reach back that far (or forward: a stamp ahead of the newest pose by over 20 ms)."""
    if stamp_s is None or not history or stamp_s < history[0][0] or stamp_s > history[-1][0] + 0.02:
        return None
    before = history[0]
    for after in history:
        if after[0] >= stamp_s:
            span = after[0] - before[0]
            if span <= 0.0:
                return after[1]
            w = (stamp_s - before[0]) / span
            (bx, by, bz), (cx, cy, cz) = before[1], after[1]
            return bx + w * (cx - bx), by + w * (cy - by), bz + w * (cz - bz)
        before = after
    return history[-1][1]


def extpos_late_s(state: DroneState) -> float:
    """How long after its pose was received an extpos may reach the drone's estimator: its wait in the ground station
    (at most `EXTPOS_MAX_WAIT_S`: older ones are dropped) plus the link's echo round trip (cflib's 95th percentile,
    through the same queue and radio turns as the extpos: a bound of the one-way trip), at most
    `ESTIMATE_HISTORY_S`. Through a shared dongle on a busy radio the round trip is 0.1-0.3 s, and an estimate that
    follows its extpos that late is decimetres behind the pose received at its own time: late, not wrong."""
    return min(ESTIMATE_HISTORY_S, EXTPOS_MAX_WAIT_S + state.link.round_trip_s)


def _distance_to_fed(
    history: deque[tuple[float, tuple[float, float, float]]],
    position: tuple[float, float, float],
    from_s: float,
    to_s: float,
) -> float:
    """The distance from ``position`` to the path of the fed positions from ``from_s`` to ``to_s`` (linear between
    the poses, clipped to the history's start); ``to_s`` lies within the history (`_pose_at` is not None)."""
    start = _pose_at(history, max(from_s, history[0][0]))
    end = _pose_at(history, to_s)
    path = [q for q in (start, *(p for t, p in history if from_s < t < to_s), end) if q is not None]
    best = math.inf
    for a, b in zip(path, path[1:] or path):
        ab = (b[0] - a[0], b[1] - a[1], b[2] - a[2])
        span = ab[0] ** 2 + ab[1] ** 2 + ab[2] ** 2
        along = sum((position[j] - a[j]) * ab[j] for j in range(3)) / span if span > 0.0 else 0.0
        w = min(1.0, max(0.0, along))
        best = min(best, math.dist(position, (a[0] + w * ab[0], a[1] + w * ab[1], a[2] + w * ab[2])))
    return best


UNFED_LANDS = frozenset({DronePhase.PLANNING, DronePhase.HOLDING, DronePhase.ARRIVED, DronePhase.TAKEOFF})
"""The phases in which a drone left unfed (`UNFED_LAND_S`) is landed (a landing one is landing already)."""


class EstimateCheck:
    """The estimate check with the mocap history and the episodes it needs (the supervisor runs it)."""

    def __init__(self, safety: SafetySettings) -> None:
        self.safety = safety
        self._diverging: dict[str, tuple[int, int, float]] = {}
        self._estimate_stopped: set[str] = set()
        self._history: dict[str, deque[tuple[float, tuple[float, float, float]]]] = {}
        self._taken_stamp: dict[str, float] = {}
        """Each drone's newest pose taken into its history (its mocap stamp)."""
        self._fed_at: dict[str, float] = {}
        """Each drone's last check that took a new pose (when its extpos went too)."""
        self._fed_again: dict[str, float] = {}
        """When each drone's poses came back after a gap over `FEED_GAP_S` (its first ones: fed before the flight
        began: the preflight waits for every estimate to agree with mocap before take-off)."""
        self._radio_unfed: set[str] = set()
        """Drones whose radio has handed no extpos to their link for over `FEED_GAP_S` (`DroneState.extpos_sent_s`)."""
        self._unfed_landed: set[str] = set()

    def check(
        self, now_s: float, agents: list[DroneAgent], tracker: PoseTracker, states: dict[str, DroneState]
    ) -> list[Finding]:
        """The on-board estimate against mocap (``ESTIMATE_DIVERGENCE_M``), in two steps. Off the newest pose in 2
        samples: a warning (also what late telemetry on a full radio looks like at flight speed). Off EVERY pose of
        the last ``ESTIMATE_HISTORY_S`` in 2 samples: the estimate is not just late, it is wrong; motors off.
        Take-off and landing are watched as the planning is (a landing flies the estimate's way: unwatched, a drone
        whose estimator diverged mid-landing slides 0.16 m sideways in its last half second without a word); a
        taking-off or landing drone whose mocap height is within ``ON_FLOOR_Z_M`` of the floor gets
        a warning instead (a cut there buys nothing, and a landed drone's outcome stays landed)."""
        out = []
        for a in agents:
            state, pose = states.get(a.name), tracker.get(a.name)
            history = self._history.setdefault(a.name, deque())
            # the pose as its estimator is fed it: a picture later than the hold bound carried ahead by its latency
            # (estimator_position; the estimate follows that, not the late pose)
            fed = estimator_position(pose, tracker.latency_s) if pose is not None else None
            new = pose is not None and pose.stamp_s > self._taken_stamp.get(a.name, -math.inf)
            if pose is not None and fed is not None and pose.valid and new:  # (not the last one again, once the
                self._taken_stamp[a.name] = pose.stamp_s  # history dropped it: that would be fed, mid-gap)
                history.append((pose.stamp_s, fed))
                if now_s - self._fed_at.get(a.name, now_s) > FEED_GAP_S:
                    self._fed_again[a.name] = now_s
                self._fed_at[a.name] = now_s
            while history and history[0][0] < now_s - ESTIMATE_HISTORY_S:
                history.popleft()
            radio_fed = state is None or state.extpos_sent_s is None or now_s - state.extpos_sent_s <= FEED_GAP_S
            if not radio_fed:
                self._radio_unfed.add(a.name)
            elif a.name in self._radio_unfed:  # its radio carries its extpos again: fed again from now
                self._radio_unfed.discard(a.name)
                self._fed_again[a.name] = now_s
            unfed_s = 0.0  # since its last extpos went, or its poses came back from a gap (then its extpos go too)
            if state is not None and state.extpos_sent_s is not None:
                unfed_s = now_s - max(state.extpos_sent_s, self._fed_again.get(a.name, -math.inf))
            seen = pose is not None and pose.valid and now_s - pose.stamp_s <= self.safety.pose_timeout_s
            if unfed_s >= UNFED_LAND_S and seen and a.phase in UNFED_LANDS and a.name not in self._unfed_landed:
                self._unfed_landed.add(a.name)
                out.append(
                    Finding(
                        "estimator",
                        ERROR,
                        f"its radio carried none of its mocap positions for {unfed_s:.1f} s: its estimate drifts on "
                        "its IMU alone: landing",
                        a.name,
                        "land",
                    )
                )
            if (
                state is None
                or state.position_m is None
                or state.telemetry_stamp_s is None
                or pose is None
                or fed is None
                or not pose.valid
                or now_s - pose.stamp_s > self.safety.pose_timeout_s
            ):
                continue
            grounded = a.phase in (DronePhase.LANDING, DronePhase.TAKEOFF) and pose.position[2] <= ON_FLOOR_Z_M
            late, wrong, stamp = self._diverging.get(a.name, (0, 0, -1.0))
            if state.telemetry_stamp_s == stamp:
                continue
            off = math.dist(state.position_m, fed)
            then = _pose_at(history, state.estimate_stamp_s)
            made_s = now_s if state.estimate_stamp_s is None else state.estimate_stamp_s
            nearest: float | None
            if (
                a.name in self._radio_unfed or made_s < self._fed_again.get(a.name, -math.inf) + FEED_SETTLE_S
            ):  # made unfed, or before it was fed again
                nearest = None
            elif then is not None and state.estimate_stamp_s is not None:  # against what mocap had fed it by then
                late_s = extpos_late_s(state)
                nearest = _distance_to_fed(history, state.position_m, made_s - late_s, made_s)
                wrong_m = ESTIMATE_WRONG_M
                what = f"the mocap poses of its own time (and the {late_s:.2f} s its extpos may take to reach it)"
            elif (
                state.estimate_stamp_s is not None and history and state.estimate_stamp_s < history[0][0]
            ):  # made before the poses kept (the loop stalled)
                nearest = None
            else:  # no stamp: only far from every recent pose is surely wrong, not late
                nearest = min((math.dist(state.position_m, p) for _, p in history), default=off)
                wrong_m, what = ESTIMATE_DIVERGENCE_M, f"every mocap pose of the last {ESTIMATE_HISTORY_S:g} s"
            late = late + 1 if off > ESTIMATE_DIVERGENCE_M else 0
            if nearest is not None:  # an estimate nothing can date against the poses neither clears nor counts
                wrong = wrong + 1 if nearest > wrong_m else 0
            self._diverging[a.name] = (late, wrong, state.telemetry_stamp_s)
            if late == 2 and wrong < 2:
                out.append(
                    Finding(
                        "estimator",
                        WARNING,
                        f"on-board estimate {off:.2f} m from mocap (late telemetry "
                        "on a full radio, or an estimator that stopped taking extpos)",
                        a.name,
                        "warn",
                    )
                )
            if nearest is None:
                continue
            if wrong == 2 and grounded:
                out.append(
                    Finding(
                        "estimator",
                        WARNING,
                        f"on-board estimate {nearest:.2f} m from {what}: the "
                        "estimator no longer follows extpos; on the floor, its landing's end is left to "
                        "it",
                        a.name,
                        "warn",
                    )
                )
            if wrong >= 2 and not grounded and a.name not in self._estimate_stopped:
                self._estimate_stopped.add(a.name)
                out.append(
                    Finding(
                        "estimator",
                        ERROR,
                        f"on-board estimate {nearest:.2f} m from {what}: the "
                        "estimator no longer follows extpos, and a landing would fly wherever the "
                        "estimate goes: motors off",
                        a.name,
                        "stop",
                    )
                )
        return out
