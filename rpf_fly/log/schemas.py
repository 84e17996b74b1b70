"""The registry of the flight log's JSON Schemas: every schema by the name written into the file, the schema of each
topic, the channels' encodings; and the names docs/log-format.md documents under ``schemas``.

The schemas themselves are Foxglove's well-known ones (rpf_fly/log/foxglove_schemas.py) and our own
(rpf_fly/log/rpf_schemas.py); the builders of the messages are in rpf_fly/log/messages.py, their encoders in
rpf_fly/log/encoding.py, the metadata records in rpf_fly/log/metadata.py. See docs/log-format.md for what each
field means.
"""

from __future__ import annotations

import json
from typing import Any

from rpf_fly.log.encoding import encode, truth_json
from rpf_fly.log.foxglove_schemas import FRAME_TRANSFORMS, LOG, POSE_IN_FRAME, SCENE_UPDATE
from rpf_fly.log.messages import stamp, truth_state
from rpf_fly.log.metadata import mission_metadata, scenario_metadata
from rpf_fly.log.rpf_schemas import DRONE_STATUS, FIRMWARE_STATE, HOST_LAG, PLANNER_STEP, RADIO_LOAD, TRUTH_STATE

__all__ = [
    "SCHEMA_ENCODING",
    "MESSAGE_ENCODING",
    "SCHEMAS",
    "LAB_SCHEMAS",
    "schema_bytes",
    "topic_schema",
    # documented as ``schemas.<name>`` (docs/log-format.md)
    "encode",
    "truth_json",
    "truth_state",
    "mission_metadata",
    "scenario_metadata",
    # rpf_fly/flight/lab.py's ``S.stamp``
    "stamp",
]

SCHEMA_ENCODING = "jsonschema"
MESSAGE_ENCODING = "json"

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
