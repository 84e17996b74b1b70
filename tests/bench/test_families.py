"""The families suite: a 1-seed x 2-family run end to end with the shipped ONNX policies (onnxruntime), the
guidance axis read from the settings dataclass, the margin counts, the claims judged per family, the CLI."""

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import pytest
from typer.testing import CliRunner

from rpf_fly.bench.claims import FAMILY_CLAIMS, HELD, NOT_EVALUATED, NOT_HELD, evaluate_claims
from rpf_fly.bench.families import (
    FAMILY_PLANNERS,
    FamiliesConfig,
    guidance_modes,
    planner_margin,
    prepare_families,
    results_json,
    run_families,
    summarise_family,
    to_markdown,
    with_guidance,
)
from rpf_fly.bench.runner import BenchError, RunRecord, summarise_runs
from rpf_fly.cli import get_app
from rpf_fly.mission.model import PlannerSettings

ROOT = Path(__file__).resolve().parents[2]
POLICIES = ROOT / "policies"


@pytest.fixture(scope="module")
def smoke():
    config = FamiliesConfig(families=("arena-a", "arena-b"), seeds=1, policies_dir=POLICIES)
    plan = prepare_families(config)
    seen = []
    result = run_families(plan, seen.append)
    return plan, result, seen, results_json(result, "rpf-fly bench --suite families --seeds 1")


def test_smoke_runs_every_planner_on_both_families(smoke):
    plan, result, seen, doc = smoke
    # rpf, rpf-mean and ppo by name, and rpf3 as the product's default (`default`)
    assert not plan.missing and set(plan.policies) == {"rpf", "rpf-mean", "ppo", "rpf3"}
    assert all(info.sha256 for info in plan.policies.values())
    modes = guidance_modes()  # ("none",) until planner.guidance lands, then every mode it offers
    assert plan.config.modes() == modes and modes[0] == "none"
    assert plan.total_runs == len(FAMILY_PLANNERS) * 2 * len(modes) == len(seen) == len(result.runs)
    keys = {(r["planner"], r["scene"], r["guidance"]) for r in result.rows}
    assert keys == {(p, f, m) for p in FAMILY_PLANNERS for f in ("arena-a", "arena-b") for m in modes}
    for row in result.rows:
        assert row["status"] == "ok" and row["runs"] == 1
        run = next(
            r
            for m, r in result.runs
            if r.planner == row["planner"] and r.scene == row["scene"] and m == row["guidance"]
        )
        assert row["min_separation_m"]["min"] == run.min_separation_m
        bar = row["below_margin"]["separation_bar_m"]
        assert bar == pytest.approx(0.25)
        assert row["below_margin"]["runs_separation"] == int(run.min_separation_m < bar)
        if row["scene"] == "arena-b":
            assert row["min_obstacle_clearance_m"] is None
        else:
            assert row["below_margin"]["runs_clearance"] == int(run.min_obstacle_clearance_m < 0.15)
    # the product's default is PlannerSettings().kind (RPF-3): flown exactly as that kind by name
    assert PlannerSettings().kind == "rpf3"
    default = {(m, r.scene): r for m, r in result.runs if r.planner == "default"}
    named = run_families(
        prepare_families(
            FamiliesConfig(planners=("rpf3",), families=("arena-a", "arena-b"), seeds=1, policies_dir=POLICIES)
        )
    )
    same = {(m, r.scene): r for m, r in named.runs}
    assert {s: r.travel_distance_m for s, r in default.items()} == {s: r.travel_distance_m for s, r in same.items()}


def test_smoke_json_markdown_and_claims(smoke):
    plan, result, seen, doc = smoke
    text = json.dumps(doc)
    back = json.loads(text)
    assert back["split"] == "bench" and back["seeds"] == {"first": 0, "count": 1}
    assert back["guidance"] == list(guidance_modes()) and len(back["runs"]) == len(seen)
    assert {run["guidance"] for run in back["runs"]} == set(guidance_modes())
    assert set(back["claims"]) == set(guidance_modes())
    claims = {c["id"]: c for c in back["claims"]["none"]}
    assert set(claims) == set("abcde")
    assert claims["b"]["status"] == NOT_EVALUATED  # the circle family did not run
    assert claims["a"]["status"] in (HELD, NOT_HELD) and set(claims["a"]["numbers"]) == {"arena-b"}
    assert "not run: circle" in claims["a"]["note"]
    assert claims["c"]["status"] in (HELD, NOT_HELD) and "arena-a" in claims["c"]["numbers"]
    assert claims["e"]["status"] in (HELD, NOT_HELD) and claims["e"]["numbers"]["runs"] == 1
    assert claims["d"]["numbers"]["runs"] == 2
    md = to_markdown(back)
    assert "### arena-a" in md and "### arena-b" in md and "default (RPF-3)" in md
    assert "rpf-fly bench --suite families --seeds 1" in md
    assert max(len(line) for line in md.splitlines()) <= 110
    assert "- **(e) " in md and "## The paper's claims, guidance none" in md


