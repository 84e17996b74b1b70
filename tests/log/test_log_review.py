"""``rpf-fly review``: the metrics of a ``sim --log`` file equal ``sim --json``; summary, plots and CSV; the
metadata a log carries; error paths (one line on stderr, exit 2)."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import pytest
from mcap.writer import Writer
from sim_logs import MISSIONS, run_cli, sim_log

from rpf_fly.log.reader import read_log
from rpf_fly.log.review import review


def assert_close(a, b, path="$"):  # type: ignore[no-untyped-def]
    """Same structure; every number within 1e-6."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and a.keys() == b.keys(), path
        for k in a:
            assert_close(a[k], b[k], f"{path}.{k}")
    elif isinstance(a, list):
        assert isinstance(b, list) and len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b)):
            assert_close(x, y, f"{path}[{i}]")
    elif isinstance(a, bool) or a is None or isinstance(a, str):
        assert a == b, (path, a, b)
    else:
        assert math.isclose(a, b, rel_tol=0, abs_tol=1e-6), (path, a, b)


@pytest.mark.parametrize("mission", ["lab-3", "circle-8-r3"])
def test_review_json_reproduces_sim_json(tmp_path, mission):
    seed = 0 if mission == "lab-3" else 4
    log, expected = sim_log(tmp_path, mission, seed)
    result = run_cli("review", log, "--json")
    assert result.exit_code == 0, result.output
    assert result.stderr == ""
    got = json.loads(result.stdout)
    assert list(got)[: len(expected)] == list(expected)  # the metrics JSON first, its keys where they always were
    assert_close({k: got[k] for k in expected}, expected)
    assert result.stdout.count("\n") == 1


def test_log_carries_the_mission_and_scenario(lab_log):
    from rpf_fly import __version__

    path, _ = lab_log
    data = read_log(path)
    mission = data.metadata["mission"]
    assert mission["yaml"] == (MISSIONS / "lab-3.yaml").read_text()
    import hashlib

    from rpf_fly.mission import load_mission

    loaded = load_mission(MISSIONS / "lab-3.yaml")
    policy_sha = hashlib.sha256(loaded.planner.policy.read_bytes()).hexdigest() if loaded.planner.policy else ""
    assert (mission["name"], mission["planner"], mission["seed"], mission["policy_sha256"]) == (
        "lab-3",
        loaded.planner.kind,
        "0",
        policy_sha,
    )
    assert mission["rpf_fly_version"] == __version__
    scenario = json.loads(data.metadata["scenario"]["json"])
    assert scenario["names"] == ["cf1", "cf2", "cf3"] and scenario["dt"] == 0.1 and scenario["height"] == 0.6
    assert scenario["arena"] == {"x": [-2.0, 2.0], "y": [-2.0, 2.0], "z": [0.0, 1.5]}
    assert scenario["obstacles"][0] == {"shape": "circle", "center": [-0.8, 0.7], "radius": 0.1}
    assert len(scenario["starts"]) == len(scenario["goals"]) == 3
    assert {"goal_tolerance", "safety_radius", "speed"} <= scenario.keys()


def test_planner_ticks_cover_every_step_and_a_final_tick(lab_log):
    path, metrics = lab_log
    data = read_log(path)
    steps = round(metrics["makespan_s"] / 0.1)
    for name in ("cf1", "cf2", "cf3"):
        ticks = data.messages(f"/{name}/planner")
        assert [m.data["tick"] for m in ticks] == list(range(steps + 1))
        assert ticks[-1].data["mode"] == "arrived" and ticks[-1].data["lambda"] is None
        assert data.messages(f"/{name}/status")[-1].data["outcome"] == "reached"
    # cf1 arrives before the end: later ticks say so
    arrived = [m.data["mode"] for m in data.messages("/cf1/planner")]
    assert arrived.index("arrived") == round(metrics["per_drone"][0]["time_to_goal_s"] / 0.1)
    assert set(arrived[arrived.index("arrived") :]) == {"arrived"}


