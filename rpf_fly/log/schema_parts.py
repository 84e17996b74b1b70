"""The pieces the log's JSON Schemas are written from: objects, numbers, times, vectors, poses, colours, arrays.

One place for how a field is spelled in JSON Schema, so Foxglove's schemas (rpf_fly/log/foxglove_schemas.py) and our
own (rpf_fly/log/rpf_schemas.py) are written alike: every field their ``required`` lists name, times
``{"sec", "nsec"}``, titles as Foxglove names its types.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any


def obj(
    properties: dict[str, Any], required: Iterable[str] | None = None, title: str = "", description: str = ""
) -> dict[str, Any]:
    out: dict[str, Any] = {}
    if title:
        out["title"] = title
    if description:
        out["description"] = description
    out["type"] = "object"
    out["properties"] = properties
    out["required"] = list(properties) if required is None else list(required)
    return out


def num(description: str = "") -> dict[str, Any]:
    return {"type": "number", "description": description} if description else {"type": "number"}


def nullable_num(description: str) -> dict[str, Any]:
    return {"type": ["number", "null"], "description": description}


def time(description: str) -> dict[str, Any]:
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


def duration(description: str) -> dict[str, Any]:
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


def vector3(description: str, title: str = "foxglove.Vector3") -> dict[str, Any]:
    return obj({"x": num("x"), "y": num("y"), "z": num("z")}, title=title, description=description)


def point3(description: str = "A point in 3D space") -> dict[str, Any]:
    return vector3(description, title="foxglove.Point3")


def quaternion(description: str) -> dict[str, Any]:
    return obj(
        {"x": num("x"), "y": num("y"), "z": num("z"), "w": num("w")},
        title="foxglove.Quaternion",
        description=description,
    )


def pose(description: str) -> dict[str, Any]:
    return obj(
        {"position": vector3("Position in 3D space"), "orientation": quaternion("Orientation in 3D space")},
        title="foxglove.Pose",
        description=description,
    )


def color(description: str) -> dict[str, Any]:
    return obj(
        {"r": num("red 0..1"), "g": num("green 0..1"), "b": num("blue 0..1"), "a": num("alpha 0..1")},
        title="foxglove.Color",
        description=description,
    )


def array(items: dict[str, Any], description: str) -> dict[str, Any]:
    return {"type": "array", "items": items, "description": description}


def enum(title: str, values: dict[int, str], description: str) -> dict[str, Any]:
    return {"title": title, "description": description, "oneOf": [{"title": t, "const": v} for v, t in values.items()]}


def vector2(description: str) -> dict[str, Any]:
    return obj({"x": num("x"), "y": num("y")}, description=description)
