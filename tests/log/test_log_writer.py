"""FlightLog writes a valid, finished MCAP file: mcap's seeking reader agrees on every count and time; several
threads may log at once; the bounded queue drops (and says so) instead of blocking; close is idempotent."""

from __future__ import annotations

import threading
import time

import pytest
from mcap.reader import make_reader

from rpf_fly.log.reader import read_log
from rpf_fly.log.writer import FlightLog

T0 = 1_700_000_000_000_000_000
MS = 1_000_000
MISSION = {"name": "unit", "yaml": "name: unit\n", "seed": 3}
SCENARIO = {"json": '{"names": ["cf1", "cf2"]}'}


def write_flight(path, drones=("cf1", "cf2"), ticks=50):  # type: ignore[no-untyped-def]
    """A small flight on every topic, with log time = publish time (clock=None)."""
    with FlightLog(path, MISSION, SCENARIO, clock=None) as log:
        log.scene(
            T0,
            [{"shape": "circle", "center": [0, 0], "radius": 0.1}, {"shape": "box", "min": [1, 1], "max": [1.5, 2]}],
            {d: (1.0, 1.0) for d in drones},
            {"x": [-2, 2], "y": [-2, 2], "z": [0, 1.5]},
            0.6,
        )
        log.event(T0, 2, "takeoff", file="flight.py", line=12)
        for k in range(ticks):
            t = T0 + k * 10 * MS
            for i, d in enumerate(drones):
                log.pose(d, t, (0.01 * k, float(i), 0.6), (0.0, 0.0, 0.0, 1.0))
                log.setpoint(d, t, (0.01 * k + 0.05, float(i), 0.6), 0.25)
                log.planner_step(
                    d,
                    t,
                    tick=k,
                    position=(0.01 * k, float(i), 0.6),
                    goal=1 + 1j,
                    mode="apf",
                    eta=0.05,
                    lam=2.0,
                    f_a=0.7 + 0.7j,
                    f_r=-0.1j,
                    f_in=0j,
                    direction=1 + 0j,
                    heading=0.0,
                    neighbours=1,
                    obstacle_distance=0.4,
                )
                if k % 10 == 0:
                    log.status(d, t, state="planning", battery_v=3.9, link_quality=0.98, latency_ms=4.0)
            log.tf(t, {d: ((0.01 * k, float(i), 0.6), None) for i, d in enumerate(drones)})
            log.truth(
                t,
                {
                    d: ((0.01 * k, float(i), 0.6), 0.1, True, False, (0.01 * k, float(i) + 0.01, 0.6))
                    for i, d in enumerate(drones)
                },
            )
            if k % 25 == 24:
                log.radio(
                    t,
                    0,
                    drones=list(drones),
                    window_s=0.25,
                    packets=25.0 * len(drones),
                    transactions=60.0 * len(drones),
                    planned_per_s=100.0 * len(drones),
                    budget_per_s=1000.0,
                )
        log.event(T0 + ticks * 10 * MS, 3, "landing early")
    return log


