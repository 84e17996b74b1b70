"""`rpf-fly bench --dynamics kinematic|firmware`: the kinematic default flies as before (the shipped results), the
firmware closed loop runs through both suites and says so in the JSON and the Markdown, a bad value is one line."""

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from rpf_fly.bench.families import FamiliesConfig, prepare_families, run_families
from rpf_fly.bench.report import results_json, to_markdown
from rpf_fly.bench.runner import BenchConfig, BenchError, prepare, run_bench
from rpf_fly.cli import bench_cmd, get_app
from rpf_fly.sim.closed_loop import DYNAMICS

ROOT = Path(__file__).resolve().parents[2]
SHIPPED = ROOT / "docs" / "bench"


def test_the_cli_offers_the_closed_loop_dynamics():
    assert bench_cmd._DYNAMICS == DYNAMICS == ("kinematic", "firmware")
    assert BenchConfig().dynamics == FamiliesConfig().dynamics == "kinematic"


def test_the_kinematic_default_reproduces_the_shipped_results():
    """The default runs are the runs shipped in docs/bench (written by the kinematic bench before the closed loop
    existed), record for record."""
    families = json.loads((SHIPPED / "families.json").read_text())
    shipped = {(r["guidance"], r["planner"], r["scene"], r["seed"]): r for r in families["runs"]}
    result = run_families(
        prepare_families(
            FamiliesConfig(planners=("apf", "orca"), families=("arena-b", "crossing"), seeds=2, guidance=("none",))
        )
    )
    assert len(result.runs) == 8
    for mode, record in result.runs:
        assert {**record.to_json_dict(), "guidance": mode} == shipped[(mode, record.planner, record.scene, record.seed)]
    paper = json.loads((SHIPPED / "results.json").read_text())
    shipped = {(r["planner"], r["scene"], r["seed"]): r for r in paper["runs"]}
    bench = run_bench(
        prepare(BenchConfig(planners=("apf", "orca"), scenes=("lab-3",), episodes=2, missions_dir=ROOT / "missions"))
    )
    assert [r.to_json_dict() for r in bench.runs] == [shipped[(r.planner, r.scene, r.seed)] for r in bench.runs]
    doc = results_json(bench)
    assert doc["dynamics"] == "kinematic" and "closed_loop" not in doc
    assert "Dynamics: kinematic" in to_markdown(doc)


def test_the_families_suite_flies_the_firmware_closed_loop(tmp_path):
    result = CliRunner().invoke(
        get_app(),
        [
            "bench",
            "--suite",
            "families",
            "--seeds",
            "1",
            "--families",
            "arena-b",
            "--planners",
            "orca",
            "--guidance",
            "none",
            "--dynamics",
            "firmware",
            "--json-file",
            str(tmp_path / "f.json"),
            "--markdown",
            str(tmp_path / "f.md"),
        ],
    )
    assert result.exit_code == 0, result.output
    doc = json.loads((tmp_path / "f.json").read_text())
    assert doc["dynamics"] == "firmware" and doc["closed_loop"]["truth_hz"] == 100
    assert doc["command"].endswith("--guidance none --dynamics firmware")
    [run] = doc["runs"]
    assert run["success"] and run["reached"] == 6
    md = (tmp_path / "f.md").read_text()
    assert "Dynamics: firmware" in md and "--dynamics firmware" in md


def test_the_paper_suite_flies_the_firmware_closed_loop(tmp_path):
    """lab-3 with its drones 0.6 m short of their goals (a short flight keeps the test short)."""
    text = (ROOT / "missions" / "lab-3.yaml").read_text().replace("../policies", str(ROOT / "policies"))
    for y, goal in (("-1.2", "1.2"), ("0.0", "0.0"), ("1.2", "-1.2")):
        text = text.replace(f"start: [-1.5, {y}], goal: [1.5, {goal}]", f"start: [0.9, {y}], goal: [1.5, {y}]")
    (tmp_path / "lab-3.yaml").write_text(text)
    plan = prepare(
        BenchConfig(planners=("apf",), scenes=("lab-3",), episodes=1, missions_dir=tmp_path, dynamics="firmware")
    )
    assert not plan.missing
    result = run_bench(plan)
    [record] = result.runs
    assert record.success and record.reached == 3
    [trajectory] = result.trajectories  # the tick truth of seed 0
    assert abs(trajectory.positions[-1] - trajectory.goals).max() < 0.1
    doc = results_json(result)
    assert doc["dynamics"] == "firmware" and doc["closed_loop"]["plan_from"] == "flight"
    assert "Dynamics: firmware" in to_markdown(doc)


def test_a_bad_dynamics_is_one_clear_line():
    for suite in ("paper", "families"):
        bad = CliRunner().invoke(get_app(), ["bench", "--suite", suite, "--dynamics", "rigid", "--seeds", "1"])
        assert bad.exit_code == 2
        assert bad.stderr.strip().splitlines() == ["--dynamics: expected kinematic or firmware, got 'rigid'"]
    with pytest.raises(BenchError, match="unknown dynamics 'rigid'"):
        prepare(BenchConfig(dynamics="rigid"))
    with pytest.raises(BenchError, match="unknown dynamics 'rigid'"):
        prepare_families(FamiliesConfig(dynamics="rigid"))
