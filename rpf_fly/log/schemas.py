"""JSON Schemas of the flight log's messages and the builders that turn Python values into those messages.

Foxglove's well-known schemas (``foxglove.PoseInFrame``, ``foxglove.SceneUpdate``, ``foxglove.FrameTransforms``,
``foxglove.Log``) are written here from the field lists Foxglove documents (every field their ``required`` lists
name, arrays included even when empty), so Foxglove's 3D, Log and plot panels open our files unchanged. Our own
``rpf_fly.PlannerStep``, ``rpf_fly.DroneStatus`` and ``rpf_fly.TruthState`` (dry runs only) follow the same
conventions: times ``{"sec", "nsec"}``, planar vectors ``{"x", "y"}``, unknown values ``null``. See
docs/log-format.md for what each field means.

The builders return plain dicts ready for :func:`encode` (floats are Python floats, NaN becomes ``null`` where the
schema allows it). Planar vectors may be given as complex numbers ``x + iy`` (rpf_fly's convention) or as
``(x, y)``; 3D positions as ``(x, y, z)`` (a complex or a pair gets ``z = 0``).
"""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path
from typing import Any, Iterable, Mapping, Optional, Sequence

import orjson

_dumps = orjson.dumps

SCHEMA_ENCODING = "jsonschema"
MESSAGE_ENCODING = "json"
WORLD_FRAME = "world"

PLANNER_MODES = ("apf", "wall", "soft", "arrived", "stalled", "hold", "takeoff", "landing", "landed", "link_lost",
                 "emergency")
"""Values of ``rpf_fly.PlannerStep.mode``: the rule that chose the direction (apf, wall, soft), or what the drone did
instead of planning (arrived, hold, and the flight phases in which it does not plan)."""

MODE_NAMES = {0: "apf", 1: "wall", 2: "soft", -1: "arrived"}
"""Planner mode codes (``PlanStep.mode``, ``Rollout.modes``) to their log names."""

DRONE_STATES = (
    "waiting", "ready", "takeoff", "planning", "holding", "arrived", "landing", "landed", "failed", "grounded",
    "link_lost", "emergency",
)
"""The flight states a ``rpf_fly.DroneStatus`` names: the drone phases (rpf_fly/flight/phases.py; a test keeps them
equal). The schema accepts any string."""

LOG_LEVELS = {1: "debug", 2: "info", 3: "warning", 4: "error", 5: "fatal"}
"""``foxglove.Log`` levels (0 is Foxglove's "unknown")."""

# ----------------------------------------------------------------------------------------------- schema parts


