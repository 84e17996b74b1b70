"""Every message of every topic validates against the JSON Schema embedded in the file, and our Foxglove schemas
carry the names and required fields that Foxglove documents (so its panels accept the messages)."""

from __future__ import annotations

import json

import jsonschema
import numpy as np
import pytest
from mcap.reader import make_reader
from test_log_writer import write_flight

from rpf_fly.log import encoding as E
from rpf_fly.log import messages as M
from rpf_fly.log import rpf_schemas as R
from rpf_fly.log import schemas as S
from rpf_fly.log.schemas import SCHEMAS

# Required fields as listed in Foxglove's schema reference (docs.foxglove.dev, foxglove-sdk schemas/jsonschema).
FOXGLOVE_REQUIRED = {
    "foxglove.PoseInFrame": ["timestamp", "frame_id", "pose"],
    "foxglove.FrameTransforms": ["transforms"],
    "foxglove.FrameTransform": ["timestamp", "parent_frame_id", "child_frame_id", "translation", "rotation"],
    "foxglove.Log": ["timestamp", "level", "message", "name", "file", "line"],
    "foxglove.SceneUpdate": ["deletions", "entities"],
    "foxglove.SceneEntity": [
        "timestamp",
        "frame_id",
        "id",
        "lifetime",
        "frame_locked",
        "metadata",
        "arrows",
        "cubes",
        "spheres",
        "cylinders",
        "lines",
        "triangles",
        "texts",
        "models",
    ],
    "foxglove.SceneEntityDeletion": ["timestamp", "type", "id"],
    "foxglove.ArrowPrimitive": ["pose", "shaft_length", "shaft_diameter", "head_length", "head_diameter", "color"],
    "foxglove.CubePrimitive": ["pose", "size", "color"],
    "foxglove.SpherePrimitive": ["pose", "size", "color"],
    "foxglove.CylinderPrimitive": ["pose", "size", "bottom_scale", "top_scale", "color"],
    "foxglove.LinePrimitive": ["type", "pose", "thickness", "scale_invariant", "points", "color", "colors", "indices"],
    "foxglove.TriangleListPrimitive": ["pose", "points", "color", "colors", "indices"],
    "foxglove.TextPrimitive": ["pose", "billboard", "font_size", "scale_invariant", "color", "text"],
    "foxglove.ModelPrimitive": ["pose", "scale", "color", "override_color", "url", "media_type", "data"],
    "foxglove.Pose": ["position", "orientation"],
    "foxglove.Vector3": ["x", "y", "z"],
    "foxglove.Quaternion": ["x", "y", "z", "w"],
    "foxglove.Color": ["r", "g", "b", "a"],
}


def titled(node, found=None):  # type: ignore[no-untyped-def]
    """Every sub-schema with a title, by title."""
    found = {} if found is None else found
    if isinstance(node, dict):
        if isinstance(node.get("title"), str) and "properties" in node:
            found.setdefault(node["title"], []).append(node)
        for value in node.values():
            titled(value, found)
    elif isinstance(node, list):
        for value in node:
            titled(value, found)
    return found


def test_schemas_are_valid_json_schema_documents():
    for name, schema in SCHEMAS.items():
        jsonschema.Draft7Validator.check_schema(schema)
        assert schema["title"] == name


def test_foxglove_schemas_require_what_foxglove_requires():
    parts = titled(list(SCHEMAS.values()))
    for title, required in FOXGLOVE_REQUIRED.items():
        assert title in parts, title
        for node in parts[title]:
            assert set(required) <= set(node["required"]), (title, node["required"])
            assert set(required) <= set(node["properties"]), title


