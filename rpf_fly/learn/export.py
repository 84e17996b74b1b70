"""Export a trained actor to ONNX (deterministic mean action, normalisation inside the graph) and check parity.

The graph takes ``local`` (B, 4) float32, ``neighbours`` (B, K, 3) float32 and ``mask`` (B, K) float32 (1 for a real
neighbour) with a fixed maximum ``K`` and a dynamic batch, and returns ``action`` (B, 2) = (eta, lambda) or
(B, 1) = the heading change. The network runs in float32 (as trained) when onnxruntime and torch agree within the
tolerance; float32 summation order differs between the two by up to a few 1e-6 on 256-wide layers with large
weights, so if that parity check fails the export is redone with a float64 copy of the weights inside the graph
(float32 in and out), where both compute the same function to ~1e-15. float64 costs about twice the per-drone
inference time, hence float32 first. The metadata says which (``rpf_fly.precision``). Zero neighbours (an all-zero mask)
is a valid input. Metadata properties record what the runtime needs (``rpf_fly.kind``, ``rpf_fly.action``,
``rpf_fly.max_neighbours``, the gain ranges, the planner preset). Every export runs :func:`check_parity`: onnxruntime
against torch, ``assert_allclose(rtol=1e-5, atol=1e-6)``, on random observations including empty neighbour sets.
"""

from __future__ import annotations

import copy
import hashlib
import json
import warnings
from pathlib import Path

import numpy as np
import torch
from torch import nn

from rpf_fly.learn.model import ActorCritic


class DeterministicPolicy(nn.Module):
    """The actor's mean action as a graph: float32 in and out; the network in ``precision`` inside."""

    def __init__(self, model: ActorCritic, precision: str = "float32"):
        super().__init__()
        self.dtype = torch.float64 if precision == "float64" else torch.float32
        self.model = copy.deepcopy(model).to(self.dtype).eval()

    def forward(self, local: torch.Tensor, neighbours: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        d = self.dtype
        return self.model.deterministic(local.to(d), neighbours.to(d), mask.to(d)).float()


def random_observations(n: int, max_neighbours: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Plausible observations for parity checks: distances in [0, 8] m, angles in [-pi, pi], masks with 0..K
    neighbours (every count appears, zero included)."""
    rng = np.random.default_rng(seed)
    local = np.stack(
        [rng.uniform(0, 6, n), rng.uniform(-np.pi, np.pi, n), rng.uniform(0, 8, n), rng.uniform(-np.pi, np.pi, n)], -1
    ).astype(np.float32)
    neighbours = np.stack(
        [
            rng.uniform(0, 6, (n, max_neighbours)),
            rng.uniform(-np.pi, np.pi, (n, max_neighbours)),
            rng.uniform(-np.pi, np.pi, (n, max_neighbours)),
        ],
        -1,
    ).astype(np.float32)
    counts = np.arange(n) % (max_neighbours + 1)
    mask = (np.arange(max_neighbours)[None, :] < counts[:, None]).astype(np.float32)
    neighbours *= mask[..., None]
    return local, neighbours, mask


def export_onnx(model: ActorCritic, path: str | Path, metadata: dict[str, str] | None = None) -> Path:
    """Write the deterministic policy to ``path`` and verify it against torch (float32, else float64)."""
    try:
        _export(model, path, metadata, "float32")
        check_parity(model, path, "float32")
    except AssertionError:
        _export(model, path, metadata, "float64")
        check_parity(model, path, "float64")
    return Path(path)


def _export(model: ActorCritic, path: str | Path, metadata: dict[str, str] | None, precision: str) -> None:
    import onnx

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    model.eval()
    k = model.config.max_neighbours
    local, neighbours, mask = (torch.from_numpy(a) for a in random_observations(4, k))
    policy = DeterministicPolicy(model, precision)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # torch warns that the TorchScript exporter is deprecated
        torch.onnx.export(
            policy,
            (local, neighbours, mask),
            str(path),
            input_names=["local", "neighbours", "mask"],
            output_names=["action"],
            dynamic_axes={
                "local": {0: "batch"},
                "neighbours": {0: "batch"},
                "mask": {0: "batch"},
                "action": {0: "batch"},
            },
            opset_version=17,
            dynamo=False,
        )
    proto = onnx.load(str(path))
    c = model.config
    props = {
        "rpf_fly.action": c.action,
        "rpf_fly.embedding": c.embedding,
        "rpf_fly.max_neighbours": str(k),
        "rpf_fly.eta_max": str(c.eta_max),
        "rpf_fly.lam_max": str(c.lam_max),
        "rpf_fly.heading_max": str(c.heading_max),
        "rpf_fly.precision": precision,
        **(metadata or {}),
    }
    for key, value in props.items():
        entry = proto.metadata_props.add()
        entry.key, entry.value = key, str(value)
    onnx.checker.check_model(proto)
    onnx.save(proto, str(path))


def check_parity(model: ActorCritic, path: str | Path, precision: str | None = None, n: int = 512) -> float:
    """Max |onnxruntime - torch| over random observations; raises AssertionError beyond rtol 1e-5, atol 1e-6.

    ``precision`` defaults to the one recorded in the file's metadata."""
    import onnxruntime as ort

    local, neighbours, mask = random_observations(n, model.config.max_neighbours, seed=1)
    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    precision = precision or session.get_modelmeta().custom_metadata_map.get("rpf_fly.precision", "float32")
    got = session.run(["action"], {"local": local, "neighbours": neighbours, "mask": mask})[0]
    with torch.no_grad():
        want = DeterministicPolicy(model, precision)(*(torch.from_numpy(a) for a in (local, neighbours, mask))).numpy()
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6)
    return float(np.max(np.abs(got - want)))


def float32_drift(model: ActorCritic, n: int = 512) -> float:
    """Max |float64 export - float32 trained model| over random observations (information for the model card)."""
    local, neighbours, mask = (torch.from_numpy(a) for a in random_observations(n, model.config.max_neighbours, seed=2))
    with torch.no_grad():
        exported = DeterministicPolicy(model, "float64")(local, neighbours, mask)
        trained = model.deterministic(local, neighbours, mask)
    return float((exported - trained).abs().max())


def file_sha256(path: str | Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def metadata_json(**items: object) -> str:
    return json.dumps(items, sort_keys=True)