def _obj(properties: dict[str, Any], required: Optional[Iterable[str]] = None, title: str = "",
         description: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    if title:
        out["title"] = title
    if description:
        out["description"] = description
    out["type"] = "object"
    out["properties"] = properties
    out["required"] = list(properties) if required is None else list(required)
    return out


def _num(description: str = "") -> dict[str, Any]:
    return {"type": "number", "description": description} if description else {"type": "number"}


def _nullable_num(description: str) -> dict[str, Any]:
    return {"type": ["number", "null"], "description": description}


def _time(description: str) -> dict[str, Any]:
    return {
        "type": "object",
        "title": "time",
        "description": description,
        "properties": {
            "sec": {"type": "integer", "minimum": 0},
            "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999},
        },
        "required": ["sec", "nsec"],
    }


def _duration(description: str) -> dict[str, Any]:
    return {
        "type": "object",
        "title": "duration",
        "description": description,
        "properties": {
            "sec": {"type": "integer"},
            "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999},
        },
        "required": ["sec", "nsec"],
    }


def _vector3(description: str, title: str = "foxglove.Vector3") -> dict[str, Any]:
    return _obj({"x": _num("x"), "y": _num("y"), "z": _num("z")}, title=title, description=description)


def _point3(description: str = "A point in 3D space") -> dict[str, Any]:
    return _vector3(description, title="foxglove.Point3")


def _quaternion(description: str) -> dict[str, Any]:
    return _obj({"x": _num("x"), "y": _num("y"), "z": _num("z"), "w": _num("w")}, title="foxglove.Quaternion",
                description=description)


def _pose(description: str) -> dict[str, Any]:
    return _obj(
        {"position": _vector3("Position in 3D space"), "orientation": _quaternion("Orientation in 3D space")},
        title="foxglove.Pose",
        description=description,
    )


def _color(description: str) -> dict[str, Any]:
    return _obj({"r": _num("red 0..1"), "g": _num("green 0..1"), "b": _num("blue 0..1"), "a": _num("alpha 0..1")},
                title="foxglove.Color", description=description)


def _array(items: dict[str, Any], description: str) -> dict[str, Any]:
    return {"type": "array", "items": items, "description": description}


def _enum(title: str, values: dict[int, str], description: str) -> dict[str, Any]:
    return {"title": title, "description": description, "oneOf": [{"title": t, "const": v} for v, t in values.items()]}


def _vector2(description: str) -> dict[str, Any]:
    return _obj({"x": _num("x"), "y": _num("y")}, description=description)


# ----------------------------------------------------------------------------------------------- Foxglove schemas

POSE_IN_FRAME: dict[str, Any] = _obj(
    {
        "timestamp": _time("Timestamp of pose"),
        "frame_id": {"type": "string", "description": "Frame of reference for pose position and orientation"},
        "pose": _pose("Pose in 3D space"),
    },
    title="foxglove.PoseInFrame",
    description="A timestamped pose for an object or reference frame in 3D space",
)

FRAME_TRANSFORM: dict[str, Any] = _obj(
    {
        "timestamp": _time("Timestamp of transform"),
        "parent_frame_id": {"type": "string", "description": "Name of the parent frame"},
        "child_frame_id": {"type": "string", "description": "Name of the child frame"},
        "translation": _vector3("Position of the child frame's origin in the parent frame"),
        "rotation": _quaternion("Orientation of the child frame in the parent frame"),
    },
    title="foxglove.FrameTransform",
    description="A transform between two reference frames in 3D space",
)

FRAME_TRANSFORMS: dict[str, Any] = _obj(
    {"transforms": _array(FRAME_TRANSFORM, "Array of transforms")},
    title="foxglove.FrameTransforms",
    description="An array of FrameTransform messages",
)

LOG: dict[str, Any] = _obj(
    {
        "timestamp": _time("Timestamp of log message"),
        "level": _enum(
            "foxglove.LogLevel", {0: "UNKNOWN", 1: "DEBUG", 2: "INFO", 3: "WARNING", 4: "ERROR", 5: "FATAL"},
            "Log level",
        ),
        "message": {"type": "string", "description": "Log message"},
        "name": {"type": "string", "description": "Process or node name"},
        "file": {"type": "string", "description": "Filename"},
        "line": {"type": "integer", "minimum": 0, "description": "Line number in the file"},
    },
    title="foxglove.Log",
    description="A log message",
)

_KEY_VALUE = _obj({"key": {"type": "string"}, "value": {"type": "string"}}, title="foxglove.KeyValuePair",
                  description="A key with its associated value")

_ARROW = _obj(
    {
        "pose": _pose("Position of the arrow's tail and orientation (identity: +x)"),
        "shaft_length": _num("Length of the arrow shaft"),
        "shaft_diameter": _num("Diameter of the arrow shaft"),
        "head_length": _num("Length of the arrow head"),
        "head_diameter": _num("Diameter of the arrow head"),
        "color": _color("Color of the arrow"),
    },
    title="foxglove.ArrowPrimitive",
    description="A primitive representing an arrow",
)

_CUBE = _obj(
    {"pose": _pose("Centre and orientation of the cube"), "size": _vector3("Size along each axis"),
     "color": _color("Color of the cube")},
    title="foxglove.CubePrimitive",
    description="A primitive representing a cube or rectangular prism",
)

_SPHERE = _obj(
    {"pose": _pose("Centre and orientation of the sphere"), "size": _vector3("Diameter along each axis"),
     "color": _color("Color of the sphere")},
    title="foxglove.SpherePrimitive",
    description="A primitive representing a sphere or ellipsoid",
)

_CYLINDER = _obj(
    {
        "pose": _pose("Centre and orientation of the cylinder (flat faces perpendicular to z)"),
        "size": _vector3("Size of the cylinder's bounding box"),
        "bottom_scale": _num("0-1, diameter of the bottom face relative to the bounding box"),
        "top_scale": _num("0-1, diameter of the top face relative to the bounding box"),
        "color": _color("Color of the cylinder"),
    },
    title="foxglove.CylinderPrimitive",
    description="A primitive representing a cylinder, elliptic cylinder, or truncated cone",
)

_LINE = _obj(
    {
        "type": _enum("foxglove.LineType", {0: "LINE_STRIP", 1: "LINE_LOOP", 2: "LINE_LIST"}, "Line drawing type"),
        "pose": _pose("Origin of the lines relative to the frame"),
        "thickness": _num("Line thickness"),
        "scale_invariant": {"type": "boolean", "description": "thickness in screen pixels (true) or metres (false)"},
        "points": _array(_point3(), "Points along the line"),
        "color": _color("Solid color of the whole line (ignored if colors is non-empty)"),
        "colors": _array(_color("A color"), "Per-point colors"),
        "indices": _array({"type": "integer", "minimum": 0}, "Indices into points and colors"),
    },
    title="foxglove.LinePrimitive",
    description="A primitive representing a series of points connected by lines",
)

_TRIANGLES = _obj(
    {
        "pose": _pose("Origin of the triangles relative to the frame"),
        "points": _array(_point3(), "Vertices, taken as triples"),
        "color": _color("Solid color (ignored if colors is non-empty)"),
        "colors": _array(_color("A color"), "Per-vertex colors"),
        "indices": _array({"type": "integer", "minimum": 0}, "Indices into points and colors"),
    },
    title="foxglove.TriangleListPrimitive",
    description="A primitive representing a set of triangles",
)

_TEXT = _obj(
    {
        "pose": _pose("Centre of the text box and orientation of the text"),
        "billboard": {"type": "boolean", "description": "Always face the camera"},
        "font_size": _num("Font size"),
        "scale_invariant": {"type": "boolean", "description": "font_size in screen pixels (true) or metres (false)"},
        "color": _color("Color of the text"),
        "text": {"type": "string", "description": "Text"},
    },
    title="foxglove.TextPrimitive",
    description="A primitive representing a text label",
)

_MODEL = _obj(
    {
        "pose": _pose("Origin of the model relative to the frame"),
        "scale": _vector3("Scale factor along each axis"),
        "color": _color("Solid color if override_color"),
        "override_color": {"type": "boolean", "description": "Use color instead of the model's materials"},
        "url": {"type": "string", "description": "URL of the model file"},
        "media_type": {"type": "string", "description": "Media type of the embedded model"},
        "data": {"type": "string", "contentEncoding": "base64", "description": "Embedded model"},
    },
    title="foxglove.ModelPrimitive",
    description="A primitive representing a 3D model",
)

SCENE_ENTITY: dict[str, Any] = _obj(
    {
        "timestamp": _time("Timestamp of the entity"),
        "frame_id": {"type": "string", "description": "Frame of reference"},
        "id": {"type": "string", "description": "Identifier; replaces any prior entity with the same id"},
        "lifetime": _duration("Time after which the entity is removed; zero: until replaced or deleted"),
        "frame_locked": {"type": "boolean", "description": "Follow frame_id as it moves (true)"},
        "metadata": _array(_KEY_VALUE, "Additional metadata"),
        "arrows": _array(_ARROW, "Arrow primitives"),
        "cubes": _array(_CUBE, "Cube primitives"),
        "spheres": _array(_SPHERE, "Sphere primitives"),
        "cylinders": _array(_CYLINDER, "Cylinder primitives"),
        "lines": _array(_LINE, "Line primitives"),
        "triangles": _array(_TRIANGLES, "Triangle list primitives"),
        "texts": _array(_TEXT, "Text primitives"),
        "models": _array(_MODEL, "Model primitives"),
    },
    title="foxglove.SceneEntity",
    description="A visual element in a 3D scene",
)

SCENE_ENTITY_DELETION: dict[str, Any] = _obj(
    {
        "timestamp": _time("Only matching entities earlier than this are deleted"),
        "type": _enum("foxglove.SceneEntityDeletionType", {0: "MATCHING_ID", 1: "ALL"}, "Type of deletion"),
        "id": {"type": "string", "description": "Identifier which must match if type is MATCHING_ID"},
    },
    title="foxglove.SceneEntityDeletion",
    description="Command to remove previously published entities",
)

SCENE_UPDATE: dict[str, Any] = _obj(
    {
        "deletions": _array(SCENE_ENTITY_DELETION, "Scene entities to delete"),
        "entities": _array(SCENE_ENTITY, "Scene entities to add or replace"),
    },
    title="foxglove.SceneUpdate",
    description="An update to the entities displayed in a 3D scene",
)

# ----------------------------------------------------------------------------------------------- our schemas

PLANNER_STEP: dict[str, Any] = _obj(
    {
        "timestamp": _time("Time of the planning tick"),
        "tick": {"type": "integer", "minimum": 0, "description": "Planning step index from 0"},
        "position": _obj({"x": _num(), "y": _num(), "z": _num()}, description="The pose the planner used (m)"),
        "goal": _vector2("The drone's goal (m)"),
        "eta": _nullable_num("Obstacle repulsion gain; null for planners without gains"),
        "lambda": _nullable_num("Inter-robot repulsion gain; null for planners without gains"),
        "f_a": _vector2("Attractive force"),
        "f_r": _vector2("Obstacle repulsive force"),
        "f_in": _vector2("Inter-robot repulsive force"),
        "direction": _vector2("Planned unit direction (zero when stalled or holding)"),
        "mode": {"type": "string", "enum": list(PLANNER_MODES), "description": "Which rule chose the direction"},
        "heading": _num("Heading of the drone (rad, counter-clockwise from +x)"),
        "neighbours": {"type": "integer", "minimum": 0, "description": "Neighbours that exerted a force"},
        "obstacle_distance": _nullable_num("Distance to the nearest visible obstacle surface (m); null if none"),
        "goal_distance": _num("Distance to the goal (m)"),
        "reference": _vector2("Where the drone planned from: its reference (its own position in its view) before "
                              "the step (m); only on ticks it planned (2026-12, for rpf-fly replay)"),
    },
    required=("timestamp", "tick", "position", "goal", "eta", "lambda", "f_a", "f_r", "f_in", "direction", "mode",
              "heading", "neighbours", "obstacle_distance", "goal_distance"),
    title="rpf_fly.PlannerStep",
    description="One planning tick of one drone",
)

DRONE_STATUS: dict[str, Any] = _obj(
    {
        "timestamp": _time("Time of the status"),
        "state": {"type": "string", "description": "Flight state: " + ", ".join(DRONE_STATES)},
        "battery_v": _nullable_num("Battery voltage (V); null if unknown"),
        "link_quality": {"type": ["number", "null"], "minimum": 0, "maximum": 1,
                         "description": "Radio link quality 0..1; null if unknown"},
        "latency_ms": _nullable_num("Radio round-trip latency (ms); null if unknown"),
        "outcome": {"type": ["string", "null"], "description": "null while flying; reached, stalled, timeout, ..."},
        "estimate": {"type": ["object", "null"], "properties": {"x": _num(), "y": _num(), "z": _num()},
                     "description": "The on-board estimate of the drone's position (m), as its firmware logs it; "
                                    "null if unknown (2026-12-04)"},
        "target": {"type": ["object", "null"], "properties": {"x": _num(), "y": _num(), "z": _num()},
                   "description": "Where the drone's own controller is taking it (m): the streamed setpoint, or the "
                                  "high-level take-off's or landing's point; null if the firmware does not log it "
                                  "(2026-12-04)"},
    },
    required=("timestamp", "state", "battery_v", "link_quality", "latency_ms", "outcome"),
    title="rpf_fly.DroneStatus",
    description="State, battery and link of one drone",
)

TRUTH_STATE: dict[str, Any] = _obj(
    {
        "timestamp": _time("When the simulated world was in this state"),
        "position": _obj({"x": _num(), "y": _num(), "z": _num()}, description="The drone's true centre (m)"),
        "yaw": _num("True yaw (rad, counter-clockwise from +x)"),
        "motors": {"type": "boolean", "description": "The motors spin"},
        "crashed": {"type": "boolean", "description": "The drone hit another drone or an obstacle (locked)"},
        "estimate": _obj({"x": _num(), "y": _num(), "z": _num()},
                         description="The firmware's estimated position (m)"),
    },
    title="rpf_fly.TruthState",
    description="One drone's true state in a dry run's simulated world (not measured: real flights have none)",
)

RADIO_LOAD: dict[str, Any] = _obj(
    {
        "timestamp": _time("End of the window"),
        "dongle": {"type": "integer", "minimum": 0, "description": "The dongle number (the URI's first number)"},
        "drones": {"type": "array", "items": {"type": "string"}, "description": "The drones on this dongle"},
        "window_s": _num("Length of the window (s)"),
        "packets": _num("Uplink packets acknowledged in the window: setpoints, extpos, commands, cflib's pings"),
        "transactions": _num("Radio transactions acknowledged in the window, cflib's empty polls included"),
        "packets_per_s": _num("packets / window_s: the dongle's measured load"),
        "transactions_per_s": _num("transactions / window_s: the dongle's air in use (polls yield to packets)"),
        "planned_per_s": _num("What the radio budget counts for this dongle while the drones stream setpoints "
                              "(rpf_fly.radio.budget: setpoints + extpos + pings)"),
        "budget_per_s": _num("What this dongle carries (radio.budget_packets_s or the dongle type's figure)"),
        "setpoints_superseded": _num("Setpoints of this dongle's drones replaced by a newer one before the radio took "
                                     "them (the radio lagged; rpf_fly/radio/outbox.py); absent in logs before "
                                     "2026-12-02"),
    },
    required=("timestamp", "dongle", "drones", "window_s", "packets", "transactions", "packets_per_s",
              "transactions_per_s", "planned_per_s", "budget_per_s"),
    title="rpf_fly.RadioLoad",
    description="One dongle's measured radio load over one window, from cflib's link statistics",
)

FIRMWARE_STATE: dict[str, Any] = _obj(
    {
        "timestamp": _time("When the simulated firmware was in this state"),
        "powered": {"type": "boolean", "description": "The flight stack runs (false while a reboot boots)"},
        "supervisor": {"type": "string", "description": "The supervisor's state, named as in the firmware "
                                                         "(supervisor_state_machine.c): 'Pre-flight checks passed', "
                                                         "'Flying', 'Locked', ..."},
        "armed": {"type": "boolean", "description": "The supervisor is armed"},
        "motors": {"type": "boolean", "description": "The motors spin"},
        "flying": {"type": "boolean", "description": "The supervisor's is-flying condition"},
        "locked": {"type": "boolean", "description": "Locked: only a reboot leaves it"},
        "crashed": {"type": "boolean", "description": "The drone hit another drone or an obstacle"},
        "emergency_stop": {"type": "boolean", "description": "An emergency stop (command, parameter or the "
                                                             "emergency-stop watchdog) is latched"},
        "commander": {"type": "string", "description": "Who feeds the controller: the streamed (CRTP) setpoints or "
                                                       "the high-level commander"},
        "high_level": {"type": "string", "description": "The high-level commander's state"},
        "setpoint_age_s": {"type": ["number", "null"], "description": "Seconds since the last streamed setpoint "
                                                                      "(null: none since power-on)"},
        "battery_v": _num("Battery voltage (V)"),
        "boots": {"type": "integer", "description": "Reboots since the lab started"},
    },
    required=("timestamp", "supervisor", "motors", "locked", "commander", "high_level"),
    title="rpf_fly.FirmwareState",
    description="One simulated Crazyflie's firmware state in a lab (rpf-fly lab): what its supervisor and "
                "commander do, whoever is connected",
)

HOST_LAG: dict[str, Any] = _obj(
    {
        "timestamp": _time("When the figures were read"),
        "bound_s": _num("A step or frame later than this against its schedule counts as behind (s)"),
        "behind_s": _num("Seconds so far during which the simulated world ran behind the bound"),
        "world": {"type": "object", "description": "The 100 Hz physics steps: runs, late_runs, max_late_s, "
                                                   "behind_s"},
        "natnet": {"type": ["object", "null"], "description": "The NatNet emulator's frames (same fields)"},
    },
    required=("timestamp", "bound_s", "behind_s", "world"),
    title="rpf_fly.HostLag",
    description="How far the host let the simulated world fall behind its own time (rpf_fly/emulator/host_lag.py)",
)

SCHEMAS: dict[str, dict[str, Any]] = {
    "foxglove.PoseInFrame": POSE_IN_FRAME,
    "foxglove.SceneUpdate": SCENE_UPDATE,
    "foxglove.FrameTransforms": FRAME_TRANSFORMS,
    "foxglove.Log": LOG,
    "rpf_fly.PlannerStep": PLANNER_STEP,
    "rpf_fly.DroneStatus": DRONE_STATUS,
    "rpf_fly.TruthState": TRUTH_STATE,
    "rpf_fly.RadioLoad": RADIO_LOAD,
    "rpf_fly.FirmwareState": FIRMWARE_STATE,
    "rpf_fly.HostLag": HOST_LAG,
}
"""Every schema the log uses, by the schema name written into the file."""

LAB_SCHEMAS = frozenset({"rpf_fly.FirmwareState", "rpf_fly.HostLag"})
"""The schemas only a lab's own log uses (``rpf-fly lab``: rpf_fly/flight/lab.py)."""

for _name, _schema in SCHEMAS.items():
    _schema["$schema"] = "http://json-schema.org/draft-07/schema#"


def schema_bytes(name: str) -> bytes:
    """The schema document as written into the MCAP Schema record."""
    return json.dumps(SCHEMAS[name], separators=(",", ":")).encode()


def topic_schema(topic: str) -> str:
    """The schema name of a topic of the contract (docs/log-format.md)."""
    if topic.startswith("/mocap/") or topic.endswith("/setpoint"):
        return "foxglove.PoseInFrame"
    if topic.startswith("/truth/"):
        return "rpf_fly.TruthState"
    if topic.startswith("/radio/"):
        return "rpf_fly.RadioLoad"
    if topic.startswith("/firmware/"):
        return "rpf_fly.FirmwareState"
    if topic == "/lab/host":
        return "rpf_fly.HostLag"
    if topic.endswith("/planner"):
        return "rpf_fly.PlannerStep"
    if topic.endswith("/status"):
        return "rpf_fly.DroneStatus"
    fixed = {"/scene": "foxglove.SceneUpdate", "/tf": "foxglove.FrameTransforms", "/events": "foxglove.Log"}
    if topic in fixed:
        return fixed[topic]
    raise KeyError(f"{topic}: not a topic of the flight log")


# ----------------------------------------------------------------------------------------------- builders

IDENTITY = (0.0, 0.0, 0.0, 1.0)


def stamp(t_ns: int) -> dict[str, int]:
    """Foxglove time ``{"sec", "nsec"}`` of nanoseconds since the Unix epoch."""
    sec, nsec = divmod(int(t_ns), 1_000_000_000)
    return {"sec": sec, "nsec": nsec}


def _opt(value: Any) -> Optional[float]:
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


def quat(value: Optional[Sequence[float]]) -> dict[str, float]:
    """``{"x", "y", "z", "w"}`` of ``(qx, qy, qz, qw)`` (None: identity)."""
    q = IDENTITY if value is None else value
    return {"x": float(q[0]), "y": float(q[1]), "z": float(q[2]), "w": float(q[3])}


def yaw_quaternion(yaw_rad: float) -> tuple[float, float, float, float]:
    """``(qx, qy, qz, qw)`` of a rotation by ``yaw_rad`` about +z."""
    half = 0.5 * float(yaw_rad)
    return (0.0, 0.0, math.sin(half), math.cos(half))


def pose_in_frame(t_ns: int, position: Any, quaternion: Optional[Sequence[float]] = None,
                  frame_id: str = WORLD_FRAME) -> dict[str, Any]:
    """A ``foxglove.PoseInFrame``."""
    return {"timestamp": stamp(t_ns), "frame_id": frame_id,
            "pose": {"position": xyz(position), "orientation": quat(quaternion)}}


def frame_transforms(t_ns: int, poses: Mapping[str, tuple[Any, Optional[Sequence[float]]]],
                     parent: str = WORLD_FRAME) -> dict[str, Any]:
    """A ``foxglove.FrameTransforms`` from ``parent`` to each named child: ``{name: (position, quaternion)}``."""
    ts = stamp(t_ns)
    return {"transforms": [
        {"timestamp": ts, "parent_frame_id": parent, "child_frame_id": str(name), "translation": xyz(p),
         "rotation": quat(q)}
        for name, (p, q) in poses.items()
    ]}


def log_message(t_ns: int, level: int, message: str, name: str = "rpf_fly", file: str = "", line: int = 0
                ) -> dict[str, Any]:
    """A ``foxglove.Log`` (level 1 debug, 2 info, 3 warning, 4 error, 5 fatal)."""
    level = int(level)
    if level not in LOG_LEVELS:
        raise ValueError(f"log level {level} is not one of 1..5")
    return {"timestamp": stamp(t_ns), "level": level, "message": str(message), "name": str(name),
            "file": str(file), "line": max(int(line), 0)}


PLANNER_FIELDS = ("tick", "position", "goal", "eta", "lambda", "f_a", "f_r", "f_in", "direction", "mode", "heading",
                  "neighbours", "obstacle_distance", "goal_distance", "reference")


def planner_step(t_ns: int, tick: int, position: Any, goal: Any, mode: Any, eta: Any = None, lam: Any = None,
                 f_a: Any = 0j, f_r: Any = 0j, f_in: Any = 0j, direction: Any = 0j, heading: float = 0.0,
                 neighbours: int = 0, obstacle_distance: Any = None, goal_distance: Any = None,
                 reference: Any = None, **extra: Any) -> dict[str, Any]:
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


def drone_status(t_ns: int, state: str, battery_v: Any = None, link_quality: Any = None, latency_ms: Any = None,
                 outcome: Optional[str] = None, estimate: Any = None, target: Any = None) -> dict[str, Any]:
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


def radio_load(t_ns: int, dongle: int, drones: Sequence[str], window_s: float, packets: float, transactions: float,
               planned_per_s: float, budget_per_s: float, setpoints_superseded: float = 0.0) -> dict[str, Any]:
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
        "timestamp": stamp(t_ns), "frame_id": frame_id, "id": entity_id, "lifetime": {"sec": 0, "nsec": 0},
        "frame_locked": False, "metadata": [],
    }
    for key in ("arrows", "cubes", "spheres", "cylinders", "lines", "triangles", "texts", "models"):
        entity[key] = list(primitives.pop(key, []))
    if primitives:
        raise TypeError(f"unknown SceneEntity primitives: {', '.join(primitives)}")
    return entity