@dataclass(frozen=True)
class WithGuidance:
    kind: str = "apf"
    guidance: Literal["none", "path"] = "path"


@dataclass(frozen=True)
class OptionalGuidance:
    kind: str = "apf"
    guidance: Literal["none", "path"] | None = None
    margin: float | None = None

    @property
    def margin_m(self) -> float:
        return 0.05 if self.margin is None else self.margin


@dataclass(frozen=True)
class GuidanceReversed:
    guidance: Literal["path", "none", "visibility"] = "none"


def test_guidance_modes_come_from_the_settings_dataclass():
    offered = guidance_modes()
    if any(f == "guidance" for f in PlannerSettings.__dataclass_fields__):
        assert "none" in offered and len(offered) >= 2
    else:
        assert offered == ("none",)
        assert with_guidance(PlannerSettings(), "none") == PlannerSettings()
        with pytest.raises(BenchError):
            with_guidance(PlannerSettings(), "path")
    assert guidance_modes(WithGuidance) == ("none", "path")
    assert guidance_modes(GuidanceReversed) == ("none", "path", "visibility")
    assert guidance_modes(OptionalGuidance) == ("none", "path")  # the guidance branch's shape: None = kind default
    assert with_guidance(OptionalGuidance(), "path").guidance == "path"
    assert planner_margin(OptionalGuidance()) == 0.05 and planner_margin(OptionalGuidance(margin=0.0)) == 0.0
    assert planner_margin(PlannerSettings()) == getattr(PlannerSettings(), "margin_m", None)
    assert with_guidance(WithGuidance(), "none") == WithGuidance(guidance="none")


def test_prepare_refuses_bad_names_and_marks_a_missing_policy(tmp_path):
    with pytest.raises(BenchError):
        prepare_families(FamiliesConfig(families=("maze",)))
    with pytest.raises(BenchError):
        prepare_families(FamiliesConfig(planners=("rrt",)))
    with pytest.raises(BenchError):
        prepare_families(FamiliesConfig(seeds=0))
    with pytest.raises(BenchError):
        prepare_families(FamiliesConfig(guidance=("teleport",)))
    plan = prepare_families(
        FamiliesConfig(
            planners=("rpf", "apf"), families=("arena-b",), seeds=1, policy_paths={"rpf": tmp_path / "none.onnx"}
        )
    )
    assert "no policy file" in plan.missing["rpf"] and plan.total_runs == len(guidance_modes())
    result = run_families(plan)
    rows = {r["planner"]: r for r in result.rows}
    assert rows["rpf"]["status"] == "missing" and rows["apf"]["status"] == "ok"


def _record(seed, sep, clear, success=True):
    return RunRecord(
        "apf",
        "doorway",
        seed,
        2,
        2,
        success,
        0,
        0,
        5.0,
        0.01,
        12.0,
        sep,
        clear,
        {"reached": 2, "stalled": 0, "timeout": 0},
        None if success else "stalled",
    )


def test_margin_counts_are_strictly_below_the_bars():
    runs = [_record(0, 0.24, 0.149), _record(1, 0.25, 0.15), _record(2, 0.31, 0.40)]
    row = summarise_family("apf", "doorway", "none", runs, 0.1, 0.05)
    assert row["below_margin"]["runs_separation"] == 1 and row["below_margin"]["runs_clearance"] == 1
    assert row["min_separation_m"]["min"] == 0.24 and row["min_obstacle_clearance_m"]["min"] == 0.149
    wider = summarise_family("apf", "doorway", "none", runs, 0.1, 0.1)
    assert wider["below_margin"]["runs_separation"] == 2 and wider["below_margin"]["runs_clearance"] == 2


def _row(planner, scene, travel, smooth, successes=2):
    runs = [
        RunRecord(
            planner,
            scene,
            s,
            4,
            4,
            s < successes,
            0,
            0,
            travel,
            smooth,
            10.0,
            0.3,
            None,
            {"reached": 4, "stalled": 0, "timeout": 0},
            None if s < successes else "stalled",
        )
        for s in range(2)
    ]
    return {**summarise_runs(planner, scene, runs), "guidance": "none"}, [r.to_json_dict() for r in runs]


