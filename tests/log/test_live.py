"""The live view's parts: the log's sink sees the file's bytes; a failing sink costs the log nothing; without
foxglove-sdk the CLI refuses in one line naming the extra; and, against the real foxglove-sdk server with real
WebSocket clients, a stalled client never blocks a publish and is counted, and a late client still gets the scene."""

from __future__ import annotations

import asyncio
import json
import socket
import struct
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import pytest
from mcap.reader import make_reader

from rpf_fly.log import messages as M
from rpf_fly.log.reader import read_log
from rpf_fly.log.writer import FlightLog

T0 = 1_700_000_000_000_000_000
MS = 1_000_000
MISSION = {"name": "unit", "yaml": "name: unit\n", "seed": 3}
SCENARIO = {"json": '{"names": ["cf1", "cf2"]}'}
ROOT = Path(__file__).resolve().parents[2]


def small_flight(log: FlightLog, ticks: int = 40) -> None:
    log.scene(
        T0,
        [{"shape": "circle", "center": [0, 0], "radius": 0.1}],
        {"cf1": (1.0, 1.0)},
        {"x": [-2, 2], "y": [-2, 2], "z": [0, 1.5]},
        0.6,
    )
    log.event(T0, 2, "takeoff")
    for k in range(ticks):
        t = T0 + k * 10 * MS
        log.poses(t, {d: ((0.01 * k, float(i), 0.6), None) for i, d in enumerate(("cf1", "cf2"))})
        log.setpoints([(d, t, (0.01 * k + 0.05, float(i), 0.6), 0.0) for i, d in enumerate(("cf1", "cf2"))])
        log.status("cf1", t, state="planning", battery_v=3.9, link_quality=0.98, latency_ms=4.0)
        log.tf(t, {"cf1": ((0.01 * k, 0.0, 0.6), None)})
        log.truth(t, {"cf1": ((0.01 * k, 0.0, 0.6), 0.1, True, False, (0.01 * k, 0.01, 0.6))})
    log.event(T0 + ticks * 10 * MS, 3, "landing early")


def test_the_sink_sees_every_written_message_with_the_files_bytes_and_log_time(tmp_path: Path):
    seen: list[tuple[str, int, bytes]] = []
    path = tmp_path / "flight.mcap"
    with FlightLog(path, MISSION, SCENARIO, sink=lambda topic, t, data: seen.append((topic, t, data))) as log:
        small_flight(log)
    with open(path, "rb") as f:
        written = [
            (channel.topic, message.log_time, message.data)
            for _, channel, message in make_reader(f).iter_messages(log_time_order=False)
        ]
    assert len(written) == log.written == 40 * 7 + 3
    assert seen == written  # same order, topics, log times and bytes: the file is the one source


def test_a_failing_sink_costs_the_log_nothing(tmp_path: Path):
    def broken(topic: str, t: int, data: bytes) -> None:
        raise RuntimeError("client gone")

    path = tmp_path / "flight.mcap"
    with FlightLog(path, MISSION, SCENARIO, sink=broken) as log:
        small_flight(log)
    data = read_log(path)
    assert not data.truncated and data.message_count == log.written == log.sink_failed == 40 * 7 + 3
    assert log.dropped == 0 and log.error is None


@pytest.fixture
def no_sdk(monkeypatch: pytest.MonkeyPatch) -> None:
    """As if foxglove-sdk were not installed (an entry of None in sys.modules makes the import fail)."""
    monkeypatch.setitem(sys.modules, "foxglove", None)
    monkeypatch.setitem(sys.modules, "foxglove.websocket", None)


def test_without_the_sdk_the_live_view_names_the_extra(no_sdk: None):
    from rpf_fly.log.live import INSTALL_HINT, LiveUnavailable, LiveView

    with pytest.raises(LiveUnavailable, match="foxglove-sdk") as err:
        LiveView(0)
    assert INSTALL_HINT in str(err.value) and INSTALL_HINT == "pip install 'rpf_fly[live]'"


def test_fly_foxglove_without_the_sdk_refuses_in_one_line_before_anything_flies(no_sdk: None, tmp_path: Path):
    from typer.testing import CliRunner

    from rpf_fly.cli import get_app

    log = tmp_path / "flight.mcap"
    result = CliRunner().invoke(
        get_app(),
        ["fly", str(ROOT / "missions" / "lab-3.yaml"), "--dry-run", "--no-console", "--log", str(log), "--foxglove"],
    )
    assert result.exit_code == 2
    assert result.output.strip().splitlines() == [
        "--foxglove: the live view needs foxglove-sdk, which is not installed: pip install 'rpf_fly[live]'"
    ]
    assert not log.exists()  # refused before the log was opened, let alone a drone connected


# ---------------------------------------------------------------- against the real server (the live extra)


def _require(module: str) -> None:
    """The live extra is part of the test install (README, .ci/run): its absence fails, it never skips."""
    try:
        __import__(module)
    except ImportError as err:
        pytest.fail(
            f"{module} is missing: the tests need the live extra: pip install -e '.[dev,live]' ({err})", pytrace=False
        )