def validate_file(path):  # type: ignore[no-untyped-def]
    """Validate every message against its channel's embedded schema; returns messages per schema name."""
    checked: dict[str, int] = {}
    with open(path, "rb") as f:
        reader = make_reader(f)
        validators = {}
        for schema, channel, message in reader.iter_messages():
            assert schema.encoding == "jsonschema" and channel.message_encoding == "json"
            if schema.id not in validators:
                validators[schema.id] = jsonschema.Draft7Validator(json.loads(schema.data))
            validators[schema.id].validate(json.loads(message.data))
            checked[schema.name] = checked.get(schema.name, 0) + 1
    return checked


def test_every_message_of_a_flight_validates(tmp_path):
    path = tmp_path / "flight.mcap"
    write_flight(path)
    checked = validate_file(path)
    assert set(checked) == set(SCHEMAS) - S.LAB_SCHEMAS


def test_every_message_of_a_simulated_mission_validates(lab_log):
    path, _ = lab_log
    checked = validate_file(path)
    # only a dry run has a simulated world's truth, only a flight a radio
    assert set(checked) == set(SCHEMAS) - {"rpf_fly.TruthState", "rpf_fly.RadioLoad"} - S.LAB_SCHEMAS
    assert checked["rpf_fly.PlannerStep"] == 3 * checked["foxglove.FrameTransforms"]


def test_topic_schema_names_follow_the_contract():
    assert S.topic_schema("/mocap/cf1") == "foxglove.PoseInFrame"
    assert S.topic_schema("/cf1/setpoint") == "foxglove.PoseInFrame"
    assert S.topic_schema("/cf1/planner") == "rpf_fly.PlannerStep"
    assert S.topic_schema("/cf1/status") == "rpf_fly.DroneStatus"
    assert S.topic_schema("/scene") == "foxglove.SceneUpdate"
    assert S.topic_schema("/tf") == "foxglove.FrameTransforms"
    assert S.topic_schema("/events") == "foxglove.Log"
    assert S.topic_schema("/truth/cf1") == "rpf_fly.TruthState"
    with pytest.raises(KeyError):
        S.topic_schema("/elsewhere")


def test_builders_reject_what_the_schemas_forbid():
    planner = jsonschema.Draft7Validator(SCHEMAS["rpf_fly.PlannerStep"])
    step = M.planner_step(0, tick=0, position=(0, 0, 0), goal=(1, 0), mode=-1, eta=float("nan"))
    planner.validate(step)
    assert step["mode"] == "arrived" and step["eta"] is None and step["goal_distance"] == 1.0
    with pytest.raises(jsonschema.ValidationError):
        planner.validate({**step, "mode": "dancing"})
    with pytest.raises(jsonschema.ValidationError):
        planner.validate({k: v for k, v in step.items() if k != "lambda"})
    status = jsonschema.Draft7Validator(SCHEMAS["rpf_fly.DroneStatus"])
    with pytest.raises(jsonschema.ValidationError):
        status.validate(M.drone_status(0, "planning", link_quality=1.5))
    assert M.stamp(1_700_000_000_123_456_789) == {"sec": 1_700_000_000, "nsec": 123_456_789}


T = 1_700_000_000_123_456_789


@pytest.mark.parametrize(
    "position, quaternion",
    [
        ((0.1, 2.0, 0.6), (0.0, 0.0, 0.5, 0.8660254)),
        (np.array([1.0, 2.0, 3.0]), None),
        ((1, 2, 3), (0, 0, 0, 1)),
        (1 + 2j, None),
        ((1.0, 2.0), None),
        ((float("nan"), 0.0, 0.0), None),
        ((np.float32(0.1), 1.0, 1.0), None),
    ],
)
def test_fast_pose_encoder_equals_the_builder(position, quaternion):
    assert E.pose_json(T, position, quaternion) == E.encode(M.pose_in_frame(T, position, quaternion))


