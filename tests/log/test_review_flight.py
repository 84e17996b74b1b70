"""``rpf-fly review`` of real dry-run flights through the real CLI: a clean flight, one stopped by Ctrl-C twice, one
killed (and its salvaged copy). The text names an interrupted flight; ``--json`` holds everything the text says,
the metrics keys where they always were."""

from __future__ import annotations

import itertools
import json
import re

import pytest
from typer.testing import CliRunner

from rpf_fly.cli import get_app
from rpf_fly.log.reader import read_log
from rpf_fly.log.review import review

# Its module and session fixtures fly once: the tests sharing them run on one xdist worker (pyproject: --dist
# loadgroup).
pytestmark = pytest.mark.xdist_group("cli_flights")

runner = CliRunner()
METRIC_KEYS = [
    "mission",
    "planner",
    "seed",
    "drones",
    "reached",
    "success",
    "collisions",
    "margin",
    "min_separation_m",
    "min_obstacle_clearance_m",
    "travel_distance_m",
    "smoothness",
    "makespan_s",
    "per_drone",
]


def run(*args):  # type: ignore[no-untyped-def]
    return runner.invoke(get_app(), ["review", *map(str, args)])


def text_and_json(log):  # type: ignore[no-untyped-def]
    text = run(log)
    assert text.exit_code == 0, text.output
    doc = run(log, "--json")
    assert doc.exit_code == 0, doc.output
    return text.stdout, json.loads(doc.stdout)


def test_a_clean_flight_is_not_interrupted_and_the_json_says_what_the_text_says(clean_cli_flight):
    text, doc = text_and_json(clean_cli_flight.log)
    assert "interrupted" not in text
    assert list(doc)[: len(METRIC_KEYS)] == METRIC_KEYS  # the metrics JSON, keys where they were
    assert doc["interrupted"] is False and doc["interruptions"] == []
    assert doc["log"]["source"] == "dry-run" and doc["log"]["clean_end"] is True and doc["log"]["truncated"] is False
    assert doc["outcomes"] == {"cf1": "reached", "cf2": "reached", "cf3": "reached"}
    # topic health: every row of the text's table is in the JSON with the same numbers
    topics = {t["topic"]: t for t in doc["topics"]}
    for line in text.splitlines():
        cells = [c.strip() for c in line.strip("│").split("│")] if line.startswith("│ /") else None
        if cells:
            topic, schema, messages, rate, gaps, _, missing = cells
            assert topics[topic]["schema"] == schema and topics[topic]["messages"] == int(messages)
            assert topics[topic]["gaps"] == int(gaps) and topics[topic]["missing"] == int(missing)
            assert rate == "-" or topics[topic]["rate_hz"] == pytest.approx(float(rate), abs=0.05)
    assert {"/mocap/cf1", "/cf1/planner", "/events", "/truth/cf3"} <= set(topics)
    # events: the counts the text prints
    counts = dict(re.findall(r"(\w+) (\d+)", text.split("events: ", 1)[1].splitlines()[0]))
    assert {k: v for k, v in doc["events"]["by_level"].items() if v} == {k: int(v) for k, v in counts.items()}
    # tracking and battery: the text's numbers, from the same computation
    rms = float(re.search(r"tracking error \|setpoint - pose\|: RMS ([0-9.]+) m", text).group(1))
    assert doc["tracking"]["all"]["rms_m"] == pytest.approx(rms, abs=5e-4)
    assert set(doc["tracking"]) == {"cf1", "cf2", "cf3", "all"}
    low = float(re.search(r"cf1 [0-9.]+ -> [0-9.]+ V \(lowest ([0-9.]+)\)", text).group(1))
    assert doc["battery"]["cf1"]["min_v"] == pytest.approx(low, abs=5e-3)