def _flat_pose(x: float, y: float, z: float) -> dict[str, Any]:
    return {"position": {"x": float(x), "y": float(y), "z": float(z)}, "orientation": quat(None)}


def scene_update(t_ns: int, obstacles: Iterable[Mapping[str, Any]] = (), goals: Mapping[str, Any] | None = None,
                 arena: Mapping[str, Sequence[float]] | None = None, height: float = 0.0) -> dict[str, Any]:
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
            cyl = {"pose": _flat_pose(cx, cy, z0 + tall / 2), "size": {"x": d, "y": d, "z": tall},
                   "bottom_scale": 1.0, "top_scale": 1.0, "color": grey}
            entities.append(scene_entity(t_ns, f"obstacle/{k}", cylinders=[cyl]))
        else:
            (x0, y0), (x1, y1) = o["min"], o["max"]
            cube = {"pose": _flat_pose((x0 + x1) / 2, (y0 + y1) / 2, z0 + tall / 2),
                    "size": {"x": float(x1 - x0), "y": float(y1 - y0), "z": tall}, "color": grey}
            entities.append(scene_entity(t_ns, f"obstacle/{k}", cubes=[cube]))
    gold = _colour(1.0, 0.8, 0.1, 0.8)
    for name, g in (goals or {}).items():
        p = xy(g)
        disc = {"pose": _flat_pose(p["x"], p["y"], height), "size": {"x": 0.2, "y": 0.2, "z": 0.01},
                "bottom_scale": 1.0, "top_scale": 1.0, "color": gold}
        label = {"pose": _flat_pose(p["x"], p["y"], height + 0.15), "billboard": True, "font_size": 14.0,
                 "scale_invariant": True, "color": _colour(1.0, 1.0, 1.0, 1.0), "text": f"goal {name}"}
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
        line = {"type": 2, "pose": _flat_pose(0, 0, 0), "thickness": 2.0, "scale_invariant": True, "points": points,
                "color": _colour(0.3, 0.6, 1.0, 1.0), "colors": [], "indices": []}
        entities.append(scene_entity(t_ns, "arena", lines=[line]))
    return {"deletions": [], "entities": entities}


