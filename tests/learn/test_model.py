"""The actor-critic: masked attention, action ranges, normalisation."""

import dataclasses

import numpy as np
import pytest
import torch

from rpf_fly.learn.model import ActorCritic, ModelConfig, RunningNorm


def obs(batch=5, k=10, seed=0):
    g = torch.Generator().manual_seed(seed)
    local = torch.rand(batch, 4, generator=g) * 5
    neighbours = torch.rand(batch, k, 3, generator=g) * 3
    mask = (torch.arange(k)[None, :] < torch.tensor([0, 1, 3, 7, 10])[:batch, None]).float()
    return local, neighbours * mask.unsqueeze(-1), mask


@pytest.mark.parametrize("embedding", ["attention", "mean"])
def test_no_neighbours_gives_zero_context_and_finite_actions(embedding):
    model = ActorCritic(ModelConfig(embedding=embedding))
    local, neighbours, mask = obs()
    c = model.embedding(local, neighbours, mask)
    assert torch.all(c[0] == 0)
    assert torch.isfinite(model.deterministic(local, neighbours, mask)).all()


@pytest.mark.parametrize("embedding", ["attention", "mean"])
def test_permutation_invariant_and_padding_ignored(embedding):
    model = ActorCritic(ModelConfig(embedding=embedding))
    local, neighbours, mask = obs()
    out = model.deterministic(local, neighbours, mask)
    perm = torch.tensor([2, 0, 1, 3, 4, 5, 6, 7, 8, 9])
    row = 3  # 7 neighbours: permute among the first three
    n2 = neighbours.clone()
    n2[row] = neighbours[row, perm]
    assert torch.allclose(model.deterministic(local, n2, mask), out, atol=1e-6)
    n3 = neighbours.clone()
    n3[:, 9] = 99.0  # padding slot of rows with fewer than 10 neighbours
    changed = model.deterministic(local, n3, mask)
    assert torch.allclose(changed[:4], out[:4], atol=1e-6)


def test_attention_weights_depend_on_neighbours_mean_does_not_weigh():
    att = ActorCritic(ModelConfig(embedding="attention"))
    local, neighbours, mask = obs()
    c = att.embedding(local, neighbours, mask)
    assert c.shape == (5, 64)


def test_action_ranges_even_for_extreme_inputs():
    local, neighbours, mask = obs()
    for action, low, high in (("gains", [0, 0], [0.1, 5.0]), ("heading", [-2.5], [2.5])):
        model = ActorCritic(ModelConfig(action=action))
        with torch.no_grad():
            for layer in model.actor:
                if isinstance(layer, torch.nn.Linear):
                    layer.weight.mul_(50)
        a = model.to_action(torch.tensor([[-1e3, 1e3], [1e3, -1e3]])[:, : model.config.action_size])
        assert torch.all(a >= torch.tensor(low) - 1e-9) and torch.all(a <= torch.tensor(high) + 1e-9)
        out = model.deterministic(local * 100, neighbours, mask)
        assert torch.all(out >= torch.tensor(low) - 1e-9) and torch.all(out <= torch.tensor(high) + 1e-9)


def test_untrained_gains_policy_starts_near_vanilla_apf():
    model = ActorCritic(ModelConfig())
    out = model.deterministic(*obs())
    assert torch.allclose(out[:, 0], torch.tensor(0.05), atol=0.005)
    assert torch.allclose(out[:, 1], torch.tensor(2.5), atol=0.25)


def test_running_norm_matches_numpy_over_batches():
    norm = RunningNorm(3)
    rng = np.random.default_rng(0)
    batches = [rng.normal(2.0, 3.0, (n, 3)) for n in (50, 7, 300)]
    for b in batches:
        norm.update(torch.from_numpy(b).float())
    everything = np.concatenate(batches)
    assert norm.mean.numpy() == pytest.approx(everything.mean(0), rel=1e-4)
    assert norm.var.numpy() == pytest.approx(everything.var(0), rel=1e-3)


def test_ppo_update_survives_a_one_sample_minibatch(tmp_path):
    """A rollout whose valid-sample count leaves a remainder of 1 must not turn the weights into NaN."""
    from rpf_fly.learn.ppo import PPOConfig, Trainer

    trainer = Trainer(PPOConfig(n_arenas=2, rollout_steps=8, minibatch_size=4, eval_every=10**9, threads=1), tmp_path)
    batch = trainer._collect()
    keep = 4 * ((batch["local"].shape[0] - 1) // 4) + 1  # a remainder of exactly one sample
    assert keep % 4 == 1 and keep > 1
    batch = {
        k: (v[:keep] if hasattr(v, "shape") and v.shape[:1] == batch["local"].shape[:1] else v)
        for k, v in batch.items()
    }
    trainer._learn(batch)
    assert all(torch.isfinite(p).all() for p in trainer.model.parameters())


def test_training_resumes_from_its_checkpoint(tmp_path):
    """A run stopped after 2 updates continues from the checkpoint: weights, optimiser, counters and curve."""
    from rpf_fly.learn.ppo import PPOConfig, Trainer

    config = PPOConfig(
        n_arenas=2,
        rollout_steps=16,
        minibatch_size=64,
        eval_every=10**9,
        checkpoint_every=1,
        threads=1,
        episodes=10**9,
        max_updates=2,
    )
    first = Trainer(config, tmp_path)
    first.run()
    saved = {k: v.clone() for k, v in first.model.state_dict().items()}
    resumed = Trainer(dataclasses.replace(config, max_updates=3), tmp_path)
    resumed.load_checkpoint()
    assert resumed.update == 2 and len(resumed.history) == 2
    assert all(torch.equal(saved[k], v) for k, v in resumed.model.state_dict().items())
    resumed.run()
    assert resumed.update == 3 and [h.update for h in resumed.history] == [1, 2, 3]
    assert (tmp_path / "training_curve.csv").read_text().count("\n") == 4  # header + 3 updates