@pytest.fixture
def sdk() -> None:
    _require("foxglove")
    _require("websockets")


async def _connect(port: int, *, stalled: bool = False):  # type: ignore[no-untyped-def]
    import websockets

    sock = socket.socket()
    if stalled:  # a tiny window and a one-message queue: once it stops reading, the server's sends back up
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 2048)
    sock.connect(("127.0.0.1", port))
    return await websockets.connect(
        f"ws://127.0.0.1:{port}",
        sock=sock,
        subprotocols=["foxglove.sdk.v1"],
        max_size=None,
        max_queue=1 if stalled else 4096,
    )


async def _subscribe_all(ws, topics: set[str]) -> dict[int, str]:  # type: ignore[no-untyped-def]
    """Read advertisements until ``topics`` are advertised, subscribing to each channel (id = channel id)."""
    channels: dict[int, str] = {}
    while not topics <= set(channels.values()):
        message = json.loads(await asyncio.wait_for(ws.recv(), 10))
        if message["op"] == "advertise":
            channels.update({c["id"]: c["topic"] for c in message["channels"]})
            await ws.send(
                json.dumps(
                    {
                        "op": "subscribe",
                        "subscriptions": [{"id": c["id"], "channelId": c["id"]} for c in message["channels"]],
                    }
                )
            )
    return channels


SUBSCRIBE_UNKNOWN = """
import asyncio, json, logging, sys
from rpf_fly.log.live import LiveView

if sys.argv[1] == "routed":  # as rpf-fly fly does (log/text_log.py): a handler on the root logger
    handler = logging.StreamHandler(sys.stdout)
    handler.setFormatter(logging.Formatter("%(levelname)s %(name)s: %(message)s"))
    logging.getLogger().addHandler(handler)
    logging.getLogger().setLevel(logging.INFO)
with LiveView(0) as view:
    async def main():
        import websockets
        async with websockets.connect(f"ws://127.0.0.1:{view.port}", subprotocols=["foxglove.sdk.v1"]) as ws:
            await ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": 4242}]}))
            await asyncio.sleep(0.5)
    asyncio.run(main())
"""


def test_the_sdks_log_records_reach_the_applications_handlers_never_stderr_by_themselves(sdk: None):
    """A client subscribing to a channel id that does not exist makes foxglove-sdk log an error: with no handler
    configured it stays off stderr (not Python's last resort, which printed it on a flight's console); with a handler
    on the root logger (``rpf-fly fly``'s text log) it arrives there, named and levelled."""

    def run(mode: str) -> subprocess.CompletedProcess:
        proc = subprocess.run(
            [sys.executable, "-c", SUBSCRIBE_UNKNOWN, mode], capture_output=True, text=True, timeout=60, cwd=ROOT
        )
        assert proc.returncode == 0, proc.stderr
        return proc

    alone = run("alone")
    assert alone.stderr == "" and alone.stdout == ""
    routed = run("routed")
    assert routed.stderr == ""
    assert "ERROR foxglove.websocket.connected_client: Client 127.0.0.1:" in routed.stdout
    assert "attempted to subscribe to unknown channel: 4242" in routed.stdout


def test_a_stalled_client_never_blocks_a_publish_and_its_drops_are_counted(sdk: None):
    from rpf_fly.log.live import LiveView

    payload = json.dumps({"pad": "x" * 200}).encode()
    n = 20_000  # 4.6 MB: more than the kernel's socket buffers take for a client that reads nothing

    async def scenario(live: LiveView) -> tuple[float, list[int]]:
        live.publish("/mocap/cf1", T0, payload)  # the channel exists: the clients can subscribe
        stalled, reader = await _connect(live.port, stalled=True), await _connect(live.port)
        await _subscribe_all(stalled, {"/mocap/cf1"})
        await _subscribe_all(reader, {"/mocap/cf1"})
        await asyncio.sleep(0.2)
        received: list[int] = []

        async def read() -> None:
            async for frame in reader:
                if isinstance(frame, bytes) and frame[0] == 1:
                    received.append(struct.unpack_from("<IQ", frame, 1)[1])
                    if received[-1] == T0 + n:
                        return

        task = asyncio.ensure_future(read())
        slowest = 0.0
        for k in range(1, n + 1):
            t0 = time.perf_counter()
            live.publish("/mocap/cf1", T0 + k, payload)
            slowest = max(slowest, time.perf_counter() - t0)
            if k % 200 == 0:
                await asyncio.sleep(0.002)  # the reader runs on this event loop
        await asyncio.wait_for(task, 20)
        stalled.transport.abort()
        await reader.close()
        return slowest, received

    with LiveView(0) as live:
        slowest, received = asyncio.run(scenario(live))
        deadline = time.monotonic() + 2
        while not live.slow_client_reports and time.monotonic() < deadline:  # the report comes from the SDK's thread
            time.sleep(0.05)
        assert live.slow_client_reports >= 1, "the server never reported the stalled client's full outbox"
        assert live.published == n + 1 and live.failed == 0
        assert "a client read too slowly and lost messages" in live.summary()
    assert slowest < 0.25  # a publish never waited for the stalled client (each takes microseconds; a busy CI)
    assert received[-1] == T0 + n and len(received) >= 0.9 * n  # the reading client kept up and got the last one