def test_a_family_claim_holds_only_where_it_holds_on_every_family():
    rows, runs = [], []
    for scene, rpf_travel in (("circle", 5.0), ("arena-b", 7.0)):
        for planner, travel in (("rpf", rpf_travel), ("rpf-mean", 6.0), ("apf", 8.0)):
            row, rr = _row(planner, scene, travel, 0.01 if planner == "rpf" else 0.02)
            rows.append(row)
            runs += rr
    claims = {c.id: c for c in evaluate_claims({"rows": rows, "runs": runs}, FAMILY_CLAIMS)}
    assert claims["a"].status == NOT_HELD  # held on circle, not on arena-b (RPF-2 shorter)
    assert "circle: held" in claims["a"].note and "arena-b: not held" in claims["a"].note
    only_circle = {"rows": [r for r in rows if r["scene"] == "circle"], "runs": runs}
    assert {c.id: c for c in evaluate_claims(only_circle, FAMILY_CLAIMS)}["a"].status == HELD


def test_cli_families_suite_writes_json_and_markdown(tmp_path):
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
            "apf,orca",
            "--out",
            str(tmp_path),
        ],
    )
    assert result.exit_code == 0, result.output
    doc = json.loads((tmp_path / "families.json").read_text())
    assert doc["families"] == ["arena-b"] and {r["planner"] for r in doc["rows"]} == {"apf", "orca"}
    md = (tmp_path / "families.md").read_text()
    assert "--suite families --seeds 1 --families arena-b --planners apf,orca" in md
    bad = CliRunner().invoke(get_app(), ["bench", "--suite", "families", "--families", "maze"])
    assert bad.exit_code == 2 and "maze" in bad.stderr
    wrong = CliRunner().invoke(get_app(), ["bench", "--guidance", "none", "--episodes", "1"])
    assert wrong.exit_code == 2 and "--suite families" in wrong.stderr


def test_first_seed_runs_later_bench_seeds_and_says_so(tmp_path):
    """--first-seed F: seeds F..F+N-1 (scenes nobody looked at), in the JSON, each run and the command line."""
    result = CliRunner().invoke(
        get_app(),
        [
            "bench",
            "--suite",
            "families",
            "--seeds",
            "2",
            "--first-seed",
            "140",
            "--families",
            "arena-b",
            "--planners",
            "apf",
            "--guidance",
            "path",
            "--json-file",
            str(tmp_path / "f.json"),
        ],
    )
    assert result.exit_code == 0, result.output
    doc = json.loads((tmp_path / "f.json").read_text())
    assert doc["seeds"] == {"first": 140, "count": 2} and [r["seed"] for r in doc["runs"]] == [140, 141]
    assert "--seeds 2 --first-seed 140 --families arena-b" in doc["command"]
    later = run_families(
        prepare_families(
            FamiliesConfig(planners=("apf",), families=("arena-b",), seeds=1, guidance=("path",), first_seed=141)
        )
    )
    assert (
        later.runs[0][1].to_json_dict()
        == [
            r
            for m, r in run_families(
                prepare_families(
                    FamiliesConfig(
                        planners=("apf",), families=("arena-b",), seeds=2, guidance=("path",), first_seed=140
                    )
                )
            ).runs
        ][1].to_json_dict()
    )
    paper = CliRunner().invoke(get_app(), ["bench", "--first-seed", "3", "--episodes", "1"])
    assert paper.exit_code == 2 and "--first-seed" in paper.stderr
    negative = CliRunner().invoke(get_app(), ["bench", "--suite", "families", "--first-seed", "-1", "--seeds", "1"])
    assert negative.exit_code == 2 and "first seed" in negative.stderr


def test_worker_processes_give_the_same_runs_in_the_same_order():
    config = FamiliesConfig(planners=("apf", "orca"), families=("arena-b", "crossing"), seeds=1)
    one = run_families(prepare_families(config))
    seen = []
    two = run_families(prepare_families(config), seen.append, jobs=2)
    assert [(m, r.to_json_dict()) for m, r in one.runs] == [(m, r.to_json_dict()) for m, r in two.runs]
    assert one.rows == two.rows and len(seen) == 4 * len(guidance_modes())


def test_rpf3_is_benched_by_name_with_its_guidance_and_margin():
    """RPF-3 is not in the default planner list (it is not the default); named, it runs with its own policy,
    guidance path and margin 0.05 (its kind's defaults)."""
    assert "rpf3" not in FAMILY_PLANNERS
    plan = prepare_families(FamiliesConfig(planners=("rpf3",), families=("arena-b",), seeds=1, policies_dir=POLICIES))
    assert not plan.missing and plan.policies["rpf3"].sha256
    settings = plan.settings["rpf3"]
    assert settings.kind == "rpf3" and settings.guidance_mode == "path" and settings.margin_m == 0.05
    assert settings.policy == (POLICIES / "rpf3.onnx").resolve()
    with pytest.raises(BenchError):
        prepare_families(FamiliesConfig(planners=("rpf4",), families=("arena-b",), seeds=1))
