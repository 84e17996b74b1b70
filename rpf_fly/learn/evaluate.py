"""Deterministic evaluation of a torch policy in the training environment (fixed scenes, mean action).

Used to measure learning: the same seeded scenes before and after training, each arena run until its first
episode ends, the policy's mean action every step.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import torch

from rpf_fly.learn.env import EnvConfig, SwarmEnv
from rpf_fly.learn.model import ActorCritic


@dataclass(frozen=True)
class Evaluation:
    """Mean robot return, fraction of arena episodes with every drone arrived and no collision, collisions."""

    mean_return: float
    success_rate: float
    collisions: int
    episodes: int


@torch.no_grad()
def evaluate_policy(model: ActorCritic, config: EnvConfig, seed: int, episodes: int) -> Evaluation:
    """Run ``episodes`` arenas (one episode each, scenes from ``seed``) with the deterministic policy."""
    env = SwarmEnv(replace(config, n_arenas=episodes), seed=seed)
    finished: dict[int, tuple[float, bool, int]] = {}
    returns = np.zeros((episodes, config.n_robots))
    for _ in range(config.max_steps):
        obs = env.observation
        local = torch.from_numpy(obs.local.reshape(-1, 4))
        neighbours = torch.from_numpy(obs.neighbours.reshape(-1, *obs.neighbours.shape[-2:]))
        mask = torch.from_numpy(obs.mask.reshape(-1, obs.mask.shape[-1]).astype(np.float32))
        action = model.deterministic(local, neighbours, mask).numpy().reshape(episodes, config.n_robots, -1)
        done_before = env.done.copy()
        result = env.step(action)
        returns += result.reward
        ended = np.flatnonzero((done_before | result.done).all(axis=1))
        stats = iter(result.episodes)
        for b in ended.tolist():
            episode = next(stats)
            if b not in finished:
                finished[b] = (float(returns[b].mean()), episode.success, episode.collided)
        returns[ended] = 0.0
        if len(finished) == episodes:
            break
    values = list(finished.values())
    return Evaluation(
        mean_return=float(np.mean([v[0] for v in values])),
        success_rate=float(np.mean([v[1] for v in values])),
        collisions=int(sum(v[2] for v in values)),
        episodes=len(values),
    )