# ----------------------------------------------------------------------------------------------- encoding

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


def pose_json(t_ns: int, position: Any, quaternion: Optional[Sequence[float]] = None) -> bytes:
    """``encode(pose_in_frame(t_ns, position, quaternion))`` (frame ``world``), fast."""
    try:
        x, y, z = position
        qx, qy, qz, qw = IDENTITY if quaternion is None else quaternion
        sec, nsec = divmod(int(t_ns), 1_000_000_000)
        return _dumps({"timestamp": {"sec": sec, "nsec": nsec}, "frame_id": WORLD_FRAME, "pose": {
            "position": {"x": float(x), "y": float(y), "z": float(z)},
            "orientation": {"x": float(qx), "y": float(qy), "z": float(qz), "w": float(qw)}}})
    except (TypeError, ValueError):
        return encode(pose_in_frame(t_ns, position, quaternion))


def tf_json(t_ns: int, poses: Mapping[str, tuple[Any, Optional[Sequence[float]]]]) -> bytes:
    """``encode(frame_transforms(t_ns, poses))``, fast."""
    try:
        sec, nsec = divmod(int(t_ns), 1_000_000_000)
        transforms = []
        for name, (p, q) in poses.items():
            x, y, z = p
            qx, qy, qz, qw = IDENTITY if q is None else q
            transforms.append({
                "timestamp": {"sec": sec, "nsec": nsec}, "parent_frame_id": WORLD_FRAME, "child_frame_id": str(name),
                "translation": {"x": float(x), "y": float(y), "z": float(z)},
                "rotation": {"x": float(qx), "y": float(qy), "z": float(qz), "w": float(qw)}})
        return _dumps({"transforms": transforms})
    except (TypeError, ValueError):
        return encode(frame_transforms(t_ns, poses))


