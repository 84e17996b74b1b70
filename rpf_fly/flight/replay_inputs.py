"""The flight log read as the replay needs it (rpf_fly/flight/replay.py): the logged planner rows grouped into
ticks, each drone's phase at a tick from its logged mode, the loop's monotonic clock back from the log's times, and
what the flight's log says happened between frames (a batching switch, a pose glitch's end, dropped messages).
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass
from typing import Any

from rpf_fly.flight.phases import DronePhase
from rpf_fly.flight.poses import stamp_from_us
from rpf_fly.log.mocap_frames import LoggedFrame
from rpf_fly.log.reader import LogData
from rpf_fly.mocap.frame import MocapFrame, RigidBodyPose

PLANNING_MODES = frozenset({"apf", "wall", "soft"})
"""Logged modes of a tick on which the drone planned (the others are what it did instead)."""

FRAME_SLACK_NS = 1000
"""A frame counts as received before a tick when its time is at most this much after the tick's: the tracker
rounds receive times to the microsecond, which may put a frame's stamp up to 0.5 us after the loop's clock reading
that fired the tick on it; the next frame is read only after the tick's planning (hundreds of microseconds)."""


class ReplayError(ValueError):
    """The log cannot be replayed; ``str()`` is one line naming the file and what is missing."""


@dataclass(frozen=True)
class LoggedRow:
    """One ``/<drone>/planner`` message, as the replay needs it."""

    tick: int
    t_ns: int
    log_time_ns: int
    mode: str
    direction: complex
    position: tuple[float, float, float]
    reference: complex | None


def logged_row(message: Any) -> LoggedRow | None:
    d = message.data
    try:
        direction = complex(float(d["direction"]["x"]), float(d["direction"]["y"]))
        p = d["position"]
        position = (float(p["x"]), float(p["y"]), float(p["z"]))
        ref = d.get("reference")
        reference = complex(float(ref["x"]), float(ref["y"])) if ref is not None else None
        return LoggedRow(
            int(d["tick"]), message.publish_time, message.log_time, str(d["mode"]), direction, position, reference
        )
    except (KeyError, TypeError, ValueError):
        return None


def phase_of_mode(mode: str) -> DronePhase:
    """The phase a drone was in at a tick, from its logged mode (as far as :func:`in_the_way` can tell them
    apart): a planning mode is planning, ``arrived`` arrived, ``hold`` holding, a phase name that phase."""
    if mode in PLANNING_MODES:
        return DronePhase.PLANNING
    if mode == "arrived":
        return DronePhase.ARRIVED
    try:
        return DronePhase(mode)
    except ValueError:
        return DronePhase.HOLDING  # hold, stalled: airborne, in the others' way


def batching_switched_off_ns(data: LogData) -> int | None:
    """When the flight switched batching off for good (event ``planner_batch``: a batched call over budget)."""
    for message in data.topics.get("/events", ()):
        d = message.data
        if isinstance(d, dict) and d.get("file") == "planner_batch" and "from now on" in str(d.get("message", "")):
            return message.publish_time
    return None


def reacquisitions(data: LogData, frames: list[LoggedFrame]) -> dict[int, set[str]]:
    """Frame index -> drones whose sample in that frame ended a pose glitch. The flight's tracker refused the
    jumped samples (they are not in the log) and gave the sample that ended the glitch no velocity; the
    supervisor's ``pose_glitch`` event "consistent again" comes in the same loop iteration, right after that
    frame, so the sample is the drone's last logged one up to the event."""
    out: dict[int, set[str]] = {}
    times = [f.t_ns for f in frames]
    for message in data.topics.get("/events", ()):
        d = message.data
        if not (
            isinstance(d, dict)
            and d.get("file") == "pose_glitch"
            and str(d.get("message", "")).startswith("mocap track consistent again")
        ):
            continue
        name = str(d.get("name", ""))
        i = bisect.bisect_right(times, message.publish_time + FRAME_SLACK_NS) - 1
        while i >= 0 and name not in frames[i].poses:
            i -= 1
        if i >= 0:
            out.setdefault(i, set()).add(name)
    return out


def missing_sequences(data: LogData, topic: str) -> int:
    seqs = {m.sequence for m in data.topics.get(topic, ())}
    return max(seqs) + 1 - len(seqs) if seqs else 0


@dataclass
class LoggedTick:
    tick: int
    t_ns: int
    rows: dict[str, LoggedRow]


def logged_ticks(data: LogData, names: list[str], last_pose_log_ns: int) -> tuple[list[LoggedTick], int]:
    """The logged ticks in order, and how many were left out at a torn end: a tick is kept only when a mocap
    message was logged after its rows (so the frame that fired it, logged right after them, is in the log)."""
    ticks: dict[int, LoggedTick] = {}
    for name in names:
        for message in data.topics.get(f"/{name}/planner", ()):
            row = logged_row(message)
            if row is None:
                continue
            tick = ticks.setdefault(row.tick, LoggedTick(row.tick, row.t_ns, {}))
            tick.rows[name] = row
    ordered = sorted(ticks.values(), key=lambda t: (t.t_ns, t.tick))
    kept = [t for t in ordered if max(r.log_time_ns for r in t.rows.values()) <= last_pose_log_ns]
    return kept, len(ordered) - len(kept)


class TrackerClock:
    """Log nanoseconds back to the loop's monotonic seconds as the flight's tracker held them."""

    def __init__(self, offset_ns: int | None, first_ns: int):
        self.exact = offset_ns is not None
        self.offset_ns = offset_ns if offset_ns is not None else first_ns

    def seconds(self, t_ns: int) -> float:
        delta = t_ns - self.offset_ns
        if self.exact and delta % 1000 == 0:
            return stamp_from_us(delta // 1000)
        return delta / 1e9


def mocap_frame(number: int, frame: LoggedFrame, clock: TrackerClock) -> MocapFrame:
    t = clock.seconds(frame.t_ns)
    bodies = {
        name: RigidBodyPose(name, i + 1, position, quaternion, True)
        for i, (name, (position, quaternion)) in enumerate(frame.poses.items())
    }
    return MocapFrame(number, t, t, None, bodies)
