"""Flight logs read by Foxglove's own MCAP reader (@mcap/core, the TypeScript library the Foxglove app opens files
with) and checked against Foxglove's published message schemas (@foxglove/schemas): an independent reader of the
same bytes (tools/mcap_js/read.mjs, docs/log-format.md "Foxglove's own reader").

The Python side of each comparison is the mcap library that wrote the file, read record by record; both sides
digest every topic's messages the same way (log time, publish time, sequence and the sha256 of the bytes)."""

from __future__ import annotations

import fcntl
import hashlib
import json
import shutil
import subprocess
import tempfile
from pathlib import Path

import pytest
from mcap.records import Channel, Message, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import Writer

from rpf_fly.log.reader import read_log, salvage

# The CLI flights of tests/conftest.py fly once for the tests that share them (pyproject: --dist loadgroup).
pytestmark = pytest.mark.xdist_group("cli_flights")

ROOT = Path(__file__).resolve().parents[2]
JS = ROOT / "tools" / "mcap_js"


@pytest.fixture(scope="module")
def foxglove_reader() -> Path:
    """tools/mcap_js/read.mjs with its pinned packages installed (``npm ci`` from the committed lock file, once)."""
    node, npm = shutil.which("node"), shutil.which("npm")
    if node is None or npm is None:
        pytest.fail("Node.js and npm are needed to read the logs with Foxglove's reader (tools/mcap_js; Node 18+)")
    # The module's tests can run on both xdist workers at once (the CLI-flight fixtures set their own groups), so
    # the install is serialised with a lock and counted done only by a marker written after ``npm ci`` succeeded:
    # a package directory that exists is not one that is complete (without the marker a second worker can run the
    # reader while the first is still unpacking @mcap/core: ERR_MODULE_NOT_FOUND).
    lock_digest = hashlib.sha256((JS / "package-lock.json").read_bytes()).hexdigest()
    marker = JS / "node_modules" / ".rpf-installed"
    lock_path = Path(tempfile.gettempdir()) / f"rpf-mcap-js-{hashlib.sha256(bytes(JS)).hexdigest()[:16]}.lock"
    with lock_path.open("w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not marker.is_file() or marker.read_text() != lock_digest:
            done = subprocess.run(
                [npm, "ci", "--no-audit", "--no-fund", "--ignore-scripts"],
                cwd=JS,
                capture_output=True,
                text=True,
                timeout=600,
            )
            assert done.returncode == 0, f"npm ci in {JS} failed:\n{done.stdout}\n{done.stderr}"
            marker.write_text(lock_digest)
    return JS / "read.mjs"


def read_js(reader: Path, mode: str, log: Path) -> dict:
    done = subprocess.run(["node", str(reader), mode, str(log)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def read_py(log: Path) -> tuple[dict[str, dict], bool]:
    """Per topic the schema name, message count and digest of every message the mcap library reads in file order
    (up to a torn end), and whether the file was read to its footer."""
    schemas: dict[int, str] = {}
    channels: dict[int, str] = {}
    lines: dict[str, list[str]] = {}
    topics: dict[str, dict] = {}
    complete = False
    with log.open("rb") as f:
        try:
            for record in StreamReader(f, validate_crcs=True).records:
                if isinstance(record, Schema):
                    schemas[record.id] = record.name
                elif isinstance(record, Channel):
                    channels[record.id] = record.topic
                    topics.setdefault(record.topic, {"schema": schemas.get(record.schema_id, "")})
                    lines.setdefault(record.topic, [])
                elif isinstance(record, Message):
                    digest = hashlib.sha256(record.data).hexdigest()
                    lines[channels[record.channel_id]].append(
                        f"{record.log_time}:{record.publish_time}:{record.sequence}:{digest}"
                    )
            complete = True
        except Exception:  # noqa: BLE001 - a killed log's torn end (EndOfFile, struct.error, ...)
            complete = False
    for topic, found in lines.items():
        found.sort()
        topics[topic]["count"] = len(found)
        topics[topic]["digest"] = hashlib.sha256("\n".join(found).encode()).hexdigest()
    return topics, complete


def same_messages(js: dict, py: dict[str, dict]) -> None:
    assert set(js["topics"]) == set(py)
    for topic, ours in py.items():
        theirs = js["topics"][topic]
        assert (theirs["schema"], theirs["count"], theirs["digest"]) == (
            ours["schema"],
            ours["count"],
            ours["digest"],
        ), topic


def every_message_valid(js: dict) -> None:
    """Every message parses as JSON, every schema is valid JSON, and every message of a topic whose schema Foxglove
    publishes (foxglove.*) validates against Foxglove's own schema of that name."""
    for topic, t in js["topics"].items():
        assert t["message_encoding"] == "json" and t["schema_encoding"] == "jsonschema", topic
        assert t["schema_parses"], topic
        assert t["json_errors"] == 0, topic
        if t["schema"].startswith("foxglove."):
            assert t["foxglove_schema"], f"{topic}: {t['schema']} is not a schema Foxglove publishes"
            assert t["foxglove_errors"] == 0, t["first_foxglove_error"]


def test_foxglove_reads_a_finished_dry_run_log_message_for_message_as_we_do(foxglove_reader, clean_cli_flight):
    """The app's reader opens the finished log through its summary and chunk indexes (CRCs checked), finds every
    topic with the same schema, and every message with the same bytes and times; every foxglove.* message is valid
    by Foxglove's own schema (poses, transforms, the scene, the event log)."""
    js = read_js(foxglove_reader, "indexed", clean_cli_flight.log)
    assert js["complete"] and js["error"] is None, js["error"]
    py, complete = read_py(clean_cli_flight.log)
    assert complete
    same_messages(js, py)
    every_message_valid(js)
    assert js["statistics_message_count"] == sum(t["count"] for t in py.values())
    assert set(js["metadata"]) >= {"mission"}
    kinds = {t["schema"] for t in js["topics"].values()}
    assert {
        "foxglove.PoseInFrame",
        "foxglove.FrameTransforms",
        "foxglove.SceneUpdate",
        "foxglove.Log",
        "rpf_fly.TruthState",
    } <= kinds
    assert js["topics"]["/events"]["count"] > 0 and js["topics"]["/truth/cf1"]["count"] > 0


def test_foxglove_reads_a_killed_flights_log_unindexed_and_its_salvage_indexed(
    foxglove_reader, killed_cli_flight, tmp_path
):
    """A SIGKILL leaves no summary or footer: the app's indexed reader refuses the file, its stream reader (what the
    app falls back to for an unindexed file) reads every message of every complete chunk, the same ones as ours;
    the salvaged copy opens indexed with exactly those messages."""
    log = killed_cli_flight.log
    indexed = read_js(foxglove_reader, "indexed", log)
    assert not indexed["complete"] and indexed["error"]
    stream = read_js(foxglove_reader, "stream", log)
    assert not stream["complete"]
    py, complete = read_py(log)
    assert not complete
    same_messages(stream, py)
    every_message_valid(stream)
    ours = read_log(log)
    assert ours.truncated and sum(stream["topics"][t]["count"] for t in stream["topics"]) == sum(ours.counts.values())
    assert stream["topics"]["/truth/cf1"]["count"] > 0

    copy = tmp_path / "salvaged.mcap"
    salvage(log, copy)
    finished = read_js(foxglove_reader, "indexed", copy)
    assert finished["complete"] and finished["error"] is None, finished["error"]
    for topic, t in stream["topics"].items():
        assert (finished["topics"][topic]["count"], finished["topics"][topic]["digest"]) == (t["count"], t["digest"])


def test_foxglove_reader_flags_a_message_its_schema_refuses_and_text_that_is_not_json(foxglove_reader, tmp_path):
    """The check can fail: a foxglove.PoseInFrame whose nanoseconds exceed a second and a message that is not JSON
    are both counted (and a valid one beside them is not)."""
    from rpf_fly.log.schemas import SCHEMAS

    path = tmp_path / "bad.mcap"
    with path.open("wb") as f:
        writer = Writer(f)
        writer.start(library="test")
        schema = writer.register_schema(
            "foxglove.PoseInFrame", "jsonschema", json.dumps(SCHEMAS["foxglove.PoseInFrame"]).encode()
        )
        channel = writer.register_channel("/mocap/cf1", "json", schema)
        pose = {"position": {"x": 0.0, "y": 0.0, "z": 0.0}, "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}}
        for k, (sec, nsec) in enumerate([(1, 5), (1, 1_500_000_000)]):
            message = {"timestamp": {"sec": sec, "nsec": nsec}, "frame_id": "world", "pose": pose}
            writer.add_message(channel, k, json.dumps(message).encode(), k)
        writer.add_message(channel, 2, b"{not json", 2)
        writer.finish()
    js = read_js(foxglove_reader, "indexed", path)
    topic = js["topics"]["/mocap/cf1"]
    assert topic["count"] == 3 and topic["json_errors"] == 1 and topic["foxglove_errors"] == 1
    assert "nsec" in topic["first_foxglove_error"]