def truth_json(t_ns: int, position: Any, yaw: float, motors: bool, crashed: bool, estimate: Any) -> bytes:
    """``encode(truth_state(t_ns, position, yaw, motors, crashed, estimate))``, fast."""
    try:
        x, y, z = position
        ex, ey, ez = estimate
        sec, nsec = divmod(int(t_ns), 1_000_000_000)
        return _dumps({"timestamp": {"sec": sec, "nsec": nsec},
                       "position": {"x": float(x), "y": float(y), "z": float(z)}, "yaw": float(yaw),
                       "motors": bool(motors), "crashed": bool(crashed),
                       "estimate": {"x": float(ex), "y": float(ey), "z": float(ez)}})
    except (TypeError, ValueError):
        return encode(truth_state(t_ns, position, yaw, motors, crashed, estimate))


_PLANNER_KEYS = frozenset(PLANNER_FIELDS) | {"lam"}
_MODE_SET = frozenset(PLANNER_MODES)


def _opt_float(value: Any) -> Optional[float]:
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
            "timestamp": {"sec": sec, "nsec": nsec}, "tick": int(f["tick"]), "position": {"x": x, "y": y, "z": z},
            "goal": goal, "eta": _opt_float(f.get("eta")),
            "lambda": _opt_float(f["lambda"] if "lambda" in f else f.get("lam")),
            "f_a": _xy_dict(f.get("f_a", 0j)), "f_r": _xy_dict(f.get("f_r", 0j)), "f_in": _xy_dict(f.get("f_in", 0j)),
            "direction": _xy_dict(f.get("direction", 0j)), "mode": mode, "heading": float(f.get("heading", 0.0)),
            "neighbours": int(f.get("neighbours", 0)), "obstacle_distance": _opt_float(f.get("obstacle_distance")),
            "goal_distance": gd,
        }
        reference = f.get("reference")
        if reference is not None:
            message["reference"] = _xy_dict(reference)
        return _dumps(message)
    except (TypeError, ValueError, KeyError, IndexError):
        return encode(planner_step(t_ns, **fields))