@pytest.mark.parametrize(
    "fields",
    [
        dict(
            tick=3,
            position=(0.1, 0.2, 0.6),
            goal=1 + 1j,
            mode=0,
            eta=0.05,
            lam=float("nan"),
            f_a=0.7 + 0.7j,
            f_r=(0.1, -0.2),
            f_in=np.complex128(0.3j),
            direction=1 + 0j,
            heading=0.1,
            neighbours=np.int64(2),
            obstacle_distance=None,
        ),
        dict(tick=0, position=(0, 0, 0), goal=(1, 0), mode="arrived"),
        {
            "tick": 0,
            "position": np.array([0.0, 1.0, 2.0]),
            "goal": np.array([1.0, 2.0]),
            "mode": np.int8(-1),
            "lambda": 2.0,
            "goal_distance": np.float64(3.0),
        },
        dict(tick=0, position=1 + 1j, goal=(1, 0), mode="hold"),
        dict(tick=0, position=(0, 0, 0), goal=(1, 0), mode="apf", obstacle_distance=float("inf")),
        dict(tick=5, position=(0.1, 0.2, 0.5), goal=(1, 0), mode="soft", direction=0.6 + 0.8j, reference=0.15 + 0.2j),
        dict(tick=5, position=(0.1, 0.2, 0.5), goal=(1, 0), mode="apf", reference=(np.float64(0.3), 0.1)),
    ],
)
def test_fast_planner_encoder_equals_the_builder(fields):
    assert E.planner_json(T, fields) == E.encode(M.planner_step(T, **fields))


def test_planner_reference_is_optional_exact_and_valid():
    """``reference`` (where the drone planned from, for rpf-fly replay) is written only when given, as the exact
    doubles, and validates against the schema either way."""
    validator = jsonschema.Draft7Validator(SCHEMAS["rpf_fly.PlannerStep"])
    without = json.loads(E.planner_json(T, dict(tick=0, position=(0, 0, 0.5), goal=(1, 0), mode="hold")))
    assert "reference" not in without
    validator.validate(without)
    ref = complex(0.1 + 0.2, -1 / 3)
    with_ref = json.loads(E.planner_json(T, dict(tick=1, position=(0, 0, 0.5), goal=(1, 0), mode="apf", reference=ref)))
    assert complex(with_ref["reference"]["x"], with_ref["reference"]["y"]) == ref
    validator.validate(with_ref)


@pytest.mark.parametrize(
    "state",
    [
        ((0.1, 2.0, 0.6), 0.5, True, False, (0.11, 2.0, 0.6)),
        ((np.float64(1.0), 2, 3), np.float32(0.25), np.bool_(False), 1, np.array([1.0, 2.0, 3.0])),
        ((float("nan"), 0.0, 0.0), float("inf"), False, True, (0.0, 0.0, 0.0)),
        ((1.0, 2.0), 0.0, True, False, 1 + 2j),
    ],
)
def test_fast_truth_encoder_equals_the_builder_and_validates(state):
    assert E.truth_json(T, *state) == E.encode(M.truth_state(T, *state))
    message = json.loads(E.truth_json(T, *state))
    if all(v is not None for v in (*message["position"].values(), message["yaw"])):
        jsonschema.Draft7Validator(SCHEMAS["rpf_fly.TruthState"]).validate(message)
    assert type(message["motors"]) is bool and type(message["crashed"]) is bool


def test_fast_encoders_raise_what_the_builders_raise():
    with pytest.raises(ValueError):
        E.planner_json(T, dict(tick=0, position=(0, 0, 0), goal=(1, 0), mode="dancing"))
    with pytest.raises(TypeError):
        E.planner_json(T, dict(tick=0, position=(0, 0, 0), goal=(1, 0), mode="apf", colour="red"))
    poses = {
        "cf1": ((1, 2, 3), None),
        "cf2": (np.array([1.0, 2.0, 3.0]), (0, 0, 0.1, 0.9)),
        'q"uote': ((0, 0, 0), None),
    }
    assert E.tf_json(T, poses) == E.encode(M.frame_transforms(T, poses))


def test_the_status_schema_names_every_drone_phase():
    from rpf_fly.flight.phases import DronePhase

    assert set(R.DRONE_STATES) == {p.value for p in DronePhase}
