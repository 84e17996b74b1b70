"""The actor-critic: attention (or mean) embedding of the neighbours, 256-256 MLP heads, squashed gains.

Embedding (paper Section IV-A; docs/learning.md, *Network*), per neighbour ``j`` of a drone with local observation
``o_loc``: ``e_j = relu(W_e [o_loc, w_j])``, ``h_j = relu(W_h e_j)``, score ``b_j = MLP_b([e_j, e_m])`` with ``e_m`` the
masked mean of ``e`` (a ReLU layer, then a linear score), ``c = sum_j softmax(b)_j h_j`` over the visible neighbours
(zero when there are none). RPF-2 replaces the attention by the plain masked mean of ``h``. ``[o_loc, c]`` feeds a
256-256 tanh MLP actor and a 256-256 tanh MLP critic.

Actions: a Gaussian over an unbounded ``u`` with a state-independent log-std. ``gains`` policies map ``u`` to
``eta = eta_max * sigmoid(u_0)`` and ``lambda = lam_max * sigmoid(u_1)`` (ranges [0, 0.1] x [0, 5]); the
``heading`` policy (vanilla PPO) maps it to ``a = a_max * tanh(u)`` in [-2.5, 2.5]. PPO's log-probabilities are
those of ``u``; the export keeps only the deterministic mean.

Observation normalisation (running mean and variance, CleanRL style) lives in the model as buffers, so the ONNX
graph normalises its own inputs.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
import torch
from torch import nn

from rpf_fly.planning.observation import LOCAL_SIZE, NEIGHBOUR_SIZE


@dataclass(frozen=True)
class ModelConfig:
    """Architecture and action ranges."""

    embedding: Literal["attention", "mean"] = "attention"
    action: Literal["gains", "heading"] = "gains"
    max_neighbours: int = 10
    embed_size: int = 64
    hidden_size: int = 64
    head_size: int = 256
    eta_max: float = 0.1
    lam_max: float = 5.0
    heading_max: float = 2.5
    initial_log_std: float = -0.5

    @property
    def action_size(self) -> int:
        return 2 if self.action == "gains" else 1


def _layer(inputs: int, outputs: int, std: float = float(np.sqrt(2))) -> nn.Linear:
    """Orthogonal weights and zero biases (CleanRL's initialisation)."""
    layer = nn.Linear(inputs, outputs)
    nn.init.orthogonal_(layer.weight, std)
    nn.init.constant_(layer.bias, 0.0)
    return layer


class RunningNorm(nn.Module):
    """Running mean and variance of a feature vector (parallel Welford update); clip to +-10 after scaling."""

    mean: torch.Tensor
    var: torch.Tensor
    count: torch.Tensor

    def __init__(self, size: int):
        super().__init__()
        self.register_buffer("mean", torch.zeros(size))
        self.register_buffer("var", torch.ones(size))
        self.register_buffer("count", torch.tensor(1e-4))

    @torch.no_grad()
    def update(self, x: torch.Tensor) -> None:
        if x.shape[0] == 0:
            return
        batch_mean = x.mean(0)
        batch_var = x.var(0, unbiased=False)
        n = x.shape[0]
        delta = batch_mean - self.mean
        total = self.count + n
        self.mean += delta * n / total
        self.var = (self.var * self.count + batch_var * n + delta**2 * self.count * n / total) / total
        self.count = total

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.clamp((x - self.mean) / torch.sqrt(self.var + 1e-8), -10.0, 10.0)


class NeighbourEmbedding(nn.Module):
    """Attention or mean pooling of the neighbour set into a fixed-size context ``c``."""

    def __init__(self, config: ModelConfig):
        super().__init__()
        self.attention = config.embedding == "attention"
        e, h = config.embed_size, config.hidden_size
        # A linear layer on a concatenation [x, y] is W_x x + W_y y: two layers that broadcast, so neither the
        # graph nor the batch needs the local observation copied K times (fewer ONNX nodes, faster per drone).
        self.embed_local = _layer(LOCAL_SIZE, e)
        self.embed_neighbour = nn.Linear(NEIGHBOUR_SIZE, e, bias=False)
        nn.init.orthogonal_(self.embed_neighbour.weight, float(np.sqrt(2)))
        self.hidden = _layer(e, h)
        if self.attention:
            self.score_each = _layer(e, e)
            self.score_mean = nn.Linear(e, e, bias=False)
            nn.init.orthogonal_(self.score_mean.weight, float(np.sqrt(2)))
            self.score = _layer(e, 1, std=1.0)

    def forward(self, local: torch.Tensor, neighbours: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        """``local`` (B, 4), ``neighbours`` (B, K, 3), ``mask`` (B, K) float 0/1 -> ``c`` (B, hidden)."""
        e = torch.relu(self.embed_local(local).unsqueeze(1) + self.embed_neighbour(neighbours))  # (B, K, E)
        h = torch.relu(self.hidden(e))  # (B, K, H)
        m = mask.unsqueeze(-1)
        count = m.sum(1, keepdim=True).clamp(min=1.0)
        if not self.attention:
            return ((h * m).sum(1, keepdim=True) / count).squeeze(1)
        e_mean = (e * m).sum(1, keepdim=True) / count
        b = self.score(torch.relu(self.score_each(e) + self.score_mean(e_mean)))
        b = b + (m - 1.0) * 1e9  # masked out: -1e9 (a finite value keeps an all-masked row NaN-free)
        w = torch.softmax(b, dim=1) * m  # an all-masked row gives zero weights, so c = 0
        return (w * h).sum(1)


class ActorCritic(nn.Module):
    """Shared embedding, 256-256 actor and critic heads, Gaussian policy over ``u``."""

    def __init__(self, config: ModelConfig):
        super().__init__()
        self.config = config
        self.local_norm = RunningNorm(LOCAL_SIZE)
        self.neighbour_norm = RunningNorm(NEIGHBOUR_SIZE)
        self.embedding = NeighbourEmbedding(config)
        features = LOCAL_SIZE + config.hidden_size
        s = config.head_size
        self.actor = nn.Sequential(
            _layer(features, s), nn.Tanh(), _layer(s, s), nn.Tanh(), _layer(s, config.action_size, std=0.01)
        )
        self.critic = nn.Sequential(_layer(features, s), nn.Tanh(), _layer(s, s), nn.Tanh(), _layer(s, 1, std=1.0))
        self.log_std = nn.Parameter(torch.full((config.action_size,), config.initial_log_std))

    def update_normalisers(self, local: torch.Tensor, neighbours: torch.Tensor, mask: torch.Tensor) -> None:
        """Fold a batch of raw observations into the running statistics (neighbour stats over real neighbours)."""
        self.local_norm.update(local)
        self.neighbour_norm.update(neighbours[mask > 0.5])

    def features(self, local: torch.Tensor, neighbours: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        local_n = self.local_norm(local)
        neighbours_n = self.neighbour_norm(neighbours) * mask.unsqueeze(-1)
        return torch.cat([local_n, self.embedding(local_n, neighbours_n, mask)], dim=-1)

    def value(self, local: torch.Tensor, neighbours: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        return self.critic(self.features(local, neighbours, mask)).squeeze(-1)

    def distribution(self, features: torch.Tensor) -> torch.distributions.Normal:
        mean = self.actor(features)
        return torch.distributions.Normal(mean, self.log_std.exp().expand_as(mean))

    def act(self, local, neighbours, mask):
        """Sample ``u``; returns ``u``, its log-probability and the value."""
        f = self.features(local, neighbours, mask)
        dist = self.distribution(f)
        u = dist.sample()
        return u, dist.log_prob(u).sum(-1), self.critic(f).squeeze(-1)

    def evaluate(self, local, neighbours, mask, u):
        """Log-probability of ``u``, entropy and value under the current parameters."""
        f = self.features(local, neighbours, mask)
        dist = self.distribution(f)
        return dist.log_prob(u).sum(-1), dist.entropy().sum(-1), self.critic(f).squeeze(-1)

    def to_action(self, u: torch.Tensor) -> torch.Tensor:
        """The environment's action from ``u``: gains (eta, lambda) or the heading change ``a``."""
        c = self.config
        if c.action == "gains":
            scale = torch.tensor([c.eta_max, c.lam_max], dtype=u.dtype)
            return torch.sigmoid(u) * scale
        return c.heading_max * torch.tanh(u)

    def deterministic(self, local: torch.Tensor, neighbours: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        """The exported policy: the action of the mean ``u``."""
        return self.to_action(self.actor(self.features(local, neighbours, mask)))
