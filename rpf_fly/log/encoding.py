"""The log's messages as bytes: compact JSON with orjson, and fast encoders for the high-rate topics.

The writer thread encodes ~3000 messages a second in a 10-drone flight (docs/log-format.md, "Cost"): the fast
encoders give the same bytes as ``encode(builder(...))`` (rpf_fly/log/messages.py; tests pin it) for about half the
cost, and fall back to the builder for anything unusual.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import orjson

from rpf_fly.log.messages import (
    IDENTITY,
    PLANNER_FIELDS,
    WORLD_FRAME,
    frame_transforms,
    planner_step,
    pose_in_frame,
    truth_state,
)
from rpf_fly.log.rpf_schemas import PLANNER_MODES

_dumps = orjson.dumps


def encode(message: Mapping[str, Any]) -> bytes:
    """Compact JSON (UTF-8) of a message; non-finite floats become null.

    orjson, not ``json.dumps``: the same JSON values (floats written as the shortest text that reads back to the same
    double), about 3x cheaper, and it writes NaN and infinities as ``null`` by itself. The log's writer thread
    encodes ~3000 messages a second in a 10-drone flight (docs/log-format.md, "Cost")."""
    return orjson.dumps(message, option=orjson.OPT_SERIALIZE_NUMPY)


# Fast encoders for the high-rate topics: the same bytes as ``encode(builder(...))`` (tests pin it), with the
# dict built inline from plain floats instead of through the per-field helpers (about 2x cheaper). Anything
# unusual (complex or 2D positions, unknown fields, bad values) takes the builder path, which also raises what
# the builder raises.


def pose_json(t_ns: int, position: Any, quaternion: Sequence[float] | None = None) -> bytes:
    """``encode(pose_in_frame(t_ns, position, quaternion))`` (frame ``world``), fast."""
    try:
        x, y, z = position
        qx, qy, qz, qw = IDENTITY if quaternion is None else quaternion
        sec, nsec = divmod(int(t_ns), 1_000_000_000)
        return _dumps(
            {
                "timestamp": {"sec": sec, "nsec": nsec},
                "frame_id": WORLD_FRAME,
                "pose": {
                    "position": {"x": float(x), "y": float(y), "z": float(z)},
                    "orientation": {"x": float(qx), "y": float(qy), "z": float(qz), "w": float(qw)},
                },
            }
        )
    except (TypeError, ValueError):
        return encode(pose_in_frame(t_ns, position, quaternion))


def tf_json(t_ns: int, poses: Mapping[str, tuple[Any, Sequence[float] | None]]) -> bytes:
    """``encode(frame_transforms(t_ns, poses))``, fast."""
    try:
        sec, nsec = divmod(int(t_ns), 1_000_000_000)
        transforms = []
        for name, (p, q) in poses.items():
            x, y, z = p
            qx, qy, qz, qw = IDENTITY if q is None else q
            transforms.append(
                {
                    "timestamp": {"sec": sec, "nsec": nsec},
                    "parent_frame_id": WORLD_FRAME,
                    "child_frame_id": str(name),
                    "translation": {"x": float(x), "y": float(y), "z": float(z)},
                    "rotation": {"x": float(qx), "y": float(qy), "z": float(qz), "w": float(qw)},
                }
            )
        return _dumps({"transforms": transforms})
    except (TypeError, ValueError):
        return encode(frame_transforms(t_ns, poses))


def truth_json(t_ns: int, position: Any, yaw: float, motors: bool, crashed: bool, estimate: Any) -> bytes:
    """``encode(truth_state(t_ns, position, yaw, motors, crashed, estimate))``, fast."""
    try:
        x, y, z = position
        ex, ey, ez = estimate
        sec, nsec = divmod(int(t_ns), 1_000_000_000)
        return _dumps(
            {
                "timestamp": {"sec": sec, "nsec": nsec},
                "position": {"x": float(x), "y": float(y), "z": float(z)},
                "yaw": float(yaw),
                "motors": bool(motors),
                "crashed": bool(crashed),
                "estimate": {"x": float(ex), "y": float(ey), "z": float(ez)},
            }
        )
    except (TypeError, ValueError):
        return encode(truth_state(t_ns, position, yaw, motors, crashed, estimate))


_PLANNER_KEYS = frozenset(PLANNER_FIELDS) | {"lam"}
_MODE_SET = frozenset(PLANNER_MODES)


def _opt_float(value: Any) -> float | None:
    return None if value is None else float(value)


def _xy_dict(value: Any) -> dict[str, float]:
    if type(value) is complex:
        return {"x": value.real, "y": value.imag}
    x, y = value
    return {"x": float(x), "y": float(y)}


def planner_json(t_ns: int, fields: Mapping[str, Any]) -> bytes:
    """``encode(planner_step(t_ns, **fields))``, fast."""
    f = fields
    try:
        if not _PLANNER_KEYS.issuperset(f) or ("lam" in f and "lambda" in f):
            raise TypeError
        mode = f["mode"]
        if type(mode) is not str or mode not in _MODE_SET:
            raise ValueError
        x, y, z = f["position"]
        x, y, z = float(x), float(y), float(z)
        goal = _xy_dict(f["goal"])
        gd = f.get("goal_distance")
        gd = math.hypot(goal["x"] - x, goal["y"] - y) if gd is None else float(gd)
        sec, nsec = divmod(int(t_ns), 1_000_000_000)
        message = {
            "timestamp": {"sec": sec, "nsec": nsec},
            "tick": int(f["tick"]),
            "position": {"x": x, "y": y, "z": z},
            "goal": goal,
            "eta": _opt_float(f.get("eta")),
            "lambda": _opt_float(f["lambda"] if "lambda" in f else f.get("lam")),
            "f_a": _xy_dict(f.get("f_a", 0j)),
            "f_r": _xy_dict(f.get("f_r", 0j)),
            "f_in": _xy_dict(f.get("f_in", 0j)),
            "direction": _xy_dict(f.get("direction", 0j)),
            "mode": mode,
            "heading": float(f.get("heading", 0.0)),
            "neighbours": int(f.get("neighbours", 0)),
            "obstacle_distance": _opt_float(f.get("obstacle_distance")),
            "goal_distance": gd,
        }
        reference = f.get("reference")
        if reference is not None:
            message["reference"] = _xy_dict(reference)
        return _dumps(message)
    except (TypeError, ValueError, KeyError, IndexError):
        return encode(planner_step(t_ns, **fields))
