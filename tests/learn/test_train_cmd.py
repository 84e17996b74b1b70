"""``rpf-fly train`` never overwrites a policy or its model card without ``--force`` (the README's own example
names the shipped ``policies/rpf.onnx``)."""

import hashlib
import shutil
from pathlib import Path

from typer.testing import CliRunner

from rpf_fly.cli import get_app

ROOT = Path(__file__).resolve().parents[2]
runner = CliRunner()


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def shipped_copy(tmp_path: Path) -> Path:
    folder = tmp_path / "policies"
    folder.mkdir()
    for suffix in (".onnx", ".yaml", ".curve.csv", ".curve.png"):
        shutil.copy(ROOT / "policies" / f"rpf{suffix}", folder / f"rpf{suffix}")
    return folder / "rpf.onnx"


def test_an_existing_policy_is_refused_with_one_line_and_left_alone(tmp_path):
    out = shipped_copy(tmp_path)
    before = {p.name: digest(p) for p in out.parent.iterdir()}
    result = runner.invoke(get_app(), ["train", "--out", str(out), "--episodes", "1", "--eval-seeds", "0"])
    assert result.exit_code == 2, result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "--force" in lines[0] and str(out) in lines[0], result.stderr
    assert str(out.with_suffix(".yaml")) in lines[0]  # the model card is named too
    assert {p.name: digest(p) for p in out.parent.iterdir()} == before
    assert not out.with_suffix(".run").exists()  # nothing started


def test_a_lone_model_card_is_protected_too(tmp_path):
    out = tmp_path / "mine.onnx"
    out.with_suffix(".yaml").write_text("policy: mine.onnx\n")
    result = runner.invoke(get_app(), ["train", "--out", str(out)])
    assert result.exit_code == 2 and "mine.yaml" in result.stderr
    assert out.with_suffix(".yaml").read_text() == "policy: mine.onnx\n"


def test_force_goes_past_the_check(tmp_path):
    out = shipped_copy(tmp_path)
    # --resume without a checkpoint fails after the overwrite check (and before any training).
    result = runner.invoke(get_app(), ["train", "--out", str(out), "--force", "--resume"])
    assert result.exit_code == 2, result.output
    assert "--resume: no checkpoint" in result.stderr and "refusing" not in result.stderr


def test_an_unknown_curriculum_family_is_refused_before_training(tmp_path):
    out = tmp_path / "p.onnx"
    result = runner.invoke(get_app(), ["train", "--out", str(out), "--curriculum", "corridor,maze", "--episodes", "1"])
    assert result.exit_code == 2, result.output
    assert "maze" in result.stderr and "corridor" in result.stderr
    assert not out.with_suffix(".run").exists()


def test_guidance_and_margin_are_checked_before_training(tmp_path):
    out = tmp_path / "p.onnx"
    result = runner.invoke(get_app(), ["train", "--out", str(out), "--guidance", "astar", "--episodes", "1"])
    assert result.exit_code == 2 and "--guidance" in result.stderr and "astar" in result.stderr
    result = runner.invoke(get_app(), ["train", "--out", str(out), "--guidance", "path", "--margin", "-0.1"])
    assert result.exit_code == 2 and "--margin" in result.stderr
    assert not out.with_suffix(".run").exists()


def test_the_card_of_a_guided_run_records_guidance_margin_cpu_time_and_load(tmp_path):
    """What ``rpf-fly train`` writes after training (one tiny guided update, then the CLI's own export and card)."""
    import yaml

    from rpf_fly.cli.train_cmd import _finish
    from rpf_fly.learn.ppo import PPOConfig, Trainer
    from rpf_fly.planning.onnx_policy import OnnxPolicy

    config = PPOConfig(
        n_arenas=1,
        rollout_steps=8,
        max_updates=1,
        episodes=10**9,
        curriculum=("arena-b",),
        guidance="path",
        margin=0.05,
        threads=1,
        epochs=1,
        minibatch_size=8,
        eval_every=10**9,
    )
    trainer = Trainer(config, tmp_path / "g.run")
    trainer.run()
    out = tmp_path / "g.onnx"
    _finish(trainer, out, "rpf-fly train --guidance path --margin 0.05", 0, ROOT / "missions", 1.0, "0" * 40, 0.5)
    card = yaml.safe_load(out.with_suffix(".yaml").read_text())
    assert card["training"]["cpu_time_s"] == 0.5 and len(card["training"]["load_average_at_end"]) == 3
    hyper = card["training"]["hyperparameters"]
    assert hyper["guidance"] == "path" and hyper["margin"] == 0.05
    meta = OnnxPolicy(out).metadata
    assert meta["rpf_fly.guidance"] == "path" and float(meta["rpf_fly.margin"]) == 0.05