def test_a_client_that_subscribes_late_still_gets_the_scene(sdk: None, tmp_path: Path):
    from rpf_fly.log.live import LiveView

    async def scenario(live: LiveView, log: FlightLog) -> list[tuple[str, int, bytes]]:
        log.scene(T0, [], {"cf1": (1.0, 1.0)}, {"x": [-2, 2], "y": [-2, 2], "z": [0, 1.5]}, 0.6)
        log.tf(T0, {"cf1": ((0.0, 0.0, 0.6), None)})
        log.drain_soon()
        while "/tf" not in live._channels:  # noqa: SLF001 - both published, nobody listening yet
            await asyncio.sleep(0.01)
        ws = await _connect(live.port)
        channels = await _subscribe_all(ws, {"/scene", "/tf"})
        await asyncio.sleep(0.2)  # the subscription reaches the server
        got: list[tuple[str, int, bytes]] = []
        for k in range(1, 30):  # the flight goes on: the next publish sends the scene again
            log.tf(T0 + k * MS, {"cf1": ((0.0, 0.0, 0.6), None)})
            log.drain_soon()
            try:
                frame = await asyncio.wait_for(ws.recv(), 0.2)
            except asyncio.TimeoutError:
                continue
            if isinstance(frame, bytes):
                sub, t = struct.unpack_from("<IQ", frame, 1)
                got.append((channels[sub], t, bytes(frame[13:])))
                if any(topic == "/scene" for topic, _, _ in got):
                    break
        await ws.close()
        return got

    path = tmp_path / "flight.mcap"
    with LiveView(0) as live, FlightLog(path, MISSION, SCENARIO, sink=live.publish) as log:
        got = asyncio.run(scenario(live, log))
    scene = [(t, data) for topic, t, data in got if topic == "/scene"]
    with open(path, "rb") as f:
        logged = [(m.log_time, m.data) for _, _, m in make_reader(f).iter_messages(topics=["/scene"])]
    assert scene == logged  # once, with the file's log time and bytes
    assert (
        json.loads(scene[0][1])["entities"]
        == M.scene_update(T0, goals={"cf1": (1.0, 1.0)}, arena={"x": [-2, 2], "y": [-2, 2], "z": [0, 1.5]}, height=0.6)[
            "entities"
        ]
    )


def test_a_subscription_before_the_scene_still_gets_it_three_times_apart(
    sdk: None, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The server may tell of a subscription before the topic's first message (a client connected at the start):
    the sends it asks for start from that message and keep their spacing, not all at once (a client whose
    subscription the server had not taken yet would miss every copy)."""
    import rpf_fly.log.live as live_module
    from rpf_fly.log.live import RESEND_AFTER_S, LiveView

    clock = [100.0]
    monkeypatch.setattr(live_module, "time", SimpleNamespace(monotonic=lambda: clock[0]))
    sent: list[float] = []

    class Recorder:
        def log(self, data: bytes, log_time: int) -> None:
            sent.append(clock[0])

    with LiveView(0) as live:
        live.prepare(["/scene", "/tf"])
        live._channels["/scene"] = Recorder()  # noqa: SLF001 - count the scene's sends on the fake clock
        live._subscribed("/scene")  # noqa: SLF001 - as the SDK's thread calls it
        clock[0] += 5.0  # the flight's first scene comes later
        live.publish("/scene", T0, b"{}")
        assert sent == [105.0, 105.0]  # the copy for the subscription, then the message itself
        for _ in range(40):  # the flight goes on: 0.1 s a message
            clock[0] += 0.1
            live.publish("/tf", T0, b"{}")
    after = [t - 105.0 for t in sent[2:]]  # each at the first message at or after its time
    assert len(after) == len(RESEND_AFTER_S), after
    assert all(a - 1e-9 <= t <= a + 0.1 + 1e-9 for t, a in zip(after, RESEND_AFTER_S, strict=True)), after


def test_a_port_already_taken_refuses_in_one_line(sdk: None, tmp_path: Path):
    from typer.testing import CliRunner

    from rpf_fly.cli import get_app
    from rpf_fly.log.live import LiveView

    with LiveView(0) as taken:
        result = CliRunner().invoke(
            get_app(),
            [
                "fly",
                str(ROOT / "missions" / "lab-3.yaml"),
                "--dry-run",
                "--no-console",
                "--log",
                str(tmp_path / "f.mcap"),
                "--foxglove-port",
                str(taken.port),
            ],
        )
    assert result.exit_code == 2
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"--foxglove: cannot serve the live view on 127.0.0.1:{taken.port}")
