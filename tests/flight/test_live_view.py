"""``rpf-fly fly --dry-run --foxglove``: real WebSocket clients against the real foxglove-sdk server, a real dry run.

A client that reads subscribes to every channel the server advertises and must receive every topic of the log,
each message decoding to the JSON the log holds at the same log time (one source of truth). A second client that
subscribes and then stops reading must not slow anyone: the flight succeeds, the log drops nothing, the reading
client still gets its messages. (A short flight's few MB fit in the kernel's socket buffers, so the server's own
outbox for the stalled client may not fill here; tests/log/test_live.py drives it to that point and counts it.)
"""

from __future__ import annotations

import asyncio
import json
import os
import socket
import struct
import subprocess
import sys
import time
from pathlib import Path

import pytest
from flight_harness import SHORT_MISSION

from rpf_fly.log import schemas as S
from rpf_fly.log.reader import read_log


def _require(module: str) -> None:
    """The live extra is part of the test install (README, .ci/run): its absence fails, it never skips."""
    try:
        __import__(module)
    except ImportError as err:
        pytest.fail(
            f"{module} is missing: the tests need the live extra: pip install -e '.[dev,live]' ({err})", pytrace=False
        )


_require("foxglove")
_require("websockets")
import websockets  # noqa: E402

DRONES = ("cf1", "cf2", "cf3")
EXPECTED_TOPICS = {"/scene", "/tf", "/events", "/radio/0"} | {
    topic for d in DRONES for topic in (f"/mocap/{d}", f"/{d}/setpoint", f"/{d}/planner", f"/{d}/status", f"/truth/{d}")
}
SUBPROTOCOL = "foxglove.sdk.v1"  # what foxglove-sdk 0.30 accepts (rust/foxglove/src/websocket/handshake.rs)
MESSAGE_DATA = 0x01  # binary opcode: u32 subscription id, u64 log time, payload (little endian)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


async def connect(port: int, deadline: float, *, slow: bool = False) -> websockets.ClientConnection:
    """Connect as soon as the server listens. ``slow``: a tiny receive buffer and a one-message queue, so a client
    that stops reading stalls its TCP window quickly and the server's outbox for it fills."""
    while True:
        sock = socket.socket()
        if slow:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 2048)
        try:
            sock.connect(("127.0.0.1", port))
            return await websockets.connect(
                f"ws://127.0.0.1:{port}",
                sock=sock,
                subprotocols=[SUBPROTOCOL],
                max_size=None,
                max_queue=1 if slow else 1024,
            )
        except OSError:
            sock.close()
            if time.monotonic() > deadline:
                raise
            await asyncio.sleep(0.1)


async def subscribe_new(ws: websockets.ClientConnection, text: str, channels: dict[int, dict]) -> None:
    """On an ``advertise``, subscribe to each new channel (subscription id = channel id)."""
    message = json.loads(text)
    if message.get("op") != "advertise":
        return
    fresh = [c for c in message["channels"] if c["id"] not in channels]
    channels.update({c["id"]: c for c in fresh})
    if fresh:
        await ws.send(
            json.dumps({"op": "subscribe", "subscriptions": [{"id": c["id"], "channelId": c["id"]} for c in fresh]})
        )


async def reader(port: int, deadline: float) -> tuple[dict[int, dict], list[tuple[str, int, bytes]]]:
    """The client that keeps up: every channel, every message, until the server closes (the flight ended)."""
    ws = await connect(port, deadline)
    assert ws.subprotocol == SUBPROTOCOL
    channels: dict[int, dict] = {}
    received: list[tuple[int, int, bytes]] = []
    try:
        async for frame in ws:
            if isinstance(frame, str):
                await subscribe_new(ws, frame, channels)
            elif frame[0] == MESSAGE_DATA:
                subscription, log_time = struct.unpack_from("<IQ", frame, 1)
                received.append((subscription, log_time, bytes(frame[13:])))
    except websockets.ConnectionClosed:
        pass
    return channels, [(channels[s]["topic"], t, payload) for s, t, payload in received]


