"""Smoke test of tools/bench_log.py (the logging-cost benchmark): a tiny run in both call styles writes the
message counts the docstring promises, and the batch calls write the same topics and counts as one call each."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

from rpf_fly.log.reader import read_log

BENCH = Path(__file__).resolve().parents[2] / "tools" / "bench_log.py"


def _bench():  # type: ignore[no-untyped-def]
    spec = importlib.util.spec_from_file_location("bench_log", BENCH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)  # type: ignore[union-attr]
    return module


@pytest.mark.parametrize("batched", [True, False])
def test_bench_log_writes_every_message_of_a_small_flight(tmp_path, batched):
    path = tmp_path / "bench.mcap"
    result = _bench().run(drones=3, rate=40.0, seconds=0.5, status_every=4, path=path, batched=batched)
    ticks = 20  # 0.5 s at 40 Hz; /tf every 2 ticks (20 Hz), status every 4 ticks
    assert result["dropped"] == 0
    assert result["calls"] == ("batched" if batched else "per message")
    counts = {topic: len(messages) for topic, messages in read_log(path).topics.items()}
    expected = {
        "/tf": 10,
        **{f"/mocap/cf{i}": ticks for i in (1, 2, 3)},
        **{f"/cf{i}/setpoint": ticks for i in (1, 2, 3)},
        **{f"/cf{i}/planner": ticks for i in (1, 2, 3)},
        **{f"/cf{i}/status": 5 for i in (1, 2, 3)},
    }
    assert counts == expected
    assert result["messages"] == sum(expected.values())
    assert result["logging_cpu_pct"] > 0 and result["writer_us_per_msg"] > 0
