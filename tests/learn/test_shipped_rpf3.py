"""RPF-3 (policies/rpf3.onnx): its model card matches it, it reads the training env's guided observation, and it flies
a generated bench scene with guidance and the margin (onnxruntime, no torch needed)."""

import hashlib
from pathlib import Path

import yaml

from rpf_fly.learn.env import EnvConfig, SwarmEnv
from rpf_fly.mission.model import PlannerSettings
from rpf_fly.planning.onnx_policy import OnnxPolicy
from rpf_fly.sim.evaluate import run_scenario
from rpf_fly.sim.generators import generate
from rpf_fly.sim.rollout import SimParams

ROOT = Path(__file__).resolve().parents[2]
POLICY = ROOT / "policies" / "rpf3.onnx"


def test_rpf3_card_matches_the_policy_and_records_guidance_and_margin():
    card = yaml.safe_load((ROOT / "policies" / "rpf3.yaml").read_text())
    assert card["policy"] == "rpf3.onnx" and card["kind"] == "rpf3"
    assert card["sha256"] == hashlib.sha256(POLICY.read_bytes()).hexdigest()
    assert card["command"].startswith("rpf-fly train") and "--guidance path" in card["command"]
    hyper = card["training"]["hyperparameters"]
    assert hyper["guidance"] == "path" and hyper["margin"] == 0.05 and hyper["curriculum"]
    assert card["training"]["wall_time_s"] > 0 and card["training"]["cpu_time_s"] > 0
    assert (ROOT / "policies" / card["curves"]["csv"]).exists() and (ROOT / "policies" / card["curves"]["png"]).exists()
    assert card["bench"]["command"].startswith("rpf-fly bench --suite families")
    loaded = OnnxPolicy(POLICY)
    assert loaded.action == "gains" and loaded.max_neighbours == 10


def test_rpf3_reads_the_guided_training_observation():
    """The env RPF-3 trained in (guidance, margin, walled families) gives observations the ONNX graph takes as is;
    its gains lie in the trained ranges and drive the env's steps."""
    env = SwarmEnv(
        EnvConfig(n_arenas=3, curriculum=("doorway", "pillars", "circle"), guidance="path", margin=0.05), seed=4
    )
    policy = OnnxPolicy(POLICY)
    for _ in range(3):
        action = policy.act(env.observation)
        assert action.shape == (3, 6, 2)
        assert (action[..., 0] > 0).all() and (action[..., 0] < 0.1).all()
        assert (action[..., 1] > 0).all() and (action[..., 1] < 5).all()
        env.step(action.astype(float))


def test_rpf3_flies_a_bench_scene_with_guidance_and_the_margin():
    settings = PlannerSettings(kind="rpf3", policy=POLICY)
    assert settings.guidance_mode == "path" and settings.margin_m == 0.05
    run = run_scenario(generate("arena-b", 0, split="bench"), settings, SimParams(), 0, "arena-b")
    m = run.metrics
    assert m.success and m.collisions_drone_drone == 0 and m.collisions_drone_obstacle == 0
    assert m.margin_m == 0.05 and m.margin_held  # no pair within 2r + margin, no drone within r + margin