def test_seeking_reader_reads_the_summary(tmp_path):
    path = tmp_path / "flight.mcap"
    log = write_flight(path)
    assert log.dropped == 0 and log.failed == 0 and log.error is None
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        stats = summary.statistics
        counts = {summary.channels[c].topic: n for c, n in stats.channel_message_counts.items()}
        assert counts == {
            "/scene": 1,
            "/events": 2,
            "/tf": 50,
            **{f"/mocap/{d}": 50 for d in ("cf1", "cf2")},
            **{f"/{d}/setpoint": 50 for d in ("cf1", "cf2")},
            **{f"/{d}/planner": 50 for d in ("cf1", "cf2")},
            **{f"/{d}/status": 5 for d in ("cf1", "cf2")},
            **{f"/truth/{d}": 50 for d in ("cf1", "cf2")},
            "/radio/0": 2,
        }
        assert stats.message_count == sum(counts.values()) == log.written
        assert stats.message_start_time == T0 and stats.message_end_time == T0 + 500 * MS
        assert stats.chunk_count >= 1
        schemas = {summary.schemas[c.schema_id].name for c in summary.channels.values()}
        assert schemas == {
            "foxglove.PoseInFrame",
            "foxglove.SceneUpdate",
            "foxglove.FrameTransforms",
            "foxglove.Log",
            "rpf_fly.PlannerStep",
            "rpf_fly.DroneStatus",
            "rpf_fly.TruthState",
            "rpf_fly.RadioLoad",
        }
        assert all(s.encoding == "jsonschema" for s in summary.schemas.values())
        assert all(c.message_encoding == "json" for c in summary.channels.values())
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
        assert metadata["mission"] == {"name": "unit", "yaml": "name: unit\n", "seed": "3"}
        assert metadata["scenario"] == SCENARIO
        seqs = [m.sequence for _, c, m in reader.iter_messages(topics=["/mocap/cf1"])]
        assert seqs == list(range(50))
        publish = [m.publish_time for _, c, m in reader.iter_messages(topics=["/cf2/planner"])]
        assert publish == [T0 + k * 10 * MS for k in range(50)]

    data = read_log(path)
    assert not data.truncated and data.counts == counts
    step = data.messages("/cf1/planner")[3].data
    assert (
        step["tick"] == 3 and step["mode"] == "apf" and step["lambda"] == 2.0 and step["f_r"] == {"x": 0.0, "y": -0.1}
    )
    assert data.messages("/cf1/setpoint")[0].data["pose"]["orientation"]["z"] == pytest.approx(0.12467473)


def test_default_clock_records_log_time_at_the_call(tmp_path):
    path = tmp_path / "clock.mcap"
    before = time.time_ns()
    with FlightLog(path, MISSION, SCENARIO) as log:
        log.pose("cf1", T0, (0, 0, 0))
    after = time.time_ns()
    (msg,) = read_log(path).messages("/mocap/cf1")
    assert msg.publish_time == T0 and before <= msg.log_time <= after


def test_truth_is_one_entry_per_sample_with_the_sample_time_as_log_time(tmp_path):
    """/truth arrives in batches (a dry run fetches the world's samples every 0.1 s): its log time is the world's
    sample time, not the clock at the call, so the review sees its real rate and no false gaps."""
    path = tmp_path / "truth.mcap"
    gate = Gate()
    with FlightLog(path, MISSION, SCENARIO) as log:
        log.pose("cf0", T0, gate)
        assert gate.entered.wait(5)  # the writer is held inside that message: the queue holds what follows
        for k in range(10):
            log.truth(
                T0 + k * 10 * MS,
                {
                    "cf1": ((0.1 * k, 0.0, 0.5), 0.0, True, False, (0.1 * k, 0.0, 0.5)),
                    "cf2": ((1.0, 0.0, 0.0), -1.5, False, True, (1.0, 0.02, 0.0)),
                },
            )
        assert len(log._queue) == 10 and log._pending() == 20  # noqa: SLF001 - one entry per sample, 2 messages each
        gate.release.set()
    data = read_log(path)
    cf1, cf2 = data.messages("/truth/cf1"), data.messages("/truth/cf2")
    assert [m.log_time for m in cf1] == [m.publish_time for m in cf1] == [T0 + k * 10 * MS for k in range(10)]
    assert [m.sequence for m in cf2] == list(range(10)) and data.schemas["/truth/cf2"] == "rpf_fly.TruthState"
    assert cf1[3].data == {
        "timestamp": {"sec": 1_700_000_000, "nsec": 30 * MS},
        "position": {"x": pytest.approx(0.3), "y": 0.0, "z": 0.5},
        "yaw": 0.0,
        "motors": True,
        "crashed": False,
        "estimate": {"x": pytest.approx(0.3), "y": 0.0, "z": 0.5},
    }
    assert cf2[0].data["crashed"] is True and cf2[0].data["motors"] is False and cf2[0].data["yaw"] == -1.5