# ----------------------------------------------------------------------------------------------- metadata records


def obstacle_dict(shape: Any) -> dict[str, Any]:
    """A mission obstacle (``CircleObstacle`` / ``BoxObstacle``) as the log writes it: ``{shape: circle, center,
    radius}`` or ``{shape: box, min, max}`` (the ``scenario`` record, ``FlightLog.scene``)."""
    if getattr(shape, "shape", None) == "circle":
        return {"shape": "circle", "center": [float(v) for v in shape.center], "radius": float(shape.radius)}
    return {"shape": "box", "min": [float(v) for v in shape.min], "max": [float(v) for v in shape.max]}


_obstacle_dict = obstacle_dict  # the name callers used first


def file_sha256(path: Optional[str | Path]) -> str:
    """Hex SHA-256 of a file ("" for None)."""
    if path is None:
        return ""
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def mission_metadata(mission: Any, seed: int = 0, source: str = "flight") -> dict[str, str]:
    """The ``mission`` metadata record of a :class:`~rpf_fly.mission.Mission` (string values)."""
    from rpf_fly import __version__

    return {
        "name": mission.name,
        "yaml": mission.text,
        "rpf_fly_version": __version__,
        "planner": mission.planner.kind,
        "policy_sha256": file_sha256(mission.planner.policy),
        "seed": str(int(seed)),
        "source": source,
    }


