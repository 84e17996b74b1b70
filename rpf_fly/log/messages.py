"""The builders that turn Python values into the log's messages: poses, transforms, events, planner steps, drone
statuses, true states, radio loads and the static scene.

They return plain dicts ready for :func:`rpf_fly.log.encoding.encode` (floats are Python floats, NaN becomes ``null``
where the schema allows it). Planar vectors may be given as complex numbers ``x + iy`` (rpf_fly's convention) or as
``(x, y)``; 3D positions as ``(x, y, z)`` (a complex or a pair gets ``z = 0``). The schemas they follow are in
rpf_fly/log/foxglove_schemas.py and rpf_fly/log/rpf_schemas.py; docs/log-format.md says what each field means.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

from rpf_fly.log.foxglove_schemas import LOG_LEVELS
from rpf_fly.log.rpf_schemas import MODE_NAMES, PLANNER_MODES

WORLD_FRAME = "world"

IDENTITY = (0.0, 0.0, 0.0, 1.0)


def stamp(t_ns: int) -> dict[str, int]:
    """Foxglove time ``{"sec", "nsec"}`` of nanoseconds since the Unix epoch."""
    sec, nsec = divmod(int(t_ns), 1_000_000_000)
    return {"sec": sec, "nsec": nsec}


def _opt(value: Any) -> float | None:
    """A float, or None for None and NaN."""
    if value is None:
        return None
    value = float(value)
    return None if math.isnan(value) else value


def xyz(value: Any) -> dict[str, float]:
    """``{"x", "y", "z"}`` of ``(x, y, z)``, ``(x, y)`` or a complex (``z = 0``)."""
    if isinstance(value, complex):
        return {"x": value.real, "y": value.imag, "z": 0.0}
    if hasattr(value, "dtype") and getattr(value, "ndim", 1) == 0:  # numpy scalar
        return xyz(complex(value))
    if len(value) == 2:
        return {"x": float(value[0]), "y": float(value[1]), "z": 0.0}
    return {"x": float(value[0]), "y": float(value[1]), "z": float(value[2])}


def xy(value: Any) -> dict[str, float]:
    """``{"x", "y"}`` of a complex ``x + iy`` or ``(x, y)``."""
    if isinstance(value, (complex, float, int)) or (hasattr(value, "dtype") and getattr(value, "ndim", 1) == 0):
        c = complex(value)
        return {"x": c.real, "y": c.imag}
    return {"x": float(value[0]), "y": float(value[1])}


def quat(value: Sequence[float] | None) -> dict[str, float]:
    """``{"x", "y", "z", "w"}`` of ``(qx, qy, qz, qw)`` (None: identity)."""
    q = IDENTITY if value is None else value
    return {"x": float(q[0]), "y": float(q[1]), "z": float(q[2]), "w": float(q[3])}


def yaw_quaternion(yaw_rad: float) -> tuple[float, float, float, float]:
    """``(qx, qy, qz, qw)`` of a rotation by ``yaw_rad`` about +z."""
    half = 0.5 * float(yaw_rad)
    return (0.0, 0.0, math.sin(half), math.cos(half))


def pose_in_frame(
    t_ns: int, position: Any, quaternion: Sequence[float] | None = None, frame_id: str = WORLD_FRAME
) -> dict[str, Any]:
    """A ``foxglove.PoseInFrame``."""
    return {
        "timestamp": stamp(t_ns),
        "frame_id": frame_id,
        "pose": {"position": xyz(position), "orientation": quat(quaternion)},
    }


def frame_transforms(
    t_ns: int, poses: Mapping[str, tuple[Any, Sequence[float] | None]], parent: str = WORLD_FRAME
) -> dict[str, Any]:
    """A ``foxglove.FrameTransforms`` from ``parent`` to each named child: ``{name: (position, quaternion)}``."""
    ts = stamp(t_ns)
    return {
        "transforms": [
            {
                "timestamp": ts,
                "parent_frame_id": parent,
                "child_frame_id": str(name),
                "translation": xyz(p),
                "rotation": quat(q),
            }
            for name, (p, q) in poses.items()
        ]
    }


def log_message(
    t_ns: int, level: int, message: str, name: str = "rpf_fly", file: str = "", line: int = 0
) -> dict[str, Any]:
    """A ``foxglove.Log`` (level 1 debug, 2 info, 3 warning, 4 error, 5 fatal)."""
    level = int(level)
    if level not in LOG_LEVELS:
        raise ValueError(f"log level {level} is not one of 1..5")
    return {
        "timestamp": stamp(t_ns),
        "level": level,
        "message": str(message),
        "name": str(name),
        "file": str(file),
        "line": max(int(line), 0),
    }


PLANNER_FIELDS = (
    "tick",
    "position",
    "goal",
    "eta",
    "lambda",
    "f_a",
    "f_r",
    "f_in",
    "direction",
    "mode",
    "heading",
    "neighbours",
    "obstacle_distance",
    "goal_distance",
    "reference",
)


def planner_step(
    t_ns: int,
    tick: int,
    position: Any,
    goal: Any,
    mode: Any,
    eta: Any = None,
    lam: Any = None,
    f_a: Any = 0j,
    f_r: Any = 0j,
    f_in: Any = 0j,
    direction: Any = 0j,
    heading: float = 0.0,
    neighbours: int = 0,
    obstacle_distance: Any = None,
    goal_distance: Any = None,
    reference: Any = None,
    **extra: Any,
) -> dict[str, Any]:
    """A ``rpf_fly.PlannerStep``. ``mode`` is a name or a mode code (0 apf, 1 wall, 2 soft, -1 arrived); ``lam``
    (or ``lambda`` through ``**extra``) and ``eta`` may be NaN or None (no gains); ``goal_distance`` defaults to the
    distance from ``position`` to ``goal``; ``reference`` (where the drone planned from) is written only when
    given."""
    if "lambda" in extra:
        lam = extra.pop("lambda")
    if extra:
        raise TypeError(f"unknown PlannerStep fields: {', '.join(sorted(extra))}")
    if not isinstance(mode, str):
        mode = MODE_NAMES[int(mode)]
    if mode not in PLANNER_MODES:
        raise ValueError(f"planner mode {mode!r} is not one of {', '.join(PLANNER_MODES)}")
    p = xyz(position)
    g = xy(goal)
    if goal_distance is None:
        goal_distance = math.hypot(g["x"] - p["x"], g["y"] - p["y"])
    out = {
        "timestamp": stamp(t_ns),
        "tick": int(tick),
        "position": p,
        "goal": g,
        "eta": _opt(eta),
        "lambda": _opt(lam),
        "f_a": xy(f_a),
        "f_r": xy(f_r),
        "f_in": xy(f_in),
        "direction": xy(direction),
        "mode": mode,
        "heading": float(heading),
        "neighbours": int(neighbours),
        "obstacle_distance": _opt(obstacle_distance),
        "goal_distance": float(goal_distance),
    }
    if reference is not None:
        out["reference"] = xy(reference)
    return out


def drone_status(
    t_ns: int,
    state: str,
    battery_v: Any = None,
    link_quality: Any = None,
    latency_ms: Any = None,
    outcome: str | None = None,
    estimate: Any = None,
    target: Any = None,
) -> dict[str, Any]:
    """A ``rpf_fly.DroneStatus`` (unknown values None; ``estimate`` and ``target`` as ``(x, y, z)``)."""
    return {
        "timestamp": stamp(t_ns),
        "state": str(state),
        "battery_v": _opt(battery_v),
        "link_quality": _opt(link_quality),
        "latency_ms": _opt(latency_ms),
        "outcome": None if outcome is None else str(getattr(outcome, "value", outcome)),
        "estimate": None if estimate is None else xyz(estimate),
        "target": None if target is None else xyz(target),
    }


def truth_state(t_ns: int, position: Any, yaw: float, motors: bool, crashed: bool, estimate: Any) -> dict[str, Any]:
    """A ``rpf_fly.TruthState``: positions ``(x, y, z)`` in metres, yaw in radians."""
    return {
        "timestamp": stamp(t_ns),
        "position": xyz(position),
        "yaw": float(yaw),
        "motors": bool(motors),
        "crashed": bool(crashed),
        "estimate": xyz(estimate),
    }


def radio_load(
    t_ns: int,
    dongle: int,
    drones: Sequence[str],
    window_s: float,
    packets: float,
    transactions: float,
    planned_per_s: float,
    budget_per_s: float,
    setpoints_superseded: float = 0.0,
) -> dict[str, Any]:
    """A ``rpf_fly.RadioLoad`` (counts over ``window_s`` seconds ending at ``t_ns``)."""
    window = float(window_s)
    return {
        "timestamp": stamp(t_ns),
        "dongle": int(dongle),
        "drones": [str(d) for d in drones],
        "window_s": window,
        "packets": float(packets),
        "transactions": float(transactions),
        "packets_per_s": float(packets) / window if window > 0 else 0.0,
        "transactions_per_s": float(transactions) / window if window > 0 else 0.0,
        "planned_per_s": float(planned_per_s),
        "budget_per_s": float(budget_per_s),
        "setpoints_superseded": float(setpoints_superseded),
    }


def _colour(r: float, g: float, b: float, a: float = 1.0) -> dict[str, float]:
    return {"r": r, "g": g, "b": b, "a": a}


def scene_entity(t_ns: int, entity_id: str, frame_id: str = WORLD_FRAME, **primitives: list) -> dict[str, Any]:
    """A ``foxglove.SceneEntity`` with every array present (empty unless given)."""
    entity: dict[str, Any] = {
        "timestamp": stamp(t_ns),
        "frame_id": frame_id,
        "id": entity_id,
        "lifetime": {"sec": 0, "nsec": 0},
        "frame_locked": False,
        "metadata": [],
    }
    for key in ("arrows", "cubes", "spheres", "cylinders", "lines", "triangles", "texts", "models"):
        entity[key] = list(primitives.pop(key, []))
    if primitives:
        raise TypeError(f"unknown SceneEntity primitives: {', '.join(primitives)}")
    return entity


def _flat_pose(x: float, y: float, z: float) -> dict[str, Any]:
    return {"position": {"x": float(x), "y": float(y), "z": float(z)}, "orientation": quat(None)}


def scene_update(
    t_ns: int,
    obstacles: Iterable[Mapping[str, Any]] = (),
    goals: Mapping[str, Any] | None = None,
    arena: Mapping[str, Sequence[float]] | None = None,
    height: float = 0.0,
) -> dict[str, Any]:
    """A ``foxglove.SceneUpdate`` of the static scene: obstacles as cylinders (``{shape: circle, center, radius}``)
    and cubes (``{shape: box, min, max}``) spanning the arena's height, goals as discs with labels at ``height``,
    and the arena (``{x: [lo, hi], y: ..., z: ...}``) as a wire box."""
    z0, z1 = (0.0, 2.0)
    if arena is not None and arena.get("z") is not None:
        z0, z1 = float(arena["z"][0]), float(arena["z"][1])
    tall = max(z1 - z0, 0.01)
    grey = _colour(0.55, 0.55, 0.6, 0.9)
    entities = []
    for k, o in enumerate(obstacles):
        if o["shape"] == "circle":
            cx, cy = o["center"]
            d = 2.0 * float(o["radius"])
            cyl = {
                "pose": _flat_pose(cx, cy, z0 + tall / 2),
                "size": {"x": d, "y": d, "z": tall},
                "bottom_scale": 1.0,
                "top_scale": 1.0,
                "color": grey,
            }
            entities.append(scene_entity(t_ns, f"obstacle/{k}", cylinders=[cyl]))
        else:
            (x0, y0), (x1, y1) = o["min"], o["max"]
            cube = {
                "pose": _flat_pose((x0 + x1) / 2, (y0 + y1) / 2, z0 + tall / 2),
                "size": {"x": float(x1 - x0), "y": float(y1 - y0), "z": tall},
                "color": grey,
            }
            entities.append(scene_entity(t_ns, f"obstacle/{k}", cubes=[cube]))
    gold = _colour(1.0, 0.8, 0.1, 0.8)
    for name, g in (goals or {}).items():
        p = xy(g)
        disc = {
            "pose": _flat_pose(p["x"], p["y"], height),
            "size": {"x": 0.2, "y": 0.2, "z": 0.01},
            "bottom_scale": 1.0,
            "top_scale": 1.0,
            "color": gold,
        }
        label = {
            "pose": _flat_pose(p["x"], p["y"], height + 0.15),
            "billboard": True,
            "font_size": 14.0,
            "scale_invariant": True,
            "color": _colour(1.0, 1.0, 1.0, 1.0),
            "text": f"goal {name}",
        }
        entities.append(scene_entity(t_ns, f"goal/{name}", cylinders=[disc], texts=[label]))
    if arena is not None:
        (ax0, ax1), (ay0, ay1) = arena["x"], arena["y"]
        corners = [(ax0, ay0), (ax1, ay0), (ax1, ay1), (ax0, ay1)]
        points = []
        for z in (z0, z1):  # bottom and top rectangles
            for a, b in zip(corners, corners[1:] + corners[:1]):
                points += [{"x": float(a[0]), "y": float(a[1]), "z": z}, {"x": float(b[0]), "y": float(b[1]), "z": z}]
        for cx, cy in corners:  # vertical edges
            points += [{"x": float(cx), "y": float(cy), "z": z0}, {"x": float(cx), "y": float(cy), "z": z1}]
        line = {
            "type": 2,
            "pose": _flat_pose(0, 0, 0),
            "thickness": 2.0,
            "scale_invariant": True,
            "points": points,
            "color": _colour(0.3, 0.6, 1.0, 1.0),
            "colors": [],
            "indices": [],
        }
        entities.append(scene_entity(t_ns, "arena", lines=[line]))
    return {"deletions": [], "entities": entities}