def test_threads_log_concurrently(tmp_path):
    path = tmp_path / "threads.mcap"
    n = 2000
    with FlightLog(path, MISSION, SCENARIO) as log:

        def fly(name: str) -> None:
            for k in range(n):
                log.pose(name, T0 + k, (k, 0, 0))
                if k % 100 == 0:
                    log.event(T0 + k, 1, f"{name} {k}")

        threads = [threading.Thread(target=fly, args=(f"cf{i}",)) for i in range(4)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
    data = read_log(path)
    assert log.dropped == 0
    for i in range(4):
        msgs = data.messages(f"/mocap/cf{i}")
        assert [m.sequence for m in msgs] == list(range(n))
        assert [m.data["pose"]["position"]["x"] for m in sorted(msgs, key=lambda m: m.sequence)] == list(range(n))
    assert sorted(m.sequence for m in data.messages("/events")) == list(range(4 * n // 100))


class Gate:
    """A position whose length blocks until released: holds the writer thread inside one message's build."""

    def __init__(self) -> None:
        self.entered = threading.Event()
        self.release = threading.Event()

    def _hold(self) -> None:
        self.entered.set()
        self.release.wait(10)

    def __len__(self) -> int:
        self._hold()
        return 3

    def __iter__(self):  # type: ignore[no-untyped-def]
        self._hold()
        return iter((0.0, 0.0, 0.0))

    def __getitem__(self, i: int) -> float:
        if i >= 3:
            raise IndexError(i)
        return 0.0


def test_full_queue_drops_new_messages_counts_and_reports_them(tmp_path):
    path = tmp_path / "full.mcap"
    gate = Gate()
    log = FlightLog(path, MISSION, SCENARIO, clock=None, max_queue=100)
    log.pose("cf1", T0, gate)
    assert gate.entered.wait(5)  # the writer thread is stuck in the first message: nothing drains
    started = time.perf_counter()
    for k in range(1, 101):
        log.pose("cf1", T0 + k, (k, 0, 0))  # fills the queue
    for k in range(101, 106):
        log.pose("cf1", T0 + k, (k, 0, 0))  # dropped
    for k in range(3):
        log.event(T0 + k, 4, f"still heard {k}")  # events pass up to twice the bound
    assert time.perf_counter() - started < 1.0  # never blocked
    assert log.dropped == 5
    gate.release.set()
    deadline = time.monotonic() + 10
    while log.written < 101 and time.monotonic() < deadline:
        time.sleep(0.01)
    log.pose("cf1", T0 + 106, (106, 0, 0))
    log.close()
    log.close()  # idempotent
    log.pose("cf1", T0 + 107, (107, 0, 0))  # after close: ignored, counted
    assert log.dropped == 6

    data = read_log(path)
    seqs = [m.sequence for m in data.messages("/mocap/cf1")]
    assert seqs == list(range(101)) + [106]  # the drops are a visible gap in the sequence
    events = [m.data for m in data.messages("/events")]
    assert [e["message"] for e in events[:3]] == [f"still heard {k}" for k in range(3)]
    assert events[-1]["level"] == 3 and "5 messages dropped" in events[-1]["message"]


def test_block_when_full_never_drops(tmp_path):
    path = tmp_path / "block.mcap"
    with FlightLog(path, MISSION, SCENARIO, clock=None, max_queue=10, block_when_full=True) as log:
        for k in range(3000):
            log.pose("cf1", T0 + k, (k, 0, 0))
    assert log.dropped == 0
    assert [m.sequence for m in read_log(path).messages("/mocap/cf1")] == list(range(3000))


def test_bad_argument_loses_one_message_not_the_log(tmp_path):
    path = tmp_path / "bad.mcap"
    with FlightLog(path, MISSION, SCENARIO, clock=None) as log:
        log.event(T0, 9, "no such level")
        log.planner_step("cf1", T0, tick=0, position=(0, 0, 0), goal=(1, 0), mode="dancing")
        log.pose("cf1", T0, (float("nan"), 0, 0))
        log.event(T0, 2, "fine")
    assert log.failed == 2 and log.error is None
    data = read_log(path)
    assert [m.data["message"] for m in data.messages("/events")] == ["fine"]
    assert data.messages("/mocap/cf1")[0].data["pose"]["position"]["x"] is None  # JSON has no NaN


def test_unwritable_path_raises_before_the_flight(tmp_path):
    with pytest.raises(OSError):
        FlightLog(tmp_path / "missing" / "dir" / "x.mcap", MISSION, SCENARIO)


def test_indexed_file_with_valid_crcs(tmp_path):
    """Chunk and summary CRCs validate; indexes support time-range and reverse reads."""
    from mcap.stream_reader import StreamReader

    path = tmp_path / "flight.mcap"
    write_flight(path, ticks=30)
    assert sum(1 for _ in StreamReader(str(path), validate_crcs=True).records) > 0
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        summary = reader.get_summary()
        assert len(summary.chunk_indexes) == summary.statistics.chunk_count >= 1
        assert len(list(reader.iter_messages(log_time_order=True, reverse=True))) == summary.statistics.message_count
        topics = list(reader.iter_messages(topics=["/cf1/planner"], starting_at=T0 + 100 * MS))
        assert [m.publish_time for _, _, m in topics] == [T0 + k * 10 * MS for k in range(10, 30)]


def test_drain_soon_writes_without_waiting_for_the_poll(tmp_path):
    """A flight wakes the writer right after a planning tick (its GIL burst then falls in the loop's idle gap);
    the writer's own poll is only a fallback."""
    with FlightLog(tmp_path / "nudged.mcap", MISSION, SCENARIO, clock=None, poll_interval_s=30.0) as log:
        time.sleep(0.1)  # the writer is now waiting on its 30 s poll
        for k in range(20):
            log.pose("cf1", T0 + k * MS, (0.0, 0.0, 0.6))
        time.sleep(0.2)
        assert log.written == 0  # nothing drains by itself before the poll
        log.drain_soon()
        deadline = time.monotonic() + 5.0
        while log.written < 20 and time.monotonic() < deadline:
            time.sleep(0.005)
        assert log.written == 20


def _planner_fields(k: int, i: int) -> dict:
    return dict(
        tick=k,
        position=(0.01 * k, float(i), 0.6),
        goal=1 + 1j,
        mode="apf",
        eta=0.05,
        lam=2.0,
        f_a=0.7 + 0.7j,
        f_r=-0.1j,
        f_in=0j,
        direction=1 + 0j,
        heading=0.0,
        neighbours=1,
        obstacle_distance=0.4,
    )


def test_batch_calls_write_what_the_per_message_calls_write(tmp_path):
    drones = ("cf1", "cf2", "cf3")
    single, batched = tmp_path / "single.mcap", tmp_path / "batched.mcap"
    with FlightLog(single, MISSION, SCENARIO, clock=None) as log:
        for k in range(20):
            t = T0 + k * 10 * MS
            for i, d in enumerate(drones):
                log.pose(d, t, (0.01 * k, float(i), 0.6), (0.0, 0.0, 0.1, 0.99))
            for i, d in enumerate(drones):
                log.setpoint(d, t + i, (0.01 * k + 0.05, float(i), 0.6), 0.25)
            for i, d in enumerate(drones):
                log.planner_step(d, t, **_planner_fields(k, i))
    with FlightLog(batched, MISSION, SCENARIO, clock=None) as log:
        for k in range(20):
            t = T0 + k * 10 * MS
            log.poses(t, {d: ((0.01 * k, float(i), 0.6), (0.0, 0.0, 0.1, 0.99)) for i, d in enumerate(drones)})
            if k == 7:  # one drone logged alone in between: the per-drone sequences stay one series
                log.setpoint("cf1", t, (0.01 * k + 0.05, 0.0, 0.6), 0.25)
                log.setpoints(
                    [(d, t + i, (0.01 * k + 0.05, float(i), 0.6), 0.25) for i, d in enumerate(drones) if d != "cf1"]
                )
            else:
                log.setpoints([(d, t + i, (0.01 * k + 0.05, float(i), 0.6), 0.25) for i, d in enumerate(drones)])
            log.planner_steps(t, {d: _planner_fields(k, i) for i, d in enumerate(drones)})
    assert log.written == 180 and log.dropped == 0 and log.failed == 0
    a, b = read_log(single), read_log(batched)
    for d in drones:
        for topic in (f"/mocap/{d}", f"/{d}/setpoint", f"/{d}/planner"):
            ma, mb = a.messages(topic), b.messages(topic)
            assert len(ma) == len(mb) == 20, topic
            assert [(m.log_time, m.publish_time, m.sequence, m.data) for m in ma] == [
                (m.log_time, m.publish_time, m.sequence, m.data) for m in mb
            ], topic


def test_batch_calls_drop_whole_and_count_every_message(tmp_path):
    path = tmp_path / "full.mcap"
    gate = Gate()
    log = FlightLog(path, MISSION, SCENARIO, clock=None, max_queue=10)
    log.pose("cf1", T0, gate)
    assert gate.entered.wait(5)  # the writer is stuck in the first message: nothing drains
    log.poses(T0 + 1, {f"cf{i}": ((0.0, 0.0, 0.0), None) for i in range(1, 9)})  # 8 messages: fit (9 of 10)
    log.poses(T0 + 2, {f"cf{i}": ((0.0, 0.0, 0.0), None) for i in range(1, 4)})  # 3 would make 12: dropped whole
    assert log.dropped == 3
    gate.release.set()
    log.close()
    log.planner_steps(T0 + 3, {"cf1": _planner_fields(0, 0), "cf2": _planner_fields(0, 1)})  # after close
    assert log.dropped == 5 and log.written == 10  # 9 poses and the drop report on /events
    data = read_log(path)
    assert [m.sequence for m in data.messages("/mocap/cf1")] == [0, 1]  # the dropped batch is a gap: 2 is missing
    assert len(data.messages("/mocap/cf2")) == 1 and len(data.messages("/mocap/cf8")) == 1


def test_a_bad_value_in_a_batch_loses_that_message_only(tmp_path):
    path = tmp_path / "bad.mcap"
    with FlightLog(path, MISSION, SCENARIO, clock=None) as log:
        log.planner_steps(
            T0,
            {
                "cf1": _planner_fields(0, 0),
                "cf2": {**_planner_fields(0, 1), "mode": "dancing"},
                "cf3": _planner_fields(0, 2),
            },
        )
    assert log.failed == 1 and log.written == 2
    data = read_log(path)
    assert [len(data.messages(f"/{d}/planner")) for d in ("cf1", "cf2", "cf3")] == [1, 0, 1]


def test_a_log_with_out_hands_every_message_over_and_writes_no_file(tmp_path):
    """``FlightLog(out=...)`` (a distributed flight's worker): each message goes to ``out`` with its topic, log time,
    publish time and the very bytes a file would hold; nothing is written at the path."""
    got: list[tuple[str, int, int, bytes]] = []
    path = tmp_path / "published.mcap"
    with FlightLog(path, MISSION, SCENARIO, clock=None, out=lambda *m: got.append(m)) as log:
        log.pose("cf1", T0, (1.0, 2.0, 0.5), (0.0, 0.0, 0.0, 1.0))
        log.status("cf1", T0 + MS, state="planning", battery_v=3.9)
        log.event(T0 + 2 * MS, 3, "hello", name="cf1", file="kind")
    assert not path.exists()
    reference = write_flight(tmp_path / "file.mcap", drones=("cf1",), ticks=1).path
    written = {t: msgs[0].data for t, msgs in read_log(reference).topics.items()}
    topics = [m[0] for m in got]
    assert topics == ["/mocap/cf1", "/cf1/status", "/events"]
    assert got[0][1] == got[0][2] == T0 and got[1][2] == T0 + MS
    import json

    assert json.loads(got[0][3]).keys() == written["/mocap/cf1"].keys()


def test_raw_messages_and_a_late_metadata_record_are_written(tmp_path):
    """The distributed flight's logger: :meth:`FlightLog.message` writes bytes already encoded with their own times;
    :meth:`FlightLog.metadata` adds a record in queue order."""
    path = tmp_path / "raw.mcap"
    with FlightLog(path, MISSION, SCENARIO) as log:
        log.message("/cf1/setpoint", T0, T0 + 5, b'{"a": 1}')
        log.message("/cf1/setpoint", T0 + MS, T0 + MS + 5, b'{"a": 2}')
        log.metadata("runtime", {"flight_id": "f1", "workers": [{"name": "dongle-0"}]})
    data = read_log(path)
    msgs = data.messages("/cf1/setpoint")
    assert [m.data["a"] for m in msgs] == [1, 2] and [m.sequence for m in msgs] == [0, 1]
    assert msgs[0].publish_time == T0 and msgs[0].log_time == T0 + 5
    assert data.metadata["runtime"]["flight_id"] == "f1" and "dongle-0" in data.metadata["runtime"]["workers"]