def test_an_emergency_stop_by_ctrl_c_is_named_interrupted(stopped_cli_flight):
    text, doc = text_and_json(stopped_cli_flight.log)
    line = next(line for line in text.splitlines() if line.startswith("interrupted"))
    assert line.startswith("interrupted (signal) at ") and "Ctrl-C" in line
    assert doc["interrupted"] is True and [i["how"] for i in doc["interruptions"]] == ["signal"]
    assert doc["log"]["clean_end"] is True  # the flight itself closed its log
    assert doc["outcomes"] == {"cf1": "emergency", "cf2": "emergency", "cf3": "emergency"}
    stops = [w for w in doc["events"]["warnings"] if "second Ctrl-C" in w["message"]]
    assert stops and stops[0]["level"] == "fatal" and stops[0]["kind"] == "emergency"
    assert "second Ctrl-C: emergency stop" in text


def test_a_killed_flight_and_its_salvaged_copy_are_named_interrupted(killed_cli_flight, tmp_path):
    log = killed_cli_flight.log
    assert read_log(log).truncated
    text = run(log)
    assert text.exit_code == 0, text.output
    assert "interrupted (killed)" in text.stdout and "ends before its footer" in text.stdout
    fixed = tmp_path / "fixed.mcap"
    assert run(log, "--salvage", fixed).exit_code == 0
    text, doc = text_and_json(fixed)
    assert "interrupted (killed)" in text and "no clean end" in text
    assert doc["log"]["truncated"] is False and doc["log"]["clean_end"] is False
    assert [i["how"] for i in doc["interruptions"]] == ["killed"]


def test_a_simulated_log_ends_cleanly(lab_log):
    path, metrics = lab_log
    result = review(read_log(path))
    assert result.source == "sim" and result.clean_end is True and not result.interrupted
    assert result.battery == {}  # a simulation has no battery telemetry


def test_a_dry_run_logs_each_dongles_measured_load_and_review_prints_it(clean_cli_flight):
    """/radio/0 (three drones, setpoints at 10 Hz, extpos at 30 Hz, cflib's pings at 10 Hz, keep-alives at 5 Hz: 165
    transactions/s planned, of the about 423 a Crazyradio PA carries of them): a window a second, the busy ones near
    the plan; the review's line and JSON say the same."""
    data = read_log(clean_cli_flight.log)
    messages = list(data.messages("/radio/0"))
    windows = [m.data for m in messages]
    assert len(windows) >= 10, windows
    # a drone is in a window once cflib has reported its link's statistics, and stays in every later one; the
    # windows before take-off may miss the drones still connecting (how many depends on the host), none after it
    first_tick = min(m.log_time for n in ("cf1", "cf2", "cf3") for m in data.messages(f"/{n}/planner"))
    after = [w for m, w in zip(messages, windows, strict=True) if m.log_time >= first_tick]
    assert len(after) >= 8 and [w for w in after if w["drones"] != ["cf1", "cf2", "cf3"]] == []
    seen = [set(w["drones"]) for w in windows if w["transactions"] > 0]  # (none counted yet: the plan's drones)
    assert all(a <= b <= {"cf1", "cf2", "cf3"} for a, b in itertools.pairwise(seen)), seen
    assert [w for w in windows if not (w["planned_per_s"] == 165.0 and 400.0 < w["budget_per_s"] < 445.0)] == []
    full = [w for w in windows if w["window_s"] > 0.9]
    assert len(full) >= len(windows) - 2, windows
    lengths = sorted(w["window_s"] for w in full)  # once a second (a starved host may stretch one, not most)
    assert 0.95 <= lengths[len(lengths) // 2] <= 1.1, lengths
    busy = sorted(w["packets_per_s"] for w in full)[len(full) // 2 :]
    assert 0.8 * 150 <= busy[len(busy) // 2] <= 1.2 * 150, busy  # measured, not copied from the plan
    assert [w for w in windows if w["transactions_per_s"] < w["packets_per_s"]] == []  # polls fill the gaps
    text, doc = text_and_json(clean_cli_flight.log)
    line = next(line for line in text.splitlines() if line.startswith("radio dongle 0"))
    peak = max(w["packets_per_s"] for w in windows)
    budget = windows[0]["budget_per_s"]
    assert f"{peak:.0f} packets/s in the busiest second" in line and f"planned 165, budget {budget:.0f}" in line
    assert doc["radio"]["0"]["peak_packets_per_s"] == pytest.approx(peak)
    assert doc["radio"]["0"]["drones"] == ["cf1", "cf2", "cf3"]
