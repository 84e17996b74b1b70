"""A writer killed with SIGKILL mid-flight: the complete chunks survive (at most about one second lost), read_log
reads them and salvage() turns the file into one that mcap's seeking reader accepts."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest
from mcap.reader import make_reader

from rpf_fly.log.reader import read_log, salvage

# Its module and session fixtures fly once: the tests sharing them run on one xdist worker (pyproject: --dist
# loadgroup).
pytestmark = pytest.mark.xdist_group("crash_log")

CHILD = textwrap.dedent(
    """
    import sys, time
    from rpf_fly.log.writer import FlightLog

    log = FlightLog(sys.argv[1], {"name": "kill-test", "seed": 0}, {"json": '{"names": ["cf1"]}'})
    print("ready", flush=True)
    k = 0
    while True:
        now = time.time_ns()
        for d in ("cf1", "cf2", "cf3", "cf4", "cf5"):
            log.pose(d, now, (k * 1e-3, 0.0, 0.5), (0.0, 0.0, 0.0, 1.0))
        log.planner_step("cf1", now, tick=k, position=(k * 1e-3, 0.0, 0.5), goal=(1.0, 1.0), mode="apf")
        k += 1
        time.sleep(0.002)
    """
)


@pytest.fixture(scope="module")
def killed(tmp_path_factory):  # type: ignore[no-untyped-def]
    """A log whose writer process was SIGKILLed 2.5 s into writing, and the kill time (ns)."""
    directory = tmp_path_factory.mktemp("killed")
    script = directory / "child.py"
    script.write_text(CHILD)
    path = directory / "killed.mcap"
    proc = subprocess.Popen([sys.executable, str(script), str(path)], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None and proc.stdout.readline().strip() == "ready"
        time.sleep(2.5)
        kill_ns = time.time_ns()
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == -signal.SIGKILL
    return path, kill_ns


def test_seeking_reader_rejects_the_killed_file(killed):
    path, _ = killed
    # Any exception: the bytes after the last complete chunk are whatever the kill left, read as a footer they fail
    # in mcap's record decoding in more than one way (McapError, struct.error, ...).
    with open(path, "rb") as f, pytest.raises(Exception):  # noqa: B017
        reader = make_reader(f)
        reader.get_summary()
        list(reader.iter_messages())


def test_read_log_recovers_every_complete_chunk(killed):
    path, kill_ns = killed
    data = read_log(path)
    assert data.truncated
    assert data.metadata["mission"] == {"name": "kill-test", "seed": "0"}
    for topic in ["/mocap/cf1", "/mocap/cf5", "/cf1/planner"]:
        msgs = data.messages(topic)
        assert [m.sequence for m in msgs] == list(range(len(msgs))), topic  # contiguous from 0
        # everything published more than ~1.2 s before the kill had been flushed (flush about once a second)
        assert msgs[-1].publish_time >= kill_ns - 1_200_000_000, (topic, (kill_ns - msgs[-1].publish_time) / 1e9)
    ticks = [m.data["tick"] for m in data.messages("/cf1/planner")]
    assert ticks == list(range(len(ticks))) and len(ticks) > 200


def test_salvage_makes_a_file_the_seeking_reader_accepts(killed, tmp_path):
    path, _ = killed
    data = read_log(path)
    out = tmp_path / "salvaged.mcap"
    result = salvage(path, out)
    assert result.truncated and result.messages == data.message_count and result.metadata == 2
    with open(out, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics.message_count == data.message_count
        counts = {summary.channels[c].topic: n for c, n in summary.statistics.channel_message_counts.items()}
        assert counts == data.counts
        assert sum(1 for _ in reader.iter_messages(log_time_order=True)) == data.message_count
        assert {m.name for m in reader.iter_metadata()} == {"mission", "scenario"}
    again = read_log(out)
    assert not again.truncated and again.counts == data.counts
    assert again.messages("/cf1/planner") == data.messages("/cf1/planner")


def test_salvage_of_a_finished_file_is_a_copy(lab_log, tmp_path):
    path, _ = lab_log
    out = tmp_path / "copy.mcap"
    result = salvage(path, out)
    assert not result.truncated
    assert read_log(out).topics == read_log(path).topics


def test_review_salvage_writes_a_finished_copy_and_says_so(killed, tmp_path):
    from typer.testing import CliRunner

    from rpf_fly.cli import get_app

    def run_cli(*args):  # type: ignore[no-untyped-def]
        return CliRunner().invoke(get_app(), [str(a) for a in args])

    path, _ = killed
    plain = run_cli("review", path)
    assert "--salvage FIXED.mcap" in plain.stderr  # the truncation warning says how to get a file Foxglove opens
    out = tmp_path / "fixed.mcap"
    result = run_cli("review", path, "--salvage", out)
    assert result.exit_code == 0, result.output
    data = read_log(path)
    assert f"{out}: {data.message_count} messages" in result.stderr
    with open(out, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and summary.statistics.message_count == data.message_count
    same = run_cli("review", path, "--salvage", path)
    assert same.exit_code == 2 and "cannot salvage" in same.stderr and len(same.stderr.strip().splitlines()) == 1
