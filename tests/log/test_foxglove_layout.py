"""docs/foxglove-layout.json: what tools/make_foxglove_layout.py writes, a well-formed layout of the app's export
format, and every topic and message path it names is one the flight log writes (so a renamed topic breaks here, not
silently in the app)."""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

from rpf_fly.log import schemas as S
from rpf_fly.log.messages import WORLD_FRAME
from rpf_fly.log.reader import read_log

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tools"))
import make_foxglove_layout as M  # noqa: E402

SHIPPED = ROOT / "docs" / "foxglove-layout.json"


def shipped() -> dict:
    return json.loads(SHIPPED.read_text())


def leaves(node: object) -> list[str]:
    if isinstance(node, str):
        return [node]
    assert isinstance(node, dict) and node["direction"] in ("row", "column"), node
    return leaves(node["first"]) + leaves(node["second"])


def field(data: object, path: str) -> object:
    for part in path.split("."):
        assert isinstance(data, dict) and part in data, (path, part)
        data = data[part]
    return data


def test_the_shipped_layout_is_what_the_script_writes():
    assert SHIPPED.read_text() == M.text()


def test_the_layout_has_the_panels_the_flight_needs_and_its_tree_names_each_once():
    layout = shipped()
    panels = leaves(layout["layout"])
    assert sorted(panels) == sorted(layout["configById"]) and len(set(panels)) == len(panels)
    assert sorted(p.split("!")[0] for p in panels) == ["3D", "Plot", "Plot", "RosOut"]  # RosOut: the Log panel
    assert layout["configById"]["RosOut!rpf-events"]["topicToRender"] == "/events"
    three_d = layout["configById"]["3D!rpf-scene"]
    assert three_d["followTf"] == WORLD_FRAME and three_d["topics"]["/scene"]["visible"]
    assert all(three_d["topics"][f"/cf{i}/setpoint"]["visible"] for i in range(1, 11))


def test_every_topic_and_path_of_the_layout_is_one_the_log_writes(lab_log):
    log = read_log(lab_log[0])  # lab-3: cf1..cf3 flown in simulation, every topic but /truth
    layout = shipped()
    three_d = layout["configById"]["3D!rpf-scene"]
    expected_schema = {"/scene": "foxglove.SceneUpdate", "/events": "foxglove.Log", "/tf": "foxglove.FrameTransforms"}
    named = set(three_d["topics"]) | {layout["configById"]["RosOut!rpf-events"]["topicToRender"]}
    script = layout["userNodes"]["rpf-separation"]["sourceCode"]
    inputs = json.loads(re.search(r"export const inputs = (\[.*?\]);", script).group(1))
    output = re.search(r'export const output = "([^"]+)";', script).group(1)
    assert inputs == ["/tf"] and output == M.SEPARATION_TOPIC
    named |= set(inputs)
    for panel in ("Plot!rpf-separation", "Plot!rpf-altitude"):
        for path in layout["configById"][panel]["paths"]:
            value = path["value"]
            if re.fullmatch(r"[0-9.]+", value):  # a reference line: 2r
                assert float(value) == 2 * 0.1
                continue
            topic, _, member = value.partition(".")
            if topic == output:  # the user script's output: a field of its Output type
                assert re.search(rf"\b{member}: number;", script), member
                continue
            named.add(topic)
            if topic in log.topics:
                field(log.messages(topic)[0].data, member)  # e.g. /mocap/cf1 .pose.position.z
    for topic in named:
        schema = S.topic_schema(topic)
        assert schema == expected_schema.get(topic, "foxglove.PoseInFrame"), topic
        if re.search(r"cf[123]\b", topic) or not re.search(r"cf\d", topic):
            assert topic in log.topics and log.schemas[topic] == schema, topic
