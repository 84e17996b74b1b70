"""The shipped policies: RPF-1 (policies/rpf.onnx) flies the paper missions, as the missions now ask for it."""

import json
from pathlib import Path

import pytest
import yaml
from typer.testing import CliRunner

from rpf_fly.cli import get_app
from rpf_fly.planning.onnx_policy import OnnxPolicy

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("mission", ["lab-3", "circle-8-r3", "arena-a-6"])
def test_shipped_rpf_policy_succeeds_on_paper_missions(mission):
    result = CliRunner().invoke(
        get_app(), ["sim", str(ROOT / "missions" / f"{mission}.yaml"), "--json", "--seed", "3", "--planner", "rpf"]
    )  # lab-3 flies the default planner, RPF-3
    assert result.exit_code == 0, result.output
    metrics = json.loads(result.stdout)
    assert metrics["planner"] == "rpf"
    assert metrics["success"] and metrics["collisions"] == {"drone_drone": 0, "drone_obstacle": 0}


@pytest.mark.parametrize("kind", ["rpf", "rpf-mean", "ppo"])
def test_each_shipped_policy_has_a_model_card_that_matches_it(kind):
    import hashlib

    policy = ROOT / "policies" / f"{kind}.onnx"
    card = yaml.safe_load((ROOT / "policies" / f"{kind}.yaml").read_text())
    assert card["kind"] == kind and card["sha256"] == hashlib.sha256(policy.read_bytes()).hexdigest()
    assert card["command"].startswith("rpf-fly train") and card["seed"] == 0 and len(card["commit"]) >= 40
    assert card["training"]["wall_time_s"] > 0 and card["training"]["env_steps"] > 0
    loaded = OnnxPolicy(policy)
    assert loaded.action == ("heading" if kind == "ppo" else "gains")
    assert loaded.metadata["rpf_fly.kind"] == kind