def test_summary_of_a_simulated_log(lab_log):
    path, metrics = lab_log
    result = review(read_log(path))
    assert result.drones == ["cf1", "cf2", "cf3"] and result.mission == "lab-3" and result.seed == 0
    stats = {t.topic: t for t in result.topics}
    assert stats["/mocap/cf1"].rate_hz == pytest.approx(10.0) and stats["/mocap/cf1"].gaps == ()
    assert stats["/mocap/cf1"].missing == 0 and stats["/scene"].count == 1
    assert result.events_by_level["info"] >= 5  # start, three arrivals, end
    assert result.duration_s == pytest.approx(metrics["makespan_s"])  # the run ends at the last arrival


def test_gaps_and_missing_sequences_are_found(tmp_path):
    from rpf_fly.log.writer import FlightLog

    path = tmp_path / "gappy.mcap"
    t0 = 1_700_000_000_000_000_000
    with FlightLog(path, {}, {}, clock=None) as log:
        for k in list(range(50)) + list(range(80, 100)):  # 0.3 s missing at 100 Hz
            log.pose("cf1", t0 + k * 10_000_000, (0, 0, 0))
    result = review(read_log(path))
    (mocap,) = [t for t in result.topics if t.topic == "/mocap/cf1"]
    assert mocap.gaps == ((pytest.approx(0.49), pytest.approx(0.31)),)
    assert mocap.missing == 0  # the writer was not asked for them: a gap, not a drop
    assert result.metrics is None and "scenario" in result.metrics_error


def test_truth_topics_name_drones_not_a_drone_called_truth(tmp_path):
    """A dry run's /truth/<drone> is a drone topic like /mocap/<drone> when the review names the drones from the
    topics (a log without its scenario record)."""
    from rpf_fly.log.review_scenario import drones_of
    from rpf_fly.log.writer import FlightLog

    path = tmp_path / "truth.mcap"
    t0 = 1_700_000_000_000_000_000
    with FlightLog(path, {}, {}, clock=None) as log:
        for k in range(20):
            log.truth(
                t0 + k * 10_000_000, {d: ((0.0, 0.0, 0.5), 0.0, True, False, (0.0, 0.0, 0.5)) for d in ("cf1", "cf2")}
            )
            log.pose("cf1", t0 + k * 10_000_000, (0, 0, 0.5))
    data = read_log(path)
    assert sorted(drones_of(data)) == ["cf1", "cf2"]
    (truth,) = [t for t in review(data).topics if t.topic == "/truth/cf2"]
    assert truth.count == 20 and truth.rate_hz == pytest.approx(100.0) and truth.gaps == ()
    result = run_cli("review", path, "--csv", tmp_path / "csv")
    assert result.exit_code == 0, result.output
    assert "/truth/cf1" in result.stdout
    with open(tmp_path / "csv" / "truth_cf1.csv", newline="") as f:
        rows = list(csv.reader(f))
    assert rows[0][3:] == [
        "timestamp.sec",
        "timestamp.nsec",
        "position.x",
        "position.y",
        "position.z",
        "yaw",
        "motors",
        "crashed",
        "estimate.x",
        "estimate.y",
        "estimate.z",
    ]
    assert len(rows) == 21 and rows[1][9:11] == ["True", "False"]


