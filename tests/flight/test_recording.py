"""The flight's MCAP recorder: it paces the log writer's drains to the planning ticks."""

from __future__ import annotations

from flight_harness import SHORT_MISSION

from rpf_fly.flight.recording import DRAIN_PERIOD_S, McapRecorder
from rpf_fly.log.reader import read_log
from rpf_fly.mission import parse_mission


def test_after_tick_wakes_the_writer_at_most_every_drain_period(tmp_path):
    recorder = McapRecorder(tmp_path / "flight.mcap", parse_mission(SHORT_MISSION))
    nudges = []
    real = recorder.log.drain_soon
    recorder.log.drain_soon = lambda: (nudges.append(1), real())[1]
    for k in range(101):  # 100 Hz ticks for one second
        recorder.after_tick(100.0 + 0.01 * k)
    recorder.close()
    # at most one per drain period, and no later than one tick after it
    assert 1.0 / (DRAIN_PERIOD_S + 0.01) <= len(nudges) <= 1.0 / DRAIN_PERIOD_S + 1
    assert "/scene" in read_log(tmp_path / "flight.mcap").topics
