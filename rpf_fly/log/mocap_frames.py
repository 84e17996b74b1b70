"""The mocap frames of a flight log, as the flight loop received them: ``/mocap/<drone>`` regrouped by frame.

The loop logs one frame's fresh, valid poses as one batch stamped with that frame's receive time (the tracker's
time, docs/log-format.md), so the poses of one frame share a publish time and a drone missing from a frame was
not tracked in it (or its sample was refused as a jump). :func:`mocap_frames` undoes the split into topics; the
replay (:mod:`rpf_fly.flight.replay`) feeds the frames to a pose tracker and ``rpf-fly mocap emulate --replay``
serves them over NatNet at their logged times.

A frame in which no drone was tracked leaves nothing in the log (there was no pose to write): a replay cannot
tell it from a moment without frames.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

from rpf_fly.log.reader import LogData

Position = tuple[float, float, float]
Quaternion = tuple[float, float, float, float]


@dataclass
class LoggedFrame:
    """One mocap frame as logged: its publish time (ns since the Unix epoch), the latest log time of its poses,
    and the tracked drones' poses (Z-up world frame, metres; quaternion ``(qx, qy, qz, qw)``)."""

    t_ns: int
    log_time_ns: int
    poses: dict[str, tuple[Position, Quaternion]] = field(default_factory=dict)


def mocap_drones(data: LogData) -> list[str]:
    """The drones with a ``/mocap/<drone>`` topic, in the scenario's order (then by name)."""
    names = [t.removeprefix("/mocap/") for t in data.topics if t.startswith("/mocap/")]
    order: list[str] = []
    try:
        import json

        order = list(json.loads(data.metadata["scenario"]["json"]).get("names", []))
    except (KeyError, ValueError, TypeError, AttributeError):
        pass
    known = [n for n in order if n in names]
    return known + sorted(n for n in names if n not in known)


def _pose(message: dict) -> tuple[Position, Quaternion] | None:
    try:
        p = message["pose"]["position"]
        q = message["pose"]["orientation"]
        position = (float(p["x"]), float(p["y"]), float(p["z"]))
        quaternion = (float(q["x"]), float(q["y"]), float(q["z"]), float(q["w"]))
    except (KeyError, TypeError, ValueError):
        return None  # a null (NaN) coordinate or a malformed message: not a pose anyone flew on
    return position, quaternion


def mocap_frames(data: LogData, drones: Iterable[str] | None = None) -> list[LoggedFrame]:
    """Every logged frame of ``drones`` (default: every ``/mocap`` topic), in publish-time order; poses with a
    null coordinate are left out (the drone counts as untracked in that frame)."""
    names = list(drones) if drones is not None else mocap_drones(data)
    frames: dict[int, LoggedFrame] = {}
    for name in names:
        for message in data.topics.get(f"/mocap/{name}", ()):
            pose = _pose(message.data) if isinstance(message.data, dict) else None
            if pose is None:
                continue
            frame = frames.get(message.publish_time)
            if frame is None:
                frame = frames[message.publish_time] = LoggedFrame(message.publish_time, message.log_time)
            frame.log_time_ns = max(frame.log_time_ns, message.log_time)
            frame.poses[name] = pose
    return [frames[t] for t in sorted(frames)]