def test_plot_and_csv(lab_log, tmp_path):
    path, _ = lab_log
    png = tmp_path / "review.png"
    out = tmp_path / "csv"
    result = run_cli("review", path, "--plot", png, "--csv", out)
    assert result.exit_code == 0, result.output
    assert "lab-3" in result.stdout and "success" in result.stdout and "/mocap/cf1" in result.stdout
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 50_000
    data = read_log(path)
    files = sorted(p.name for p in out.iterdir())
    assert files == sorted(t.strip("/").replace("/", "_") + ".csv" for t in data.topics)

    def header_and_rows(name):  # type: ignore[no-untyped-def]
        with open(out / name, newline="") as f:
            rows = list(csv.reader(f))
        return rows[0], rows[1:]

    header, rows = header_and_rows("mocap_cf1.csv")
    assert header == [
        "log_time_ns",
        "publish_time_ns",
        "sequence",
        "timestamp.sec",
        "timestamp.nsec",
        "frame_id",
        "pose.position.x",
        "pose.position.y",
        "pose.position.z",
        "pose.orientation.x",
        "pose.orientation.y",
        "pose.orientation.z",
        "pose.orientation.w",
    ]
    assert len(rows) == len(data.messages("/mocap/cf1")) and rows[0][5] == "world"
    header, rows = header_and_rows("cf2_planner.csv")
    for column in (
        "tick",
        "position.x",
        "goal.y",
        "eta",
        "lambda",
        "f_a.x",
        "f_r.y",
        "f_in.x",
        "direction.y",
        "mode",
        "heading",
        "neighbours",
        "obstacle_distance",
        "goal_distance",
    ):
        assert column in header, column
    header, rows = header_and_rows("cf1_status.csv")
    assert header[3:] == [
        "timestamp.sec",
        "timestamp.nsec",
        "state",
        "battery_v",
        "link_quality",
        "latency_ms",
        "outcome",
        "estimate",
        "target",
    ]  # a simulation's drones have no firmware: both null
    assert rows[-1][header.index("outcome")] == "reached" and rows[0][header.index("battery_v")] == ""
    header, rows = header_and_rows("events.csv")
    assert {"level", "message", "name", "file", "line"} <= set(header)
    header, _ = header_and_rows("scene.csv")
    assert "entities" in header  # arrays as JSON in one cell


def test_json_output_ignores_plot_messages(lab_log, tmp_path):
    path, expected = lab_log
    result = run_cli("review", path, "--json", "--plot", tmp_path / "p.png")
    assert result.exit_code == 0
    got = json.loads(result.stdout)
    assert {k: got[k] for k in expected} == expected


def one_error_line(result, prefix):  # type: ignore[no-untyped-def]
    assert result.exit_code == 2, result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"{prefix}: "), result.stderr
    assert result.stdout == "" and "Traceback" not in result.output
    return lines[0]


def test_missing_file(tmp_path):
    log = tmp_path / "nope.mcap"
    assert one_error_line(run_cli("review", log, "--json"), str(log)).endswith("no such file")


def test_directory(tmp_path):
    one_error_line(run_cli("review", tmp_path), str(tmp_path))


@pytest.mark.parametrize("content", [b"", b"hello, not a log\n" * 10, b"\x89MCAP0\r\n" + b"\x00" * 3])
def test_not_mcap(tmp_path, content):
    log = tmp_path / "bad.mcap"
    log.write_bytes(content)
    assert "not an MCAP file" in one_error_line(run_cli("review", log, "--json"), str(log))


def test_mcap_without_metadata_cannot_give_metrics(tmp_path):
    log = tmp_path / "other.mcap"
    with open(log, "wb") as f:
        writer = Writer(f)
        writer.start()
        writer.finish()
    assert "cannot compute metrics" in one_error_line(run_cli("review", log, "--json"), str(log))
    table = run_cli("review", log)
    assert table.exit_code == 0 and "metrics: not available" in table.stdout


def test_truncated_file_is_reviewed_with_a_warning(lab_log, tmp_path):
    path, expected = lab_log
    raw = path.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(raw[: len(raw) - 300])  # the summary section and footer gone; every chunk kept
    result = run_cli("review", cut, "--json")
    assert result.exit_code == 0, result.output
    (warning,) = result.stderr.strip().splitlines()
    assert warning.startswith(f"{cut}: warning:")
    got = json.loads(result.stdout)
    assert {k: got[k] for k in expected} == expected
    assert got["log"]["truncated"] is True and [i["how"] for i in got["interruptions"]] == ["killed"]


def test_sim_log_to_an_unwritable_path(tmp_path):
    log = tmp_path / "missing" / "x.mcap"
    result = run_cli("sim", Path(MISSIONS / "lab-3.yaml"), "--log", log)
    one_error_line(result, str(log))