async def stalled(port: int, deadline: float, done: asyncio.Event) -> int:
    """The client that subscribes to the high-rate topics and then never reads again."""
    ws = await connect(port, deadline, slow=True)
    channels: dict[int, dict] = {}
    while not {"/mocap/cf1", "/truth/cf1", "/tf"} <= {c["topic"] for c in channels.values()}:
        frame = await asyncio.wait_for(ws.recv(), timeout=max(1.0, deadline - time.monotonic()))
        if isinstance(frame, str):
            await subscribe_new(ws, frame, channels)
    await done.wait()
    ws.transport.abort()  # noqa: SLF001 - leave without a handshake: its queue is full
    return len(channels)


async def watch(port: int, timeout_s: float = 90.0) -> tuple[dict[int, dict], list[tuple[str, int, bytes]], int]:
    deadline = time.monotonic() + timeout_s
    done = asyncio.Event()
    slow = asyncio.ensure_future(stalled(port, deadline, done))
    try:
        channels, received = await asyncio.wait_for(reader(port, deadline), timeout=timeout_s)
    finally:
        done.set()
    return channels, received, await slow


def test_a_live_client_receives_every_topic_as_the_log_has_it_and_a_stalled_one_slows_nothing(tmp_path: Path):
    mission = tmp_path / "short.yaml"
    mission.write_text(SHORT_MISSION)
    log_path = tmp_path / "flight.mcap"
    port = free_port()
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "rpf_fly",
            "fly",
            str(mission),
            "--dry-run",
            "--no-console",
            "--log",
            str(log_path),
            "--foxglove",
            "--foxglove-port",
            str(port),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=tmp_path,
        env=dict(os.environ, PYTHONUNBUFFERED="1"),
    )
    try:
        channels, received, stalled_subscriptions = asyncio.run(watch(port))
        out, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 0, out + err
    assert f"live: serving the flight on ws://localhost:{port}" in err
    log = read_log(log_path)
    assert not log.truncated

    # Every channel carries the log's schema and encoding; every topic of the log came through live.
    for channel in channels.values():
        topic = channel["topic"]
        assert channel["schemaName"] == log.schemas[topic] == S.topic_schema(topic)
        assert (channel["encoding"], channel["schemaEncoding"]) == (S.MESSAGE_ENCODING, S.SCHEMA_ENCODING)
        assert json.loads(channel["schema"]) == S.SCHEMAS[log.schemas[topic]]
    topics = {topic for topic, _, _ in received}
    advertised = {c["topic"]: c["id"] for c in channels.values()}
    missing = {
        t: (f"channel {advertised[t]}" if t in advertised else "never advertised", len(log.messages(t)))
        for t in set(log.topics) - topics
    }
    assert topics == EXPECTED_TOPICS == set(log.topics), (
        f"not received live (how advertised, messages logged): {missing}; channels {sorted(advertised)}"
    )
    assert set(advertised) == EXPECTED_TOPICS  # every channel advertised from the start, none the log lacks

    # One source of truth: each live message is the log's message of that topic at that log time.
    by_time: dict[tuple[str, int], list] = {}
    for topic in topics:
        for m in log.messages(topic):
            by_time.setdefault((topic, m.log_time), []).append(m.data)
    unmatched = [(topic, t) for topic, t, payload in received if json.loads(payload) not in by_time.get((topic, t), [])]
    assert not unmatched, unmatched[:5]
    scene = [json.loads(p) for topic, _, p in received if topic == "/scene"]
    assert scene and scene[0] == log.messages("/scene")[0].data  # sent again when the client subscribed

    # The reader kept up although the other client stalled: it missed nothing after it subscribed, beyond the
    # first messages of each channel (published before its subscription reached the server).
    for topic in ("/mocap/cf1", "/truth/cf1", "/cf1/setpoint"):
        live_times = [t for name, t, _ in received if name == topic]
        logged = [m.log_time for m in log.messages(topic) if m.log_time >= live_times[0]]
        assert len(live_times) >= 0.95 * len(logged), (topic, len(live_times), len(logged))

    # The stalled client cost the flight nothing: no message dropped by the log, every drone reached its goal.
    assert stalled_subscriptions >= 3
    assert "messages dropped" not in " ".join(m.data["message"] for m in log.messages("/events"))
    for name in DRONES:
        sequences = [m.sequence for m in log.messages(f"/mocap/{name}")]
        assert sequences == list(range(len(sequences)))
        assert f"{name}: reached" in out
    assert f"messages served at ws://localhost:{port}" in out
