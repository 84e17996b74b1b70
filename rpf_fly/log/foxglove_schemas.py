"""Foxglove's well-known schemas the log uses: ``foxglove.PoseInFrame``, ``foxglove.FrameTransforms``,
``foxglove.Log`` and ``foxglove.SceneUpdate``.

Written here from the field lists Foxglove documents (every field their ``required`` lists name, arrays included even
when empty), so Foxglove's 3D, Log and plot panels open our files unchanged (docs/log-format.md). The registry of
every schema the log writes is rpf_fly/log/schemas.py.
"""

from __future__ import annotations

from typing import Any

from rpf_fly.log.schema_parts import (
    array as _array,
)
from rpf_fly.log.schema_parts import (
    color as _color,
)
from rpf_fly.log.schema_parts import (
    duration as _duration,
)
from rpf_fly.log.schema_parts import (
    enum as _enum,
)
from rpf_fly.log.schema_parts import (
    num as _num,
)
from rpf_fly.log.schema_parts import (
    obj as _obj,
)
from rpf_fly.log.schema_parts import (
    point3 as _point3,
)
from rpf_fly.log.schema_parts import (
    pose as _pose,
)
from rpf_fly.log.schema_parts import (
    quaternion as _quaternion,
)
from rpf_fly.log.schema_parts import (
    time as _time,
)
from rpf_fly.log.schema_parts import (
    vector3 as _vector3,
)

LOG_LEVELS = {1: "debug", 2: "info", 3: "warning", 4: "error", 5: "fatal"}
"""``foxglove.Log`` levels (0 is Foxglove's "unknown")."""

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
            "foxglove.LogLevel",
            {0: "UNKNOWN", 1: "DEBUG", 2: "INFO", 3: "WARNING", 4: "ERROR", 5: "FATAL"},
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

_KEY_VALUE = _obj(
    {"key": {"type": "string"}, "value": {"type": "string"}},
    title="foxglove.KeyValuePair",
    description="A key with its associated value",
)

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
    {
        "pose": _pose("Centre and orientation of the cube"),
        "size": _vector3("Size along each axis"),
        "color": _color("Color of the cube"),
    },
    title="foxglove.CubePrimitive",
    description="A primitive representing a cube or rectangular prism",
)

_SPHERE = _obj(
    {
        "pose": _pose("Centre and orientation of the sphere"),
        "size": _vector3("Diameter along each axis"),
        "color": _color("Color of the sphere"),
    },
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