def scenario_metadata(mission: Any, scenario: Any = None) -> dict[str, str]:
    """The ``scenario`` metadata record: everything the review needs to score the run, as one JSON string.

    ``scenario`` (a :class:`~rpf_fly.sim.Scenario`) gives the actual (jittered) starts and goals; without it the
    mission's nominal layout is used (a flight)."""
    if scenario is not None:
        names = list(scenario.names)
        starts = [[float(p.real), float(p.imag)] for p in scenario.starts]
        goals = [[float(p.real), float(p.imag)] for p in scenario.goals]
        shapes = scenario.shapes
        ax, ay = scenario.arena_x, scenario.arena_y
    else:
        names = [d.name for d in mission.drones]
        starts = [[float(v) for v in d.start] for d in mission.drones]
        goals = [[float(v) for v in d.goal] for d in mission.drones]
        shapes = mission.obstacles
        ax, ay = mission.arena.x, mission.arena.y
    body = {
        "names": names,
        "starts": starts,
        "goals": goals,
        "obstacles": [obstacle_dict(s) for s in shapes],
        "arena": {"x": [float(v) for v in ax], "y": [float(v) for v in ay],
                  "z": [float(v) for v in mission.arena.z]},
        "dt": float(mission.flight.dt),
        "goal_tolerance": float(mission.flight.goal_tolerance),
        "safety_radius": float(mission.planner.safety_radius),
        "margin": float(mission.planner.margin_m),
        "speed": float(mission.flight.speed),
        "height": float(mission.flight.height),
    }
    return {"json": json.dumps(body)}
