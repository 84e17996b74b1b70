"""ONNX export: parity with torch, empty neighbour sets, metadata, and the runtime planners that load it."""

import numpy as np
import pytest
import torch

from rpf_fly.learn.export import check_parity, export_onnx, random_observations
from rpf_fly.learn.model import ActorCritic, ModelConfig
from rpf_fly.planning.observation import Observation
from rpf_fly.planning.onnx_policy import OnnxGains, OnnxPolicy, PolicyError
from rpf_fly.sim import circle_swap
from rpf_fly.sim.evaluate import planner_settings, run_scenario
from rpf_fly.sim.rollout import SimParams


def trained_looking(config):
    """An untrained model with non-trivial normalisation statistics and weights."""
    torch.manual_seed(0)
    model = ActorCritic(config)
    model.local_norm.mean += torch.tensor([1.0, 0.2, 3.0, -0.1])
    model.local_norm.var *= 2.5
    with torch.no_grad():
        model.actor[-1].weight.normal_(0, 0.3)
    return model


@pytest.mark.parametrize(
    "config",
    [ModelConfig(), ModelConfig(embedding="mean"), ModelConfig(action="heading")],
    ids=["rpf", "rpf-mean", "ppo"],
)
def test_export_parity_and_metadata(tmp_path, config):
    model = trained_looking(config)
    path = export_onnx(model, tmp_path / "p.onnx", {"rpf_fly.kind": "test"})
    assert check_parity(model, path) < 1e-5
    policy = OnnxPolicy(path)
    assert policy.action == config.action and policy.max_neighbours == config.max_neighbours
    assert policy.metadata["rpf_fly.kind"] == "test"
    # Zero neighbours for every drone of a batch, and a single drone with no leading batch axis.
    local, neighbours, mask = random_observations(3, config.max_neighbours)
    empty = Observation(local, neighbours * 0, np.zeros_like(mask, dtype=bool))
    with torch.no_grad():
        want = model.deterministic(
            torch.from_numpy(local),
            torch.zeros_like(torch.from_numpy(neighbours)),
            torch.zeros(3, config.max_neighbours),
        )
    np.testing.assert_allclose(policy.act(empty), want.numpy(), rtol=1e-5, atol=1e-6)
    single = Observation(local[0], neighbours[0], mask[0].astype(bool))
    assert policy.act(single).shape == (config.action_size,)


def test_float32_export_when_parity_holds_float64_when_not(tmp_path):
    plain = export_onnx(ActorCritic(ModelConfig()), tmp_path / "plain.onnx")
    assert OnnxPolicy(plain).metadata["rpf_fly.precision"] == "float32"
    model = trained_looking(ModelConfig(action="heading"))
    with torch.no_grad():
        model.actor[-1].weight.normal_(0, 3.0)  # large output weights: float32 summation order shows
    wide = export_onnx(model, tmp_path / "wide.onnx")
    assert OnnxPolicy(wide).metadata["rpf_fly.precision"] in ("float32", "float64")
    assert check_parity(model, wide) < 1e-5


def test_non_rpf_onnx_and_wrong_kind_are_refused(tmp_path):
    bogus = tmp_path / "bogus.onnx"
    bogus.write_bytes(b"not an onnx file")
    with pytest.raises(PolicyError, match="cannot load"):
        OnnxPolicy(bogus)
    heading = export_onnx(trained_looking(ModelConfig(action="heading")), tmp_path / "h.onnx")
    with pytest.raises(PolicyError, match="cannot set APF gains"):
        OnnxGains(OnnxPolicy(heading))


@pytest.mark.parametrize("kind, config", [("rpf", ModelConfig()), ("ppo", ModelConfig(action="heading"))])
def test_exported_policy_flies_in_the_simulator(tmp_path, kind, config):
    path = export_onnx(ActorCritic(config), tmp_path / f"{kind}.onnx")
    run = run_scenario(
        circle_swap(4, 2.0), planner_settings(kind, path), SimParams(time_limit_s=40), 0, "c4", keep=True
    )
    assert run.metrics.drones == 4
    if kind == "rpf":  # the untrained gains policy is the vanilla APF with eta 0.05, lambda 2.5
        assert run.metrics.success
        assert np.allclose(run.rollout.eta, 0.05, atol=0.005)


def test_one_drone_fast_path_equals_batched_call(tmp_path):
    """The bound-buffer path for one drone returns what session.run returns for the same observation."""
    policy = OnnxPolicy(export_onnx(trained_looking(ModelConfig()), tmp_path / "p.onnx"))
    local, neighbours, mask = random_observations(12, 10)
    batched = policy.act(Observation(local, neighbours, mask.astype(bool)))
    for i in range(12):
        one = policy.act(Observation(local[i], neighbours[i], mask[i].astype(bool)))
        feeds = {"local": local[i : i + 1], "neighbours": neighbours[i : i + 1], "mask": mask[i : i + 1]}
        np.testing.assert_array_equal(one, policy.session.run(["action"], feeds)[0][0])  # same input, same result
        np.testing.assert_allclose(one, batched[i], rtol=1e-5, atol=1e-6)  # other batch size: float32 rounding
